"""The front end as plain whole-array numpy (the implementation the compiled kernels replaced):
the reference the equivalence tests compare the kernels with."""

from __future__ import annotations

from collections import deque

import numpy as np
from scipy import ndimage
from scipy.spatial import ConvexHull, QhullError

from i2v_loc.stages.background import OUTSIDE, grid_shape, region_box


def voxel_keys(points, voxel_m):
    ijk = np.floor((points - points.min(axis=0)) / voxel_m).astype(np.int64)
    dims = ijk.max(axis=0) + 1
    keys = ijk[:, 0]
    for axis in range(1, ijk.shape[1]):
        keys = keys * dims[axis] + ijk[:, axis]
    return keys


def voxel_centroids(points, voxel_m, values=None):
    if voxel_m <= 0 or len(points) == 0:
        return points, values
    data = points if values is None else np.hstack([points, values.reshape(len(points), -1)])
    _, inverse, counts = np.unique(voxel_keys(points, voxel_m), return_inverse=True, return_counts=True)
    sums = np.column_stack(
        [np.bincount(inverse, weights=data[:, c], minlength=len(counts)) for c in range(data.shape[1])]
    )
    means = sums / counts[:, None]
    return means[:, :3].astype(points.dtype), (None if values is None else means[:, 3:])


def grid_labels(points, voxel_m, origin=None):
    """``origin``: the grid's corner (default: the cloud's minimum)."""
    origin = points.min(axis=0) if origin is None else origin
    ijk = np.floor((points - origin) / voxel_m).astype(np.int64)
    ijk -= ijk.min(axis=0)
    occupied = np.zeros(tuple(ijk.max(axis=0) + 1), dtype=bool)
    occupied[ijk[:, 0], ijk[:, 1], ijk[:, 2]] = True
    labels, _ = ndimage.label(occupied, structure=np.ones((3, 3, 3), dtype=bool))
    return labels[ijk[:, 0], ijk[:, 1], ijk[:, 2]].astype(np.int64) - 1


def euclidean_labels(points, tolerance_m):
    """Connected components of a k-d tree's pairs at most ``tolerance_m`` apart."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    pairs = cKDTree(points).query_pairs(tolerance_m, output_type="ndarray")
    graph = coo_matrix((np.ones(len(pairs), dtype=np.int8), (pairs[:, 0], pairs[:, 1])), shape=(len(points),) * 2)
    return connected_components(graph, directed=False)[1].astype(np.int64)


def split_by_label(labels):
    order = np.argsort(labels, kind="stable")
    groups = np.split(order, np.flatnonzero(np.diff(labels[order])) + 1)
    return sorted(groups, key=len, reverse=True)


def min_area_rect(xy):
    """(centre, length, width, yaw) or None for a flat hull."""
    xy = np.asarray(xy, dtype=float)
    try:
        hull = xy[ConvexHull(xy).vertices]
    except (QhullError, ValueError):
        return None
    edges = np.diff(np.vstack([hull, hull[:1]]), axis=0)
    angles = np.unique(np.mod(np.arctan2(edges[:, 1], edges[:, 0]), np.pi / 2))
    c, s = np.cos(angles), np.sin(angles)
    u = hull[:, 0][None] * c[:, None] + hull[:, 1][None] * s[:, None]
    v = -hull[:, 0][None] * s[:, None] + hull[:, 1][None] * c[:, None]
    du, dv = u.max(1) - u.min(1), v.max(1) - v.min(1)
    best = int(np.argmin(du * dv))
    cu, cv = (u[best].max() + u[best].min()) / 2, (v[best].max() + v[best].min()) / 2
    a = angles[best]
    center = np.array([cu * np.cos(a) - cv * np.sin(a), cu * np.sin(a) + cv * np.cos(a)])
    if du[best] >= dv[best]:
        return center, du[best], dv[best], a
    return center, dv[best], du[best], a + np.pi / 2


def synchronise(stamps_s, tol, reference):
    """(reference stamp, members) of the window start holding the most stamps (ties: the earliest)."""
    stamps = np.asarray(stamps_s, dtype=np.float64)
    inside = (stamps[None, :] >= stamps[:, None] - 1e-9) & (stamps[None, :] <= stamps[:, None] + tol + 1e-9)
    counts = inside.sum(axis=1)
    best = np.flatnonzero(counts == counts.max())
    members = inside[best[np.argmin(stamps[best])]]
    group = stamps[members]
    return float({"earliest": group.min(), "latest": group.max(), "mean": group.mean()}[reference]), members


def merge(stage, scans):
    """(points, lag, reference stamp, faults, dropped) of ``Concatenation.merge``."""
    faults, dropped, sweeps = {}, {"out_of_sync": 0, "empty": 0, "missing": 0, "nan_points": 0}, []
    for name, config in stage.sensors.items():
        if name not in scans:
            faults[name], dropped["missing"] = "missing", dropped["missing"] + 1
            continue
        scan = scans[name]
        finite = np.isfinite(scan.points).all(axis=1) & np.isfinite(scan.time_offset_s)
        if (~finite).any():
            faults[name], dropped["nan_points"] = "nan_points", dropped["nan_points"] + int((~finite).sum())
        r2 = np.einsum("ij,ij->i", scan.points, scan.points, dtype=np.float64)
        keep = finite & (r2 >= config.min_range_m**2) & (r2 <= config.max_range_m**2)
        if not keep.any() or not np.isfinite(scan.stamp_s):
            faults[name], dropped["empty"] = "empty", dropped["empty"] + 1
            continue
        sweeps.append((name, scan.stamp_s + config.time_offset_s, scan.points[keep], scan.time_offset_s[keep]))
    for name in scans.keys() - stage.sensors.keys():
        faults[name] = "unknown_sensor"
    reference, in_sync = stage._synchronise([s[1] for s in sweeps])
    clouds, lags = [np.zeros((0, 3), np.float32)], [np.zeros(0, np.float32)]
    for (name, stamp, pts, offsets), ok in zip(sweeps, in_sync):
        if not ok:
            faults[name], dropped["out_of_sync"] = "out_of_sync", dropped["out_of_sync"] + 1
            continue
        t = np.eye(4, dtype=np.float32)
        t[:3, :3], t[:3, 3] = stage._to_yard[name]
        clouds.append(pts @ t[:3, :3].T + t[:3, 3])
        lags.append(np.float32(reference - stamp) - offsets)
    return np.concatenate(clouds), np.concatenate(lags), reference, faults, dropped


def interpolate(points, lag_s, motion):
    moved = np.zeros(len(points), dtype=bool)
    for hint in motion:
        center = np.broadcast_to(np.asarray(hint.center_xy, dtype=np.float64), (len(points), 2))
        yaw = np.full(len(points), hint.yaw_rad)
        if np.isfinite(hint.age_s):  # the box where it stood when each point was captured
            since = hint.age_s - lag_s.astype(np.float64)
            center = center + since[:, None] * np.asarray(hint.velocity_xy, dtype=np.float64)
            yaw = yaw + hint.yaw_rate_rad_s * since
        d = points[:, :2] - center.astype(np.float32)
        c, s = np.cos(yaw), np.sin(yaw)
        along, across = d[:, 0] * c + d[:, 1] * s, -d[:, 0] * s + d[:, 1] * c
        inside = (np.abs(along) <= hint.half_length_m) & (np.abs(across) <= hint.half_width_m) & ~moved
        velocity = np.asarray(hint.velocity_xy, dtype=np.float32)
        if hint.yaw_rate_rad_s:
            velocity = velocity + np.float32(hint.yaw_rate_rad_s) * np.column_stack([-d[inside, 1], d[inside, 0]])
        points[inside, :2] += lag_s[inside, None] * velocity
        moved |= inside


class BackgroundMap:
    """The voxel occupancy map with fancy-indexed updates over the whole grid (padded by the
    dilation: one voxel of padding let a dilation of 2 or 3 index past the array)."""

    def __init__(self, params, region):
        self.params = params
        self.origin = np.array(region_box(region)[:3], dtype=np.float64)
        self.pad = max(1, params.dilation_voxels)
        self.padded = tuple(n + 2 * self.pad for n in grid_shape(params, region))
        cells = int(np.prod(self.padded))
        self._strides = np.array([self.padded[1] * self.padded[2], self.padded[2], 1], dtype=np.int64)
        d = params.dilation_voxels
        offsets = np.array(np.meshgrid(*[np.arange(-d, d + 1)] * 3, indexing="ij")).reshape(3, -1).T
        self._offsets = offsets @ self._strides
        self.counts = np.zeros(cells, dtype=np.uint8)
        self.is_background = np.zeros(cells, dtype=bool)
        self.dilated = np.zeros(cells, dtype=np.uint16)
        inside = np.zeros(self.padded, dtype=bool)
        inside[self.pad : -self.pad, self.pad : -self.pad, self.pad : -self.pad] = True
        self.dilated[~inside.ravel()] = OUTSIDE
        self.history = deque()
        self.frames_seen = 0
        self.pending = None

    samples = property(lambda self: len(self.history))
    ready = property(lambda self: self.samples >= self.params.min_samples)
    threshold = property(lambda self: max(1, int(np.ceil(self.params.occupied_fraction * self.samples - 1e-9))))
    forget = property(lambda self: int(np.floor(self.params.forget_fraction * self.samples + 1e-9)))

    def voxel_index(self, points):
        q = np.asarray(points, dtype=np.float32) - (self.origin - self.pad * self.params.voxel_size_m).astype(
            np.float32
        )
        q *= np.float32(1.0 / self.params.voxel_size_m)
        np.clip(q, 0.0, np.array(self.padded, dtype=np.float32) - 0.5, out=q)
        return q.astype(np.int64) @ self._strides

    def process(self, points, protected=()):
        index = self.voxel_index(points)
        state = self.dilated[index]
        in_region = state < OUTSIDE
        foreground = state == 0 if self.ready else in_region.copy()
        columns = index // self.padded[2]
        if len(protected) and self.ready:
            foreground |= in_region & self._protected_columns(protected, self.params.keep_margin_m)[columns]
        pending, self.pending = self.pending, None
        if self.frames_seen % self.params.learn_every_frames == 0:
            learn = in_region
            if len(protected):
                learn = learn & ~self._protected_columns(protected, self.params.protect_margin_m)[columns]
            self.pending = index[learn]  # counted in on the next frame
        if pending is not None:
            self.learn(pending)
        self.frames_seen += 1
        return in_region, foreground

    def learn(self, index):
        was_filling = self.samples < self.params.window_frames
        self.counts[index] += 1
        self.history.append(index)
        old = self.history.popleft() if self.samples > self.params.window_frames else None
        if old is not None:
            self.counts[old] -= 1
        state = (self.counts >= self.threshold) | (self.is_background & (self.counts > self.forget))
        changed = np.flatnonzero(state != self.is_background)
        assert was_filling or np.isin(changed, np.concatenate([index, [] if old is None else old])).all()
        on = ~self.is_background[changed]
        self.is_background[changed] = on
        for offset in self._offsets:
            self.dilated[changed[on] + offset] += 1
            self.dilated[changed[~on] + offset] -= 1

    def _protected_columns(self, boxes, margin_m):
        nx, ny = self.padded[0], self.padded[1]
        mask = np.zeros(nx * ny, dtype=bool)
        voxel, margin = self.params.voxel_size_m, margin_m + self.params.voxel_size_m / 2
        for box in boxes:
            reach = np.hypot(box.half_length_m, box.half_width_m) + margin
            lo = np.floor((np.asarray(box.center_xy) - reach - self.origin[:2]) / voxel).astype(int) + self.pad
            hi = np.ceil((np.asarray(box.center_xy) + reach - self.origin[:2]) / voxel).astype(int) + self.pad
            lo, hi = np.clip(lo, 0, [nx - 1, ny - 1]), np.clip(hi, 0, [nx - 1, ny - 1])
            ii, jj = np.meshgrid(np.arange(lo[0], hi[0] + 1), np.arange(lo[1], hi[1] + 1), indexing="ij")
            cx = self.origin[0] + (ii - self.pad + 0.5) * voxel - box.center_xy[0]
            cy = self.origin[1] + (jj - self.pad + 0.5) * voxel - box.center_xy[1]
            c, s = np.cos(box.yaw_rad), np.sin(box.yaw_rad)
            inside = (np.abs(cx * c + cy * s) <= box.half_length_m + margin) & (
                np.abs(-cx * s + cy * c) <= box.half_width_m + margin
            )
            mask[(ii * ny + jj)[inside]] = True
        return mask


def fit_ground(region, roi_points, rng):
    """(normal, offset) of the RANSAC plane with one (samples x hypotheses) distance matrix, or None."""
    p = region.params
    sample = voxel_centroids(roi_points.astype(np.float64), p.ransac_sample_voxel_m)[0]
    idx = rng.integers(0, len(sample), size=(p.ransac_iterations, 3))
    a, b, c = sample[idx[:, 0]], sample[idx[:, 1]], sample[idx[:, 2]]
    normals = np.cross(b - a, c - a)
    norms = np.linalg.norm(normals, axis=1)
    ok = norms > 1e-9
    normals = normals[ok] / norms[ok, None]
    normals *= np.sign(normals[:, 2:3] + 1e-12)
    admissible = normals[:, 2] >= np.cos(np.radians(p.max_ground_tilt_deg))
    normals = normals[admissible]
    offsets = -np.einsum("ij,ij->i", normals, a[ok][admissible])
    distances = np.abs(sample @ normals.T + offsets)
    scores = (distances < p.ground_distance_threshold_m).sum(axis=0)
    best = int(np.argmax(scores))
    if scores[best] < max(3, p.min_ground_fraction * len(sample)):
        return None
    inliers = sample[distances[:, best] < p.ground_distance_threshold_m]
    centre = inliers.mean(axis=0)
    refined = np.linalg.svd(inliers - centre, full_matrices=False)[2][2]
    refined *= np.sign(refined[2] + 1e-12)
    if refined[2] >= np.cos(np.radians(p.max_ground_tilt_deg)):
        return refined, -float(refined @ centre)
    return normals[best], offsets[best]
