"""Reading single point-cloud files: PCD and PLY (open3d), NPY (N, 3+), KITTI BIN (float32 x y z i)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

SUFFIXES = (".pcd", ".ply", ".npy", ".bin")


class CloudError(ValueError):
    """A point-cloud file is missing, of an unknown kind, or unreadable."""


def read_cloud(path: str | Path) -> np.ndarray:
    """(N, 3) float32 points of a cloud file; non-finite points are kept (the pipeline counts them)."""
    path = Path(path)
    if not path.is_file():
        raise CloudError(f"{path}: no such file")
    suffix = path.suffix.lower()
    if suffix not in SUFFIXES:
        raise CloudError(f"{path}: unknown cloud format {suffix!r}; expected one of {', '.join(SUFFIXES)}")
    try:
        points = {".npy": _read_npy, ".bin": _read_kitti_bin}.get(suffix, _read_open3d)(path)
    except CloudError:
        raise
    except Exception as err:  # numpy / open3d raise many kinds on corrupt files
        raise CloudError(f"{path}: cannot read: {err}") from err
    return points


def _read_npy(path: Path) -> np.ndarray:
    data = np.load(path, allow_pickle=False)
    if data.ndim != 2 or data.shape[1] < 3:
        raise CloudError(f"{path}: expected an (N, 3+) array, got shape {data.shape}")
    if len(data) == 0:
        raise CloudError(f"{path}: empty array, no points")
    return data[:, :3].astype(np.float32)


POINT_BYTES_KITTI = 16  # float32 x, y, z, intensity


def _read_kitti_bin(path: Path) -> np.ndarray:
    size = path.stat().st_size
    if size == 0:
        raise CloudError(f"{path}: empty file, no points")
    if size % POINT_BYTES_KITTI:
        raise CloudError(f"{path}: {size} bytes is not a multiple of {POINT_BYTES_KITTI} "
                         "(KITTI points are 4 float32: x, y, z, intensity)")
    return np.fromfile(path, dtype=np.float32).reshape(-1, 4)[:, :3].copy()


def _read_open3d(path: Path) -> np.ndarray:
    import open3d as o3d

    cloud = o3d.io.read_point_cloud(str(path), remove_nan_points=False, remove_infinite_points=False)
    points = np.asarray(cloud.points, dtype=np.float32)
    if len(points) == 0:
        raise CloudError(f"{path}: no points read (empty or unreadable {path.suffix} file)")
    return points
