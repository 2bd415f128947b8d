"""Stage 6: centroid (Eq. 6) and its correction for occluded faces with the known dimensions (Eq. 7).

Worked in the unit's own axes (forward u along the unit's yaw, left v): a sensor sees the faces
turned towards it, so the centroid is pulled towards them; the true centre lies half the known
dimension behind a seen face plane: c_u = plane_u -+ D_u / 2, i.e. C + (D_u - 2 d_u) / 2 with d_u
the centroid-to-plane distance (the paper's Eq. 7 with d the distance to the plane). Which end of
the measured extent is a face: the one whose end slab spreads wider across the other axis (a face
perpendicular to the axis; an end cut by occlusion, or the chassis rails behind a cab, is only a
narrow edge). When both ends look alike: the middle of the extent if it covers the dimension,
else the end closest to the centroid (the paper's rule).
The axes come from the yaw hint (the unit's last estimated yaw) when given, else from the
L-shape fit of the unit's points (closeness criterion), its longer extent matched to the longer
known dimension.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from i2v_loc.params import CentroidParams, UnitDimensions
from i2v_loc.stages.primitives import l_shape_yaw, unit_axes

FACE_SLAB_M = 0.3  # points this close to an end of the extent belong to that end's face


@dataclass
class CorrectedUnit:
    center: np.ndarray  # (3,) corrected box centre, yard frame
    centroid: np.ndarray  # (3,) raw centroid (Eq. 6)
    axis_yaw_rad: float  # direction of the unit's length axis used here (defined modulo pi)
    shape_yaw_rad: float  # the L-shape fit of the points alone (modulo pi; modulo pi/2 for a square unit)
    extent_m: tuple[float, float]  # measured extent along (length, width) axes
    points: int


class CentroidCorrector:
    def __init__(self, params: CentroidParams):
        self.params = params

    def process(
        self,
        points: np.ndarray,
        dims: UnitDimensions,
        ground_z_m: float = 0.0,
        yaw_hint_rad: float | None = None,
    ) -> CorrectedUnit:
        """``yaw_hint_rad``: the unit's axis."""
        pts = np.asarray(points, dtype=np.float64)
        centroid = pts.mean(axis=0)
        shape_yaw = self._shape_yaw(pts, dims)
        yaw = shape_yaw if yaw_hint_rad is None else float(yaw_hint_rad)
        axes = unit_axes(yaw)
        local = (pts[:, :2] - centroid[:2]) @ axes.T  # (N, 2): u forward, v left
        low, high = local.min(axis=0), local.max(axis=0)
        extent = high - low
        if not self.params.enabled:
            return CorrectedUnit(centroid, centroid, yaw, shape_yaw, (float(extent[0]), float(extent[1])), len(pts))
        known = np.array([dims.length_m, dims.width_m])
        shift = self._from_face_plane(local, low, high, known)
        center_xy = centroid[:2] + shift @ axes
        center_z = ground_z_m + dims.floor_m + dims.height_m / 2
        return CorrectedUnit(
            np.array([*center_xy, center_z]), centroid, yaw, shape_yaw, (float(extent[0]), float(extent[1])), len(pts)
        )

    @staticmethod
    def _from_face_plane(local: np.ndarray, low: np.ndarray, high: np.ndarray, known: np.ndarray) -> np.ndarray:
        """Centre offset (local axes) half a dimension behind the seen face plane of each axis."""
        offset = np.empty(2)
        for axis in (0, 1):
            other = local[:, 1 - axis]
            spread_low = np.ptp(other[local[:, axis] <= low[axis] + FACE_SLAB_M])
            spread_high = np.ptp(other[local[:, axis] >= high[axis] - FACE_SLAB_M])
            if abs(spread_low - spread_high) > FACE_SLAB_M:  # one end is a face, the other a cut edge
                low_is_face = spread_low > spread_high
            elif high[axis] - low[axis] >= known[axis]:  # both ends are faces: middle of the extent
                offset[axis] = (low[axis] + high[axis]) / 2
                continue
            else:  # the paper's rule: the plane closest to the centroid
                low_is_face = -low[axis] < high[axis]
            offset[axis] = low[axis] + known[axis] / 2 if low_is_face else high[axis] - known[axis] / 2
        return offset

    @staticmethod
    def _shape_yaw(points: np.ndarray, dims: UnitDimensions) -> float:
        yaw = l_shape_yaw(points[:, :2])
        local = (points[:, :2] - points[:, :2].mean(axis=0)) @ unit_axes(yaw).T
        along_is_longer = np.ptp(local[:, 0]) >= np.ptp(local[:, 1])
        if along_is_longer != (dims.length_m >= dims.width_m):
            yaw += np.pi / 2
        return float(yaw)
