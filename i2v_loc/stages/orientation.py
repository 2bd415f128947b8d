"""Stage 8: unit yaw from PCA on the history of corrected centroids (Eq. 11-12) and the hitch
angle Delta = beta - alpha (Eq. 13).

Yaw is the unit's forward heading (towards the truck's front), not the direction of travel: a
reversing vehicle moves against its yaw. The principal direction of the centroid history gives
the axis; the 180 deg ambiguity is resolved, in order of preference, by the trailer-to-truck
direction (both units face the truck's front: true whether driving forward or reversing),
by continuity with the previous yaw, and for a first estimate of a lone unit by the direction
of travel. Below ``min_travel_m`` of travel over the history the last yaw is held; a unit with
no yaw yet takes its shape axis (minimum-area rectangle); such a guess (no travel, no partner
unit) is provisional: the first real measurement replaces it at once. The yaw is exponentially
smoothed, then its per-frame change bounded by ``max_yaw_rate_deg_s`` (the bound is the real
rate limit). A unit unseen for more than ``history_gap_s`` restarts its centroid history but
keeps its yaw.
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


@dataclass
class _UnitState:
    history: deque
    yaw_deg: float | None = None
    last_seen_s: float | None = None
    provisional: bool = False  # the yaw is a shape-axis guess (no travel, no partner unit)


class OrientationEstimator:
    def __init__(self, params: OrientationParams):
        self.params = params
        self.states: dict[int, _UnitState] = {}
        self._last_stamp_s: float | None = None

    def process(self, units: list[UnitObservation], stamp_s: float, live_track_ids: set[int]) -> dict[int, float]:
        """Yaw (deg) per observed track id; forgets tracks not in ``live_track_ids``."""
        frame_dt = self._step(stamp_s)
        self.states = {k: v for k, v in self.states.items() if k in live_track_ids}
        forwards = self._forward_directions(units)
        yaws = {}
        for unit in units:
            state = self.states.setdefault(unit.track_id, _UnitState(deque(maxlen=self.params.history_frames)))
            recent = self._recent(state, stamp_s)
            if not recent:  # unseen too long: its old centroids say nothing of its motion now
                state.history.clear()
            # the rate bound covers the time since the unit's own last sighting (not just one frame)
            dt = (
                frame_dt
                if not recent or not np.isfinite(stamp_s)
                else float(np.clip(stamp_s - state.last_seen_s, 1e-3, 2.0))
            )
            state.last_seen_s = stamp_s if np.isfinite(stamp_s) else state.last_seen_s
            state.history.append(np.asarray(unit.center[:2], dtype=float))
            measured, reliable = self._measure(state, unit, forwards.get((unit.vehicle_id, unit.kind)))
            state.yaw_deg = self._next_yaw(state, measured, reliable, dt)
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

    def _forward_directions(self, units: list[UnitObservation]) -> dict[tuple[int, str], np.ndarray]:
        """Per (vehicle, kind) with both units seen: a vector pointing forward, from the trailer's centre
        to the truck's."""
        by_vehicle: dict[int, dict[str, UnitObservation]] = {}
        for u in units:
            by_vehicle.setdefault(u.vehicle_id, {})[u.kind] = u
        out = {}
        for vid, pair in by_vehicle.items():
            if "truck" not in pair or "trailer" not in pair:
                continue
            truck, trailer = (np.asarray(pair[k].center[:2], dtype=float) for k in ("truck", "trailer"))
            out[(vid, "trailer")] = out[(vid, "truck")] = truck - trailer
        return out

    def _recent(self, state: _UnitState, stamp_s: float) -> bool:
        """Seen within ``history_gap_s`` before this frame (a unit seen for the first time is not)."""
        if state.last_seen_s is None or not np.isfinite(stamp_s):
            return state.last_seen_s is not None
        return stamp_s - state.last_seen_s <= self.params.history_gap_s

    def _measure(
        self, state: _UnitState, unit: UnitObservation, forward: np.ndarray | None
    ) -> tuple[float | None, bool]:
        """(measured yaw or None to hold, whether it rests on travel or the partner unit)."""
        history = np.array(state.history)
        travel = history[-1] - history[0]
        has_forward = forward is not None and np.hypot(*forward) > 1e-6
        moved = len(history) >= 2 and np.hypot(*travel) >= self.params.min_travel_m
        if moved:
            axis_deg = self._pca_axis_deg(history)
        elif state.yaw_deg is not None and not (state.provisional and has_forward):
            return None, False  # standing still: hold
        else:
            axis_deg = unit.shape_axis_deg
        return self._resolve_direction(axis_deg, forward, state.yaw_deg, travel), moved or has_forward

    @staticmethod
    def _pca_axis_deg(history_xy: np.ndarray) -> float:
        """Principal direction of the centroid history (eigenvector of the largest eigenvalue of Q)."""
        q = np.cov(history_xy.T)  # Eq. 11-12: (1 / (n - 1)) sum (c - mean)(c - mean)^T
        eigvals, eigvecs = np.linalg.eigh(q)
        v = eigvecs[:, np.argmax(eigvals)]
        return float(np.degrees(np.arctan2(v[1], v[0])))

    @staticmethod
    def _resolve_direction(
        axis_deg: float, forward: np.ndarray | None, previous_deg: float | None, travel: np.ndarray
    ) -> float:
        axis = np.array([np.cos(np.radians(axis_deg)), np.sin(np.radians(axis_deg))])
        if forward is not None and np.hypot(*forward) > 1e-6:
            sign = 1.0 if axis @ forward >= 0 else -1.0
        elif previous_deg is not None:
            sign = 1.0 if abs(wrap_deg(axis_deg - previous_deg)) <= 90 else -1.0
        else:
            sign = 1.0 if axis @ travel >= 0 else -1.0
        return float(wrap_deg(axis_deg if sign > 0 else axis_deg + 180.0))

    def _next_yaw(self, state: _UnitState, measured_deg: float | None, reliable: bool, dt: float) -> float | None:
        if measured_deg is None:
            return state.yaw_deg
        if state.yaw_deg is None or (state.provisional and reliable):
            state.provisional = not reliable
            return measured_deg
        return self._bounded_smoothed(state.yaw_deg, measured_deg, dt)

    def _bounded_smoothed(self, previous_deg: float, measured_deg: float, dt: float) -> float:
        """Exponential smoothing, then the rate bound on the resulting change."""
        step = (1.0 - self.params.smoothing) * wrap_deg(measured_deg - previous_deg)
        max_step = self.params.max_yaw_rate_deg_s * dt
        return float(wrap_deg(previous_deg + float(np.clip(step, -max_step, max_step))))
