"""Metric primitives against hand-computed values."""

from __future__ import annotations

import math

import numpy as np
import pytest

from i2v_loc.evaluation import dcap
from i2v_loc.evaluation import metrics as m
from i2v_loc.geometry import box_poses, pose_matrix
from i2v_loc.params import Params


def test_constant_yaw_bias_gives_its_rmse():
    truth = np.linspace(-170, 170, 50)
    assert m.orientation_rmse_deg(truth + 1.0, truth) == pytest.approx(1.0)


def test_yaw_error_wraps_around_180():
    assert m.angle_error_deg(179.0, -179.0) == pytest.approx(-2.0)
    assert m.angle_error_deg(-179.0, 179.0) == pytest.approx(2.0)
    assert m.orientation_rmse_deg([179.0, -179.5], [-179.0, 179.5]) == pytest.approx(math.sqrt((4 + 1) / 2))
    # exactly opposite headings are +180, the closed end of (-180, 180]
    assert m.angle_error_deg(0.0, 180.0) == pytest.approx(180.0)


def test_heading_flip_counts_errors_beyond_90_degrees():
    errors = m.angle_error_deg([10.0, 190.0, 45.0, -100.0], [10.0, 10.0, 0.0, 0.0])
    assert list(np.abs(errors)) == pytest.approx([0.0, 180.0, 45.0, 100.0])
    assert m.heading_flip_rate(errors) == pytest.approx(0.5)
    assert m.heading_flip_rate([np.nan, 5.0]) == 0.0


def test_position_rmse_eq14():
    est = [[1.0, 0.0], [0.0, 2.0]]
    gt = [[0.0, 0.0], [0.0, 0.0]]
    assert m.position_rmse_m(est, gt) == pytest.approx(math.sqrt((1 + 4) / 2))


def test_hitch_rmse_eq16_wraps_each_difference():
    # truth: truck 170, trailer -170 -> hitch +20; estimate: truck 175, trailer -168 -> hitch +17
    assert m.hitch_rmse_deg([175.0], [-168.0], [170.0], [-170.0]) == pytest.approx(3.0)
    # a common yaw error on both units leaves the hitch exact
    assert m.hitch_rmse_deg([12.0, 52.0], [32.0, 12.0], [10.0, 50.0], [30.0, 10.0]) == pytest.approx(0.0)


def test_rmse_ignores_missing_values_and_is_nan_when_empty():
    assert m.rmse([3.0, np.nan, -3.0]) == pytest.approx(3.0)
    assert math.isnan(m.rmse([np.nan]))


def test_transform_errors_on_a_known_transform():
    truth = pose_matrix(1.0, 2.0, 0.5, 0.0, 0.0, 30.0)
    estimate = pose_matrix(1.3, 1.6, 0.5, 0.0, 0.0, 35.0)
    e = m.transform_errors(estimate[None], truth[None])
    assert e["delta"][0] == pytest.approx([0.3, -0.4, 0.0])
    assert e["delta_T"][0] == pytest.approx(0.5)
    assert e["rra"][0] == pytest.approx(math.radians(5.0))
    s = m.dcap_summary(np.stack([estimate, truth]), np.stack([truth, truth]))
    assert s["delta_T_m"] == pytest.approx(0.25)
    assert s["delta_y_m"] == pytest.approx(0.2)
    assert s["rra_rad"] == pytest.approx(math.radians(5.0) / 2)


def test_latency_stats():
    s = m.latency_stats(np.arange(1, 101, dtype=float))
    assert s["mean"] == pytest.approx(50.5)
    assert s["p50"] == pytest.approx(50.5)
    assert s["p95"] == pytest.approx(95.05)


def test_association_is_optimal_and_gated():
    cost = np.array([[1.0, 0.5], [0.6, 10.0], [np.inf, 9.0]])
    # greedy would give row 0 -> col 1 (0.5) and strand row 1; the optimum is 0->1, 1->0
    assert sorted(m.associate(cost, gate=2.0)) == [(0, 1), (1, 0)]
    assert m.associate(np.array([[5.0]]), gate=2.0) == []
    assert m.associate(np.zeros((0, 3)), gate=2.0) == []


def test_id_switches_skip_gaps():
    assert m.id_switches([1, 1, None, 1, 2, 2, None, 3]) == 2
    assert m.id_switches([None, None]) == 0


def test_front_to_rear_with_known_hitch_angle():
    """Straight vehicle: F and B lie on the axis; the transform is a pure translation whose x
    is the distance from the cab's front to the trailer's rear."""
    v = Params().vehicles["man_tgx"]
    static = dcap.static_front_to_rear(v)
    assert np.allclose(static[:3, :3], np.eye(3))
    truck_centre_x = v.truck.wheelbase_m + v.truck.front_overhang_m - v.truck.length_m / 2  # from the rear axle
    front_x = truck_centre_x + v.truck.length_m / 2
    rear_x = -v.truck.hitch_behind_rear_axle_m + v.trailer.hitch_to_front_m - v.trailer.length_m
    assert static[0, 3] == pytest.approx(front_x - rear_x)  # F seen from B: ahead, along +x
    assert static[1, 3] == pytest.approx(0.0)
    top_truck = v.truck.floor_m + v.truck.height_m
    top_trailer = v.trailer.floor_m + v.trailer.height_m
    assert static[2, 3] == pytest.approx(top_truck - top_trailer)


def test_front_to_rear_rotation_is_the_hitch_angle():
    v = Params().vehicles["volvo_fh"]
    truck = box_poses([[5.0, 2.0, 1.75]], [30.0])
    trailer = box_poses([[0.0, 0.0, 2.45]], [10.0])
    t = dcap.front_to_rear(truck, trailer, v)[0]
    assert math.degrees(math.atan2(t[1, 0], t[0, 0])) == pytest.approx(20.0)
    assert m.transform_errors(t[None], dcap.static_front_to_rear(v)[None])["rra"][0] == pytest.approx(
        math.radians(20.0)
    )
