"""The hinged two-box fit on constructed points: known pose and hitch recovered."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from hinged_points import vehicle_points

from i2v_loc.params import Params
from i2v_loc.stages.hinged_fit import (
    CHASSIS_GAP_M,
    LEFT,
    REAR,
    Measurement,
    Prior,
    TurnFrame,
    explained_share,
    faces,
    fit,
    fit_hinge,
    rear_sigma_m,
    trailer_pose_only,
    with_rear_end,
)
from i2v_loc.stages.vehicle_model import VehicleModel

PARAMS = Params()
SENSORS = ((0.0, -15.0, 4.0), (-22.0, 18.0, 4.0))
TRUTH = (2.0, 3.0, np.radians(20.0))  # tractor rear axle x, y, yaw
PRIOR_OFFSET = (0.3, -0.2, np.radians(2.0), np.radians(3.0))  # a poor prediction


def volvo() -> VehicleModel:
    return VehicleModel.from_config("volvo_fh", PARAMS.vehicles["volvo_fh"])


def no_gap() -> VehicleModel:
    """The Volvo with the trailer's front face on the cab's back face (at hitch 0)."""
    m = volvo()
    cab_back_from_kingpin = m.tractor.rear_m + m.kingpin_behind_axle_m
    return replace(m, trailer=replace(m.trailer, front_m=cab_back_from_kingpin))


def check(model: VehicleModel, hitch_deg: float, drop=(), sensors=SENSORS, hitch_tol_deg: float = 0.3) -> None:
    hitch = np.radians(hitch_deg)
    points = vehicle_points(model, *TRUTH, hitch, sensors=sensors, drop=drop, seed=int(hitch_deg) + 100)
    dx, dy, dyaw, dhitch = PRIOR_OFFSET
    prior = Prior(TRUTH[0] + dx, TRUTH[1] + dy, TRUTH[2] + dyaw, hitch + dhitch, model)
    m = fit(points, prior, PARAMS.articulated, iterations=20)
    assert m is not None
    assert np.hypot(m.x_m - TRUTH[0], m.y_m - TRUTH[1]) < 0.03
    assert abs(np.degrees(m.yaw_rad - TRUTH[2])) < 0.2
    assert abs(np.degrees(m.hitch_rad - hitch)) < hitch_tol_deg
    assert np.mean(m.explained) > 0.95
    sigma_hitch_deg = np.degrees(np.sqrt(m.covariance[3, 3]))
    assert 0.05 < sigma_hitch_deg < 1.0


@pytest.mark.parametrize("hitch_deg", [0.0, 45.0, 80.0, -80.0])
def test_fit_recovers_pose_and_hitch_with_a_gap(hitch_deg):
    assert volvo().trailer.front_m + volvo().kingpin_behind_axle_m < volvo().tractor.rear_m - 1.0  # a gap > 1 m
    check(volvo(), hitch_deg)


@pytest.mark.parametrize("hitch_deg", [0.0, 15.0])
def test_fit_recovers_pose_and_hitch_without_a_gap(hitch_deg):
    check(no_gap(), hitch_deg)


@pytest.mark.parametrize("hitch_deg, face", [(45.0, (1, "left")), (0.0, (1, "rear")), (80.0, (0, "front"))])
def test_fit_with_one_face_occluded(hitch_deg, face):
    check(volvo(), hitch_deg, drop=(face,))


@pytest.mark.parametrize("name, hitch_tol_deg", [("man_tgx", 0.3), ("twizy", 0.5)])  # the Twizy's trailer is 2.5 m long
def test_semitrailer_and_drawbar_trailer_at_45_deg(name, hitch_tol_deg):
    """Over ten noise draws: one draw moves the Twizy's 2 m car's yaw by up to 0.45 deg (the even
    thinning's too), so the errors are judged as RMS, each draw's position within 3 cm."""
    model, hitch = VehicleModel.from_config(name, PARAMS.vehicles[name]), np.radians(45.0)
    dx, dy, dyaw, dhitch = PRIOR_OFFSET
    prior = Prior(TRUTH[0] + dx, TRUTH[1] + dy, TRUTH[2] + dyaw, hitch + dhitch, model)
    errors = []
    for seed in range(10):
        points = vehicle_points(model, *TRUTH, hitch, sensors=SENSORS, seed=1000 + seed)
        m = fit(points, prior, PARAMS.articulated, iterations=20)
        assert np.hypot(m.x_m - TRUTH[0], m.y_m - TRUTH[1]) < 0.03 and np.mean(m.explained) > 0.95
        errors.append((np.degrees(m.yaw_rad - TRUTH[2]), np.degrees(m.hitch_rad - hitch)))
    yaw_rms, hitch_rms = np.sqrt(np.mean(np.square(errors), axis=0))
    assert yaw_rms < 0.25 and hitch_rms < hitch_tol_deg


def test_rigid_vehicle_fit():
    bus = VehicleModel.rigid("rigid", 11.6, 2.55, 3.1)
    points = vehicle_points(bus, 1.0, 2.0, 0.4, sensors=SENSORS)
    m = fit(points, Prior(1.3, 1.8, 0.43, 0.0, bus), PARAMS.articulated, iterations=20)
    assert m.hitch_rad is None and m.covariance.shape == (3, 3)
    assert np.hypot(m.x_m - 1.0, m.y_m - 2.0) < 0.03 and abs(np.degrees(m.yaw_rad - 0.4)) < 0.2


def test_foreign_points_are_not_explained_and_do_not_move_the_fit():
    model = volvo()
    points = vehicle_points(model, *TRUTH, 0.5, sensors=SENSORS)
    pole = np.column_stack([np.full(40, 4.0), np.full(40, 7.5), np.linspace(0.2, 3.0, 40)])  # 1.5 m beside the cab
    m = fit(np.vstack([points, pole]), Prior(*TRUTH, 0.5, model), PARAMS.articulated)
    near_pole = np.hypot(m.points[:, 0] - 4.0, m.points[:, 1] - 7.5) < 0.2
    assert near_pole.any() and not m.explained[near_pole].any()
    assert np.hypot(m.x_m - TRUTH[0], m.y_m - TRUTH[1]) < 0.03 and abs(np.degrees(m.hitch_rad - 0.5)) < 0.3


def test_hidden_trailer_leaves_the_hitch_at_the_prior_and_says_so():
    model = volvo()
    points = vehicle_points(
        model, *TRUTH, 0.3, sensors=SENSORS, drop=tuple((1, f) for f in ("front", "rear", "left", "right", "roof"))
    )
    m = fit(points, Prior(*TRUTH, 0.2, model), PARAMS.articulated)
    assert abs(m.hitch_rad - 0.2) < np.radians(1.0)  # not measured: kept at the prior
    assert np.degrees(np.sqrt(m.covariance[3, 3])) > 10.0  # and its sigma says so


def test_too_few_points_is_no_measurement():
    model = volvo()
    assert fit(np.zeros((5, 3)), Prior(*TRUTH, 0.0, model), PARAMS.articulated) is None


def test_analytic_jacobian_matches_finite_differences():
    from i2v_loc.stages.hinged_fit import faces

    model = volvo()
    v = np.array([*TRUTH, 0.6])
    points = vehicle_points(model, *v, sensors=SENSORS, noise_m=0.05)[::7]
    z = points[:, 2]
    at = faces(v, points[:, :2], z, model, 0.25, trailer_slack_m=1.0)
    eps = 1e-6
    for k in range(4):
        step = np.zeros(4)
        step[k] = eps
        numeric = (
            faces(v + step, points[:, :2], z, model, 0.25, 1.0).residual
            - faces(v - step, points[:, :2], z, model, 0.25, 1.0).residual
        ) / (2 * eps)
        same_face = np.abs(numeric) < 1e3  # a point switching faces inside the step has no derivative
        np.testing.assert_allclose(at.jacobian[same_face, k], numeric[same_face], atol=1e-5)


def test_a_hidden_cab_is_not_measured_only_its_trailer_is():
    """A cab hidden from every sensor: the fit's observed directions are the trailer's pose; turning
    the cab about the kingpin (the trailer standing still) is none of them, whereas with the cab
    seen all four directions are measured."""
    model, hitch = volvo(), np.radians(30.0)
    cab = tuple((0, f) for f in ("front", "rear", "left", "right", "roof"))
    hidden = vehicle_points(model, *TRUTH, hitch, sensors=SENSORS, drop=cab)
    prior = Prior(*TRUTH, hitch, model)
    rows, noise = fit(hidden, prior, PARAMS.articulated).observed
    assert rows.shape[0] == 3 and noise.shape == (3, 3)
    m_kp, yaw = model.kingpin_behind_axle_m, TRUTH[2]
    cab_turn = np.array([-m_kp * np.sin(yaw), m_kp * np.cos(yaw), 1.0, -1.0])  # kingpin, trailer fixed
    trailer_yaw = np.array([0.0, 0.0, 0.0, 1.0])
    assert np.all(np.abs(rows @ cab_turn) < 0.05 * np.linalg.norm(rows, axis=1) * np.linalg.norm(cab_turn))
    assert np.abs(rows @ trailer_yaw).max() > 0.5 * np.linalg.norm(rows, axis=1).max()
    seen = fit(vehicle_points(model, *TRUTH, hitch, sensors=SENSORS), prior, PARAMS.articulated)
    assert seen.observed[0].shape[0] == 4
    # all measured: the observed directions carry the covariance's information (the weak prior's aside)
    information = seen.observed[0].T @ np.linalg.inv(seen.observed[1]) @ seen.observed[0]
    assert np.allclose(np.linalg.inv(information), seen.covariance, rtol=0.05, atol=1e-6)


def test_the_trailers_pose_alone_is_its_kingpin_and_yaw_as_the_fit_measured_them():
    """``trailer_pose_only`` of a fit that saw both units: three directions, none of them the cab
    turned about the kingpin (the trailer standing still), carrying the fit's information on the
    kingpin's place and the trailer's yaw (no floor: it is added per measured direction)."""
    params = PARAMS.articulated.model_copy(update={"fit_position_floor_m": 0.0, "fit_angle_floor_deg": 0.0})
    model, hitch = volvo(), np.radians(30.0)
    prior = Prior(*TRUTH, hitch, model)
    m = fit(vehicle_points(model, *TRUTH, hitch, sensors=SENSORS), prior, params)
    rows, noise = trailer_pose_only(m, model, params).observed
    assert rows.shape == (3, 4) and noise.shape == (3, 3)
    m_kp, yaw = model.kingpin_behind_axle_m, m.yaw_rad
    cab_turn = np.array([-m_kp * np.sin(yaw), m_kp * np.cos(yaw), 1.0, -1.0])
    assert np.abs(rows @ cab_turn).max() < 1e-9 * np.abs(rows).max()
    kingpin_and_yaw = np.array(
        [[1.0, 0.0, m_kp * np.sin(yaw), 0.0], [0.0, 1.0, -m_kp * np.cos(yaw), 0.0], [0, 0, 1, 1]]
    )
    measured = np.linalg.inv(rows.T @ np.linalg.inv(noise) @ rows + np.outer(cab_turn, cab_turn))  # cab turn pinned
    fitted = kingpin_and_yaw @ m.covariance @ kingpin_and_yaw.T
    assert np.allclose(np.diag(kingpin_and_yaw @ measured @ kingpin_and_yaw.T), np.diag(fitted), rtol=0.1)


def test_the_observed_directions_are_the_data_information_less_the_prior():
    """The compiled directions against the plain arithmetic: inverse covariance less the prior's
    information, eigen-directions in the prior's units kept above the prior's own."""
    from i2v_loc.stages.hinged_fit import _observed

    rng = np.random.default_rng(5)
    sigmas, floor = np.array([2.0, 2.0, 0.35, 0.52]), np.array([0.02, 0.02, 0.003, 0.003])
    for _ in range(50):
        a = rng.normal(size=(4, 4)) * rng.uniform(0.01, 3.0, 4)
        data = a @ a.T  # some directions well seen, others hardly
        marginal = np.linalg.inv(data + np.diag(1 / sigmas**2))
        rows, noise = _observed(marginal, sigmas, floor)
        values, vectors = np.linalg.eigh(sigmas[:, None] * data * sigmas[None, :])
        keep = values > 1.0
        assert rows.shape[0] == keep.sum()
        want = (vectors[:, keep] / sigmas[:, None]) @ np.diag(values[keep]) @ (vectors[:, keep] / sigmas[:, None]).T
        seen = rows.T @ np.linalg.inv(noise - (rows * floor**2) @ rows.T) @ rows
        assert np.allclose(seen, want, rtol=1e-6, atol=1e-9 * np.abs(want).max())


def test_a_few_cab_points_among_thousands_of_trailer_points_still_measure_the_cab():
    """One sensor sees a cab's corner (40 points) behind a densely seen trailer (thousands): the
    fit's sample keeps a share of the cab's points, so the cab's yaw is measured (all four pose
    directions) and the hitch comes out right; an even stride over all points kept one or two."""
    model, hitch = volvo(), np.radians(30.0)
    cab_hidden = tuple((0, f) for f in ("front", "rear", "left", "right", "roof"))
    trailer_hidden = tuple((1, f) for f in ("front", "rear", "left", "right", "roof"))
    trailer = vehicle_points(model, *TRUTH, hitch, sensors=SENSORS, spacing=0.05, drop=cab_hidden)
    cab = vehicle_points(model, *TRUTH, hitch, sensors=SENSORS, drop=trailer_hidden)
    cab = cab[np.random.default_rng(3).choice(len(cab), 40, replace=False)]
    points = np.vstack([trailer, cab])
    points = points[np.lexsort((points[:, 1], points[:, 0]))]  # spatial order, as voxel centroids come
    assert len(trailer) > 50 * len(cab)
    dx, dy, dyaw, dhitch = PRIOR_OFFSET
    prior = Prior(TRUTH[0] + dx, TRUTH[1] + dy, TRUTH[2] + dyaw, hitch + dhitch, model)
    m = fit(points, prior, PARAMS.articulated, iterations=20)
    assert np.count_nonzero(m.unit == 0) >= 15
    assert m.observed[0].shape[0] == 4
    assert abs(np.degrees(m.yaw_rad - TRUTH[2])) < 0.5 and abs(np.degrees(m.hitch_rad - hitch)) < 0.5


def test_the_sample_keeps_each_unit_a_tenth_and_stays_within_the_budget():
    from i2v_loc.stages.hinged_fit import thin_by_unit

    model = volvo()
    prior = Prior(*TRUTH, 0.0, model)
    tractor_c, trailer_c = model.box_centers(*TRUTH, 0.0)
    rng = np.random.default_rng(0)
    on_cab = np.column_stack([tractor_c + rng.normal(0.0, 0.3, (30, 2)), np.ones(30)])
    on_trailer = np.column_stack([trailer_c + rng.normal(0.0, 0.5, (3000, 2)), np.ones(3000)])
    sample = thin_by_unit(np.vstack([on_trailer, on_cab]), 200, prior)
    assert len(sample) == 200
    assert (np.linalg.norm(sample[:, :2] - tractor_c, axis=1) < 1.5).sum() == 20  # a tenth of 200, not 2
    many_cab = np.column_stack([tractor_c + rng.normal(0.0, 0.3, (1000, 2)), np.ones(1000)])  # a quarter
    sample = thin_by_unit(np.vstack([on_trailer, many_cab]), 200, prior)
    assert len(sample) == 200 and (np.linalg.norm(sample[:, :2] - tractor_c, axis=1) < 1.5).sum() == 50


def test_a_hidden_cab_folded_over_its_trailer_gets_no_share_of_the_trailers_points():
    """Folded at 60 degrees the MAN's cab box (grown by the sample's margin) overlaps its trailer:
    with the cab hidden, the points in that box are the trailer's, and they are not given the
    cab's tenth of the sample (20 of 200): about their even share stays (3)."""
    import math

    from i2v_loc.stages import kernels
    from i2v_loc.stages.hinged_fit import UNIT_SAMPLE_MARGIN_M, thin_by_unit

    model, hitch = VehicleModel.from_config("man_tgx", PARAMS.vehicles["man_tgx"]), np.radians(60.0)
    cab_hidden = tuple((0, f) for f in ("front", "rear", "left", "right", "roof"))
    points = vehicle_points(model, *TRUTH, hitch, sensors=SENSORS, spacing=0.05, drop=cab_hidden)
    tractor_c, _ = model.box_centers(*TRUTH, hitch)
    grow = UNIT_SAMPLE_MARGIN_M
    cab_box = np.array(
        [*tractor_c, math.cos(TRUTH[2]), math.sin(TRUTH[2]), model.tractor.length_m / 2 + grow,
         model.tractor.width_m / 2 + grow]
    )  # fmt: skip

    def in_cab_box(p):
        return kernels.in_upright_box(np.ascontiguousarray(p), cab_box, np.empty(len(p), dtype=bool))

    assert in_cab_box(points) > 300  # the trailer's points reach into the cab's box
    assert in_cab_box(thin_by_unit(points, 200, Prior(*TRUTH, hitch, model))) <= 6


def twizy() -> VehicleModel:
    return VehicleModel.from_config("twizy", PARAMS.vehicles["twizy"])


def behind_cab(model: VehicleModel, x: float, y: float, yaw: float, back_m, across_m, z_m) -> np.ndarray:
    """Yard points ``back_m`` behind the cab's rear face, ``across_m`` left of its axis, ``z_m`` high."""
    local_x, local_y = model.tractor.rear_m - np.ravel(back_m), np.ravel(across_m)
    c, s = np.cos(yaw), np.sin(yaw)
    return np.column_stack([x + c * local_x - s * local_y, y + s * local_x + c * local_y, np.ravel(z_m)])


def test_the_chassis_behind_a_cab_is_not_its_rear_face():
    """Behind an articulated vehicle's cab, below half its height and within its width, stand its
    chassis, coupling and rear wheels (the simulator's Twizy has a plate there, 0.6-0.75 m high):
    more than CHASSIS_GAP_M behind the rear face such a point says nothing (residual 0, face -1);
    nearer, higher or beside the cab it is the rear face's. A start's hypothesis excuses none."""
    model, hitch = twizy(), np.radians(10.0)
    v = np.array([*TRUTH, hitch])
    half = model.tractor.floor_m + model.tractor.height_m / 2
    back = np.array([0.3, 0.45, 0.05, 0.3, 0.3])
    across = np.array([0.2, -0.5, 0.2, 0.2, model.tractor.width_m / 2 + 0.2])
    z = np.array([half - 0.2, 0.4, half - 0.2, half + 0.2, half - 0.2])
    xy = behind_cab(model, *TRUTH, back, across, z)[:, :2]
    tracked = faces(v, xy, z, model, PARAMS.articulated.fit_top_band_m)
    assert tracked.unit.tolist() == [0] * 5
    assert tracked.face.tolist()[:4] == [-1, -1, REAR, REAR] and tracked.face[4] >= 0  # the last: its side's
    np.testing.assert_allclose(tracked.residual[:2], 0.0)
    np.testing.assert_allclose(tracked.jacobian[:2], 0.0)
    np.testing.assert_allclose(tracked.residual[2:4], back[2:4], atol=1e-9)  # on the rear face's plane
    placed = faces(v, xy, z, model, PARAMS.articulated.fit_top_band_m, chassis_gap_m=np.inf)
    assert placed.face.tolist()[:4] == [REAR] * 4
    np.testing.assert_allclose(placed.residual[:2], back[:2], atol=1e-9)
    assert Prior(*TRUTH, hitch, model).chassis_gap_m == CHASSIS_GAP_M < 0.3
    assert Prior(*TRUTH, hitch, model, hypothesis=True).chassis_gap_m == np.inf


def test_a_plate_behind_the_cab_leaves_the_fit_at_its_pose():
    model, hitch = twizy(), np.radians(10.0)
    back, across = np.meshgrid(np.arange(0.15, 0.5, 0.025), np.arange(0.0, 0.5, 0.025))
    plate = behind_cab(model, *TRUTH, back, across, np.full(back.size, 0.65))
    points = np.vstack([vehicle_points(model, *TRUTH, hitch, sensors=SENSORS, seed=5), plate])
    dx, dy, dyaw, dhitch = PRIOR_OFFSET
    m = fit(points, Prior(TRUTH[0] + dx, TRUTH[1] + dy, TRUTH[2] + dyaw, hitch + dhitch, model), PARAMS.articulated, 20)
    assert np.hypot(m.x_m - TRUTH[0], m.y_m - TRUTH[1]) < 0.03
    assert abs(np.degrees(m.yaw_rad - TRUTH[2])) < 0.2 and abs(np.degrees(m.hitch_rad - hitch)) < 0.3
    on_plate = np.isclose(m.points[:, 2], 0.65)
    assert on_plate.sum() >= 5 and (m.face[on_plate] == -1).all()


def test_the_hinge_fitted_to_a_turns_frames_at_once_is_the_truth_where_single_frames_are_not():
    """A tractor with its kingpin on the rear axle and its trailer's front 1.5 m ahead of it, taken
    for the catalogue's Volvo FH (kingpin 0.3 m ahead, front 0.9 m), seen by one sensor at hitch
    angles of 20-45 deg. Each frame fitted with the hinge free stops in the valley where kingpin
    and front trade; the six frames fitted together with one shared hinge find it within 3 cm."""
    model = volvo()
    truth = replace(model, kingpin_behind_axle_m=0.0, trailer=replace(model.trailer, front_m=1.5))
    frames, single_kingpins = [], []
    for k, hitch_deg in enumerate([20, 25, 30, 35, 40, 45]):
        yaw, hitch = TRUTH[2] + np.radians(3 * k), np.radians(-hitch_deg)
        points = vehicle_points(truth, TRUTH[0], TRUTH[1], yaw, hitch, sensors=[SENSORS[0]], seed=k)
        m = fit(points, Prior(TRUTH[0], TRUTH[1], yaw, hitch, model), PARAMS.articulated, iterations=20)
        free = fit(points, replace(Prior(m.x_m, m.y_m, m.yaw_rad, m.hitch_rad, model), free_kingpin=True),
                   PARAMS.articulated, iterations=20)  # fmt: skip
        single_kingpins.append(free.kingpin_m)
        frames.append(TurnFrame.of(m, 0.0, model, PARAMS.articulated.fit_top_band_m))
    hinge = fit_hinge(frames, model, PARAMS.articulated)
    assert hinge.kingpin_m == pytest.approx(0.0, abs=0.03)
    assert hinge.trailer_front_m == pytest.approx(1.5, abs=0.03)
    assert max(abs(k) for k in single_kingpins) > 0.1
    assert hinge.std_m.max() < 0.05 and len(hinge.poses) == 6


def _turn_frames(truth: VehicleModel, model: VehicleModel, sensor, hitches_deg, first: int = 0) -> list[TurnFrame]:
    """Frames of a turn seen by one ``sensor``, each fitted with ``model`` from the true pose."""
    frames = []
    for k, hitch_deg in enumerate(hitches_deg, start=first):
        yaw, hitch = TRUTH[2] + np.radians(3 * k), np.radians(hitch_deg)
        points = vehicle_points(truth, TRUTH[0], TRUTH[1], yaw, hitch, sensors=[sensor], seed=k)
        m = fit(points, Prior(TRUTH[0], TRUTH[1], yaw, hitch, model), PARAMS.articulated, iterations=20)
        frames.append(TurnFrame.of(m, 0.0, model, PARAMS.articulated.fit_top_band_m))
    return frames


def test_the_cabs_length_fitted_with_the_hinge_keeps_a_cab_seen_from_behind_from_moving_the_kingpin():
    """A tractor with its cab 0.3 m shorter than the catalogue's Volvo and its kingpin on the rear
    axle (0.3 m ahead), seen by one sensor from behind (the cab's rear face shows, not its front)
    and then from ahead. With the catalogue's cab the rear face moves the kingpin by the cab's
    error, and frames of both views disagree; with the cab's length shared, the rear view alone pins
    the kingpin only given the length (the length is not measured), both views pin all three."""
    model = volvo()
    truth = replace(model, kingpin_behind_axle_m=0.0, tractor=replace(model.tractor, length_m=2.25))
    from_behind = _turn_frames(truth, model, (-10.0, 7.0, 4.0), [25, 30, 35, 40])
    from_ahead = _turn_frames(truth, model, (14.0, -4.0, 4.0), [25, 30, 35, 40], first=4)
    cab_prior = (model.tractor.length_m, 0.3)
    assert fit_hinge(from_behind, model, PARAMS.articulated).kingpin_m == pytest.approx(0.3, abs=0.05)
    alone = fit_hinge(from_behind, model, PARAMS.articulated, cab_prior=cab_prior)
    assert alone.std_m.max() < 0.05 and alone.cab_std_m > 0.1
    fixed = fit_hinge(from_behind + from_ahead, model, PARAMS.articulated)
    assert max(abs(fixed.kingpin_m), abs(fixed.trailer_front_m - 0.9)) > 0.1
    both = fit_hinge(from_behind + from_ahead, model, PARAMS.articulated, cab_prior=cab_prior)
    assert both.kingpin_m == pytest.approx(0.0, abs=0.03)
    assert both.trailer_front_m == pytest.approx(0.9, abs=0.03)
    assert both.cab_length_m == pytest.approx(2.25, abs=0.03) and both.cab_std_m < 0.05


def test_the_cabs_length_is_fitted_with_the_hinge_only_once_its_rear_face_showed():
    """The same tractor (cab 0.3 m shorter than the catalogue's) seen from ahead only: nothing shows
    the cab's rear face, so its length is not fitted (the catalogue's stays; fitted, a cab could grow
    back into the gap unseen); the kingpin and the front are those fitted without it. The frames
    seen from behind show the face below the cab's roof, and count its points."""
    model = volvo()
    truth = replace(model, kingpin_behind_axle_m=0.0, tractor=replace(model.tractor, length_m=2.25))
    from_ahead = _turn_frames(truth, model, (14.0, -4.0, 4.0), [25, 30, 35, 40])
    from_behind = _turn_frames(truth, model, (-10.0, 7.0, 4.0), [25, 30, 35, 40])
    assert [f.cab_rear_points for f in from_ahead] == [0, 0, 0, 0]
    assert sum(f.cab_rear_points for f in from_behind) >= 3 * len(from_behind)
    ahead = fit_hinge(from_ahead, model, PARAMS.articulated, cab_prior=(model.tractor.length_m, 0.3))
    assert ahead.cab_length_m is None and ahead.cab_std_m == np.inf
    without = fit_hinge(from_ahead, model, PARAMS.articulated)
    assert (ahead.kingpin_m, ahead.trailer_front_m) == (without.kingpin_m, without.trailer_front_m)
    assert ahead.kingpin_m == pytest.approx(0.0, abs=0.05)
    behind = fit_hinge(from_behind, model, PARAMS.articulated, cab_prior=(model.tractor.length_m, 0.3))
    assert behind.cab_length_m is not None


def test_a_turn_frame_counts_the_cabs_rear_points_below_its_roof_band_only():
    """Points a fit put on the cab's rear face in its roof band or above its roof are not on it (the
    roof's edge, or a trailer's front seen above a lower cab): ``TurnFrame.of`` does not count them,
    nor the trailer's or another face's."""
    model, band = volvo(), PARAMS.articulated.fit_top_band_m
    top = model.tractor.top_m
    heights = np.array([1.0, 1.5, 2.0, top - band - 0.05, top - band + 0.05, top + 0.2, 2.0, 2.0])
    points = np.column_stack([np.zeros((len(heights), 2)), heights + 0.4])  # on ground 0.4 m high
    unit = np.array([0, 0, 0, 0, 0, 0, 1, 0], dtype=np.int8)
    face = np.array([REAR] * 7 + [LEFT], dtype=np.int8)
    m = Measurement(*TRUTH, 0.0, np.eye(4), points, unit, 0.0, face=face)
    assert TurnFrame.of(m, 0.4, model, band).cab_rear_points == 4
    assert TurnFrame.of(m, 0.0, model, band).cab_rear_points == 3
    assert TurnFrame.of(m, 0.4, model, 0.0).cab_rear_points == 5


def test_a_rear_end_seen_moves_the_fit_along_the_trailer_as_far_as_the_fit_is_unsure():
    """The trailer's rear end seen 0.4 m behind the fit's rear face (sigma 0.15 m): a fit unsure
    along the trailer (2 m) moves back 0.4 m along the trailer's axis (30 deg: the tractor's hitch
    and yaw stay) and is sure within 0.15 m after; a fit sure within 2 cm barely moves."""
    model, yaw, hitch = volvo(), np.radians(10.0), np.radians(20.0)
    points = vehicle_points(model, 2.0, 3.0, yaw, hitch, sensors=SENSORS)
    m = fit(points, Prior(2.0, 3.0, yaw, hitch, model), PARAMS.articulated)
    params, floor = PARAMS.articulated, np.diag([0.03, 0.03, np.radians(0.3), np.radians(0.3)]) ** 2
    axis = np.array([np.cos(yaw + hitch), np.sin(yaw + hitch)])
    for along_sigma, moved in ((2.0, -0.4), (0.02, -0.4 * 0.02**2 / (0.02**2 + 0.15**2))):
        pose = np.diag([0.02, 0.02, np.radians(0.1), np.radians(0.1)]) ** 2
        pose[:2, :2] += (along_sigma**2 - 0.02**2) * np.outer(axis, axis)
        unsure = replace(m, covariance=pose + floor)
        assert rear_sigma_m(unsure, model, params) == pytest.approx(along_sigma, rel=0.02)
        fused = with_rear_end(unsure, model, -0.4, 0.15, params)
        step = fused.vector - m.vector
        assert step[:2] @ axis == pytest.approx(moved, abs=0.005)
        assert abs(step[:2] @ np.array([-axis[1], axis[0]])) < 0.005 and np.abs(step[2:]).max() < 1e-3
        assert rear_sigma_m(fused, model, params) < min(along_sigma, 0.15)


def test_a_rigid_boxs_lower_roof_step_is_explained_and_a_crowns_inside_is_not():
    """A rigid box explains the points inside its footprint that are the highest of their column
    (a truck's cab roof 1 m below its cargo box's), not those with others above them (a crown's
    inside), nor anything outside it; an articulated fit's share is its own labels'."""
    model = VehicleModel.rigid("rigid", 10.0, 2.5, 3.6)
    side = np.column_stack([np.linspace(-4.9, 4.9, 50), np.full(50, -1.25), np.full(50, 2.0)])
    cab_roof = np.column_stack([np.linspace(3.0, 4.8, 10), np.zeros(10), np.full(10, 2.6)])
    below_it = cab_roof - [0.0, 0.0, 1.0]  # inside, under the roof's points: no body's surface
    outside = np.array([[6.0, 0.0, 2.6], [0.0, 3.0, 2.6]])
    points = np.vstack([side, cab_roof, below_it, outside])
    unit = np.r_[np.zeros(50), np.full(22, -1)].astype(np.int8)
    m = Measurement(0.0, 0.0, 0.0, None, np.eye(3), points, unit, 0.0)
    assert explained_share(m, model) == pytest.approx(60 / 72)
    turned = replace(m, yaw_rad=np.pi / 2)  # the same points, the box across them: the roof outside
    assert explained_share(turned, model) < 55 / 72
    hinged = VehicleModel.from_config("man_tgx", Params().vehicles["man_tgx"])
    assert explained_share(replace(m, hitch_rad=0.0), hinged) == pytest.approx(50 / 72)
