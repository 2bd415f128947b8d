"""Stage 2: per-sensor sweeps to one synchronised cloud in the yard frame (paper section 3.2).

Order: clean each sweep (NaN/inf, range limits), put its stamp on the common clock
(``SensorConfig.time_offset_s``), choose the reference time, drop sweeps outside the tolerance
window, transform to the yard frame (extrinsics), move points of moving objects to the reference
time (Eq. 3), then voxel-grid centroids (Eq. 1-2).

What is interpolated (Eq. 3): a point captured at t is moved to the reference time t_ref along
the straight line between its positions at two frame times, i.e. p + v * (t_ref - t), where v is
the velocity of the tracked object it lies on (the Pipeline passes the previous frame's tracks as
``MotionHint``). Static points (the yard, parked objects) need no interpolation. Each sensor's
stamp is interpolated onto the common clock by its known offset; every point's capture time is
stamp + its column time offset (``SensorScan.time_offset_s``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from i2v_loc.frame import SensorScan
from i2v_loc.geometry import extrinsics_matrix
from i2v_loc.params import ConcatenationParams, SensorConfig
from i2v_loc.stages.primitives import voxel_centroids

DROP_REASONS = ("out_of_sync", "empty", "missing", "nan_points")


@dataclass
class MotionHint:
    """A moving object: points inside its xy box (centre, yaw, half sizes) move with ``velocity_xy`` (m/s)."""

    center_xy: tuple[float, float]
    yaw_rad: float
    half_length_m: float
    half_width_m: float
    velocity_xy: tuple[float, float]  # of the box centre
    yaw_rate_rad_s: float = 0.0  # the box also turns about its centre


@dataclass
class ConcatenationResult:
    points: np.ndarray  # (N, 3) float32, yard frame, at the reference time
    stamp_s: float  # reference time on the common clock; NaN when no sweep was usable
    sensors_used: list[str]
    faults: dict[str, str] = field(default_factory=dict)  # sensor -> reason
    dropped: dict[str, int] = field(default_factory=dict)  # reason -> count (sweeps; points for nan_points)
    lag_s: np.ndarray | None = None  # (N,) reference time minus each point's capture time (``merge`` only)


@dataclass
class _CleanSweep:
    name: str
    stamp_s: float
    points: np.ndarray
    time_offset_s: np.ndarray


class Concatenation:
    def __init__(self, params: ConcatenationParams, sensors: list[SensorConfig]):
        self.params = params
        self.sensors = {s.name: s for s in sensors}
        self._to_yard = {s.name: extrinsics_matrix(s.extrinsics).astype(np.float32) for s in sensors}

    def process(self, scans: dict[str, SensorScan], motion: list[MotionHint] = ()) -> ConcatenationResult:
        """Merged, motion-interpolated and voxel-downsampled cloud (the paper's order)."""
        merged = self.merge(scans)
        points = merged.points
        if self.params.motion_interpolation and motion:
            self.interpolate(points, merged.lag_s, motion)
        merged.points, _ = voxel_centroids(points, self.params.voxel_size_m)
        merged.lag_s = None
        return merged

    def merge(self, scans: dict[str, SensorScan]) -> ConcatenationResult:
        """Cleaned, synchronised sweeps in the yard frame with each point's lag to the reference time;
        neither interpolated nor downsampled (the default method does both on the foreground only)."""
        faults: dict[str, str] = {}
        dropped = dict.fromkeys(DROP_REASONS, 0)
        sweeps = self._clean_all(scans, faults, dropped)
        reference_s, in_sync = self._synchronise([s.stamp_s for s in sweeps])
        for sweep, ok in zip(sweeps, in_sync):
            if not ok:
                faults[sweep.name] = "out_of_sync"
                dropped["out_of_sync"] += 1
        kept = [s for s, ok in zip(sweeps, in_sync) if ok]
        points, lag_s = self._merge(kept, reference_s)
        return ConcatenationResult(points, reference_s, [s.name for s in kept], faults, dropped, lag_s)

    # ----------------------------------------------------------------- cleaning

    def _clean_all(self, scans: dict[str, SensorScan], faults: dict, dropped: dict) -> list[_CleanSweep]:
        sweeps = []
        for name in self.sensors:
            if name not in scans:
                faults[name] = "missing"
                dropped["missing"] += 1
                continue
            sweep = self._clean(scans[name], faults, dropped)
            if sweep is not None:
                sweeps.append(sweep)
        for name in scans.keys() - self.sensors.keys():
            faults[name] = "unknown_sensor"
        return sweeps

    def _clean(self, scan: SensorScan, faults: dict, dropped: dict) -> _CleanSweep | None:
        config = self.sensors[scan.sensor]
        points, offsets = scan.points, scan.time_offset_s
        finite = np.isfinite(points).all(axis=1) & np.isfinite(offsets)
        n_bad = int(len(points) - finite.sum())
        if n_bad:
            faults[scan.sensor] = "nan_points"
            dropped["nan_points"] += n_bad
        range_sq = np.einsum("ij,ij->i", points, points, dtype=np.float64)
        keep = finite & (range_sq >= config.min_range_m**2) & (range_sq <= config.max_range_m**2)
        if not keep.any() or not np.isfinite(scan.stamp_s):
            faults[scan.sensor] = "empty"
            dropped["empty"] += 1
            return None
        return _CleanSweep(scan.sensor, scan.stamp_s + config.time_offset_s, points[keep], offsets[keep])

    # ----------------------------------------------------------------- synchronisation

    def _synchronise(self, stamps_s: list[float]) -> tuple[float, np.ndarray]:
        """Reference time and which sweeps are within the tolerance window.

        The window is placed where it holds the most sweeps (ties: the earliest), so one stale or
        late sensor is dropped instead of dragging the reference away from the others.
        """
        if not stamps_s:
            return float("nan"), np.zeros(0, dtype=bool)
        stamps = np.asarray(stamps_s)
        tol = self.params.sync_tolerance_s
        # each stamp as the window start; count the sweeps in [start, start + tol]
        inside = (stamps[None, :] >= stamps[:, None] - 1e-9) & (stamps[None, :] <= stamps[:, None] + tol + 1e-9)
        counts = inside.sum(axis=1)
        best = np.flatnonzero(counts == counts.max())
        start = best[np.argmin(stamps[best])]
        members = inside[start]
        group = stamps[members]
        reference = {"earliest": group.min(), "latest": group.max(), "mean": group.mean()}[self.params.reference]
        return float(reference), members

    # ----------------------------------------------------------------- merging

    def _merge(self, sweeps: list[_CleanSweep], reference_s: float) -> tuple[np.ndarray, np.ndarray]:
        if not sweeps:
            return np.zeros((0, 3), dtype=np.float32), np.zeros(0, dtype=np.float32)
        clouds, lags = [], []
        for sweep in sweeps:
            t = self._to_yard[sweep.name]
            clouds.append(np.asarray(sweep.points, dtype=np.float32) @ t[:3, :3].T + t[:3, 3])
            lags.append(np.float32(reference_s - sweep.stamp_s) - sweep.time_offset_s.astype(np.float32))
        return np.concatenate(clouds), np.concatenate(lags)

    @staticmethod
    def interpolate(points: np.ndarray, lag_s: np.ndarray, motion: list[MotionHint]) -> None:
        """Move the points of each moving object to the reference time (in place); a point inside
        several boxes (truck and trailer overlap at the hitch) moves once, with the first box."""
        moved = np.zeros(len(points), dtype=bool)
        for hint in motion:
            d = points[:, :2] - np.asarray(hint.center_xy, dtype=np.float32)
            c, s = np.cos(hint.yaw_rad), np.sin(hint.yaw_rad)
            along, across = d[:, 0] * c + d[:, 1] * s, -d[:, 0] * s + d[:, 1] * c
            inside = (np.abs(along) <= hint.half_length_m) & (np.abs(across) <= hint.half_width_m) & ~moved
            velocity = np.asarray(hint.velocity_xy, dtype=np.float32)
            if hint.yaw_rate_rad_s:
                velocity = velocity + np.float32(hint.yaw_rate_rad_s) * np.column_stack([-d[inside, 1], d[inside, 0]])
            points[inside, :2] += lag_s[inside, None] * velocity
            moved |= inside
