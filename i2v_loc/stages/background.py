"""Static background removal (default method): a voxel occupancy map of the yard learned online.

The region of interest is cut into ``voxel_size_m`` voxels. Every ``learn_every_frames`` frames
the voxels the frame occupies are counted (a voxel counts once per sample, however many points
fall in it) in a sliding window of ``window_frames`` samples; a voxel occupied in at least
``occupied_fraction`` of the samples in the window becomes background (walls, ground, containers,
parked trailers) and stays so until it is occupied in no more than ``forget_fraction`` of them
(hysteresis: a wall hidden behind a docked truck is not forgotten at once); the background is
grown by ``dilation_voxels`` for range noise. Points in a background voxel are
removed. Until ``min_samples`` samples are in, nothing is background (the pipeline falls back to
its behaviour without the map).

Voxels in the xy footprint of a protected track's box (plus ``protect_margin_m``) are not
learned, so a vehicle that stops does not become background; points in the box (plus
``keep_margin_m``) are never background, so a vehicle that stood still before it was tracked
(its voxels learned) is not cut either. Which tracks are protected is the
pipeline's choice (those that have travelled; a parked trailer never does).

The map is a dense grid: ``counts`` (uint8 per voxel) and ``dilated`` (how many background voxels
in each voxel's 3x3x3 neighbourhood). Once the window is full the threshold is fixed and only the
voxels whose count crossed it are updated; while the window fills the threshold grows with the
sample count, so the map is rebuilt at once (a few ms per learning frame, first seconds only).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from i2v_loc.params import BackgroundParams, RegionParams

FORMAT_VERSION = 1
OUTSIDE = np.uint16(60000)  # padding marker in ``dilated`` (above any neighbourhood count)


@dataclass
class ProtectedBox:
    """A track's box in the xy plane (centre, yaw of the length axis, half sizes) whose voxels are not learned."""

    center_xy: tuple[float, float]
    yaw_rad: float
    half_length_m: float
    half_width_m: float


def region_box(region: RegionParams) -> tuple[float, ...]:
    return (region.x_min_m, region.y_min_m, region.z_min_m, region.x_max_m, region.y_max_m, region.z_max_m)


def grid_shape(params: BackgroundParams, region: RegionParams) -> tuple[int, int, int]:
    """Voxels along x, y, z covering the region (its far faces rounded up to whole voxels)."""
    box = np.array(region_box(region))
    return tuple(int(n) for n in np.ceil((box[3:] - box[:3]) / params.voxel_size_m - 1e-9))


def check_grid(params: BackgroundParams, region: RegionParams) -> None:
    """ValueError naming the fix when the padded grid would exceed ``max_voxels`` (also for a region
    so large, or infinite, that the voxel count overflows)."""
    box = np.array(region_box(region), dtype=float)
    extent = np.ceil((box[3:] - box[:3]) / params.voxel_size_m - 1e-9) + 2  # float: no integer overflow
    cells = float(np.prod(extent)) if np.all(np.isfinite(extent)) else float("inf")
    if not cells <= params.max_voxels:
        raise ValueError(
            f"background grid of {cells:.3g} cells (region {region_box(region)} at "
            f"{params.voxel_size_m} m) exceeds background.max_voxels {params.max_voxels}: "
            "enlarge background.voxel_size_m or shrink the region"
        )


@dataclass
class BackgroundResult:
    in_region: np.ndarray  # (N,) bool: inside the region of interest (the grid)
    foreground: np.ndarray  # (N,) bool: in the region and not background (= in_region until the map is ready)


class BackgroundMap:
    def __init__(self, params: BackgroundParams, region: RegionParams):
        check_grid(params, region)
        self.params = params
        self.region_box = region_box(region)
        self.origin = np.array(self.region_box[:3], dtype=np.float64)
        self.shape = grid_shape(params, region)
        # one voxel of padding on every side: points outside the region are clipped into it, and
        # neighbour offsets of a region voxel never leave the array
        self.padded = tuple(n + 2 for n in self.shape)
        cells = int(np.prod(self.padded, dtype=np.int64))
        self._strides = np.array([self.padded[1] * self.padded[2], self.padded[2], 1], dtype=np.int64)
        d = params.dilation_voxels
        offsets = np.array(np.meshgrid(*[np.arange(-d, d + 1)] * 3, indexing="ij")).reshape(3, -1).T
        self._offsets = offsets @ self._strides
        self.counts = np.zeros(cells, dtype=np.uint8)
        self.is_background = np.zeros(cells, dtype=bool)
        # background voxels within the dilation of each voxel; padding holds OUTSIDE so that one
        # lookup answers both "in the region" (< OUTSIDE) and "foreground" (== 0)
        self.dilated = np.zeros(cells, dtype=np.uint16)
        self.dilated[~self._region_cells()] = OUTSIDE
        self.history: deque[np.ndarray] = deque()
        self.frames_seen = 0

    def _region_cells(self) -> np.ndarray:
        inside = np.zeros(self.padded, dtype=bool)
        inside[1:-1, 1:-1, 1:-1] = True
        return inside.ravel()

    # ----------------------------------------------------------------- queries

    @property
    def samples(self) -> int:
        return len(self.history)

    @property
    def ready(self) -> bool:
        return self.samples >= self.params.min_samples

    @property
    def threshold(self) -> int:
        """Samples a voxel must be occupied in to be background (grows while the window fills)."""
        return max(1, int(np.ceil(self.params.occupied_fraction * self.samples - 1e-9)))

    def voxel_index(self, points: np.ndarray) -> np.ndarray:
        """Flat index (padded grid) of each point's voxel; points outside the region land in the padding."""
        q = np.asarray(points, dtype=np.float32) - (self.origin - self.params.voxel_size_m).astype(np.float32)
        q *= np.float32(1.0 / self.params.voxel_size_m)
        np.clip(q, 0.0, np.array(self.padded, dtype=np.float32) - 0.5, out=q)
        ijk = q.astype(np.int64)
        flat = ijk[:, 0] * self._strides[0]
        flat += ijk[:, 1] * self._strides[1]
        flat += ijk[:, 2]
        return flat

    def classify(self, index: np.ndarray) -> BackgroundResult:
        state = self.dilated[index]
        in_region = state < OUTSIDE
        return BackgroundResult(in_region, state == 0 if self.ready else in_region)

    # ----------------------------------------------------------------- learning

    def process(self, points: np.ndarray, protected: list[ProtectedBox] = ()) -> BackgroundResult:
        """Region and foreground masks of ``points`` (yard frame) with the map as it was before this
        frame; then learns from the frame when it is a learning frame."""
        index = self.voxel_index(points)
        result = self.classify(index)
        columns = index // self.padded[2] if len(protected) else None
        if len(protected) and self.ready:
            # a tracked vehicle's points are never background, even where a standing vehicle was learned
            result.foreground |= (
                result.in_region & self._protected_columns(protected, self.params.keep_margin_m)[columns]
            )
        if self.frames_seen % self.params.learn_every_frames == 0:
            learn = result.in_region
            if len(protected):
                learn = learn & ~self._protected_columns(protected, self.params.protect_margin_m)[columns]
            self.learn(index[learn])
        self.frames_seen += 1
        return result

    def learn(self, index: np.ndarray) -> None:
        """Add one sample: the voxels in ``index`` (region voxels; duplicates allowed) were occupied."""
        index = index.astype(np.int32)
        was_filling = self.samples < self.params.window_frames
        self.counts[index] += 1  # fancy += counts a repeated voxel once: one sample, one count
        self.history.append(index)
        old = self.history.popleft() if self.samples > self.params.window_frames else None
        if old is not None:
            self.counts[old] -= 1
        if was_filling:
            self._rebuild()
        else:
            self._update(index if old is None else np.concatenate([index, old]))

    @property
    def forget_threshold(self) -> int:
        """A background voxel occupied in at most this many samples of the window is forgotten."""
        return int(np.floor(self.params.forget_fraction * self.samples + 1e-9))

    def _state(self, counts: np.ndarray, current: np.ndarray) -> np.ndarray:
        # hysteresis: a wall hidden behind a standing truck for a while stays background
        return (counts >= self.threshold) | (current & (counts > self.forget_threshold))

    def _rebuild(self) -> None:
        """While the window fills the thresholds move: compare every voxel."""
        self._flip(np.flatnonzero(self._state(self.counts, self.is_background) != self.is_background))

    def _update(self, touched: np.ndarray) -> None:
        """Once the thresholds are fixed only the touched voxels can change."""
        current = self.is_background[touched]
        self._flip(np.unique(touched[self._state(self.counts[touched], current) != current]))

    def _flip(self, changed: np.ndarray) -> None:
        """Toggle the background state of these (unique) voxels and their neighbourhood counts."""
        if not len(changed):
            return
        on = ~self.is_background[changed]
        self.is_background[changed] = on
        added, removed = changed[on], changed[~on]
        for offset in self._offsets:  # unique cells: each fancy update touches a voxel once
            self.dilated[added + offset] += 1
            self.dilated[removed + offset] -= 1

    def _protected_columns(self, boxes: list[ProtectedBox], margin_m: float) -> np.ndarray:
        """(x, y) columns of the padded grid (flattened) whose centre lies in a box plus the margin."""
        nx, ny = self.padded[0], self.padded[1]
        mask = np.zeros(nx * ny, dtype=bool)
        voxel, margin = self.params.voxel_size_m, margin_m + self.params.voxel_size_m / 2
        for box in boxes:
            reach = np.hypot(box.half_length_m, box.half_width_m) + margin
            lo = np.floor((np.asarray(box.center_xy) - reach - self.origin[:2]) / voxel).astype(int) + 1
            hi = np.ceil((np.asarray(box.center_xy) + reach - self.origin[:2]) / voxel).astype(int) + 1
            lo, hi = np.clip(lo, 0, [nx - 1, ny - 1]), np.clip(hi, 0, [nx - 1, ny - 1])
            ii, jj = np.meshgrid(np.arange(lo[0], hi[0] + 1), np.arange(lo[1], hi[1] + 1), indexing="ij")
            cx = self.origin[0] + (ii - 0.5) * voxel - box.center_xy[0]
            cy = self.origin[1] + (jj - 0.5) * voxel - box.center_xy[1]
            c, s = np.cos(box.yaw_rad), np.sin(box.yaw_rad)
            inside = (np.abs(cx * c + cy * s) <= box.half_length_m + margin) & (
                np.abs(-cx * s + cy * c) <= box.half_width_m + margin
            )
            mask[(ii * ny + jj)[inside]] = True
        return mask

    # ----------------------------------------------------------------- saving

    def save(self, path: str | Path) -> None:
        """The learned map (background voxels and grid) as .npz; loaded maps start as a full window."""
        np.savez_compressed(
            path,
            format_version=FORMAT_VERSION,
            origin=self.origin,
            shape=np.array(self.shape),
            voxel_size_m=self.params.voxel_size_m,
            background=np.flatnonzero(self.is_background).astype(np.int64),
        )

    def load(self, path: str | Path) -> None:
        """Replace the map by a saved one; refuses a map of another grid (region or voxel size)."""
        path = Path(path)
        if not path.is_file():
            raise ValueError(f"{path}: no such background map")
        with np.load(path) as data:
            if int(data["format_version"]) != FORMAT_VERSION:
                raise ValueError(
                    f"{path}: background map format {int(data['format_version'])}, expected {FORMAT_VERSION}"
                )
            same = (
                np.allclose(data["origin"], self.origin)
                and tuple(data["shape"]) == self.shape
                and np.isclose(float(data["voxel_size_m"]), self.params.voxel_size_m)
            )
            if not same:
                raise ValueError(f"{path}: background map of another grid (region or background.voxel_size_m changed)")
            cells = data["background"]
        # a loaded map acts as a full window in which its voxels were always occupied
        window = self.params.window_frames
        self.counts[:] = 0
        self.counts[cells] = window
        self.history = deque([cells.astype(np.int32)] * window)
        self._rebuild()
