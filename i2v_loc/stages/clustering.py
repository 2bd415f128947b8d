"""Stage 4: Euclidean clustering (paper Eq. 4) and the whole-vehicle volume gate (Eq. 5).

The neighbour search runs on voxel centroids (``voxel_size_m``, 0 = every point) and the labels
are copied back to the points: same clusters up to about half a voxel at the tolerance, and
tens of times fewer neighbour pairs on dense walls.
Volume of a cluster = its oriented box: minimum-area rectangle in xy times the height range.
A cluster is a candidate for every configured vehicle whose gate V_e +- dV holds it (closest
V_e first). Clusters bigger than every gate are ``too_large``, smaller than every gate or with
fewer than ``min_points`` are ``too_small``; none is dropped silently.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from i2v_loc.params import ClusteringParams, VehicleConfig
from i2v_loc.stages.primitives import Rect, euclidean_labels, oriented_box_volume, split_by_label


@dataclass
class Cluster:
    points: np.ndarray  # (N, 3)
    volume_m3: float
    rect: Rect
    status: str  # too_small | too_large | candidate | (later) vehicle:<name> | unmatched
    candidates: list[str] = field(default_factory=list)

    @property
    def center(self) -> np.ndarray:
        return self.points.mean(axis=0)


@dataclass
class ClusteringResult:
    clusters: list[Cluster]  # clusters with at least min_points, largest first
    noise_clusters: int  # clusters below min_points (not listed)


class Clustering:
    def __init__(self, params: ClusteringParams, vehicles: dict[str, VehicleConfig]):
        self.params = params
        self.gates = {name: self.gate(v) for name, v in vehicles.items()}

    @staticmethod
    def gate(v: VehicleConfig) -> tuple[float, float, float]:
        """(V_min, V_e, V_max) of Eq. 5; V_min is at least the trailer gate's lower bound (a vehicle
        cluster holds its trailer), so a wide whole-vehicle tolerance does not admit small clutter."""
        trailer_min = v.trailer.volume_m3 - v.trailer_volume_tolerance_m3
        v_min = max(v.vehicle_volume_m3 - v.vehicle_volume_tolerance_m3, trailer_min)
        return v_min, v.vehicle_volume_m3, v.vehicle_volume_m3 + v.vehicle_volume_tolerance_m3

    def process(self, points: np.ndarray) -> ClusteringResult:
        labels = euclidean_labels(points, self.params.tolerance_m, self.params.voxel_size_m)
        groups = split_by_label(labels)
        clusters, noise = [], 0
        for idx in groups:
            if len(idx) < self.params.min_points:
                noise += 1
                continue
            clusters.append(self.describe(points[idx]))
        return ClusteringResult(clusters, noise)

    def describe(self, points: np.ndarray) -> Cluster:
        volume, rect = oriented_box_volume(points)
        if len(points) > self.params.max_points:
            return Cluster(points, volume, rect, "too_large")
        candidates = self.matching_vehicles(volume)
        if candidates:
            return Cluster(points, volume, rect, "candidate", candidates)
        return Cluster(points, volume, rect, self._out_of_gate_status(volume))

    def matching_vehicles(self, volume_m3: float) -> list[str]:
        inside = [(abs(volume_m3 - ve), name) for name, (lo, ve, hi) in self.gates.items() if lo <= volume_m3 <= hi]
        return [name for _, name in sorted(inside)]

    def _out_of_gate_status(self, volume_m3: float) -> str:
        if not self.gates:
            return "unmatched"
        if volume_m3 > max(hi for _, _, hi in self.gates.values()):
            return "too_large"
        if volume_m3 < min(lo for lo, _, _ in self.gates.values()):
            return "too_small"
        return "unmatched"
