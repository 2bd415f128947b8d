"""What the sensors saw through: a ray from a sensor to its return crossed every place between,
so a place a ray crossed and ended beyond holds no surface (the points alone cannot tell an empty
place from a hidden one: a pole's shadow on a trailer's side is a hole in its points too). A ray
that returned nothing crossed everything within its sensor's reach (``Unreturned``), or met a
surface too dark to answer: it weighs against the returns a place had, never alone.

Asked rarely (a vehicle's start), so nothing is precomputed: each question is one compiled pass
over the frame's rays."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from i2v_loc.stages import kernels
from i2v_loc.stages.kinematic_filter import UnitMotion


@dataclass(eq=False)
class Unreturned:
    """The rays of a frame's sweeps that returned nothing: nothing surfaced along them as far as
    their sensor reaches, or nothing that reflected enough (a dark body far off drops some of its
    returns, so these weigh against the returns a place had, never alone). Kept per sweep as the
    sweeps gave them, or as what gives them; picked out and their ends worked out only when asked
    (a start's check)."""

    # per sweep (M_k, 3) unit, in its sensor's frame, or what gives them (``SensorScan.unreturned_directions``)
    sweeps: list[np.ndarray | Callable[[], np.ndarray]]
    rotations: np.ndarray  # (S, 3, 3) each sweep's sensor frame to the yard frame
    origins: np.ndarray  # (S, 3) yard frame
    ranges_m: np.ndarray  # (S,) how far each sweep's sensor reaches

    @cached_property
    def directions(self) -> list[np.ndarray]:
        """Per sweep (M_k, 3) unit, in its sensor's frame."""
        return [d() if callable(d) else d for d in self.sweeps]

    @cached_property
    def ends(self) -> np.ndarray:
        """Each ray's far end (M, 3) float32, yard frame, where its sensor's reach ends; the sweeps
        one after the other (rows ``bounds``)."""
        parts = zip(self.directions, self.rotations, self.origins, self.ranges_m)
        return np.concatenate([(d * r) @ rotation.T + o for d, rotation, o, r in parts]).astype(np.float32)

    @cached_property
    def bounds(self) -> np.ndarray:
        """(S + 1,) each sweep's first row of ``ends``, then M."""
        return np.cumsum([0] + [len(d) for d in self.directions])


@dataclass(eq=False)
class Rays:
    """A frame's rays: each sweep's returns (yard frame) and its sensor's origin; ``to_level`` turns
    the yard frame into the frame the questions are asked in (the tracker's level frame)."""

    points: np.ndarray  # (N, 3) yard frame, the sweeps one after the other
    origins: np.ndarray  # (S, 3) yard frame, one per sweep
    bounds: np.ndarray  # (S + 1,) the sweeps' first rows, then N
    to_level: np.ndarray  # (3, 3) rotation
    lag_s: np.ndarray | None = None  # (N,) the frame's reference time minus each ray's capture time
    unreturned: Unreturned | None = None  # the rays that returned nothing (None: not known)

    def through(
        self, center_xy: tuple[float, float], yaw_rad: float, half_length_m: float, half_width_m: float,
        z_range_m: tuple[float, float], beyond_m: float,
    ) -> tuple[int, int, float]:  # fmt: skip
        """How many rays cross the upright box (level frame: centre, yaw of its length, half sizes,
        bottom and top) and end at least ``beyond_m`` past the point where they leave it, how many
        end in it, and how far ahead of the box's centre along its length the crossing rays reach
        inside it (-inf for none)."""
        box = _box(center_xy, yaw_rad, half_length_m, half_width_m, z_range_m)
        through, ended, front = kernels.rays_through_box(
            self.points, self.origins, self.bounds, self._rotation, box, float(beyond_m)
        )
        return int(through), int(ended), float(front)

    def unreturned_through(
        self, center_xy: tuple[float, float], yaw_rad: float, half_length_m: float, half_width_m: float,
        z_range_m: tuple[float, float],
    ) -> tuple[int, float]:  # fmt: skip
        """How many of the rays that returned nothing cross the upright box (as ``through``), and
        how far ahead of its centre along its length they reach inside it (-inf for none)."""
        rays = self.unreturned
        if rays is None or not rays.bounds[-1]:
            return 0, -np.inf
        box = _box(center_xy, yaw_rad, half_length_m, half_width_m, z_range_m)
        through, _, front = kernels.rays_through_box(rays.ends, rays.origins, rays.bounds, self._rotation, box, 0.0)
        return int(through), float(front)

    def crossings(
        self, point_xy: np.ndarray, direction_xy: np.ndarray, half_length_m: float, top_z_m: float, beyond_m: float,
        motion: UnitMotion | None = None,
    ) -> np.ndarray:  # fmt: skip
        """Where rays cross the upright plane through ``point_xy`` along ``direction_xy`` (level
        frame) within ``half_length_m`` of the point and below ``top_z_m``, having come from their
        sensor's side and ending ``beyond_m`` or more behind it: (n, 2) along the line from the
        point, and height. With a unit's ``motion``, the plane is the unit's at the reference time
        and each ray is carried with the unit from its capture time (a sweep's 0.1 s moves a
        trailer's rear half a metre at 5 m/s: rays captured after it left crossed where it was)."""
        plane = np.array([*point_xy, *direction_xy, half_length_m, top_z_m], dtype=float)
        carry = np.zeros(5) if motion is None else np.array([*motion.center_xy, *motion.velocity_xy, motion.rate_rad_s])
        return kernels.plane_crossings(
            self.points, self.origins, self.bounds, self._rotation, self._lag_s, plane, carry, float(beyond_m)
        )

    def hidden_along_side(
        self, center_xy: tuple[float, float], yaw_rad: float, half_length_m: float, half_width_m: float,
        along_m: np.ndarray, height_m: float, cone_rad: float, before_m: float,
    ) -> np.ndarray:  # fmt: skip
        """Which places ``along_m`` the upright box's length (level frame: centre, yaw, half sizes;
        ``height_m`` up) every sensor's view of ends short of: on the side facing each sweep's
        sensor, some of its returns lie within ``cone_rad`` of the ray there and all of those ended
        ``before_m`` or more before it, on something not within ``before_m`` of the box (its own returns hide
        nothing of it: a container's end hides its length). A sweep with no return near the ray
        (the sky, or out of its view) shows nothing hidden; neither does a sweep whose sensor is
        not known."""
        box = np.array([*center_xy, np.cos(yaw_rad), np.sin(yaw_rad), half_length_m, half_width_m], dtype=float)
        in_cone, before = kernels.rays_before_side(
            self.points, self.origins, self.bounds, self._rotation, box,
            np.asarray(along_m, dtype=float), float(height_m), float(np.cos(cone_rad)), float(before_m),
        )  # fmt: skip
        known = np.isfinite(self.origins).all(axis=1)
        if not known.any():
            return np.zeros(len(along_m), dtype=bool)
        return ((in_cone > 0) & (before == in_cone))[:, known].all(axis=1)

    @cached_property
    def _rotation(self) -> np.ndarray:
        """``to_level`` as the kernels take it, once per frame (a copy: a read-only one is another
        specialisation)."""
        return np.array(self.to_level, dtype=float)

    @cached_property
    def _lag_s(self) -> np.ndarray:
        """Each ray's lag as the kernel takes it (zeros when not known); converted once per frame,
        not per crossing asked."""
        return np.zeros(len(self.points)) if self.lag_s is None else np.asarray(self.lag_s, dtype=float)

    @cached_property
    def level_points(self) -> np.ndarray:
        """Every ray's return, level frame (N, 3)."""
        return self.points @ np.asarray(self.to_level).T

    def at_view_top(self, points: np.ndarray, tolerance_rad: float) -> bool:
        """Whether any of ``points`` (level frame) lies within ``tolerance_rad`` of the elevation of
        the highest return of some sweep, seen from its sensor: the top of that sensor's view, where
        what is higher is not seen (a car's sensor whose beams reach 2 deg up sees a trailer's side
        up to 2.1 m at 10 m)."""
        yard = points @ np.asarray(self.to_level)  # a sensor's view is in its own frame, not the ground's
        elevation = _elevations(yard, self.origins)  # (sweeps, points)
        with np.errstate(invalid="ignore"):
            return bool(np.any(elevation >= (self.top_elevations - tolerance_rad)[:, None]))

    @cached_property
    def top_elevations(self) -> np.ndarray:
        """Per sweep, the elevation of its highest return from its sensor (NaN: no sensor known)."""
        return np.array(
            [
                np.max(_elevations(self.points[a:b], origin[None]), initial=-np.inf)
                for origin, a, b in zip(self.origins, self.bounds[:-1], self.bounds[1:])
            ]
        )


def _box(
    center_xy: tuple[float, float], yaw_rad: float, half_length_m: float, half_width_m: float,
    z_range_m: tuple[float, float],
) -> np.ndarray:  # fmt: skip
    """An upright box as the kernels take it: centre, cos and sin of its yaw, half sizes, bottom, top."""
    return np.array(
        [*center_xy, np.cos(yaw_rad), np.sin(yaw_rad), half_length_m, half_width_m, *z_range_m], dtype=float
    )


def _elevations(points: np.ndarray, origins: np.ndarray) -> np.ndarray:
    """(origins, points) elevation angles of ``points`` seen from each of ``origins``."""
    d = points[None, :, :] - origins[:, None, :]
    return np.arctan2(d[..., 2], np.hypot(d[..., 0], d[..., 1]))
