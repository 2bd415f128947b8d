"""Orientation stage: PCA yaw on the centroid history (Eq. 11-12), direction, hitch angle (Eq. 13)."""

import numpy as np
import pytest

from i2v_loc.params import OrientationParams
from i2v_loc.stages.orientation import OrientationEstimator, UnitObservation

PARAMS = OrientationParams(history_frames=10, min_travel_m=0.3, max_yaw_rate_deg_s=720.0, smoothing=0.0)


def run(estimator, tracks, n_frames=15, dt=0.1):
    """tracks: {track_id: (vehicle_id, kind, start_xy, velocity_xy, shape_axis_deg)}; returns last yaws."""
    yaws = {}
    for k in range(n_frames):
        units = [
            UnitObservation(tid, vid, kind, np.array([*(np.array(start) + k * dt * np.array(vel)), 1.0]), shape)
            for tid, (vid, kind, start, vel, shape) in tracks.items()
        ]
        yaws = estimator.process(units, k * dt, set(tracks))
    return yaws


def test_pca_yaw_on_a_straight_diagonal_track_is_45_deg():
    rng = np.random.default_rng(0)
    est = OrientationEstimator(PARAMS)
    for k in range(20):
        center = np.array([k * 0.2, k * 0.2, 1.0]) + np.r_[rng.normal(0, 0.03, 2), 0]
        yaw = est.process([UnitObservation(1, 1, "trailer", center, 0.0)], k * 0.1, {1})[1]
    assert yaw == pytest.approx(45.0, abs=0.5)


@pytest.mark.parametrize("hitch_deg", [30.0, -30.0])
@pytest.mark.parametrize("reversing", [False, True])
def test_hitch_angle_sign_forward_and_reversing(hitch_deg, reversing):
    """Truck heads along +x; the trailer's axis is at hitch_deg, and it lies behind the truck."""
    speed = -1.0 if reversing else 1.0
    trailer_dir = np.array([np.cos(np.radians(hitch_deg)), np.sin(np.radians(hitch_deg))])
    trailer_start = -6.0 * trailer_dir
    tracks = {
        1: (7, "truck", (2.0, 0.0), (speed, 0.0), 0.0),
        2: (7, "trailer", tuple(trailer_start), tuple(speed * trailer_dir), hitch_deg % 180),
    }
    yaws = run(OrientationEstimator(PARAMS), tracks)
    assert yaws[1] == pytest.approx(0.0, abs=0.5)
    assert yaws[2] == pytest.approx(hitch_deg, abs=0.5)
    assert OrientationEstimator.hitch_deg(yaws[1], yaws[2]) == pytest.approx(hitch_deg, abs=0.5)


def test_hitch_is_wrapped():
    assert OrientationEstimator.hitch_deg(170.0, -170.0) == pytest.approx(20.0)
    assert OrientationEstimator.hitch_deg(-170.0, 170.0) == pytest.approx(-20.0)
    assert OrientationEstimator.hitch_deg(None, 3.0) is None


def test_standstill_holds_the_last_yaw_and_first_estimate_uses_the_shape_axis():
    est = OrientationEstimator(PARAMS)
    # standing still from the start: shape axis 120 deg (mod 180), truck ahead along 120 deg
    fwd = np.array([np.cos(np.radians(120)), np.sin(np.radians(120))])
    for k in range(5):
        yaws = est.process(
            [
                UnitObservation(1, 1, "truck", np.r_[5 * fwd, 0], 120.0),
                UnitObservation(2, 1, "trailer", np.r_[-2 * fwd, 0], 120.0),
            ],
            k * 0.1,
            {1, 2},
        )
    assert yaws[1] == pytest.approx(120.0) and yaws[2] == pytest.approx(120.0)
    # later, tiny jitter while standing does not move the yaw even if the shape axis wobbles
    yaws = est.process([UnitObservation(1, 1, "truck", np.r_[5 * fwd + 0.01, 0], 100.0)], 0.6, {1, 2})
    assert yaws[1] == pytest.approx(120.0)


def test_yaw_change_is_rate_bounded():
    est = OrientationEstimator(
        OrientationParams(history_frames=2, min_travel_m=0.01, max_yaw_rate_deg_s=10.0, smoothing=0.0)
    )
    est.process([UnitObservation(1, 1, "truck", np.array([0.0, 0.0, 0]), 0.0)], 0.0, {1})
    first = est.process([UnitObservation(1, 1, "truck", np.array([1.0, 0.0, 0]), 0.0)], 0.1, {1})[1]
    turned = est.process([UnitObservation(1, 1, "truck", np.array([1.0, 1.0, 0]), 0.0)], 0.2, {1})[1]
    assert first == pytest.approx(0.0, abs=1e-6)
    assert turned == pytest.approx(1.0, abs=1e-6)  # 90 deg measured, 10 deg/s * 0.1 s allowed


def test_reacquired_unit_keeps_its_yaw_and_restarts_its_history():
    est = OrientationEstimator(PARAMS.model_copy(update={"history_gap_s": 0.5}))
    for k in range(10):  # driving north-east
        yaw = est.process([UnitObservation(1, 1, "trailer", np.array([k * 0.2, k * 0.2, 1.0]), 45.0)], k * 0.1, {1})[1]
    assert yaw == pytest.approx(45.0, abs=0.5)
    # back after 2 s, 5 m away to the side: without the restart the jump would be read as travel
    yaw = est.process([UnitObservation(1, 1, "trailer", np.array([1.8 + 3.5, 1.8 - 3.5, 1.0]), 45.0)], 2.9, {1})[1]
    assert yaw == pytest.approx(45.0, abs=0.5)
    assert len(est.states[1].history) == 1


def test_smoothing_does_not_halve_the_rate_bound():
    """Smoothed first, then bounded: with smoothing 0.5 the yaw still turns at max_yaw_rate_deg_s."""
    est = OrientationEstimator(
        OrientationParams(history_frames=2, min_travel_m=0.01, max_yaw_rate_deg_s=10.0, smoothing=0.5)
    )
    est.process([UnitObservation(1, 1, "truck", np.array([0.0, 0.0, 0]), 0.0)], 0.0, {1})
    est.process([UnitObservation(1, 1, "truck", np.array([1.0, 0.0, 0]), 0.0)], 0.1, {1})
    turned = est.process([UnitObservation(1, 1, "truck", np.array([1.0, 1.0, 0]), 0.0)], 0.2, {1})[1]
    assert turned == pytest.approx(1.0, abs=1e-6)  # 10 deg/s * 0.1 s, not half of it
    # a small change is smoothed, not bounded: 2 deg measured -> half of it
    est2 = OrientationEstimator(
        OrientationParams(history_frames=2, min_travel_m=0.01, max_yaw_rate_deg_s=100.0, smoothing=0.5)
    )
    est2.process([UnitObservation(1, 1, "truck", np.array([0.0, 0.0, 0]), 0.0)], 0.0, {1})
    est2.process([UnitObservation(1, 1, "truck", np.array([1.0, 0.0, 0]), 0.0)], 0.1, {1})
    yaw = est2.process([UnitObservation(1, 1, "truck", np.array([2.0, np.tan(np.radians(2.0)), 0]), 0.0)], 0.2, {1})[1]
    assert yaw == pytest.approx(1.0, abs=1e-6)


def test_rate_bound_covers_the_time_since_the_unit_was_last_seen():
    est = OrientationEstimator(
        OrientationParams(history_frames=2, min_travel_m=0.01, max_yaw_rate_deg_s=10.0, smoothing=0.0)
    )
    est.process([UnitObservation(1, 1, "truck", np.array([0.0, 0.0, 0]), 0.0)], 0.0, {1})
    est.process([UnitObservation(1, 1, "truck", np.array([1.0, 0.0, 0]), 0.0)], 0.1, {1})
    est.process([], 0.2, {1})
    est.process([], 0.3, {1})  # unseen for two frames: 0.3 s since its last sighting
    turned = est.process([UnitObservation(1, 1, "truck", np.array([1.0, 1.0, 0]), 0.0)], 0.4, {1})[1]
    assert turned == pytest.approx(3.0, abs=1e-6)


def forward_trailer_pair(truck_yaw_deg, trailer_yaw_deg, hitch_ahead_m=5.64, truck_ahead_m=3.27, shift=(0.0, 0.0)):
    """Truck and trailer centres of an articulated vehicle whose hitch is at ``shift``."""
    hitch = np.array(shift, dtype=float)
    truck = hitch + truck_ahead_m * np.array([np.cos(np.radians(truck_yaw_deg)), np.sin(np.radians(truck_yaw_deg))])
    trailer = hitch - hitch_ahead_m * np.array(
        [np.cos(np.radians(trailer_yaw_deg)), np.sin(np.radians(trailer_yaw_deg))]
    )
    return np.r_[truck, 1.0], np.r_[trailer, 1.0]


def test_provisional_shape_guess_is_replaced_at_once_by_the_first_real_measurement():
    """A lone truck standing still gets its shape axis, its direction unknown (here the wrong one);
    when its trailer appears ahead of it along that axis, the trailer-to-truck direction replaces the
    guess at once (no rate-bounded creep through 180 deg)."""
    est = OrientationEstimator(PARAMS.model_copy(update={"max_yaw_rate_deg_s": 10.0}))
    truck = np.array([0.0, 0.0, 1.0])
    guess = est.process([UnitObservation(1, 1, "truck", truck, 0.0)], 0.0, {1, 2})[1]
    assert guess == pytest.approx(0.0) and est.states[1].provisional
    yaws = est.process(
        [
            UnitObservation(1, 1, "truck", truck, 0.0),
            UnitObservation(2, 1, "trailer", np.array([8.0, 0.0, 1.0]), 0.0),
        ],
        0.1,
        {1, 2},
    )
    assert abs(yaws[1]) == pytest.approx(180.0) and abs(yaws[2]) == pytest.approx(180.0)
    assert not est.states[1].provisional
