"""The localization pipeline: wires the stages of ``i2v_loc.stages`` (docs/pipeline.md).

``Pipeline.process(frame)`` never raises on bad sensor data: faults are counted and reported in
the result (docs/formats.md, state line). ``update_params`` validates a JSON merge patch at once
(``ParamsError``) and applies it at the start of the next ``process`` call; it may be called from
another thread.
"""

from __future__ import annotations

import time
from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from i2v_loc.frame import Frame
from i2v_loc.geometry import box_poses
from i2v_loc.params import Params, VehicleConfig, apply_patch
from i2v_loc.pipelines.handoff import ParameterHandoff
from i2v_loc.stages.articulation import centre_to_hitch_m
from i2v_loc.stages.background import BackgroundMap, ProtectedBox, region_box
from i2v_loc.stages.centroid import CentroidCorrector, CorrectedUnit
from i2v_loc.stages.classification import TruckTrailerClassifier
from i2v_loc.stages.clustering import Cluster, Clustering
from i2v_loc.stages.concatenation import Concatenation, MotionHint
from i2v_loc.stages.orientation import OrientationEstimator, UnitObservation
from i2v_loc.stages.primitives import voxel_centroids
from i2v_loc.stages.region import Region
from i2v_loc.stages.tracking import Detection, Track, Tracker

# "paper": the stages as published (yaw from PCA on the centroid history alone).
# "default": the unit's shape axis as the yaw axis (PCA keeps the history, the travel test and
# the 180 deg resolution; far lower hitch error in turns), the learned static background removed
# before anything else (interpolation, voxel grid and clustering run on the foreground only),
# voxel-grid connected components, the ground refitted once a second, lost tracks re-acquired
# with their ID and yaw, truck + trailer pairs reported from their first frame.
# A preset fills only the fields the given parameters leave at the model default (``method_params``).
# "articulated": the front end of "default", then one hinged-model fit and kinematic UKF per
# vehicle (i2v_loc/pipelines/articulated.py); ``Pipeline(params, "articulated")`` builds that pipeline.
METHODS = ("paper", "default", "articulated")
METHOD_PATCHES = {
    "paper": {},
    "articulated": {"background": {"enabled": True}, "region": {"ground_refit_frames": 10}},
    "default": {
        "background": {"enabled": True},
        "clustering": {"algorithm": "grid", "hitch_range_deg": 90.0},
        "region": {"ground_refit_frames": 10},
        "tracking": {"confirm_paired": True, "reacquire_distance_m": 3.0},
        "centroid": {"truck_front_anchor": True},
        "classification": {
            "truck_one_end": True,
            "complete_width": True,
            "max_hitch_gap_m": 2.0,
            "min_height_fraction": 0.6,
        },
        "orientation": {
            "shape_weight": 1.0,
            "flip_confirm_frames": 5,
            "hitch_forward": True,
            "max_yaw_rate_deg_s": 45.0,
        },
    },
}
STAGES = (
    "concatenation",
    "background",
    "region",
    "clustering",
    "classification",
    "centroid",
    "tracking",
    "orientation",
)
MOTION_HINT_MIN_SPEED_M_S = 0.1
MOTION_HINT_MARGIN_M = 0.5
PREDICTION_S = 0.1  # protected boxes are moved ahead by one frame of the track's velocity
MAX_HITCH_ANGLE_DEG = 100.0  # a semitrailer jack-knifes beyond about 90 deg; 10 deg for the centres' errors
SQUARE_ASPECT = 1.3  # units with length < 1.3 x width have their shape axis known modulo 90 deg only


def method_params(params: Params, method: str) -> Params:
    """``params`` with the method's preset filled in where they hold the model default: a value the
    user set (any value other than the default) always wins over the preset."""
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}; known: {', '.join(METHODS)}")
    patch = _unset_only(METHOD_PATCHES[method], params.model_dump(mode="json"), Params().model_dump(mode="json"))
    return apply_patch(params, patch, source=f"method {method}") if patch else params


def _unset_only(preset: dict, given: dict, defaults: dict) -> dict:
    """The part of ``preset`` whose fields are at their default in ``given``."""
    out = {}
    for key, value in preset.items():
        if isinstance(value, dict):
            sub = _unset_only(value, given.get(key, {}), defaults.get(key, {}))
            if sub:
                out[key] = sub
        elif given.get(key) == defaults.get(key):
            out[key] = value
    return out


def _r(value: float, digits: int = 4) -> float:
    return round(float(value), digits)


@dataclass
class UnitResult:
    track_id: int
    center: np.ndarray
    yaw_deg: float | None
    dimensions: tuple[float, float, float]
    points: int

    def to_json(self) -> dict:
        return {
            "track_id": self.track_id,
            "center": [_r(v) for v in self.center],
            "yaw_deg": None if self.yaw_deg is None else _r(self.yaw_deg, 3),
            "dimensions": [_r(v, 3) for v in self.dimensions],
            "points": int(self.points),
        }


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


@dataclass
class _UnitCandidate:
    kind: str
    vehicle: str
    group: int
    points: np.ndarray
    dims: tuple[float, float, float] = (0.0, 0.0, 0.0)
    corrected: CorrectedUnit | None = None
    yaw_hint_rad: float | None = None  # forward heading of the track it probably continues


@dataclass
class _YawHint:
    kind: str
    vehicle: str
    center_xy: np.ndarray  # where the track's unit is expected in this frame
    yaw_rad: float  # its forward heading


@dataclass
class _Timer:
    latency_ms: dict[str, float] = field(default_factory=dict)
    _t: float = field(default_factory=time.perf_counter)
    _start: float = field(default_factory=time.perf_counter)

    def lap(self, stage: str) -> None:
        now = time.perf_counter()
        self.latency_ms[stage] = (now - self._t) * 1e3
        self._t = now

    def total(self) -> dict[str, float]:
        self.latency_ms["total"] = (time.perf_counter() - self._start) * 1e3
        return self.latency_ms


class Pipeline(ParameterHandoff):
    def __new__(cls, params: Params, method: str = "paper"):
        if method == "articulated":
            from i2v_loc.pipelines.articulated import ArticulatedPipeline

            return ArticulatedPipeline(params)
        return super().__new__(cls)

    def __init__(self, params: Params, method: str = "paper"):
        params = method_params(params, method)
        self.method = method
        self._init_params(params)
        self.counters: Counter = Counter()
        self.tracker = Tracker(params.tracking)
        self.orientation = OrientationEstimator(params.orientation)
        self.background: BackgroundMap | None = None
        self._build(params)
        self._motion: list[MotionHint] = []

    def _build(self, params: Params) -> None:
        """Stages for ``params`` (already in ``_active``)."""
        self.concatenation = Concatenation(params.concatenation, params.sensors)
        self.region = Region(params.region)
        self.clustering = Clustering(params.clustering, params.vehicles)
        self.classifier = TruckTrailerClassifier(params.classification, params.vehicles)
        self.centroid = CentroidCorrector(params.centroid)
        self.tracker.params = params.tracking  # tracks and yaw histories survive a parameter change
        self.orientation.params = params.orientation
        self._build_background(params)

    def _build_background(self, params: Params) -> None:
        """The learned map survives a parameter change unless its grid or learning rule changed."""
        if not params.background.enabled:
            self.background = None
            return
        old = self.background
        if old is not None and old.params == params.background and old.region_box == region_box(params.region):
            return
        self.background = BackgroundMap(params.background, params.region)

    def save_background(self, path) -> None:
        """Write the learned background map (.npz); ``load_background`` restores it."""
        if self.background is None:
            raise ValueError("the background map is disabled (background.enabled is false)")
        self.background.save(path)

    def load_background(self, path) -> None:
        if self.background is None:
            raise ValueError("the background map is disabled (background.enabled is false)")
        self.background.load(path)

    # ----------------------------------------------------------------- processing

    def process(self, frame: Frame) -> FrameResult:
        self._apply_pending()
        params = self._active
        timer = _Timer()
        merged, region, n_points = self._foreground(frame, timer)
        clustering = self.clustering.process(region.points)
        timer.lap("clustering")
        ground_z = region.ground.height_at if region.ground else (lambda x, y: 0.0)
        hints = self._yaw_hints()
        units, cluster_lines = self._classify(clustering.clusters, ground_z, hints)
        timer.lap("classification")
        for unit in units:
            unit.corrected = self._correct(unit, params.vehicles[unit.vehicle], ground_z, hints)
        units = self._articulated(units, params)
        timer.lap("centroid")
        tracked = self.tracker.process([self._detection(u) for u in units], merged.stamp_s)
        timer.lap("tracking")
        vehicles = self._orient(tracked.all_tracks, merged.stamp_s, params)
        timer.lap("orientation")
        self._motion = self._motion_hints(tracked.all_tracks)
        self._count(merged, region, clustering, cluster_lines)
        return FrameResult(
            frame.index,
            merged.stamp_s,
            timer.total(),
            merged.faults,
            {k: v for k, v in merged.dropped.items() if k != "missing"},
            cluster_lines,
            vehicles,
            region.ground_found,
            n_points,
            region.points,
        )

    def _foreground(self, frame: Frame, timer: _Timer):
        """(merged, region, points after concatenation): ``region.points`` are the non-ground points the
        clustering sees (for the default method: off the background, interpolated, voxel-downsampled)."""
        if self.background is None:  # the paper's order
            merged = self.concatenation.process(frame.scans, self._motion)
            timer.lap("concatenation")
            region = self.region.process(merged.points)
            timer.lap("region")
            return merged, region, len(merged.points)
        merged = self.concatenation.merge(frame.scans)
        timer.lap("concatenation")
        split = self.background.process(merged.points, self._protected_boxes())
        timer.lap("background")
        region = self.region.process(merged.points, split.in_region, split.foreground)
        points = region.points.copy()
        if self._active.concatenation.motion_interpolation and self._motion:
            self.concatenation.interpolate(points, merged.lag_s[region.index], self._motion)
        region.points, _ = voxel_centroids(points, self._active.concatenation.voxel_size_m)
        region.index = None
        timer.lap("region")
        return merged, region, len(merged.points)

    def _protected_boxes(self) -> list[ProtectedBox]:
        """Boxes of the confirmed live and lost tracks that have travelled: their voxels are not
        learned. (Protecting young tracks too, so that a vehicle starting slowly along its own length
        is not learned, kept static false vehicles alive: measured 4x more false vehicle frames.)"""
        bg = self._active.background
        boxes = []
        for t in self.tracker.tracks + self.tracker.lost:
            if not t.confirmed or t.travel_m < bg.protect_min_travel_m or t.last_detection is None:
                continue
            unit: _UnitCandidate = t.last_detection.payload
            length, width, _ = unit.dims
            # where the unit is now: the filter's prediction for a live track, the last sighting for a lost one
            center = t.position[:2] + t.velocity * PREDICTION_S if t.lost_at_s is None else t.last_detection.center[:2]
            boxes.append(ProtectedBox(tuple(center), unit.corrected.axis_yaw_rad, length / 2, width / 2))
        return boxes

    def _classify(
        self, clusters: list[Cluster], ground_z, hints: list[_YawHint]
    ) -> tuple[list[_UnitCandidate], list[dict]]:
        units, lines = [], []
        for group, cluster in enumerate(clusters):
            status = cluster.status
            if status == "candidate":
                center = cluster.center
                heading = self._trailer_heading(hints, cluster)
                result = self.classifier.process(
                    cluster.points, cluster.candidates, ground_z(center[0], center[1]), heading
                )
                status = f"vehicle:{result.vehicle}" if result.vehicle else "unmatched"
                for kind, pts in (("truck", result.truck), ("trailer", result.trailer)):
                    if result.vehicle and pts is not None:
                        units.append(_UnitCandidate(kind, result.vehicle, group, pts))
            lines.append(
                {
                    "points": int(len(cluster.points)),
                    "center": [_r(v, 3) for v in cluster.center],
                    "volume_m3": _r(cluster.volume_m3, 2),
                    "status": status,
                }
            )
        return units, lines

    def _trailer_heading(self, hints: list[_YawHint], cluster: Cluster) -> float | None:
        """Heading of the trailer track nearest the cluster's centre within the cluster's half length
        plus the association gate (the trailer's box centre lies in the cluster's box)."""
        best, best_d = None, cluster.rect.length_m / 2 + self._active.tracking.max_distance_m
        for hint in hints:
            d = float(np.hypot(*(hint.center_xy - cluster.rect.center_xy)))
            if hint.kind == "trailer" and hint.vehicle in cluster.candidates and d < best_d:
                best, best_d = hint.yaw_rad, d
        return best

    def _correct(self, unit: _UnitCandidate, vehicle: VehicleConfig, ground_z, hints: list[_YawHint]) -> CorrectedUnit:
        dims = vehicle.truck if unit.kind == "truck" else vehicle.trailer
        points = unit.points
        centroid_xy = points[:, :2].mean(axis=0)
        unit.dims = (dims.length_m, dims.width_m, dims.height_m)
        unit.yaw_hint_rad = self._yaw_hint(hints, unit, centroid_xy)
        anchor = unit.kind == "truck" and self._active.centroid.truck_front_anchor
        return self.centroid.process(points, dims, ground_z(*centroid_xy), unit.yaw_hint_rad, anchor)

    def _yaw_hints(self) -> list[_YawHint]:
        """Tracks with a yaw (live: where the filter expects them now; lost: their last sighting); not a
        provisional one (a lone unit's shape-axis guess, its direction unknown)."""
        hints = []
        for t in self.tracker.tracks + self.tracker.lost:
            state = self.orientation.states.get(t.track_id)
            if state is None or state.yaw_deg is None or state.provisional or t.last_detection is None:
                continue
            center = t.position[:2] + t.velocity * PREDICTION_S if t.lost_at_s is None else t.last_detection.center[:2]
            hints.append(_YawHint(t.kind, t.vehicle, center, float(np.radians(state.yaw_deg))))
        return hints

    def _yaw_hint(self, hints: list[_YawHint], unit: _UnitCandidate, centroid_xy: np.ndarray) -> float | None:
        """Yaw of the nearest track of the unit's kind and vehicle that it can continue: the points'
        centroid lies within half the unit's length of its box centre (one end seen), and the box
        centre within the association gate of the track."""
        best, best_d = None, unit.dims[0] / 2 + self._active.tracking.max_distance_m
        for hint in hints:
            d = float(np.hypot(*(hint.center_xy - centroid_xy)))
            if hint.kind == unit.kind and hint.vehicle == unit.vehicle and d < best_d:
                best, best_d = hint.yaw_rad, d
        return best

    def _articulated(self, units: list[_UnitCandidate], params: Params) -> list[_UnitCandidate]:
        """Drops trucks that the articulation rules out (``classification.max_hitch_gap_m``): the hitch
        point lies at the trailer's front (by its track's yaw, else the end facing the truck); the
        truck's centre is its centre-to-hitch distance from it, ahead of it (|hitch angle| at most
        MAX_HITCH_ANGLE_DEG). A truck elsewhere is a piece of the trailer or of the yard left over by
        the split; the cluster's trailer is still reported."""
        max_gap = params.classification.max_hitch_gap_m
        if max_gap <= 0:
            return units
        trailers = {u.group: u for u in units if u.kind == "trailer"}
        kept = []
        for unit in units:
            trailer = trailers.get(unit.group)
            if (
                unit.kind == "truck"
                and trailer is not None
                and not self._truck_at_hitch(unit, trailer, params.vehicles[unit.vehicle], max_gap)
            ):
                self.counters["truck_off_hitch"] += 1
                continue
            kept.append(unit)
        return kept

    @staticmethod
    def _truck_at_hitch(
        truck: _UnitCandidate, trailer: _UnitCandidate, vehicle: VehicleConfig, max_gap_m: float
    ) -> bool:
        truck_ahead_m, hitch_ahead_m = centre_to_hitch_m(vehicle)
        truck_xy, trailer_xy = truck.corrected.center[:2], trailer.corrected.center[:2]
        axis = trailer.corrected.axis_yaw_rad
        ahead = np.array([np.cos(axis), np.sin(axis)])
        front = (
            truck_xy - trailer_xy
            if trailer.yaw_hint_rad is None
            else np.array([np.cos(trailer.yaw_hint_rad), np.sin(trailer.yaw_hint_rad)])
        )
        ahead *= 1.0 if ahead @ front >= 0 else -1.0
        to_truck = truck_xy - (trailer_xy + hitch_ahead_m * ahead)
        distance_m = float(np.hypot(*to_truck))
        angle_deg = float(np.degrees(np.arccos(np.clip(ahead @ to_truck / max(distance_m, 1e-9), -1.0, 1.0))))
        return abs(distance_m - truck_ahead_m) <= max_gap_m and angle_deg <= MAX_HITCH_ANGLE_DEG

    @staticmethod
    def _detection(unit: _UnitCandidate) -> Detection:
        return Detection(unit.kind, unit.vehicle, unit.group, unit.corrected.center, unit)

    def _orient(self, tracks: list[Track], stamp_s: float, params: Params) -> list[VehicleResult]:
        seen = [t for t in tracks if t.detection is not None]
        observations = [self._observation(t, params) for t in seen]
        kept = {t.track_id for t in tracks + self.tracker.lost}  # a re-acquired unit keeps its yaw
        yaws = self.orientation.process(observations, stamp_s, kept)
        by_vehicle: dict[int, dict[str, UnitResult]] = {}
        names: dict[int, str] = {}
        for t in seen:
            if not t.confirmed:
                continue
            payload: _UnitCandidate = t.detection.payload
            by_vehicle.setdefault(t.vehicle_id, {})[t.kind] = UnitResult(
                t.track_id, t.detection.center, yaws.get(t.track_id), payload.dims, payload.corrected.points
            )
            names[t.vehicle_id] = t.vehicle
        return [self._vehicle_result(vid, names[vid], units) for vid, units in sorted(by_vehicle.items())]

    def _observation(self, track: Track, params: Params) -> UnitObservation:
        unit: _UnitCandidate = track.detection.payload
        hitch_offset_m = 0.0
        if track.kind == "trailer":
            hitch_offset_m = centre_to_hitch_m(params.vehicles[unit.vehicle])[1]
        return UnitObservation(
            track.track_id,
            track.vehicle_id,
            track.kind,
            track.detection.center,
            float(np.degrees(unit.corrected.shape_yaw_rad)) % 180.0,
            self._shape_period_deg(unit.dims),
            hitch_offset_m,
        )

    @staticmethod
    def _shape_period_deg(dims: tuple[float, float, float]) -> float:
        length, width, _ = dims
        return 180.0 if length >= SQUARE_ASPECT * width else 90.0

    def _vehicle_result(self, vehicle_id: int, name: str, units: dict[str, UnitResult]) -> VehicleResult:
        truck, trailer = units.get("truck"), units.get("trailer")
        hitch = OrientationEstimator.hitch_deg(truck and truck.yaw_deg, trailer and trailer.yaw_deg)
        transform = None
        if hitch is not None:
            t_truck, t_trailer = box_poses([truck.center, trailer.center], [truck.yaw_deg, trailer.yaw_deg])
            transform = np.linalg.inv(t_trailer) @ t_truck
        return VehicleResult(vehicle_id, name, truck, trailer, hitch, transform)

    def _motion_hints(self, tracks: list[Track]) -> list[MotionHint]:
        hints = []
        for t in tracks:
            if t.detection is None or np.hypot(*t.velocity) < MOTION_HINT_MIN_SPEED_M_S:
                continue
            unit: _UnitCandidate = t.detection.payload
            length, width, _ = unit.dims
            hints.append(
                MotionHint(
                    tuple(t.detection.center[:2]),
                    unit.corrected.axis_yaw_rad,
                    length / 2 + MOTION_HINT_MARGIN_M,
                    width / 2 + MOTION_HINT_MARGIN_M,
                    tuple(t.velocity),
                )
            )
        return hints

    def _count(self, merged, region, clustering, cluster_lines: list[dict]) -> None:
        self.counters["frames"] += 1
        for reason, n in merged.dropped.items():
            self.counters[reason] += n
        if not region.ground_found:
            self.counters["no_ground"] += 1
        self.counters["noise_clusters"] += clustering.noise_clusters
        for line in cluster_lines:
            if line["status"] in ("too_large", "too_small", "unmatched"):
                self.counters[line["status"]] += 1
