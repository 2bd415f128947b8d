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
rate limit). With ``flip_confirm_frames`` a measurement more than 90 deg from the unit's yaw (a
180 deg flip, impossible between frames at yard speeds) is ignored unless it persists that many
frames, then taken at once (the old yaw was the wrong one). With ``hitch_forward`` the truck's
forward direction starts at the trailer's hitch point (``hitch_offset_m`` ahead of the trailer's
centre, at its truck end) instead of the trailer's centre: the truck's heading itself, at any
hitch angle (from the trailer's centre it is up to 60 deg off at a 90 deg hitch angle, which
picks the wrong 90 deg equivalent of a square cab). ``shape_weight`` blends the
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
    hitch_offset_m: float = 0.0  # trailers: from the centre forward to the hitch (kingpin or drawbar eye)


@dataclass
class _UnitState:
    history: deque
    yaw_deg: float | None = None
    last_seen_s: float | None = None
    provisional: bool = False  # the yaw is a shape-axis guess (no travel, no partner unit)
    flips: int = 0  # consecutive measurements more than 90 deg from the yaw


class OrientationEstimator:
    def __init__(self, params: OrientationParams):
        self.params = params
        self.states: dict[int, _UnitState] = {}
        self._last_stamp_s: float | None = None

    def process(self, units: list[UnitObservation], stamp_s: float, live_track_ids: set[int]) -> dict[int, float]:
        """Yaw (deg) per observed track id; forgets tracks not in ``live_track_ids`` (which should hold
        the lost tracks that may be re-acquired too: they keep their yaw)."""
        frame_dt = self._step(stamp_s)
        self.states = {k: v for k, v in self.states.items() if k in live_track_ids}
        forwards = self._forward_directions(units)
        yaws = {}
        for unit in units:
            state = self.states.setdefault(unit.track_id, _UnitState(deque(maxlen=self.params.history_frames)))
            recent = self._recent(state, stamp_s)
            if not recent:  # a re-acquired unit: its old centroids say nothing of its motion now
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
        """Per (vehicle, kind) with both units seen: a vector pointing forward. Trailer: from its centre
        to the truck's. Truck: the same, or with ``hitch_forward`` from the trailer's hitch point."""
        by_vehicle: dict[int, dict[str, UnitObservation]] = {}
        for u in units:
            by_vehicle.setdefault(u.vehicle_id, {})[u.kind] = u
        out = {}
        for vid, pair in by_vehicle.items():
            if "truck" not in pair or "trailer" not in pair:
                continue
            truck, trailer = (np.asarray(pair[k].center[:2], dtype=float) for k in ("truck", "trailer"))
            out[(vid, "trailer")] = out[(vid, "truck")] = truck - trailer
            if self.params.hitch_forward and pair["trailer"].hitch_offset_m:
                axis = np.radians(pair["trailer"].shape_axis_deg)
                ahead = np.array([np.cos(axis), np.sin(axis)])
                ahead *= 1.0 if ahead @ (truck - trailer) >= 0 else -1.0
                out[(vid, "truck")] = truck - (trailer + pair["trailer"].hitch_offset_m * ahead)
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
        elif has_forward and self.params.shape_weight > 0:
            axis_deg = float(np.degrees(np.arctan2(forward[1], forward[0])))  # first estimate at standstill
        else:
            axis_deg = unit.shape_axis_deg
        # the shape axis of a square cab is known modulo 90 deg only: its equivalent nearest the forward
        # direction (the truck is ahead of the trailer; with hitch_forward, its heading), else nearest
        # its last yaw, is the one; the centre's path (PCA) is up to 45 deg off the heading of a cab
        # turning while reversing
        reference_deg = axis_deg
        if unit.shape_period_deg < 180.0 and self.params.shape_weight > 0:
            if has_forward:
                reference_deg = float(np.degrees(np.arctan2(forward[1], forward[0])))
            elif state.yaw_deg is not None and not state.provisional:
                reference_deg = state.yaw_deg
        axis_deg = self._blend_with_shape(axis_deg, unit.shape_axis_deg, unit.shape_period_deg, reference_deg)
        if self.params.prefer_continuity and state.yaw_deg is not None and len(history) >= 2:
            forward = None  # seen in the last frames: a yaw cannot turn over between two frames
        return self._resolve_direction(axis_deg, forward, state.yaw_deg, travel), moved or has_forward

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

    def _blend_with_shape(
        self, axis_deg: float, shape_axis_deg: float, period_deg: float = 180.0, reference_deg: float | None = None
    ) -> float:
        """The measured axis moved towards the shape axis: its equivalent (modulo 180 deg, or modulo
        90 deg for a nearly square unit such as a tractor cab) nearest ``reference_deg`` (default: the
        measured axis)."""
        w = self.params.shape_weight
        if w <= 0:
            return axis_deg
        shape = self._nearest_equivalent(
            axis_deg if reference_deg is None else reference_deg, shape_axis_deg, period_deg
        )
        shape = self._nearest_equivalent(axis_deg, shape, 180.0)
        return float(axis_deg + w * (shape - axis_deg))

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
            state.provisional, state.flips = not reliable, 0
            return measured_deg
        confirm = self.params.flip_confirm_frames
        if confirm and abs(wrap_deg(measured_deg - state.yaw_deg)) > 90.0:
            state.flips += 1
            if state.flips < confirm:
                return state.yaw_deg  # an isolated flip: a wrong truck / trailer split, not a turn
            state.flips = 0
            return measured_deg  # a persistent one: the old direction was the wrong one
        state.flips = 0
        return self._bounded_smoothed(state.yaw_deg, measured_deg, dt)

    def _bounded_smoothed(self, previous_deg: float, measured_deg: float, dt: float) -> float:
        """Exponential smoothing, then the rate bound on the resulting change."""
        step = (1.0 - self.params.smoothing) * wrap_deg(measured_deg - previous_deg)
        max_step = self.params.max_yaw_rate_deg_s * dt
        return float(wrap_deg(previous_deg + float(np.clip(step, -max_step, max_step))))
