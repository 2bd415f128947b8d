"""Vectorised point-cloud primitives shared by several stages (no stage state here)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from i2v_loc.stages import kernels


def voxel_keys(points: np.ndarray, voxel_m: float) -> np.ndarray:
    """One int64 key per point for the voxel (or 2D cell) it falls in (paper Eq. 1, origin at the cloud minimum)."""
    ijk = np.floor((points - points.min(axis=0)) / voxel_m).astype(np.int64)
    dims = ijk.max(axis=0) + 1
    keys = ijk[:, 0]
    for axis in range(1, ijk.shape[1]):
        keys = keys * dims[axis] + ijk[:, axis]
    return keys


def _voxel_ids(points: np.ndarray, voxel_m: float, take: np.ndarray | None = None, float64: bool = False):
    """(voxel id of each point, -1 where not taken; voxel keys, dims and the key lookup), ids in key
    order. The grid is computed in the points' precision (float32 stays float32) unless ``float64``."""
    if points.dtype != np.float32:
        points = np.asarray(points, dtype=np.float64)
    points = np.ascontiguousarray(points)
    if take is None:
        take = np.ones(len(points), dtype=bool)
    dtype = np.float64 if float64 else points.dtype.type
    ids, voxel_keys, dims, bits, word_rank, table_keys, table_ids = kernels.voxel_ids(
        points, take, dtype(voxel_m), dtype(1.0)
    )
    if not len(bits):  # hashed: numpy's sort (vectorised) of the distinct keys, then the ids follow
        voxel_keys = np.sort(voxel_keys)
        kernels.rank_in_key_order(voxel_keys, ids, table_keys, table_ids)
    return points, ids, voxel_keys, dims, (bits, word_rank, table_keys, table_ids)


def voxel_centroids(
    points: np.ndarray,
    voxel_m: float,
    values: np.ndarray | None = None,
    take: np.ndarray | None = None,
    float64: bool = False,
):
    """Centroid of the points of each occupied voxel (paper Eq. 2), voxels in key order.

    ``values`` (N, k) are averaged per voxel along with the points; returns (centroids, means or None).
    ``take`` (bool mask) uses only those points; ``float64`` computes the grid and returns the
    centroids in float64 (else in the points' dtype). Sums are float64, in point order.
    """
    out_dtype = np.float64 if float64 else points.dtype
    if voxel_m <= 0 or len(points) == 0 or (take is not None and not take.any()):
        chosen = points if take is None else points[take]
        return chosen.astype(out_dtype, copy=False), (values if take is None or values is None else values[take])
    points, ids, voxel_keys, _, _ = _voxel_ids(points, voxel_m, take, float64)
    extra = (
        np.zeros((len(points), 0)) if values is None else np.asarray(values, dtype=np.float64).reshape(len(points), -1)
    )
    sums, counts = kernels.voxel_sums(points, extra, ids, len(voxel_keys))
    means = sums / counts[:, None]
    return means[:, :3].astype(out_dtype), (None if values is None else means[:, 3:])


def grid_labels(points: np.ndarray, voxel_m: float) -> np.ndarray:
    """Cluster label per point: 26-connected components of the occupied voxels of size ``voxel_m``
    (neighbouring voxels join: points up to about 2 * sqrt(3) * voxel apart, never closer ones split);
    components numbered in the raster order of their first voxel."""
    if len(points) == 0:
        return np.zeros(0, dtype=np.int64)
    _, ids, voxel_keys, dims, lookup = _voxel_ids(points, voxel_m)
    return kernels.voxel_components(voxel_keys, dims, *lookup)[ids]


def euclidean_labels(points: np.ndarray, tolerance_m: float, voxel_m: float = 0.0) -> np.ndarray:
    """Cluster label per point: connected components of the 'closer than tolerance' graph (Eq. 4).

    With ``voxel_m`` > 0 the graph is built on the voxel centroids and the labels copied back.
    """
    n = len(points)
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    if voxel_m > 0:
        _, first, inverse = np.unique(voxel_keys(points, voxel_m), return_index=True, return_inverse=True)
        centroids, _ = voxel_centroids(points, voxel_m)  # same key order as np.unique above
        return euclidean_labels(centroids, tolerance_m)[inverse.reshape(-1)]
    xyz = np.zeros((n, 3))
    xyz[:, : points.shape[1]] = points  # a 2-D cloud gets a zero third coordinate: the same distances
    return kernels.radius_components(xyz, float(tolerance_m))


def split_by_label(labels: np.ndarray) -> list[np.ndarray]:
    """Point indices of each label (in point order), largest group first (ties: lower label first)."""
    if len(labels) == 0:
        return []
    labels = np.asarray(labels)
    low, high = int(labels.min()), int(labels.max())
    if low >= 0 and high < 4 * len(labels) + 1024:
        order, counts = kernels.counting_order(labels.astype(np.int64, copy=False), high + 1)
        counts = counts[counts > 0]
    else:
        order = np.argsort(labels, kind="stable")
        counts = np.diff(np.concatenate([[0], np.flatnonzero(np.diff(labels[order])) + 1, [len(labels)]]))
    bounds = np.concatenate([[0], np.cumsum(counts)])
    return [order[bounds[g] : bounds[g + 1]] for g in np.argsort(-counts, kind="stable")]


@dataclass
class Rect:
    """Minimum-area rectangle in the xy plane: centre, side lengths (length >= width), yaw of the long side."""

    center_xy: np.ndarray
    length_m: float
    width_m: float
    yaw_rad: float

    @property
    def area_m2(self) -> float:
        return self.length_m * self.width_m

    def holds(self, points: np.ndarray, margin_m: float = 0.0) -> np.ndarray:
        """Which of ``points`` lie (xy) within ``margin_m`` of the rectangle (``kernels.in_upright_box``)."""
        c, s = np.cos(self.yaw_rad), np.sin(self.yaw_rad)
        box = np.array([*self.center_xy, c, s, self.length_m / 2 + margin_m, self.width_m / 2 + margin_m])
        inside = np.empty(len(points), dtype=bool)
        kernels.in_upright_box(np.ascontiguousarray(points), box, inside)
        return inside


def min_area_rect(xy: np.ndarray) -> Rect:
    """Rotating-calipers minimum-area rectangle over the convex hull's edge directions (compiled)."""
    xy = np.ascontiguousarray(xy, dtype=np.float64)
    cx, cy, du, dv, a = kernels.min_area_rect(xy)
    if np.isnan(cx):
        return _degenerate_rect(xy)
    center = np.array([cx, cy])
    if du >= dv:
        return Rect(center, float(du), float(dv), float(a))
    return Rect(center, float(dv), float(du), float(a + np.pi / 2))


def rect_along(xy: np.ndarray, yaw_rad: float) -> Rect:
    """The rectangle with its length along ``yaw_rad`` enclosing the points (a given axis, not fitted)."""
    axes = unit_axes(yaw_rad)
    local = np.asarray(xy, dtype=float) @ axes.T
    low, high = local.min(axis=0), local.max(axis=0)
    return Rect((low + high) / 2 @ axes, float(high[0] - low[0]), float(high[1] - low[1]), float(yaw_rad))


def _degenerate_rect(xy: np.ndarray) -> Rect:
    """Collinear or tiny point sets: a zero-width rectangle along the principal axis."""
    if len(xy) == 0:
        return Rect(np.zeros(2), 0.0, 0.0, 0.0)
    centered = xy - xy.mean(axis=0)
    axis = np.linalg.svd(centered, full_matrices=False)[2][0] if len(xy) > 1 else np.array([1.0, 0.0])
    proj = centered @ axis
    center = xy.mean(axis=0) + axis * (proj.max() + proj.min()) / 2
    return Rect(center, float(np.ptp(proj)), 0.0, float(np.arctan2(axis[1], axis[0])))


def oriented_box_volume(points: np.ndarray) -> tuple[float, Rect]:
    """Volume of the oriented box of a cluster: min-area rectangle in xy times the height range."""
    rect = min_area_rect(points[:, :2])
    height = float(np.ptp(points[:, 2])) if len(points) else 0.0
    return rect.area_m2 * height, rect


def unit_axes(yaw_rad: float) -> np.ndarray:
    """Rows: the forward and left unit vectors of a heading in the xy plane."""
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    return np.array([[c, s], [-s, c]])


def l_shape_yaw(xy: np.ndarray, min_distance_m: float = 0.01, max_points: int = 1500) -> float:
    """Axis (radians, modulo pi/2) of the rectangle whose edges the points hug (closeness criterion
    of L-shape fitting): a coarse 1 deg sweep over 90 deg, then a 0.1 deg sweep around the best.
    Unlike the minimum-area rectangle it is not fooled by an L-shaped view (a right triangle hull
    has equal-area rectangles on its legs and its hypotenuse)."""
    xy = np.asarray(xy, dtype=float)
    if len(xy) > max_points:
        xy = xy[np.linspace(0, len(xy) - 1, max_points).astype(int)]
    xy = xy - xy.mean(axis=0)
    coarse = np.radians(np.arange(0.0, 90.0, 1.0))
    best = coarse[np.argmax(_closeness(xy, coarse, min_distance_m))]
    fine = best + np.radians(np.arange(-1.0, 1.0001, 0.1))
    return float(np.mod(fine[np.argmax(_closeness(xy, fine, min_distance_m))], np.pi / 2))


def _closeness(xy: np.ndarray, angles: np.ndarray, min_distance_m: float) -> np.ndarray:
    c, s = np.cos(angles), np.sin(angles)
    u = xy[:, :1] * c + xy[:, 1:] * s  # (N, A)
    v = -xy[:, :1] * s + xy[:, 1:] * c
    du = np.minimum(u - u.min(axis=0), u.max(axis=0) - u)
    dv = np.minimum(v - v.min(axis=0), v.max(axis=0) - v)
    return (1.0 / np.maximum(np.minimum(du, dv), min_distance_m)).sum(axis=0)
