"""The articulated estimator's level frame: the yard frame turned so that the ground plane is
level (docs/pipeline.md, Articulated estimator).

The hinged model's faces are upright in its vehicle's frame; on a graded yard a vehicle stands
perpendicular to the ground, not to gravity, and its upright faces lean by the grade (2 deg over
a 3.5 m high trailer: 12 cm). The tracker fits and filters in a frame whose z is the ground's
normal; the results are turned back into the yard frame. The frame turns only when the ground's
normal moved by ``TURN_MIN_DEG`` (every refit of the ground plane moves it by a few hundredths of a
degree, which would move a vehicle 30 m away by a centimetre), and is the yard frame itself on
ground within ``LEVEL_MAX_TILT_DEG`` of level.
"""

from __future__ import annotations

import numpy as np

from i2v_loc.stages.region import GroundPlane

LEVEL_MAX_TILT_DEG = 0.5  # ground within this of level: the yard frame is the level frame
TURN_MIN_DEG = 0.25
UP = np.array([0.0, 0.0, 1.0])
LEVEL = np.eye(3)  # the rotation on level ground: the points are used as they are
LEVEL.flags.writeable = False


class LevelFrame:
    def __init__(self) -> None:
        self.rotation = LEVEL  # yard -> level
        self._followed: GroundPlane | None = None  # the plane last followed (refitted every few frames only)

    @property
    def normal(self) -> np.ndarray:
        """The yard frame's direction that is up in the level frame."""
        return self.rotation[2]

    def update(self, ground: GroundPlane | None) -> None:
        """Follow the ground plane of this frame (none found: keep the last)."""
        if ground is None or ground is self._followed:
            return
        self._followed = ground
        target = ground.normal if _angle_deg(ground.normal, UP) > LEVEL_MAX_TILT_DEG else UP
        if _angle_deg(target, self.normal) > TURN_MIN_DEG:
            self.rotation = _rotation_onto_up(target)

    def points(self, points: np.ndarray) -> np.ndarray:
        """Yard-frame points (N, 3) in the level frame (the same array on level ground)."""
        return points if self.rotation is LEVEL else points @ self.rotation.T

    def ground(self, plane: GroundPlane | None):
        """The ground's height z(x, y) in the level frame (0 without a plane)."""
        if plane is None:
            return lambda x, y: 0.0
        n = self.rotation @ plane.normal
        return lambda x, y: float(-(n[0] * x + n[1] * y + plane.offset) / n[2])

    def to_yard(self, point: np.ndarray) -> np.ndarray:
        """A level-frame point (3,) in the yard frame."""
        return self.rotation.T @ point

    def yaw_to_yard(self, yaw_rad: float) -> float:
        """The yard-frame yaw of a level-frame heading (of the heading's projection on the yard's xy)."""
        heading = self.rotation.T @ np.array([np.cos(yaw_rad), np.sin(yaw_rad), 0.0])
        return float(np.arctan2(heading[1], heading[0]))

    def vector_to_yard(self, xy: np.ndarray) -> np.ndarray:
        """A level-frame horizontal vector (2,) (a velocity) in the yard's xy."""
        return (self.rotation.T @ np.array([xy[0], xy[1], 0.0]))[:2]


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip(a @ b / (np.linalg.norm(a) * np.linalg.norm(b)), -1.0, 1.0))))


def _rotation_onto_up(normal: np.ndarray) -> np.ndarray:
    """The smallest rotation taking ``normal`` (unit, z > 0) onto +z (Rodrigues)."""
    n = normal / np.linalg.norm(normal)
    axis = np.cross(n, UP)
    s, c = np.linalg.norm(axis), float(n @ UP)
    if s < 1e-12:
        return LEVEL
    k = axis / s
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + s * kx + (1.0 - c) * kx @ kx
