"""Stage 7: SORT tracking of truck and trailer units (paper section 3.5, Eq. 8-10).

Each unit track is a constant-velocity Kalman filter on (x, vx, y, vy) (filterpy). Detections are
assigned to predicted tracks of the same kind by the Hungarian algorithm on Euclidean distance,
gated at ``max_distance_m`` (paper: 1 m). Unassigned detections start tracks; tracks unseen for
more than ``max_age_frames`` die; a track is confirmed (reported) after ``min_hits`` hits.
A truck and a trailer detected in one vehicle cluster share a vehicle ID (the older one wins).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from filterpy.common import Q_discrete_white_noise
from filterpy.kalman import KalmanFilter
from scipy.optimize import linear_sum_assignment

from i2v_loc.params import TrackingParams

UNASSIGNABLE = 1e6


@dataclass
class Detection:
    kind: str  # "truck" | "trailer"
    vehicle: str  # configured vehicle name
    group: int  # index of the vehicle cluster in this frame: units of one group are one vehicle
    center: np.ndarray  # (3,) corrected centre
    payload: Any = None  # carried to the output unchanged


@dataclass
class Track:
    track_id: int
    vehicle_id: int
    kind: str
    vehicle: str
    kf: KalmanFilter
    z_m: float
    hits: int = 1
    misses: int = 0
    confirmed: bool = False
    detection: Detection | None = None

    @property
    def position(self) -> np.ndarray:
        return np.array([self.kf.x[0, 0], self.kf.x[2, 0], self.z_m])

    @property
    def velocity(self) -> np.ndarray:
        return np.array([self.kf.x[1, 0], self.kf.x[3, 0]])


@dataclass
class TrackingResult:
    tracks: list[Track]  # confirmed tracks updated in this frame
    all_tracks: list[Track] = field(default_factory=list)  # every live track (for motion hints)


class Tracker:
    def __init__(self, params: TrackingParams):
        self.params = params
        self.tracks: list[Track] = []
        self._track_ids = itertools.count(1)
        self._vehicle_ids = itertools.count(1)
        self._last_stamp_s: float | None = None

    def process(self, detections: list[Detection], stamp_s: float) -> TrackingResult:
        dt = self._step(stamp_s)
        for track in self.tracks:
            self._set_dt(track.kf, dt)
            track.kf.predict()
        matches, unmatched = self._associate(detections)
        for t_idx, d_idx in matches:
            self._update(self.tracks[t_idx], detections[d_idx])
        matched_tracks = {t for t, _ in matches}
        for t_idx, track in enumerate(self.tracks):
            if t_idx not in matched_tracks:
                track.misses += 1
                track.detection = None
        for d_idx in unmatched:
            self.tracks.append(self._new_track(detections[d_idx]))
        self.tracks = [t for t in self.tracks if t.misses <= self.params.max_age_frames]
        self._share_vehicle_ids()
        reported = [t for t in self.tracks if t.confirmed and t.detection is not None]
        return TrackingResult(reported, list(self.tracks))

    # ----------------------------------------------------------------- internals

    def _step(self, stamp_s: float) -> float:
        dt = 0.1 if self._last_stamp_s is None or not np.isfinite(stamp_s) else stamp_s - self._last_stamp_s
        if np.isfinite(stamp_s):
            self._last_stamp_s = stamp_s
        return float(np.clip(dt, 1e-3, 2.0))

    def _associate(self, detections: list[Detection]) -> tuple[list[tuple[int, int]], list[int]]:
        if not self.tracks or not detections:
            return [], list(range(len(detections)))
        predicted = np.array([t.position[:2] for t in self.tracks])
        measured = np.array([d.center[:2] for d in detections])
        cost = np.linalg.norm(predicted[:, None] - measured[None], axis=2)
        kinds_differ = np.array([[t.kind != d.kind for d in detections] for t in self.tracks])
        cost[kinds_differ | (cost > self.params.max_distance_m)] = UNASSIGNABLE
        rows, cols = linear_sum_assignment(cost)
        matches = [(int(r), int(c)) for r, c in zip(rows, cols) if cost[r, c] < UNASSIGNABLE]
        assigned = {c for _, c in matches}
        return matches, [d for d in range(len(detections)) if d not in assigned]

    def _update(self, track: Track, detection: Detection) -> None:
        track.kf.update(detection.center[:2].reshape(2, 1))
        track.z_m = float(detection.center[2])
        track.hits += 1
        track.misses = 0
        track.detection = detection
        track.vehicle = detection.vehicle
        track.confirmed = track.confirmed or track.hits >= self.params.min_hits

    def _new_filter(self, center: np.ndarray) -> KalmanFilter:
        kf = KalmanFilter(dim_x=4, dim_z=2)
        kf.x = np.array([[center[0]], [0.0], [center[1]], [0.0]])
        kf.H = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0]])
        kf.R *= self.params.measurement_noise_m**2
        kf.P = np.diag([self.params.measurement_noise_m**2, 4.0, self.params.measurement_noise_m**2, 4.0])
        self._set_dt(kf, 0.1)
        return kf

    def _new_track(self, detection: Detection) -> Track:
        kf = self._new_filter(detection.center)
        return Track(
            next(self._track_ids),
            0,
            detection.kind,
            detection.vehicle,
            kf,
            float(detection.center[2]),
            confirmed=self.params.min_hits <= 1,
            detection=detection,
        )

    def _set_dt(self, kf: KalmanFilter, dt: float) -> None:
        kf.F = np.array([[1.0, dt, 0, 0], [0, 1.0, 0, 0], [0, 0, 1.0, dt], [0, 0, 0, 1.0]])
        kf.Q = Q_discrete_white_noise(dim=2, dt=dt, var=self.params.process_noise, block_size=2, order_by_dim=True)

    def _share_vehicle_ids(self) -> None:
        """Units seen in one vehicle cluster this frame get one vehicle ID (the oldest they hold)."""
        groups: dict[int, list[Track]] = {}
        for track in self.tracks:
            if track.detection is not None:
                groups.setdefault(track.detection.group, []).append(track)
        for members in groups.values():
            ids = [t.vehicle_id for t in members if t.vehicle_id]
            vehicle_id = min(ids) if ids else next(self._vehicle_ids)
            for t in members:
                t.vehicle_id = vehicle_id
        for track in self.tracks:
            if not track.vehicle_id:
                track.vehicle_id = next(self._vehicle_ids)
