"""The ``default`` method, the articulated estimator: the front end (merge, background, region) then
one hinged-model fit and one kinematic UKF per vehicle (docs/pipeline.md, Articulated estimator).
Same interface and state line as the paper's pipeline (``i2v_loc.results``); each vehicle adds
``kind``, ``hitch_std_deg``, ``jackknife`` and ``speed_m_s``. Its parameters are the model's defaults.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass

import numpy as np

from i2v_loc.frame import Frame
from i2v_loc.geometry import box_poses, rigid_inverse
from i2v_loc.params import Params
from i2v_loc.pipelines.handoff import ParameterHandoff
from i2v_loc.results import FrameResult, StageTimer, UnitResult, VehicleResult, _r, count_frame, frame_result
from i2v_loc.stages.background import BackgroundMap, ProtectedBox, region_box
from i2v_loc.stages.concatenation import Concatenation, MotionHint
from i2v_loc.stages.kinematic_filter import unit_motions
from i2v_loc.stages.level_frame import LevelFrame
from i2v_loc.stages.primitives import Rect, voxel_centroids
from i2v_loc.stages.region import Region
from i2v_loc.stages.vehicle_model import Box
from i2v_loc.stages.vehicle_start import Background
from i2v_loc.stages.vehicle_tracker import VehicleReport, VehicleTracker
from i2v_loc.stages.visibility import Rays

MOTION_MARGIN_M = 0.5
MIN_MOTION_SPEED_M_S = 0.1


@dataclass
class ArticulatedVehicleResult(VehicleResult):
    kind: str = "articulated"  # or rigid
    hitch_std_deg: float | None = None
    jackknife: bool = False
    speed_m_s: float = 0.0

    def to_json(self) -> dict:
        out = super().to_json()
        out.update(
            {
                "kind": self.kind,
                "speed_m_s": _r(self.speed_m_s, 3),
                "jackknife": self.jackknife,
                "hitch_std_deg": None if self.hitch_std_deg is None else _r(self.hitch_std_deg, 3),
            }
        )
        return out


class ArticulatedPipeline(ParameterHandoff):
    method = "default"

    def __init__(self, params: Params):
        self._init_params(params)
        self.counters: Counter = Counter()
        self.tracker = VehicleTracker(params.articulated, params.vehicles)
        self.level = LevelFrame()  # the tracker's frame: the ground level in it
        self._ground = self.level.ground(None)  # the last frame's ground height in the level frame
        self.background: BackgroundMap | None = None
        self._reports: list[VehicleReport] = []
        self._reports_stamp_s = float("nan")  # the reference time of the frame the reports are of
        self._build(params)

    def _build(self, params: Params) -> None:
        self.concatenation = Concatenation(params.concatenation, params.sensors)
        self.region = Region(params.region)
        self.tracker.params = params.articulated  # vehicles survive a parameter change
        if not params.background.enabled:  # the user turned the map off: vehicles start at once
            self.background = None
        elif (
            self.background is None
            or self.background.params != params.background
            or self.background.region_box != region_box(params.region)
        ):
            self.background = BackgroundMap(params.background, params.region)  # else the learned map survives

    def forget_vehicles(self) -> None:
        """Drop every vehicle and seed (a looping replay starts over); the map and parameters stay."""
        self.tracker.forget()
        self._reports = []

    def save_background(self, path) -> None:
        self._map().save(path)

    def load_background(self, path) -> None:
        self._map().load(path)

    def _map(self) -> BackgroundMap:
        if self.background is None:
            raise ValueError("the background map is disabled (background.enabled is false)")
        return self.background

    # ----------------------------------------------------------------- processing

    def process(self, frame: Frame) -> FrameResult:
        self._apply_pending()
        params = self._active
        timer = StageTimer()
        merged = self.concatenation.merge(frame.scans)
        timer.lap("merge")
        units = list(self._unit_boxes())  # the last frame's vehicles, for the map and the de-skew
        if self.background is not None:
            split = self.background.process(merged.points, self._protected_boxes(units))
            region = self.region.process(merged.points, split.in_region, split.foreground)
        else:
            region = self.region.process(merged.points)
        points = region.points  # the region's own gathered copy: interpolated in place
        if params.concatenation.motion_interpolation and self._reports:
            age_s = merged.stamp_s - self._reports_stamp_s
            self.concatenation.interpolate(points, merged.lag_s[region.index], self._motion_hints(units, age_s))
        points, _ = voxel_centroids(points, params.concatenation.voxel_size_m)
        timer.lap("front_end")
        self.level.update(region.ground)
        ground = self._ground = self.level.ground(region.ground)
        if np.isfinite(merged.stamp_s):
            level_points = self.level.points(points)
            known = np.isfinite(merged.sweep_origins).all(axis=1).any()  # else no ray is known (a cloud file)
            rays = (
                Rays(
                    merged.points,
                    merged.sweep_origins,
                    merged.sweep_bounds,
                    self.level.rotation,
                    merged.lag_s,
                    merged.unreturned,
                )
                if known
                else None
            )
            self._reports = self.tracker.process(level_points, ground, merged.stamp_s, self._map_state(), rays)
            self._reports_stamp_s = merged.stamp_s
        timer.lap("vehicles")
        vehicles = [self._result(r, ground) for r in self._reports]
        self._count(merged, region)
        # the seeding of new vehicles runs inside the tracker's one call: "candidates" stays 0
        return frame_result(frame.index, merged, timer.total(), [], vehicles, region.ground_found, points)

    def _map_state(self) -> Background:
        """No map, or one still learned, or learned (the start's rules differ: ``vehicle_start.Background``)."""
        if self.background is None:
            return Background.NONE
        return Background.READY if self.background.ready else Background.LEARNING

    def _result(self, report: VehicleReport, ground) -> ArticulatedVehicleResult:
        s, model = report.state, report.model
        tractor_xy, trailer_xy = model.box_centers(s.x_m, s.y_m, s.yaw_rad, s.hitch_rad)
        seen = report.dimensions_seen
        truck = self._unit(report.id, tractor_xy, s.yaw_rad, model.tractor, report.tractor_points, ground, seen[0])
        if model.trailer is None:
            return ArticulatedVehicleResult(
                report.id, model.name, truck, None, None, None, "rigid", None, False, s.speed_m_s
            )
        trailer = self._unit(
            report.id, trailer_xy, s.yaw_rad + s.hitch_rad, model.trailer, report.trailer_points, ground, seen[1]
        )
        t_truck, t_trailer = box_poses([truck.center, trailer.center], [truck.yaw_deg, trailer.yaw_deg])
        return ArticulatedVehicleResult(
            report.id,
            model.name,
            truck,
            trailer,
            float(np.degrees(s.hitch_rad)),
            rigid_inverse(t_trailer) @ t_truck,
            "articulated",
            float(np.degrees(s.hitch_std_rad)),
            s.jackknife,
            s.speed_m_s,
        )

    def _unit(
        self, vehicle_id: int, center_xy: np.ndarray, yaw_rad: float, box: Box, points: int, ground, seen
    ) -> UnitResult:
        """A unit's box in the yard frame from its level-frame centre and yaw."""
        z = ground(*center_xy) + box.floor_m + box.height_m / 2
        center = self.level.to_yard(np.array([center_xy[0], center_xy[1], z]))
        yaw_deg = float(np.degrees(self.level.yaw_to_yard(yaw_rad)))
        return UnitResult(vehicle_id, center, yaw_deg, box.dims, points, seen)

    def _unit_boxes(self):
        """(centre xy, yaw, box, centre velocity xy, yaw rate, travel, articulated) of every unit of
        the vehicles of the last frame, in the yard frame."""
        for center, yaw, box, velocity, rate, travel, articulated in self._level_unit_boxes():
            velocity = self.level.vector_to_yard(velocity)
            yield self._yard_xy(center), self.level.yaw_to_yard(yaw), box, velocity, rate, travel, articulated

    def _yard_xy(self, center_xy) -> np.ndarray:
        """The yard xy of a level-frame place on the ground."""
        x, y = center_xy
        return self.level.to_yard(np.array([x, y, self._ground(x, y)]))[:2]

    def _level_unit_boxes(self):
        for r in self._reports:
            model = r.model
            for motion, box in zip(unit_motions(r.state, model), model.boxes):
                yield (
                    motion.center_xy, motion.yaw_rad, box, motion.velocity_xy, motion.rate_rad_s, r.travel_m,
                    model.articulated,
                )  # fmt: skip

    def _protected_boxes(self, units) -> list[ProtectedBox]:
        """Every articulated vehicle's boxes (one standing from the start is no background), a rigid
        one's once it travelled (a parked container that fooled the start becomes background), and
        every seed's that moved before it started."""
        min_travel = self._active.background.protect_min_travel_m
        tracked = [
            ProtectedBox(tuple(c), yaw, box.length_m / 2, box.width_m / 2)
            for c, yaw, box, _, _, travel, articulated in units
            if articulated or travel >= min_travel
        ]
        return tracked + [self._yard_box(rect) for rect in self.tracker.moving_seeds()]

    def _yard_box(self, rect: Rect) -> ProtectedBox:
        center, yaw = self._yard_xy(rect.center_xy), self.level.yaw_to_yard(rect.yaw_rad)
        return ProtectedBox(tuple(center), yaw, rect.length_m / 2, rect.width_m / 2)

    def _motion_hints(self, units, age_s: float) -> list[MotionHint]:
        """The last frame's units, ``age_s`` before this frame's reference time: each point is tested
        against its unit's box moved on to the point's capture time."""
        return [
            MotionHint(
                tuple(c),
                yaw,
                box.length_m / 2 + MOTION_MARGIN_M,
                box.width_m / 2 + MOTION_MARGIN_M,
                tuple(v),
                rate,
                age_s,
            )
            for c, yaw, box, v, rate, _, _ in units
            if np.hypot(*v) >= MIN_MOTION_SPEED_M_S
        ]

    def _count(self, merged, region) -> None:
        count_frame(self.counters, merged, region.ground_found)
        self.counters["fits_rejected"] = self.tracker.rejected
