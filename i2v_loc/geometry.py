"""Small geometry helpers shared by the simulator, the stages and the evaluation."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation


def wrap_deg(angle_deg):
    """Wrap angles to (-180, 180] degrees; works on scalars and arrays."""
    wrapped = -((-np.asarray(angle_deg, dtype=float) + 180.0) % 360.0 - 180.0)
    return float(wrapped) if np.ndim(wrapped) == 0 else wrapped


def wrap_rad(angle_rad):
    """Wrap angles to (-pi, pi] radians."""
    return np.radians(wrap_deg(np.degrees(angle_rad)))


def pose_matrix(x: float, y: float, z: float, roll_deg: float, pitch_deg: float, yaw_deg: float) -> np.ndarray:
    """4x4 homogeneous transform from translation and Z-Y-X (yaw, pitch, roll) angles in degrees."""
    t = np.eye(4)
    t[:3, :3] = Rotation.from_euler("ZYX", [yaw_deg, pitch_deg, roll_deg], degrees=True).as_matrix()
    t[:3, 3] = (x, y, z)
    return t


def matrix_to_pose(t: np.ndarray) -> tuple[float, float, float, float, float, float]:
    """Inverse of ``pose_matrix``: (x, y, z, roll_deg, pitch_deg, yaw_deg)."""
    yaw, pitch, roll = Rotation.from_matrix(t[:3, :3]).as_euler("ZYX", degrees=True)
    return float(t[0, 3]), float(t[1, 3]), float(t[2, 3]), float(roll), float(pitch), float(yaw)


def extrinsics_matrix(ext) -> np.ndarray:
    """4x4 sensor-to-yard transform of an ``Extrinsics`` section."""
    return pose_matrix(ext.x_m, ext.y_m, ext.z_m, ext.roll_deg, ext.pitch_deg, ext.yaw_deg)


def transform_points(t: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Apply a 4x4 transform to (N, 3) points."""
    return points @ t[:3, :3].T + t[:3, 3]


def planar_pose(x: float, y: float, yaw_rad: float, z: float = 0.0) -> np.ndarray:
    """4x4 transform of a pose on the ground plane."""
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    t = np.eye(4)
    t[:2, :2] = [[c, -s], [s, c]]
    t[:3, 3] = (x, y, z)
    return t


def rotation_angle_rad(r_a: np.ndarray, r_b: np.ndarray) -> float:
    """Geodesic angle between two rotation matrices (dCAP's RRA for one pair)."""
    cos = (np.trace(r_a.T @ r_b) - 1.0) / 2.0
    return float(np.arccos(np.clip(cos, -1.0, 1.0)))
