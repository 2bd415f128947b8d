"""Stage 5: truck / trailer classification inside a vehicle cluster (paper section 3.4).

A second Euclidean clustering with the trailer's tolerance finds the trailer (its own volume
gate V_trailer +- dV_trailer, and not longer than the trailer plus ``max_length_excess_m``);
the truck is the vehicle cluster minus the trailer points, and must hold ``min_truck_points``
(a car-sized box alone passing the Twizy's trailer gate is not an articulated vehicle).

Why the second clustering runs on the trailer *body* in xy: the tractor's chassis rails,
fifth wheel, drawbar and wheels connect the cab to the trailer at low height, so the second
clustering only looks at points higher than the trailer's floor (+ ``floor_margin_m``) above
the ground. There the cab and the trailer front are separated by a horizontal gap (about
0.7 m on the MAN, 1.3 m on the Volvo), while the 32-beam rings on one wall are up to 0.5 m apart
vertically at 20 m: in 3D an epsilon below the gap would cut walls into rings; in xy the rings
of one wall fall on one line. So epsilon must be below the cab-trailer gap and above the
horizontal point spacing (about 0.1-0.25 m): 0.35 m by default. Points below the floor inside
the trailer body's footprint (its wheels, landing legs, and the fifth wheel under it) join the
trailer; everything else is the truck.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from i2v_loc.params import ClassificationParams, VehicleConfig
from i2v_loc.stages.primitives import (
    euclidean_labels,
    min_area_rect,
    oriented_box_volume,
    rect_along,
    split_by_label,
    voxel_keys,
)

FOOTPRINT_MARGIN_M = 0.1
HEADING_TRUST_DEG = 20.0  # a fitted rectangle further off the tracked heading is not the trailer's axis
TOP_PERCENTILE = 95  # a candidate's top: robust to a few stray points above it
MISSING_WALL_M = 0.3  # a trailer found this much narrower than its width lacks its far wall; the
# widened footprint reaches this far beyond the width (range noise, the fitted axis a little off)
TOLERANCE_FACTORS = (1.0, 0.6, 0.4)  # retries of the second clustering with smaller epsilon


@dataclass
class Classification:
    vehicle: str | None  # configured vehicle name, None when no trailer passed the gate
    truck: np.ndarray | None  # (N, 3) points; at least min_truck_points when vehicle is set
    trailer: np.ndarray | None


class TruckTrailerClassifier:
    def __init__(self, params: ClassificationParams, vehicles: dict[str, VehicleConfig]):
        self.params = params
        self.vehicles = vehicles
        self._cache: dict = {}

    def process(
        self, points: np.ndarray, candidates: list[str], ground_z_m: float = 0.0, heading_rad: float | None = None
    ) -> Classification:
        """The candidate vehicle whose trailer gate fits best (error / tolerance) wins. ``heading_rad``:
        the trailer's heading when its track knows it: the footprint is laid along it (with
        ``complete_width``) and the truck is at its front end (with ``truck_one_end``)."""
        best, best_score = Classification(None, None, None), np.inf
        if not (self.params.truck_one_end or self.params.complete_width):
            heading_rad = None  # the paper's classification: no track knowledge
        self._cache: dict = {}  # sub-clusters per (floor, tolerance): vehicles often share a floor height
        for name in candidates:
            vehicle = self.vehicles[name]
            body = np.flatnonzero(points[:, 2] - ground_z_m >= vehicle.trailer.floor_m + self.params.floor_margin_m)
            found = self._find_trailer(points[body], vehicle, ground_z_m)
            if found is None:
                continue
            trailer_body, error = found
            is_trailer, along_m = self._in_footprint(
                points, points[body[trailer_body]], vehicle.trailer.width_m, heading_rad
            )
            is_truck = ~is_trailer
            if self.params.truck_one_end:
                is_truck &= self._truck_end(along_m, is_truck, heading_rad is not None, self.params.min_truck_points)
            if is_truck.sum() < self.params.min_truck_points:
                continue  # a lone box is not an articulated vehicle (the truck may be occluded, not absent)
            score = error / vehicle.trailer_volume_tolerance_m3
            if score < best_score:
                best, best_score = Classification(name, points[is_truck], points[is_trailer]), score
        return best

    @staticmethod
    def _truck_end(along_m: np.ndarray, rest: np.ndarray, front_known: bool = False, min_points: int = 1) -> np.ndarray:
        """The tractor is at one end of the trailer: keep the remaining points of its front half (when
        ``along_m`` runs forward and that half holds a truck), else of the half holding most of them;
        the other end's (a dock's bumpers, a person, a trailer wall left over by the split) are dropped."""
        front = along_m > 0
        in_front = int((rest & front).sum())
        if front_known and in_front >= min_points:
            return front
        return front if in_front >= (rest & ~front).sum() else ~front

    def _in_footprint(
        self, points: np.ndarray, body: np.ndarray, width_m: float, heading_rad: float | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Points whose xy falls inside the body's oriented rectangle (plus a small margin), and each
        point's coordinate along the rectangle's long axis from its centre (forward along
        ``heading_rad`` when given).

        With ``complete_width``: when the roof is not seen, a trailer's far wall can be a sub-cluster
        of its own (the walls are its width apart) or joined to the cab: a body narrower than the
        trailer's width by more than MISSING_WALL_M is widened to it on the side holding more points
        (a wall along the whole trailer outweighs a cab beside its front corner). The widened
        rectangle is laid along the heading when known: the minimum-area rectangle of a wall and a
        strip of roof is skewed by several degrees, which leaves the far wall's end out. So is a
        rectangle more than HEADING_TRUST_DEG off the heading (a short trailer seen in part: its
        length and width swapped). Otherwise a trailer keeps its own rectangle: the tracked heading
        lags a turning trailer by degrees."""
        rect = min_area_rect(body[:, :2])
        widen = self.params.complete_width and width_m - rect.width_m > MISSING_WALL_M
        if heading_rad is not None:
            if widen or abs(np.sin(rect.yaw_rad - heading_rad)) > np.sin(np.radians(HEADING_TRUST_DEG)):
                rect = rect_along(body[:, :2], heading_rad)
            elif np.cos(rect.yaw_rad - heading_rad) < 0:
                rect.yaw_rad += np.pi  # the same rectangle, its axis forward
        d = points[:, :2] - rect.center_xy
        along = d @ [np.cos(rect.yaw_rad), np.sin(rect.yaw_rad)]
        across = d @ [-np.sin(rect.yaw_rad), np.cos(rect.yaw_rad)]
        margin = FOOTPRINT_MARGIN_M
        beside = np.abs(along) <= rect.length_m / 2 + margin
        low, high = -rect.width_m / 2 - margin, rect.width_m / 2 + margin
        if widen and width_m - rect.width_m > MISSING_WALL_M:
            missing_m = width_m - rect.width_m + MISSING_WALL_M
            left = int((beside & (across > high) & (across <= high + missing_m)).sum())
            right = int((beside & (across < low) & (across >= low - missing_m)).sum())
            if left or right:
                low, high = (low, high + missing_m) if left >= right else (low - missing_m, high)
        return beside & (across >= low) & (across <= high), along

    def _find_trailer(self, body: np.ndarray, vehicle: VehicleConfig, ground_z_m: float = 0.0):
        """Second clustering at the trailer tolerance; when the cab still touches the trailer (the
        inner corners close in at large hitch angles) retry with smaller tolerances.

        A smaller tolerance only splits sub-clusters, and a part's box is never bigger, longer or
        higher than the whole's: the body is not clustered when it is itself below the trailer's
        gates, and the retries run only while some sub-cluster is too big, too long or too low."""
        if not self._may_hold_trailer(body, vehicle, ground_z_m):
            return None
        for factor in TOLERANCE_FACTORS:
            key = (vehicle.trailer.floor_m, factor)
            if key not in self._cache:
                self._cache[key] = self.sub_clusters(body, self.params.trailer_tolerance_m * factor)
            found, splittable = self._best_trailer(body, self._cache[key], vehicle, ground_z_m)
            if found is not None or not splittable:
                return found
        return None

    def _may_hold_trailer(self, body: np.ndarray, vehicle: VehicleConfig, ground_z_m: float) -> bool:
        if len(body) < self.params.min_trailer_points:
            return False
        if self.params.min_height_fraction > 0 and body[:, 2].max() - ground_z_m < self._min_top_m(vehicle):
            return False
        return oriented_box_volume(body)[0] >= vehicle.trailer.volume_m3 - vehicle.trailer_volume_tolerance_m3

    def _min_top_m(self, vehicle: VehicleConfig) -> float:
        return vehicle.trailer.floor_m + self.params.min_height_fraction * vehicle.trailer.height_m

    def sub_clusters(self, points: np.ndarray, tolerance_m: float | None = None) -> list[np.ndarray]:
        """Point indices of the xy clusters with at least ``min_trailer_points`` points."""
        if len(points) == 0:
            return []
        xy = points[:, :2].astype(np.float64)
        _, first, inverse = np.unique(voxel_keys(xy, self.params.xy_grid_m), return_index=True, return_inverse=True)
        cell_labels = euclidean_labels(xy[first], tolerance_m or self.params.trailer_tolerance_m)
        labels = cell_labels[inverse.reshape(-1)]
        return [g for g in split_by_label(labels) if len(g) >= self.params.min_trailer_points]

    def _best_trailer(
        self, points: np.ndarray, groups: list[np.ndarray], vehicle: VehicleConfig, ground_z_m: float = 0.0
    ):
        """((indices, volume error) or None, whether a sub-cluster was too big or too long) of the
        sub-cluster closest to the trailer volume inside its gate, not too long and
        (``min_height_fraction``) reaching high enough: a car's body passes the Twizy trailer's
        volume gate, but its top is 1 m below the trailer's."""
        expected = vehicle.trailer.volume_m3
        min_top_m = self._min_top_m(vehicle)
        best, best_error, splittable = None, np.inf, False
        for idx in groups:
            volume, rect = oriented_box_volume(points[idx])
            error = abs(volume - expected)
            too_long = rect.length_m > vehicle.trailer.length_m + self.params.max_length_excess_m
            too_low = (
                self.params.min_height_fraction > 0
                and np.percentile(points[idx, 2], TOP_PERCENTILE) - ground_z_m < min_top_m
            )
            # a part's top percentile can be higher than the whole's (a trailer joined to a low cab)
            splittable |= too_long or too_low or volume > expected + vehicle.trailer_volume_tolerance_m3
            if error <= vehicle.trailer_volume_tolerance_m3 and not too_long and not too_low and error < best_error:
                best, best_error = idx, error
        return (None if best is None else (best, best_error)), splittable
