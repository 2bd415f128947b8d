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

import itertools
from dataclasses import dataclass, field

import numpy as np

from i2v_loc.frame import SensorScan
from i2v_loc.geometry import extrinsics_matrix
from i2v_loc.params import ConcatenationParams, SensorConfig
from i2v_loc.stages import kernels
from i2v_loc.stages.primitives import voxel_centroids
from i2v_loc.stages.visibility import Unreturned

DROP_REASONS = ("out_of_sync", "empty", "missing", "nan_points")


@dataclass
class MotionHint:
    """A moving object: points inside its xy box (centre, yaw, half sizes) move with ``velocity_xy`` (m/s).
    ``age_s``: seconds from this pose to the merged frame's reference time; the box is then moved to
    each point's capture time before the point is tested (NaN: the box as it is)."""

    center_xy: tuple[float, float]
    yaw_rad: float
    half_length_m: float
    half_width_m: float
    velocity_xy: tuple[float, float]  # of the box centre
    yaw_rate_rad_s: float = 0.0  # the box also turns about its centre
    age_s: float = float("nan")


@dataclass
class ConcatenationResult:
    points: np.ndarray  # (N, 3) float32, yard frame, at the reference time
    stamp_s: float  # reference time on the common clock; NaN when no sweep was usable
    sensors_used: list[str]
    faults: dict[str, str] = field(default_factory=dict)  # sensor -> reason
    dropped: dict[str, int] = field(default_factory=dict)  # reason -> count (sweeps; points for nan_points)
    lag_s: np.ndarray | None = None  # (N,) reference time minus each point's capture time (``merge`` only)
    sweep_bounds: np.ndarray | None = None  # (S + 1,) each used sweep's first row, then N (``merge`` only)
    sweep_origins: np.ndarray | None = None  # (S, 3) their sensors' positions, yard frame, NaN if unknown (merge)
    unreturned: Unreturned | None = None  # the used sweeps' rays that returned nothing, where known (merge)


class Concatenation:
    def __init__(self, params: ConcatenationParams, sensors: list[SensorConfig]):
        self.params = params
        self.sensors = {s.name: s for s in sensors if s.enabled}
        self.disabled = {s.name for s in sensors if not s.enabled}
        to_yard = {s.name: extrinsics_matrix(s.extrinsics).astype(np.float32) for s in self.sensors.values()}
        self._to_yard = {name: (np.ascontiguousarray(t[:3, :3]), t[:3, 3].copy()) for name, t in to_yard.items()}
        kernels.warm_up()

    def process(self, scans: dict[str, SensorScan], motion: list[MotionHint] = ()) -> ConcatenationResult:
        """Merged, motion-interpolated and voxel-downsampled cloud (the paper's order)."""
        merged = self.merge(scans)
        points = merged.points
        if self.params.motion_interpolation and motion:
            self.interpolate(points, merged.lag_s, motion)
        merged.points, _ = voxel_centroids(points, self.params.voxel_size_m)
        merged.lag_s = merged.sweep_bounds = merged.sweep_origins = merged.unreturned = None  # the rows are voxels now
        return merged

    def merge(self, scans: dict[str, SensorScan]) -> ConcatenationResult:
        """Cleaned, synchronised sweeps in the yard frame with each point's lag to the reference time;
        neither interpolated nor downsampled (the default method does both on the foreground only).

        One compiled pass per sweep cleans it and writes its points in the yard frame straight into
        the merged cloud; a sweep dropped as out of sync afterwards is cut out again."""
        faults: dict[str, str] = {}
        dropped = dict.fromkeys(DROP_REASONS, 0)
        present = [scans[name] for name in self.sensors if name in scans]
        total = sum(len(scan.points) for scan in present)
        points, offsets = np.empty((total, 3), dtype=np.float32), np.empty(total, dtype=np.float32)
        sweeps = []  # (name, stamp on the common clock, first row, rows)
        start = 0
        for name in self.sensors:
            if name not in scans:
                faults[name] = "missing"
                dropped["missing"] += 1
                continue
            scan, config, (rotation, translation) = scans[name], self.sensors[name], self._to_yard[name]
            kept, n_bad = kernels.sweep_to_yard(
                np.ascontiguousarray(scan.points), np.ascontiguousarray(scan.time_offset_s), rotation, translation,
                config.min_range_m**2, config.max_range_m**2, points, offsets, start,
            )  # fmt: skip
            if n_bad:
                faults[name] = "nan_points"
                dropped["nan_points"] += n_bad
            if not kept or not np.isfinite(scan.stamp_s):
                faults[name] = "empty"
                dropped["empty"] += 1
                continue
            sweeps.append((name, scan.stamp_s + config.time_offset_s, start, kept))
            start += kept
        for name in scans.keys() - self.sensors.keys():
            faults[name] = "disabled" if name in self.disabled else "unknown_sensor"
        reference_s, in_sync = self._synchronise([stamp for _, stamp, _, _ in sweeps])
        for (name, *_), ok in zip(sweeps, in_sync):
            if not ok:
                faults[name] = "out_of_sync"
                dropped["out_of_sync"] += 1
        kept_sweeps = [sweep for sweep, ok in zip(sweeps, in_sync) if ok]
        if len(kept_sweeps) == len(sweeps):
            points, offsets = points[:start], offsets[:start]
        else:
            rows = np.concatenate([np.arange(first, first + n) for _, _, first, n in kept_sweeps] or [[]]).astype(int)
            points, offsets = points[rows], offsets[rows]
        lag_s = np.repeat(
            np.array([np.float32(reference_s - stamp) for _, stamp, _, _ in kept_sweeps], dtype=np.float32),
            [n for *_, n in kept_sweeps],
        )
        lag_s -= offsets
        bounds = np.array(list(itertools.accumulate((n for *_, n in kept_sweeps), initial=0)))
        origins = np.array(
            [self._to_yard[name][1] if scans[name].from_sensor else [np.nan] * 3 for name, *_ in kept_sweeps],
            dtype=float,
        ).reshape(-1, 3)
        names = [name for name, *_ in kept_sweeps]
        unreturned = self._unreturned([scans[name] for name in names])
        return ConcatenationResult(points, reference_s, names, faults, dropped, lag_s, bounds, origins, unreturned)

    def _unreturned(self, used: list[SensorScan]) -> Unreturned | None:
        """The rays of the ``used`` sweeps that returned nothing, of those that tell them."""
        told = [scan for scan in used if scan.from_sensor and scan.unreturned is not None]
        if not told:
            return None
        return Unreturned(
            [scan.unreturned_directions for scan in told],
            np.array([self._to_yard[scan.sensor][0] for scan in told], dtype=float),
            np.array([self._to_yard[scan.sensor][1] for scan in told], dtype=float),
            np.array([self.sensors[scan.sensor].max_range_m for scan in told], dtype=float),
        )

    # ----------------------------------------------------------------- synchronisation

    def _synchronise(self, stamps_s: list[float]) -> tuple[float, np.ndarray]:
        """Reference time and which sweeps are within the tolerance window.

        The window is placed where it holds the most sweeps (ties: the earliest), so one stale or
        late sensor is dropped instead of dragging the reference away from the others.
        """
        if not stamps_s:
            return float("nan"), np.zeros(0, dtype=bool)
        tol = self.params.sync_tolerance_s
        # each stamp as the window start; the sweeps in [start, start + tol] (a handful: plain Python)
        inside = [[s - 1e-9 <= t <= s + tol + 1e-9 for t in stamps_s] for s in stamps_s]
        counts = [sum(row) for row in inside]
        best = [i for i, count in enumerate(counts) if count == max(counts)]
        members = inside[min(best, key=lambda i: stamps_s[i])]  # ties: the earliest start
        group = [stamp for stamp, member in zip(stamps_s, members) if member]
        reference = self.params.reference
        value = min(group) if reference == "earliest" else max(group) if reference == "latest" else np.mean(group)
        return float(value), np.array(members)

    @staticmethod
    def interpolate(points: np.ndarray, lag_s: np.ndarray, motion: list[MotionHint]) -> None:
        """Move the points of each moving object to the reference time (in place); a point inside
        several boxes (truck and trailer overlap at the hitch) moves once, with the first box."""
        if not len(motion) or not len(points):
            return
        boxes = np.array(
            [
                (*h.center_xy, np.cos(h.yaw_rad), np.sin(h.yaw_rad), h.half_length_m, h.half_width_m,
                 *h.velocity_xy, h.yaw_rate_rad_s, h.age_s)
                for h in motion
            ],
            dtype=np.float64,
        )  # fmt: skip
        kernels.interpolate(points, np.ascontiguousarray(lag_s, dtype=np.float32), boxes)
