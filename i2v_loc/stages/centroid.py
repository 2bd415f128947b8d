"""Stage 6: centroid (Eq. 6) and its correction for occluded faces with the known dimensions (Eq. 7).

Worked in the unit's own axes (forward u along the unit's yaw, left v): a sensor sees the faces
turned towards it, so the centroid is pulled towards them; the face plane closest to the
centroid on each axis is a seen face, and the true centre lies half the known dimension behind
it: c_u = plane_u -+ D_u / 2, i.e. C + (D_u - 2 d_u) / 2 with d_u the centroid-to-plane
distance (the paper's Eq. 7 with d the distance to the closest plane). When the measured extent
already covers the dimension the centre is the middle of the extent.
The axes come from the yaw hint (the unit's last estimated yaw) when given, else from the
minimum-area rectangle of the unit's points, its long side matched to the longer known dimension.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from i2v_loc.params import CentroidParams, UnitDimensions
from i2v_loc.stages.primitives import min_area_rect, unit_axes


@dataclass
class CorrectedUnit:
    center: np.ndarray  # (3,) corrected box centre, yard frame
    centroid: np.ndarray  # (3,) raw centroid (Eq. 6)
    axis_yaw_rad: float  # direction of the unit's length axis (defined modulo pi)
    extent_m: tuple[float, float]  # measured extent along (length, width) axes
    points: int


class CentroidCorrector:
    def __init__(self, params: CentroidParams):
        self.params = params

    def process(self, points: np.ndarray, dims: UnitDimensions, ground_z_m: float = 0.0,
                yaw_hint_rad: float | None = None) -> CorrectedUnit:
        pts = np.asarray(points, dtype=np.float64)
        centroid = pts.mean(axis=0)
        yaw = self._axis_yaw(pts, dims, yaw_hint_rad)
        axes = unit_axes(yaw)
        local = (pts[:, :2] - centroid[:2]) @ axes.T  # (N, 2): u forward, v left
        low, high = local.min(axis=0), local.max(axis=0)
        extent = high - low
        if not self.params.enabled:
            return CorrectedUnit(centroid, centroid, yaw, (float(extent[0]), float(extent[1])), len(pts))
        known = np.array([dims.length_m, dims.width_m])
        shift = np.where(extent >= known, (low + high) / 2, self._from_closest_plane(low, high, known))
        center_xy = centroid[:2] + shift @ axes
        center_z = ground_z_m + dims.floor_m + dims.height_m / 2
        return CorrectedUnit(np.array([*center_xy, center_z]), centroid, yaw,
                             (float(extent[0]), float(extent[1])), len(pts))

    @staticmethod
    def _from_closest_plane(low: np.ndarray, high: np.ndarray, known: np.ndarray) -> np.ndarray:
        """Centre offset (local axes) half a dimension behind the face plane nearest the centroid."""
        low_is_closer = -low < high
        return np.where(low_is_closer, low + known / 2, high - known / 2)

    @staticmethod
    def _axis_yaw(points: np.ndarray, dims: UnitDimensions, yaw_hint_rad: float | None) -> float:
        if yaw_hint_rad is not None:
            return float(yaw_hint_rad)
        rect = min_area_rect(points[:, :2])
        return rect.yaw_rad if dims.length_m >= dims.width_m else rect.yaw_rad + np.pi / 2
