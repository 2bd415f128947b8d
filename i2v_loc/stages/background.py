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
in each voxel's 3x3x3 neighbourhood). One compiled pass per frame looks every point up and, on a
learning frame, lists its voxel once (the sample); the sample is counted in on the next frame, so
the pass and the scattered counting never add up in one frame (a decision follows a frame later:
nothing against a window of seconds). Once the window is full the threshold is fixed and only the
voxels whose count changed are re-decided; while the window fills the threshold grows with the
sample count, so every voxel counted so far is re-decided (all others cannot change).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from i2v_loc.params import BackgroundParams, RegionParams
from i2v_loc.stages import kernels

FORMAT_VERSION = 1
OUTSIDE = np.uint16(60000)  # padding marker in ``dilated`` (above any neighbourhood count)
_NO_COLUMNS = np.zeros(0, dtype=bool)
# voxel indices as int32: the grid is capped at max_voxels (at most 2e8) cells; half the memory
# traffic of int64 in the per-point pass
CELL = np.int32
_NO_CELLS = np.zeros(0, dtype=CELL)


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
    extent = np.ceil((box[3:] - box[:3]) / params.voxel_size_m - 1e-9) + 2 * _padding(params)  # float: no overflow
    cells = float(np.prod(extent)) if np.all(np.isfinite(extent)) else float("inf")
    if not cells <= params.max_voxels:
        raise ValueError(
            f"background grid of {cells:.3g} cells (region {region_box(region)} at "
            f"{params.voxel_size_m} m) exceeds background.max_voxels {params.max_voxels}: "
            "enlarge background.voxel_size_m or shrink the region"
        )


def _padding(params: BackgroundParams) -> int:
    return max(1, params.dilation_voxels)


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
        # padding on every side: points outside the region are clipped into it, and neighbour
        # offsets of a region voxel (up to the dilation) never leave the array
        self.pad = _padding(params)
        self.padded = tuple(n + 2 * self.pad for n in self.shape)
        cells = int(np.prod(self.padded, dtype=np.int64))
        self._strides = np.array([self.padded[1] * self.padded[2], self.padded[2], 1], dtype=np.int64)
        d = params.dilation_voxels
        offsets = np.array(np.meshgrid(*[np.arange(-d, d + 1)] * 3, indexing="ij")).reshape(3, -1).T
        self._offsets = offsets @ self._strides
        self.counts = np.zeros(cells, dtype=np.uint8)
        self.is_background = np.zeros(cells, dtype=bool)
        # background voxels within the dilation of each voxel; padding holds OUTSIDE (never 0)
        self.dilated = np.zeros(cells, dtype=np.uint16)
        region_cells = self._region_cells()
        self.dilated[~region_cells] = OUTSIDE
        # the per-point lookup reads a bit (in the region, dilated count 0) that stays in cache
        self._free_bits = np.packbits(region_cells, bitorder="little")
        self._grid = np.array([*self.padded, self.pad], dtype=np.int64)
        self.history: deque[np.ndarray] = deque()  # the voxels of each sample, each once
        self.frames_seen = 0
        self._seen = np.zeros(
            cells // 8 + 1, dtype=np.uint8
        )  # a bit per voxel for the learning pass, clear between frames
        self._occupied: list[np.ndarray] = []  # while the window fills: the voxels counted for the first time
        self._pending: np.ndarray | None = None  # the last learning frame's sample, counted in on the next frame
        self._cells, self._columns = _NO_CELLS, _NO_CELLS  # the pass's scratch (voxel and column per point)
        self._shift = (self.origin - self.pad * params.voxel_size_m).astype(np.float32)
        self._scale = np.float32(1.0 / params.voxel_size_m)
        self._upper = np.array(self.padded, dtype=np.float32) - np.float32(0.5)
        kernels.warm_up()

    def _region_cells(self) -> np.ndarray:
        inside = np.zeros(self.padded, dtype=bool)
        inside[self.pad : -self.pad, self.pad : -self.pad, self.pad : -self.pad] = True
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
        return self._thresholds(self.samples)[0]

    # ----------------------------------------------------------------- learning

    def process(self, points: np.ndarray, protected: list[ProtectedBox] = ()) -> BackgroundResult:
        """Region and foreground masks of ``points`` (yard frame) with the map as it was before this
        frame; on a learning frame the frame's sample (its voxels) is taken, and counted in on the
        next frame: the map's two costly halves, a pass over the points and the scattered counts
        and decisions, never fall on one frame (the map's decisions follow a frame later)."""
        points = np.ascontiguousarray(points, dtype=np.float32)
        n = len(points)
        result = BackgroundResult(np.empty(n, dtype=bool), np.empty(n, dtype=bool))
        learning = self.frames_seen % self.params.learn_every_frames == 0
        keep = self._protected_columns(protected, self.params.keep_margin_m) if self.ready else None
        protect = self._protected_columns(protected, self.params.protect_margin_m) if learning else None
        learned = np.empty(n if learning else 0, dtype=CELL)
        if len(self._cells) < n:  # scratch kept between frames: fresh pages cost more than the pass
            self._cells, self._columns = np.empty(2 * n, dtype=CELL), np.empty(2 * n, dtype=CELL)
        n_learned = kernels.background_pass(
            points, self._shift, self._scale, self._upper, self._grid, self._free_bits, self.ready,
            _NO_COLUMNS if keep is None else keep, learning, _NO_COLUMNS if protect is None else protect,
            self._seen, result.in_region, result.foreground, learned, self._cells, self._columns,
        )  # fmt: skip
        if self._pending is not None:
            self._add_sample(self._pending)
        self._pending = learned[:n_learned].copy() if learning else None
        self.frames_seen += 1
        return result

    def _add_sample(self, index: np.ndarray) -> None:
        """Count a sample in; once the window is full the oldest goes out, and only the voxels of the
        two can change their decision."""
        if self.samples < self.params.window_frames:
            kernels.count_sample(index, self.counts, False, 0, self.is_background, _NO_CELLS)
            self._filling(index)
            return
        old = self.history.popleft()
        kernels.forget_counts(old, self.counts)  # first: the new sample's voxels then reach their final count
        threshold, forget = self._thresholds(self.params.window_frames)
        flips = np.empty(len(index) + len(old), dtype=CELL)
        n_flips = kernels.count_sample(index, self.counts, True, threshold, self.is_background, flips)
        n_flips = kernels.forgotten(old, self.counts, self.is_background, threshold, forget, flips, n_flips)
        kernels.flip_cells(flips[:n_flips], self.is_background, self.dilated, self._free_bits, self._offsets)
        self.history.append(index)

    def _filling(self, index: np.ndarray) -> None:
        """A sample while the window fills: the thresholds moved, so every voxel ever counted may
        change (all others have count 0 and are not background, as counts only grow meanwhile)."""
        self.history.append(index)
        self._occupied.append(index[self.counts[index] == 1])
        self._update(np.concatenate(self._occupied))
        if self.samples == self.params.window_frames:
            self._occupied = []

    def _thresholds(self, samples: int) -> tuple[int, int]:
        """(occupied in at least, forgotten at most) samples, of ``samples``."""
        occupied = max(1, int(np.ceil(self.params.occupied_fraction * samples - 1e-9)))
        return occupied, int(np.floor(self.params.forget_fraction * samples + 1e-9))

    @property
    def forget_threshold(self) -> int:
        """A background voxel occupied in at most this many samples of the window is forgotten."""
        return self._thresholds(self.samples)[1]

    def _rebuild(self) -> None:
        """Compare every voxel (a loaded map)."""
        state = (self.counts >= self.threshold) | (self.is_background & (self.counts > self.forget_threshold))
        self._update(np.flatnonzero(state != self.is_background).astype(CELL))

    def _update(self, touched: np.ndarray) -> None:
        """Re-decide these voxels (repeats allowed) and move the dilated counts of those that change."""
        kernels.update_cells(
            touched, self.counts, self.is_background, self.dilated, self._free_bits, self._offsets,
            self.threshold, self.forget_threshold,
        )  # fmt: skip

    def _protected_columns(self, boxes: list[ProtectedBox], margin_m: float) -> np.ndarray | None:
        """(x, y) columns of the padded grid (flattened) whose centre lies in a box plus the margin; None without boxes."""
        if not len(boxes):
            return None
        rows = np.array(
            [(*b.center_xy, np.cos(b.yaw_rad), np.sin(b.yaw_rad), b.half_length_m, b.half_width_m) for b in boxes],
            dtype=np.float64,
        )
        nx, ny = self.padded[0], self.padded[1]
        mask = np.zeros(nx * ny, dtype=bool)
        voxel = self.params.voxel_size_m
        corner = self.origin[:2] - (self.pad - 1) * voxel  # the kernel counts one voxel of padding
        kernels.box_columns(rows, margin_m + voxel / 2, corner[0], corner[1], voxel, nx, ny, mask)
        return mask

    # ----------------------------------------------------------------- saving

    def _reindex(self, flat: np.ndarray, pad_from: int, pad_to: int) -> np.ndarray:
        """Flat voxel indices of a grid padded by ``pad_from`` as indices of one padded by ``pad_to``
        (files hold one voxel of padding, whatever the dilation)."""
        if pad_from == pad_to:
            return flat
        ijk = np.unravel_index(flat, tuple(n + 2 * pad_from for n in self.shape))
        return np.ravel_multi_index(
            tuple(i + pad_to - pad_from for i in ijk), tuple(n + 2 * pad_to for n in self.shape)
        )

    def save(self, path: str | Path) -> None:
        """The learned map (background voxels and grid) as .npz; loaded maps start as a full window."""
        np.savez_compressed(
            path,
            format_version=FORMAT_VERSION,
            origin=self.origin,
            shape=np.array(self.shape),
            voxel_size_m=self.params.voxel_size_m,
            background=self._reindex(np.flatnonzero(self.is_background), self.pad, 1),
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
            cells = self._reindex(data["background"].astype(np.int64), 1, self.pad).astype(CELL)
        # a loaded map acts as a full window in which its voxels were always occupied
        window = self.params.window_frames
        self.counts[:] = 0
        self.counts[cells] = window
        self.history = deque([cells] * window)
        self._occupied = []
        self._pending = None
        self._rebuild()
