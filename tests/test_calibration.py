"""The calibration registers sensors on constructed scenes with known extrinsics: the ground, one
long wall and, for part of the recording, a standing vehicle. Each sensor samples its own fixed
spots of the scene (as a static LiDAR does), with millimetre noise from sweep to sweep."""

from __future__ import annotations

import numpy as np

from i2v_loc.evaluation.calibration import extrinsics_error
from i2v_loc.geometry import extrinsics_matrix, transform_points
from i2v_loc.params import CalibrationParams, Extrinsics, SensorConfig
from i2v_loc.stages.calibration import Calibrator, rigid_step, still_points

REFERENCE = SensorConfig(name="a", extrinsics=Extrinsics(x_m=-10.0, y_m=0.0, z_m=5.0, yaw_deg=0.0))
TRUE_B = Extrinsics(x_m=10.0, y_m=0.0, z_m=5.0, roll_deg=0.5, pitch_deg=-0.3, yaw_deg=90.0)
GUESS_B = TRUE_B.model_copy(update={"x_m": 10.4, "y_m": -0.2, "yaw_deg": 93.0})  # 0.4 m along the wall
WINDOWS = 6
VEHICLE_WINDOWS = range(2, 5)


def _surface(rng, origin, u, v, density_per_m2):
    """Random points on the parallelogram origin + s u + t v (s, t in [0, 1])."""
    area = np.linalg.norm(np.cross(u, v))
    s, t = rng.random((2, int(area * density_per_m2)))
    return np.asarray(origin) + np.outer(s, u) + np.outer(t, v)


def _scene(rng):
    ground = _surface(rng, (-25, -8, 0), (50, 0, 0), (0, 28, 0), 6)
    wall = _surface(rng, (-25, 20, 0), (50, 0, 0), (0, 0, 4), 40)
    return np.vstack([ground, wall])


def _vehicle(rng):
    """A standing 12 x 2.5 x 4 m box along x at (0, 4): its sides and its ends."""
    x0, y0, length, width, height = -6.0, 2.75, 12.0, 2.5, 4.0
    faces = [
        _surface(rng, (x0, y0, 0), (length, 0, 0), (0, 0, height), 40),
        _surface(rng, (x0, y0 + width, 0), (length, 0, 0), (0, 0, height), 40),
        _surface(rng, (x0, y0, 0), (0, width, 0), (0, 0, height), 40),
        _surface(rng, (x0 + length, y0, 0), (0, width, 0), (0, 0, height), 40),
    ]
    return np.vstack(faces)


def _windows(with_vehicle: bool, seed: int = 0):
    """Per window, each sensor's three sweeps in its own frame (true extrinsics)."""
    rng = np.random.default_rng(seed)
    spots = {name: (_scene(rng), _vehicle(rng)) for name in ("a", "b")}
    to_sensor = {
        "a": np.linalg.inv(extrinsics_matrix(REFERENCE.extrinsics)),
        "b": np.linalg.inv(extrinsics_matrix(TRUE_B)),
    }
    windows = []
    for index in range(WINDOWS):
        window = {}
        for name, (scene, vehicle) in spots.items():
            points = np.vstack([scene, vehicle]) if with_vehicle and index in VEHICLE_WINDOWS else scene
            window[name] = [
                transform_points(to_sensor[name], points) + rng.normal(0, 0.002, points.shape) for _ in range(3)
            ]
        windows.append(window)
    return windows


def _calibrate(with_vehicle: bool):
    sensors = [REFERENCE, SensorConfig(name="b", extrinsics=GUESS_B)]
    results = Calibrator(CalibrationParams()).calibrate(sensors, _windows(with_vehicle))
    return {r.name: r for r in results}


def test_a_standing_vehicle_fixes_the_direction_along_the_only_wall():
    b = _calibrate(with_vehicle=True)["b"]
    error_cm, error_deg = extrinsics_error(b.extrinsics, TRUE_B)
    assert error_cm < 2.0 and error_deg < 0.1, (error_cm, error_deg)
    assert b.fitness >= CalibrationParams().min_fitness and b.target == "a"
    assert b.constraint_points > CalibrationParams().min_constraint_points


def test_without_the_vehicle_the_direction_along_the_wall_is_reported_weak():
    """Only the wall's ends and its sampling speak for x: the result says so (its x is whatever that
    weak pull gives, here 0.19 m off); y, z, yaw, roll and pitch are fixed by the wall and the ground."""
    result = _calibrate(with_vehicle=False)["b"]
    assert result.constraint_points < CalibrationParams().min_constraint_points
    b = result.extrinsics
    assert abs(b.y_m - TRUE_B.y_m) < 0.02 and abs(b.z_m - TRUE_B.z_m) < 0.02
    assert abs(b.yaw_deg - TRUE_B.yaw_deg) < 0.1
    assert abs(b.roll_deg - TRUE_B.roll_deg) < 0.1 and abs(b.pitch_deg - TRUE_B.pitch_deg) < 0.1


def test_fitness_refuses_a_sensor_25_cm_off():
    params = CalibrationParams()
    calibrator = Calibrator(params)
    windows = _windows(with_vehicle=True)
    truth = {"a": extrinsics_matrix(REFERENCE.extrinsics), "b": extrinsics_matrix(TRUE_B)}
    points = {n: [calibrator._still_points(w[n], truth[n]) for w in windows] for n in truth}
    targets = [calibrator._cloud(p) for p in points["a"]]
    at_truth, rmse = calibrator.quality(points["b"], targets)
    off = rigid_step(np.array([0, 0, 0, 0.18, 0.18, 0]), truth["b"][:3, 3])
    at_25_cm, _ = calibrator.quality([transform_points(off, p) for p in points["b"]], targets)
    assert at_truth > 0.9 and rmse < 0.01
    assert at_25_cm < params.min_fitness


def test_still_points_keep_what_stood_still_in_every_sweep():
    rng = np.random.default_rng(3)
    wall = _surface(rng, (0, 5, 0), (10, 0, 0), (0, 0, 3), 40)
    mover = _surface(rng, (0, -5, 0), (0, 0, 3), (0, 2, 0), 40)  # a face moving 0.5 m along x per sweep
    sweeps = [np.vstack([wall, mover + [0.5 * k, 0, 0]]) for k in range(3)]
    kept = still_points(sweeps)
    assert len(kept) == len(wall) and np.allclose(kept, wall)
