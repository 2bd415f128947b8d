"""Geometry helpers against hand-computed values."""

from __future__ import annotations

import numpy as np
import pytest

from i2v_loc.geometry import (
    box_corners,
    box_poses,
    matrix_to_pose,
    planar_pose,
    planar_poses,
    pose_matrix,
    rigid_inverse,
    rotate_xy,
    rotation_angle_rad,
    transform_points,
    wrap_deg,
    wrap_rad,
)


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


def test_rotation_angle_of_stacks():
    a = np.stack([pose_matrix(0, 0, 0, 0, 0, y)[:3, :3] for y in (0, 10, 170)])
    b = np.stack([pose_matrix(0, 0, 0, 0, 0, y)[:3, :3] for y in (5, -20, -170)])
    np.testing.assert_allclose(rotation_angle_rad(a, b), np.radians([5, 30, 20]), atol=1e-9)


@pytest.mark.parametrize(
    "angle, wrapped",
    [
        (0, 0),
        (np.pi, np.pi),
        (-np.pi, np.pi),
        (3 * np.pi, np.pi),
        (4.0, 4.0 - 2 * np.pi),
        (-4.0, 2 * np.pi - 4.0),
        (7.0, 7.0 - 2 * np.pi),
    ],
)
def test_wrap_rad_is_half_open_like_wrap_deg(angle, wrapped):
    assert wrap_rad(angle) == pytest.approx(wrapped, abs=1e-12)
    assert isinstance(wrap_rad(angle), float)


def test_wrap_rad_on_arrays_matches_wrap_deg():
    angles = np.linspace(-20.0, 20.0, 101)
    np.testing.assert_allclose(wrap_rad(angles), np.radians(wrap_deg(np.degrees(angles))), atol=1e-12)


def test_planar_poses_stack_the_single_pose_and_move_points():
    poses = planar_poses([1.0, -2.0], [3.0, 0.5], np.radians([90.0, 180.0]), 0.7)
    assert poses.shape == (2, 4, 4)
    np.testing.assert_allclose(poses[1], planar_pose(-2.0, 0.5, np.pi, 0.7))
    # the local x axis of a 90 degree pose points along the yard's +y
    np.testing.assert_allclose(transform_points(poses[0], np.array([[2.0, 0.0, 0.0]])), [[1.0, 5.0, 0.7]], atol=1e-12)
    np.testing.assert_allclose(poses[0], pose_matrix(1.0, 3.0, 0.7, 0, 0, 90.0), atol=1e-12)


def test_box_poses_from_centres_and_headings_in_degrees():
    poses = box_poses([[5.0, 2.0, 1.75], [0.0, 0.0, 2.45]], [30.0, -120.0])
    np.testing.assert_allclose(poses[0], pose_matrix(5.0, 2.0, 1.75, 0, 0, 30.0), atol=1e-12)
    np.testing.assert_allclose(poses[1], pose_matrix(0.0, 0.0, 2.45, 0, 0, -120.0), atol=1e-12)
    assert box_poses([1.0, 2.0, 3.0], 45.0).shape == (1, 4, 4)


def test_rotate_xy_turns_counter_clockwise_and_broadcasts():
    np.testing.assert_allclose(rotate_xy([1.0, 0.0], np.pi / 2), [0.0, 1.0], atol=1e-12)
    np.testing.assert_allclose(
        rotate_xy([[1.0, 0.0], [0.0, 2.0]], np.radians([90.0, 90.0])), [[0.0, 1.0], [-2.0, 0.0]], atol=1e-12
    )
    assert rotate_xy([3.0, 4.0], np.linspace(0, 1, 5)).shape == (5, 2)
    np.testing.assert_allclose(np.linalg.norm(rotate_xy([3.0, 4.0], np.linspace(0, 6, 7)), axis=1), 5.0)


def test_box_corners_of_one_box_and_of_a_stack():
    # a 4 m x 2 m box at (10, 5) heading north: its front is at y = 7, its left side at x = 9
    corners = box_corners((10.0, 5.0, 1.0), 4.0, 2.0, np.pi / 2)
    np.testing.assert_allclose(corners, [[9.0, 7.0], [11.0, 7.0], [11.0, 3.0], [9.0, 3.0]], atol=1e-12)
    stack = box_corners([[0.0, 0.0], [10.0, 5.0]], [2.0, 4.0], [1.0, 2.0], [0.0, np.pi / 2])
    assert stack.shape == (2, 4, 2)
    np.testing.assert_allclose(stack[0], [[1.0, 0.5], [1.0, -0.5], [-1.0, -0.5], [-1.0, 0.5]])
    np.testing.assert_allclose(stack[1], corners, atol=1e-12)


def test_a_rigid_inverse_undoes_the_transform():
    from i2v_loc.geometry import extrinsics_matrix
    from i2v_loc.params import Extrinsics

    t = extrinsics_matrix(Extrinsics(x_m=3.0, y_m=-7.5, z_m=2.0, yaw_deg=130.0, pitch_deg=-4.0, roll_deg=2.5))
    inverse = rigid_inverse(t)
    assert np.allclose(inverse @ t, np.eye(4), atol=1e-12) and np.allclose(inverse, np.linalg.inv(t), atol=1e-12)
