"""Stage 8: unit yaw from PCA on the history of corrected centroids (Eq. 11-12) and the hitch
angle Delta = beta - alpha (Eq. 13).

Yaw is the unit's forward heading (towards the truck's front), not the direction of travel: a
reversing vehicle moves against its yaw. The principal direction of the centroid history gives
the axis; the 180 deg ambiguity is resolved, in order of preference, by the trailer-to-truck
direction (both units face the truck's front: true whether driving forward or reversing),
by continuity with the previous yaw, and for a first estimate of a lone unit by the direction
of travel. Below ``min_travel_m`` of travel over the history the last yaw is held; a unit with
no yaw yet takes its shape axis (minimum-area rectangle). The per-frame yaw change is bounded
by ``max_yaw_rate_deg_s`` and then exponentially smoothed. ``shape_weight`` blends the
measured axis with the unit's shape axis (0 = the paper's pure PCA); for a nearly square unit the
shape axis is only known modulo 90 deg and the PCA axis picks the equivalent (for a first estimate,
the trailer-to-truck direction does). With ``prefer_continuity`` a unit seen in the previous
frames keeps its direction (no 180 deg turn-over from one bad truck detection); the
trailer-to-truck direction then only decides for new or re-acquired units. A unit unseen for
more than ``history_gap_s`` restarts its centroid history but keeps its yaw.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from i2v_loc.geometry import wrap_deg
from i2v_loc.params import OrientationParams


@dataclass
class UnitObservation:
    track_id: int
    vehicle_id: int
    kind: str  # "truck" | "trailer"
    center: np.ndarray  # (3,) corrected centre
    shape_axis_deg: float  # long axis of the unit's points, modulo 180
    shape_period_deg: float = 180.0  # 90 for a nearly square unit (its long axis is ambiguous)


@dataclass
class _UnitState:
    history: deque
    yaw_deg: float | None = None
    last_seen_s: float | None = None


class OrientationEstimator:
    def __init__(self, params: OrientationParams):
        self.params = params
        self.states: dict[int, _UnitState] = {}
        self._last_stamp_s: float | None = None

    def process(self, units: list[UnitObservation], stamp_s: float, live_track_ids: set[int]) -> dict[int, float]:
        """Yaw (deg) per observed track id; forgets tracks not in ``live_track_ids``."""
        dt = self._step(stamp_s)
        self.states = {k: v for k, v in self.states.items() if k in live_track_ids}
        forwards = self._forward_directions(units)
        yaws = {}
        for unit in units:
            state = self.states.setdefault(unit.track_id, _UnitState(deque(maxlen=self.params.history_frames)))
            recent = self._recent(state, stamp_s)
            if not recent:  # a re-acquired unit: its old centroids say nothing of its motion now
                state.history.clear()
            state.last_seen_s = stamp_s if np.isfinite(stamp_s) else state.last_seen_s
            state.history.append(np.asarray(unit.center[:2], dtype=float))
            measured = self._measure(state, unit, forwards.get(unit.vehicle_id))
            state.yaw_deg = self._bounded_smoothed(state.yaw_deg, measured, dt)
            yaws[unit.track_id] = state.yaw_deg
        return yaws

    @staticmethod
    def hitch_deg(truck_yaw_deg: float | None, trailer_yaw_deg: float | None) -> float | None:
        if truck_yaw_deg is None or trailer_yaw_deg is None:
            return None
        return float(wrap_deg(trailer_yaw_deg - truck_yaw_deg))

    # ----------------------------------------------------------------- internals

    def _step(self, stamp_s: float) -> float:
        dt = 0.1 if self._last_stamp_s is None or not np.isfinite(stamp_s) else stamp_s - self._last_stamp_s
        if np.isfinite(stamp_s):
            self._last_stamp_s = stamp_s
        return float(np.clip(dt, 1e-3, 2.0))

    @staticmethod
    def _forward_directions(units: list[UnitObservation]) -> dict[int, np.ndarray]:
        """Per vehicle with both units seen: the trailer-to-truck vector (points forward for both)."""
        by_vehicle: dict[int, dict[str, np.ndarray]] = {}
        for u in units:
            by_vehicle.setdefault(u.vehicle_id, {})[u.kind] = np.asarray(u.center[:2], dtype=float)
        return {vid: c["truck"] - c["trailer"] for vid, c in by_vehicle.items() if "truck" in c and "trailer" in c}

    def _recent(self, state: _UnitState, stamp_s: float) -> bool:
        """Seen within ``history_gap_s`` before this frame (a unit seen for the first time is not)."""
        if state.last_seen_s is None or not np.isfinite(stamp_s):
            return state.last_seen_s is not None
        return stamp_s - state.last_seen_s <= self.params.history_gap_s

    def _measure(self, state: _UnitState, unit: UnitObservation, forward: np.ndarray | None) -> float | None:
        history = np.array(state.history)
        travel = history[-1] - history[0]
        if len(history) >= 2 and np.hypot(*travel) >= self.params.min_travel_m:
            axis_deg = self._pca_axis_deg(history)
        elif state.yaw_deg is not None:
            return None  # standing still: hold
        elif forward is not None and np.hypot(*forward) > 1e-6 and self.params.shape_weight > 0:
            # first estimate: of the shape axis's equivalents (90 deg apart on a square cab) the one
            # nearest the trailer-to-truck direction (the truck is ahead of the trailer); the paper
            # (shape_weight 0) takes the shape axis as it comes
            axis_deg = float(np.degrees(np.arctan2(forward[1], forward[0])))
            axis_deg = self._nearest_equivalent(axis_deg, unit.shape_axis_deg, unit.shape_period_deg)
        else:
            axis_deg = unit.shape_axis_deg
        axis_deg = self._blend_with_shape(axis_deg, unit.shape_axis_deg, unit.shape_period_deg)
        if self.params.prefer_continuity and state.yaw_deg is not None and len(history) >= 2:
            forward = None  # seen in the last frames: a yaw cannot turn over between two frames
        return self._resolve_direction(axis_deg, forward, state.yaw_deg, travel)

    @staticmethod
    def _nearest_equivalent(reference_deg: float, axis_deg: float, period_deg: float) -> float:
        return float(reference_deg + (axis_deg - reference_deg + period_deg / 2) % period_deg - period_deg / 2)

    @staticmethod
    def _pca_axis_deg(history_xy: np.ndarray) -> float:
        """Principal direction of the centroid history (eigenvector of the largest eigenvalue of Q)."""
        q = np.cov(history_xy.T)  # Eq. 11-12: (1 / (n - 1)) sum (c - mean)(c - mean)^T
        eigvals, eigvecs = np.linalg.eigh(q)
        v = eigvecs[:, np.argmax(eigvals)]
        return float(np.degrees(np.arctan2(v[1], v[0])))

    def _blend_with_shape(self, axis_deg: float, shape_axis_deg: float, period_deg: float = 180.0) -> float:
        """The measured axis moved towards the shape axis (its equivalent nearest the measured one,
        modulo 180 deg, or modulo 90 deg for a nearly square unit such as a tractor cab)."""
        w = self.params.shape_weight
        if w <= 0:
            return axis_deg
        shape = self._nearest_equivalent(axis_deg, shape_axis_deg, period_deg)
        return float(axis_deg + w * (shape - axis_deg))

    @staticmethod
    def _resolve_direction(axis_deg: float, forward: np.ndarray | None, previous_deg: float | None,
                           travel: np.ndarray) -> float:
        axis = np.array([np.cos(np.radians(axis_deg)), np.sin(np.radians(axis_deg))])
        if forward is not None and np.hypot(*forward) > 1e-6:
            sign = 1.0 if axis @ forward >= 0 else -1.0
        elif previous_deg is not None:
            sign = 1.0 if abs(wrap_deg(axis_deg - previous_deg)) <= 90 else -1.0
        else:
            sign = 1.0 if axis @ travel >= 0 else -1.0
        return float(wrap_deg(axis_deg if sign > 0 else axis_deg + 180.0))

    def _bounded_smoothed(self, previous_deg: float | None, measured_deg: float | None, dt: float) -> float | None:
        if measured_deg is None:
            return previous_deg
        if previous_deg is None:
            return measured_deg
        max_step = self.params.max_yaw_rate_deg_s * dt
        step = float(np.clip(wrap_deg(measured_deg - previous_deg), -max_step, max_step))
        return float(wrap_deg(previous_deg + (1.0 - self.params.smoothing) * step))
