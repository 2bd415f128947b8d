"""Geometry helpers against hand-computed values."""

from __future__ import annotations

import numpy as np
import pytest

from i2v_loc.geometry import matrix_to_pose, pose_matrix, rotation_angle_rad, transform_points, wrap_deg


@pytest.mark.parametrize(
    "angle, wrapped", [(0, 0), (180, 180), (-180, 180), (190, -170), (-190, 170), (540, 180), (359.5, -0.5)]
)
def test_wrap_deg(angle, wrapped):
    assert wrap_deg(angle) == pytest.approx(wrapped)


def test_pose_round_trip_and_yaw_rotates_x_to_y():
    t = pose_matrix(1.0, 2.0, 3.0, 5.0, -4.0, 90.0)
    assert matrix_to_pose(t) == pytest.approx((1.0, 2.0, 3.0, 5.0, -4.0, 90.0))
    p = transform_points(pose_matrix(0, 0, 0, 0, 0, 90), np.array([[1.0, 0.0, 0.0]]))
    assert p[0] == pytest.approx([0.0, 1.0, 0.0], abs=1e-12)


def test_rotation_angle():
    a = pose_matrix(0, 0, 0, 0, 0, 10)[:3, :3]
    b = pose_matrix(0, 0, 0, 0, 0, 40)[:3, :3]
    assert rotation_angle_rad(a, b) == pytest.approx(np.radians(30))
