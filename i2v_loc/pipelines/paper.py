"""The ``paper`` method: the published pipeline, kept faithful for comparison (docs/pipeline.md).

merge (extrinsics, sync, motion interpolation, voxel grid) -> front end (region, RANSAC ground)
-> candidates (Euclidean clusters, whole-vehicle volume gate) -> vehicles (truck / trailer split,
centroid correction, SORT per unit, PCA yaw, hitch angle). Its parameters differing from the model's
defaults are ``params/presets/paper.yaml``.

``process(frame)`` never raises on bad sensor data: faults are counted and reported in the result
(docs/formats.md, state line). ``update_params`` validates a JSON merge patch at once
(``ParamsError``) and applies it at the start of the next ``process`` call; it may be called from
another thread.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass

import numpy as np

from i2v_loc.frame import Frame
from i2v_loc.geometry import box_poses
from i2v_loc.params import Params, VehicleConfig
from i2v_loc.pipelines.handoff import ParameterHandoff
from i2v_loc.pipelines.presets import with_preset
from i2v_loc.results import FrameResult, StageTimer, UnitResult, VehicleResult, _r, count_frame, frame_result
from i2v_loc.stages.centroid import CentroidCorrector, CorrectedUnit
from i2v_loc.stages.classification import TruckTrailerClassifier
from i2v_loc.stages.clustering import Cluster, Clustering
from i2v_loc.stages.concatenation import Concatenation, MotionHint
from i2v_loc.stages.orientation import OrientationEstimator, UnitObservation
from i2v_loc.stages.region import Region
from i2v_loc.stages.tracking import Detection, Track, Tracker

MOTION_HINT_MIN_SPEED_M_S = 0.1
MOTION_HINT_MARGIN_M = 0.5
PREDICTION_S = 0.1  # a track's yaw hint is placed one frame of its velocity ahead


@dataclass
class _UnitCandidate:
    kind: str
    vehicle: str
    group: int
    points: np.ndarray
    dims: tuple[float, float, float] = (0.0, 0.0, 0.0)
    corrected: CorrectedUnit | None = None


@dataclass
class _YawHint:
    kind: str
    vehicle: str
    center_xy: np.ndarray  # where the track's unit is expected in this frame
    yaw_rad: float  # its forward heading


class PaperPipeline(ParameterHandoff):
    method = "paper"

    def __init__(self, params: Params):
        params = with_preset(params, "paper")
        self._init_params(params)
        self.counters: Counter = Counter()
        self.tracker = Tracker(params.tracking)
        self.orientation = OrientationEstimator(params.orientation)
        self._build(params)
        self._motion: list[MotionHint] = []

    def forget_vehicles(self) -> None:
        """Drop every track and yaw history (a looping replay starts over)."""
        self.tracker = Tracker(self._active.tracking)
        self.orientation = OrientationEstimator(self._active.orientation)
        self._motion = []

    def _build(self, params: Params) -> None:
        """Stages for ``params`` (already in ``_active``)."""
        self.concatenation = Concatenation(params.concatenation, params.sensors)
        self.region = Region(params.region)
        self.clustering = Clustering(params.clustering, params.vehicles)
        self.classifier = TruckTrailerClassifier(params.classification, params.vehicles)
        self.centroid = CentroidCorrector(params.centroid)
        self.tracker.params = params.tracking  # tracks and yaw histories survive a parameter change
        self.orientation.params = params.orientation

    # ----------------------------------------------------------------- processing

    def process(self, frame: Frame) -> FrameResult:
        self._apply_pending()
        params = self._active
        timer = StageTimer()
        merged = self.concatenation.process(frame.scans, self._motion)
        timer.lap("merge")
        region = self.region.process(merged.points)
        timer.lap("front_end")
        clustering = self.clustering.process(region.points)
        timer.lap("candidates")
        ground_z = region.ground.height_at if region.ground else (lambda x, y: 0.0)
        hints = self._yaw_hints()
        units, cluster_lines = self._classify(clustering.clusters, ground_z)
        for unit in units:
            unit.corrected = self._correct(unit, params.vehicles[unit.vehicle], ground_z, hints)
        tracked = self.tracker.process([self._detection(u) for u in units], merged.stamp_s)
        vehicles = self._orient(tracked.all_tracks, merged.stamp_s)
        timer.lap("vehicles")
        self._motion = self._motion_hints(tracked.all_tracks)
        self._count(merged, region, clustering, cluster_lines)
        return frame_result(
            frame.index, merged, timer.total(), cluster_lines, vehicles, region.ground_found, region.points
        )

    def _classify(self, clusters: list[Cluster], ground_z) -> tuple[list[_UnitCandidate], list[dict]]:
        units, lines = [], []
        for group, cluster in enumerate(clusters):
            status = cluster.status
            if status == "candidate":
                center = cluster.center
                result = self.classifier.process(cluster.points, cluster.candidates, ground_z(center[0], center[1]))
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

    def _correct(self, unit: _UnitCandidate, vehicle: VehicleConfig, ground_z, hints: list[_YawHint]) -> CorrectedUnit:
        dims = vehicle.truck if unit.kind == "truck" else vehicle.trailer
        centroid_xy = unit.points[:, :2].mean(axis=0)
        unit.dims = (dims.length_m, dims.width_m, dims.height_m)
        yaw_hint_rad = self._yaw_hint(hints, unit, centroid_xy)
        return self.centroid.process(unit.points, dims, ground_z(*centroid_xy), yaw_hint_rad)

    def _yaw_hints(self) -> list[_YawHint]:
        """Tracks with a yaw, where the filter expects them now; not a provisional one (a lone unit's
        shape-axis guess, its direction unknown)."""
        hints = []
        for t in self.tracker.tracks:
            state = self.orientation.states.get(t.track_id)
            if state is None or state.yaw_deg is None or state.provisional:
                continue
            center = t.position[:2] + t.velocity * PREDICTION_S
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

    @staticmethod
    def _detection(unit: _UnitCandidate) -> Detection:
        return Detection(unit.kind, unit.vehicle, unit.group, unit.corrected.center, unit)

    def _orient(self, tracks: list[Track], stamp_s: float) -> list[VehicleResult]:
        seen = [t for t in tracks if t.detection is not None]
        observations = [
            UnitObservation(
                t.track_id,
                t.vehicle_id,
                t.kind,
                t.detection.center,
                float(np.degrees(t.detection.payload.corrected.shape_yaw_rad)) % 180.0,
            )
            for t in seen
        ]
        yaws = self.orientation.process(observations, stamp_s, {t.track_id for t in tracks})
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

    @staticmethod
    def _vehicle_result(vehicle_id: int, name: str, units: dict[str, UnitResult]) -> VehicleResult:
        truck, trailer = units.get("truck"), units.get("trailer")
        hitch = OrientationEstimator.hitch_deg(truck and truck.yaw_deg, trailer and trailer.yaw_deg)
        transform = None
        if hitch is not None:
            t_truck, t_trailer = box_poses([truck.center, trailer.center], [truck.yaw_deg, trailer.yaw_deg])
            transform = np.linalg.inv(t_trailer) @ t_truck
        return VehicleResult(vehicle_id, name, truck, trailer, hitch, transform)

    @staticmethod
    def _motion_hints(tracks: list[Track]) -> list[MotionHint]:
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
        count_frame(self.counters, merged, region.ground_found)
        self.counters["noise_clusters"] += clustering.noise_clusters
        for line in cluster_lines:
            if line["status"] in ("too_large", "too_small", "unmatched"):
                self.counters[line["status"]] += 1
