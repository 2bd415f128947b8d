"""Stage 5: truck / trailer classification inside a vehicle cluster (paper section 3.4).

A second Euclidean clustering with the trailer's tolerance finds the trailer (its own volume
gate V_trailer +- dV_trailer, and not longer than the trailer plus ``max_length_excess_m``);
the truck is the vehicle cluster minus the trailer points.

The second clustering runs on the xy projection: the cab and the trailer front are separated by
a horizontal gap (about 0.7 m on the MAN, 1.3 m on the Volvo), while the 32-beam rings on one
side wall are up to 0.5 m apart vertically at 20 m; in 3D an epsilon below the gap would cut the
walls into rings, in xy the rings of one wall fall on one line. So epsilon must be below the
cab-trailer gap and above the horizontal point spacing (about 0.1 m after the voxel grid):
0.35 m by default.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from i2v_loc.params import ClassificationParams, VehicleConfig
from i2v_loc.stages.primitives import euclidean_labels, oriented_box_volume, split_by_label, voxel_keys

XY_GRID_M = 0.05  # the xy projection is thinned to this grid before the second clustering


@dataclass
class Classification:
    vehicle: str | None  # configured vehicle name, None when no trailer passed the gate
    truck: np.ndarray | None  # (N, 3) points, None when nothing is left after removing the trailer
    trailer: np.ndarray | None


class TruckTrailerClassifier:
    def __init__(self, params: ClassificationParams, vehicles: dict[str, VehicleConfig]):
        self.params = params
        self.vehicles = vehicles

    def process(self, points: np.ndarray, candidates: list[str]) -> Classification:
        groups = self.sub_clusters(points)
        for name in candidates:
            trailer_idx = self._best_trailer(points, groups, self.vehicles[name])
            if trailer_idx is None:
                continue
            rest = np.ones(len(points), dtype=bool)
            rest[trailer_idx] = False
            truck = points[rest] if rest.sum() >= self.params.min_truck_points else None
            return Classification(name, truck, points[trailer_idx])
        return Classification(None, None, None)

    def sub_clusters(self, points: np.ndarray) -> list[np.ndarray]:
        """Point indices of the xy clusters with at least ``min_trailer_points`` points."""
        if len(points) == 0:
            return []
        xy = points[:, :2].astype(np.float64)
        _, first, inverse = np.unique(voxel_keys(xy, XY_GRID_M), return_index=True, return_inverse=True)
        cell_labels = euclidean_labels(xy[first], self.params.trailer_tolerance_m)
        labels = cell_labels[inverse.reshape(-1)]
        return [g for g in split_by_label(labels) if len(g) >= self.params.min_trailer_points]

    def _best_trailer(self, points: np.ndarray, groups: list[np.ndarray], vehicle: VehicleConfig) -> np.ndarray | None:
        expected = vehicle.trailer.volume_m3
        best, best_error = None, np.inf
        for idx in groups:
            volume, rect = oriented_box_volume(points[idx])
            error = abs(volume - expected)
            too_long = rect.length_m > vehicle.trailer.length_m + self.params.max_length_excess_m
            if error <= vehicle.trailer_volume_tolerance_m3 and not too_long and error < best_error:
                best, best_error = idx, error
        return best
