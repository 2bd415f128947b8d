"""Small geometry helpers shared by the simulator, the stages and the evaluation."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation


def _wrap(angle, half_turn: float):
    """Wrap to (-half_turn, half_turn]; scalars stay floats, arrays stay arrays. (A float in Python's
    own arithmetic, whose ``%`` is numpy's: the same value at a tenth of the cost.)"""
    if isinstance(angle, float):
        return float(-((-angle + half_turn) % (2.0 * half_turn) - half_turn))
    wrapped = -((-np.asarray(angle, dtype=float) + half_turn) % (2.0 * half_turn) - half_turn)
    return float(wrapped) if np.ndim(wrapped) == 0 else wrapped


def wrap_deg(angle_deg):
    """Wrap angles to (-180, 180] degrees; works on scalars and arrays."""
    return _wrap(angle_deg, 180.0)


def wrap_rad(angle_rad):
    """Wrap angles to (-pi, pi] radians; works on scalars and arrays."""
    return _wrap(angle_rad, np.pi)


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


def planar_poses(x, y, yaw_rad, z=0.0) -> np.ndarray:
    """Stacked 4x4 transforms (N, 4, 4) of poses on the ground plane; arguments broadcast to (N,)."""
    x, y, yaw, z = np.broadcast_arrays(*(np.atleast_1d(np.asarray(v, dtype=float)) for v in (x, y, yaw_rad, z)))
    c, s = np.cos(yaw), np.sin(yaw)
    t = np.zeros((len(x), 4, 4))
    t[:, 0, 0], t[:, 0, 1], t[:, 1, 0], t[:, 1, 1] = c, -s, s, c
    t[:, 2, 2] = t[:, 3, 3] = 1.0
    t[:, 0, 3], t[:, 1, 3], t[:, 2, 3] = x, y, z
    return t


def rigid_inverse(t: np.ndarray) -> np.ndarray:
    """The inverse of a rigid 4x4 transform: the rotation transposed, the translation turned back."""
    out = np.eye(4)
    out[:3, :3] = t[:3, :3].T
    out[:3, 3] = -(t[:3, :3].T @ t[:3, 3])
    return out


def planar_pose(x: float, y: float, yaw_rad: float, z: float = 0.0) -> np.ndarray:
    """4x4 transform of a pose on the ground plane."""
    return planar_poses(x, y, yaw_rad, z)[0]


def box_poses(centers, yaws_deg) -> np.ndarray:
    """Stacked 4x4 poses (N, 4, 4) of upright boxes from centres (N, 3) and headings (N,) in degrees
    (GT and state units); one centre and heading give (1, 4, 4)."""
    c = np.asarray(centers, dtype=float).reshape(-1, 3)
    return planar_poses(c[:, 0], c[:, 1], np.radians(yaws_deg), c[:, 2])


def rotate_xy(points_xy, yaw_rad) -> np.ndarray:
    """Points (..., 2) turned counter-clockwise by ``yaw_rad``, which broadcasts against (...)."""
    points = np.asarray(points_xy, dtype=float)
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    return np.stack([c * points[..., 0] - s * points[..., 1], s * points[..., 0] + c * points[..., 1]], axis=-1)


BOX_CORNER_SIGNS = np.array([[1.0, 1.0], [1.0, -1.0], [-1.0, -1.0], [-1.0, 1.0]])  # front-left, clockwise


def box_corners(center_xy, length_m, width_m, yaw_rad) -> np.ndarray:
    """Ground-plane corners (..., 4, 2) of boxes: front-left, front-right, rear-right, rear-left.
    ``center_xy`` is (..., 2) (a z column, if any, is ignored); the rest broadcast to (...)."""
    half = np.stack(
        np.broadcast_arrays(np.asarray(length_m, dtype=float) / 2.0, np.asarray(width_m, dtype=float) / 2.0), -1
    )
    local = BOX_CORNER_SIGNS * half[..., None, :]
    return (
        rotate_xy(local, np.asarray(yaw_rad, dtype=float)[..., None])
        + np.asarray(center_xy, dtype=float)[..., None, :2]
    )


def rotation_angle_rad(r_a, r_b):
    """Geodesic angle between rotation matrices (dCAP's RRA): (3, 3) pairs give a float,
    stacks (N, 3, 3) an (N,) array."""
    # trace(R_a^T R_b) = sum of the element-wise product
    trace = np.einsum("...ij,...ij->...", np.asarray(r_a, dtype=float), np.asarray(r_b, dtype=float))
    angle = np.arccos(np.clip((trace - 1.0) / 2.0, -1.0, 1.0))
    return float(angle) if np.ndim(angle) == 0 else angle
