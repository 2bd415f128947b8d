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
    split_by_label,
    voxel_keys,
)

FOOTPRINT_MARGIN_M = 0.1
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

    def process(self, points: np.ndarray, candidates: list[str], ground_z_m: float = 0.0) -> Classification:
        """The candidate vehicle whose trailer gate fits best (error / tolerance) wins."""
        best, best_score = Classification(None, None, None), np.inf
        self._cache: dict = {}  # sub-clusters per (floor, tolerance): vehicles often share a floor height
        for name in candidates:
            vehicle = self.vehicles[name]
            body = np.flatnonzero(points[:, 2] - ground_z_m >= vehicle.trailer.floor_m + self.params.floor_margin_m)
            found = self._find_trailer(points[body], vehicle)
            if found is None:
                continue
            trailer_body, error = found
            is_trailer = self._in_footprint(points, points[body[trailer_body]])
            is_truck = ~is_trailer
            if is_truck.sum() < self.params.min_truck_points:
                continue  # a lone box is not an articulated vehicle (the truck may be occluded, not absent)
            score = error / vehicle.trailer_volume_tolerance_m3
            if score < best_score:
                best, best_score = Classification(name, points[is_truck], points[is_trailer]), score
        return best

    @staticmethod
    def _in_footprint(points: np.ndarray, body: np.ndarray) -> np.ndarray:
        """Points whose xy falls inside the body's oriented rectangle (plus a small margin)."""
        return min_area_rect(body[:, :2]).holds(points, FOOTPRINT_MARGIN_M)

    def _find_trailer(self, body: np.ndarray, vehicle: VehicleConfig):
        """Second clustering at the trailer tolerance; when the cab still touches the trailer (the
        inner corners close in at large hitch angles) retry with smaller tolerances.

        A smaller tolerance only splits sub-clusters, and a part's box is never bigger or longer than
        the whole's: the body is not clustered when it is itself below the trailer's gates, and the
        retries run only while some sub-cluster is too big or too long."""
        if not self._may_hold_trailer(body, vehicle):
            return None
        for factor in TOLERANCE_FACTORS:
            key = (vehicle.trailer.floor_m, factor)
            if key not in self._cache:
                self._cache[key] = self.sub_clusters(body, self.params.trailer_tolerance_m * factor)
            found, splittable = self._best_trailer(body, self._cache[key], vehicle)
            if found is not None or not splittable:
                return found
        return None

    def _may_hold_trailer(self, body: np.ndarray, vehicle: VehicleConfig) -> bool:
        if len(body) < self.params.min_trailer_points:
            return False
        return oriented_box_volume(body)[0] >= vehicle.trailer.volume_m3 - vehicle.trailer_volume_tolerance_m3

    def sub_clusters(self, points: np.ndarray, tolerance_m: float | None = None) -> list[np.ndarray]:
        """Point indices of the xy clusters with at least ``min_trailer_points`` points."""
        if len(points) == 0:
            return []
        xy = points[:, :2].astype(np.float64)
        _, first, inverse = np.unique(voxel_keys(xy, self.params.xy_grid_m), return_index=True, return_inverse=True)
        cell_labels = euclidean_labels(xy[first], tolerance_m or self.params.trailer_tolerance_m)
        labels = cell_labels[inverse.reshape(-1)]
        return [g for g in split_by_label(labels) if len(g) >= self.params.min_trailer_points]

    def _best_trailer(self, points: np.ndarray, groups: list[np.ndarray], vehicle: VehicleConfig):
        """((indices, volume error) or None, whether a sub-cluster was too big or too long) of the
        sub-cluster closest to the trailer volume inside its gate and not too long."""
        expected = vehicle.trailer.volume_m3
        best, best_error, splittable = None, np.inf, False
        for idx in groups:
            volume, rect = oriented_box_volume(points[idx])
            error = abs(volume - expected)
            too_long = rect.length_m > vehicle.trailer.length_m + self.params.max_length_excess_m
            splittable |= too_long or volume > expected + vehicle.trailer_volume_tolerance_m3
            if error <= vehicle.trailer_volume_tolerance_m3 and not too_long and error < best_error:
                best, best_error = idx, error
        return (None if best is None else (best, best_error)), splittable
