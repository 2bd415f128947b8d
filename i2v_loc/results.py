"""What a pipeline returns per frame (the state line of docs/formats.md), shared by every pipeline.

``frame_result`` builds the ``FrameResult`` from the merged cloud and the front end's output, the
same way for every pipeline; ``StageTimer`` measures the stages under the names every pipeline
reports (``STAGES``, then ``total``).
"""

from __future__ import annotations

import time
from collections import Counter
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from i2v_loc.stages.concatenation import ConcatenationResult

# merge: the sensors' clouds into the yard frame; front_end: ground (and background) removal;
# candidates: the clusters vehicles are looked for in; vehicles: fitting, tracking, orientation
STAGES = ("merge", "front_end", "candidates", "vehicles")


def _r(value: float, digits: int = 4) -> float:
    return round(float(value), digits)


@dataclass
class UnitResult:
    track_id: int
    center: np.ndarray
    yaw_deg: float | None
    dimensions: tuple[float, float, float]
    points: int
    dimensions_seen: tuple[bool, bool, bool] | None = None  # default method: measured, or a prior

    def to_json(self) -> dict:
        out = {
            "track_id": self.track_id,
            "center": [_r(v) for v in self.center],
            "yaw_deg": None if self.yaw_deg is None else _r(self.yaw_deg, 3),
            "dimensions": [_r(v, 3) for v in self.dimensions],
            "points": int(self.points),
        }
        if self.dimensions_seen is not None:
            out["dimensions_seen"] = [bool(v) for v in self.dimensions_seen]
        return out


@dataclass
class VehicleResult:
    id: int
    vehicle: str
    truck: UnitResult | None
    trailer: UnitResult | None
    hitch_deg: float | None
    tractor_to_trailer: np.ndarray | None

    def to_json(self) -> dict:
        t = self.tractor_to_trailer
        return {
            "id": self.id,
            "vehicle": self.vehicle,
            "hitch_deg": None if self.hitch_deg is None else _r(self.hitch_deg, 3),
            "truck": self.truck.to_json() if self.truck else None,
            "trailer": self.trailer.to_json() if self.trailer else None,
            "tractor_to_trailer": None if t is None else [[_r(v, 6) for v in row] for row in t],
        }


@dataclass
class FrameResult:
    frame: int
    stamp_s: float
    latency_ms: dict[str, float]
    faults: dict[str, str]
    dropped: dict[str, int]
    clusters: list[dict]
    vehicles: list[VehicleResult]
    ground_found: bool = True
    points: int = 0  # points after concatenation
    foreground: np.ndarray | None = None  # (N, 3) non-ground (and non-background) points, yard frame; not in to_json()

    def to_json(self) -> dict:
        """The state line of docs/formats.md."""
        return {
            "type": "state",
            "frame": int(self.frame),
            "stamp_s": None if not np.isfinite(self.stamp_s) else _r(self.stamp_s, 6),
            "latency_ms": {k: _r(v, 3) for k, v in self.latency_ms.items()},
            "faults": dict(self.faults),
            "dropped": dict(self.dropped),
            "clusters": self.clusters,
            "vehicles": [v.to_json() for v in self.vehicles],
        }


def frame_result(
    index: int,
    merged: ConcatenationResult,
    latency_ms: dict[str, float],
    clusters: list[dict],
    vehicles: list[VehicleResult],
    ground_found: bool,
    foreground: np.ndarray,
) -> FrameResult:
    """The frame's result; a sensor missing from the frame is a fault, not a count of dropped points."""
    dropped = {k: v for k, v in merged.dropped.items() if k != "missing"}
    return FrameResult(
        index,
        merged.stamp_s,
        latency_ms,
        merged.faults,
        dropped,
        clusters,
        vehicles,
        ground_found,
        len(merged.points),
        foreground,
    )


def count_frame(counters: Counter, merged: ConcatenationResult, ground_found: bool) -> None:
    """The counts every pipeline keeps: frames, points dropped per reason, frames without ground."""
    counters["frames"] += 1
    for reason, n in merged.dropped.items():
        counters[reason] += n
    if not ground_found:
        counters["no_ground"] += 1


@dataclass
class StageTimer:
    """Per-stage wall time in ms: ``lap(stage)`` closes the stage, ``total()`` adds ``total``. A stage
    that did not run this frame is reported as 0 (every state line has the same keys)."""

    latency_ms: dict[str, float] = field(default_factory=lambda: dict.fromkeys(STAGES, 0.0))
    _t: float = field(default_factory=time.perf_counter)
    _start: float = field(default_factory=time.perf_counter)

    def lap(self, stage: str) -> None:
        if stage not in STAGES:
            raise ValueError(f"unknown stage {stage!r}; known: {', '.join(STAGES)}")
        now = time.perf_counter()
        self.latency_ms[stage] += (now - self._t) * 1e3
        self._t = now

    def total(self) -> dict[str, float]:
        self.latency_ms["total"] = (time.perf_counter() - self._start) * 1e3
        return self.latency_ms
