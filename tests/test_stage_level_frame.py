"""The articulated estimator's level frame against poses built as the simulator builds them on a
graded yard (the yard tilted about y, a vehicle's planar pose on it)."""

from __future__ import annotations

import numpy as np
import pytest

from i2v_loc.geometry import planar_pose, pose_matrix
from i2v_loc.stages.level_frame import LevelFrame
from i2v_loc.stages.region import GroundPlane


def plane(tilt: np.ndarray, offset_m: float = 0.0) -> GroundPlane:
    """The ground of a yard tilted by ``tilt`` (4x4), lowered by ``offset_m``."""
    normal = tilt[:3, :3] @ np.array([0.0, 0.0, 1.0])
    return GroundPlane(normal, offset_m, float(np.degrees(np.arccos(normal[2]))), 1.0)


@pytest.mark.parametrize("yaw_deg", [0.0, 45.0, 90.0, 160.0, -120.0])
def test_a_vehicle_on_a_grade_is_upright_and_its_yaw_is_the_simulators(yaw_deg):
    tilt = pose_matrix(0, 0, 0, 0, -3.0, 0)  # the ground rising 3 deg along +x
    pose = tilt @ planar_pose(12.0, -7.0, np.radians(yaw_deg), 0.0)
    level = LevelFrame()
    level.update(plane(tilt))
    # a vertical edge of the vehicle (upright on the ground) is vertical in the level frame
    edge = np.array([[2.0, 1.2, 0.0, 1.0], [2.0, 1.2, 3.5, 1.0]]) @ pose.T
    upright = level.points(edge[:, :3])
    assert np.allclose(upright[0, :2], upright[1, :2], atol=1e-9)
    assert upright[0, 2] == pytest.approx(level.ground(plane(tilt))(*upright[0, :2]), abs=1e-9)
    # the vehicle's level-frame yaw, turned back, is the yaw the ground truth reports
    level_yaw = np.arctan2(*(level.rotation @ pose[:3, 0])[1::-1])
    assert np.degrees(level_yaw) == pytest.approx(yaw_deg, abs=1e-9)
    truth = np.arctan2(pose[1, 0], pose[0, 0])
    assert level.yaw_to_yard(level_yaw) == pytest.approx(truth, abs=1e-12)
    assert np.allclose(level.to_yard(upright[1]), edge[1, :3], atol=1e-12)
    if yaw_deg not in (0.0, 90.0):  # up the grade or along it the projection keeps the yaw; obliquely not
        assert abs(truth - np.radians(yaw_deg)) > 1e-5


def test_level_ground_leaves_the_yard_frame_and_small_refits_do_not_turn_it():
    level = LevelFrame()
    level.update(plane(pose_matrix(0, 0, 0, 0.3, -0.2, 0)))
    assert np.array_equal(level.rotation, np.eye(3))
    level.update(plane(pose_matrix(0, 0, 0, 0, -2.0, 0)))
    turned = level.rotation.copy()
    assert not np.allclose(turned, np.eye(3))
    level.update(plane(pose_matrix(0, 0, 0, 0.1, -2.05, 0)))  # a refit a hair off
    assert np.array_equal(level.rotation, turned)
    level.update(None)  # no plane this frame
    assert np.array_equal(level.rotation, turned)
