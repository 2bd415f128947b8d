"""Reading single point-cloud files: PCD and PLY (open3d), NPY (N, 3+), KITTI or nuScenes BIN
(``formats.files.read_bin``: the layout from the content unless given)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

SUFFIXES = (".pcd", ".ply", ".npy", ".bin")


class CloudError(ValueError):
    """A point-cloud file is missing, of an unknown kind, or unreadable."""


def read_cloud(path: str | Path, bin_layout: str | None = None) -> np.ndarray:
    """(N, 3) float32 points of a cloud file; non-finite points are kept (the pipeline counts them).
    ``bin_layout``: ``kitti`` or ``nuscenes`` for a ``.bin`` whose content does not tell."""
    path = Path(path)
    if not path.is_file():
        raise CloudError(f"{path}: no such file")
    suffix = path.suffix.lower()
    if suffix not in SUFFIXES:
        raise CloudError(f"{path}: unknown cloud format {suffix!r}; expected one of {', '.join(SUFFIXES)}")
    try:
        points = (
            _read_bin(path, bin_layout) if suffix == ".bin" else {".npy": _read_npy}.get(suffix, _read_open3d)(path)
        )
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


def _read_bin(path: Path, layout: str | None) -> np.ndarray:
    from i2v_loc.formats.base import FormatError
    from i2v_loc.formats.files import read_bin

    try:
        return read_bin(path, layout).astype(np.float32)
    except FormatError as err:
        raise CloudError(str(err)) from None


PCD_HEADER_LINES_MAX = 20


def _check_pcd_complete(path: Path) -> None:
    """A PCD file must hold the points its header declares: open3d pads a truncated ASCII file
    with made-up points instead of failing."""
    with open(path, "rb") as fh:
        header: dict[str, list[str]] = {}
        for _ in range(PCD_HEADER_LINES_MAX):
            line = fh.readline().decode("ascii", errors="replace").strip()
            if not line or line.startswith("#"):
                continue
            key, *values = line.split()
            header[key.upper()] = values
            if key.upper() == "DATA":
                break
        data_start = fh.tell()
        if "DATA" not in header or "POINTS" not in header:
            raise CloudError(f"{path}: not a PCD file (no POINTS / DATA in its header)")
        declared = int(header["POINTS"][0])
        kind = header["DATA"][0].lower() if header["DATA"] else ""
        if kind == "ascii":
            found = sum(1 for line in fh if line.strip())
        elif kind == "binary":
            point_bytes = sum(
                int(size) * int(count)
                for size, count in zip(header.get("SIZE", []), header.get("COUNT", ["1"] * len(header.get("SIZE", []))))
            )
            found = (path.stat().st_size - data_start) // point_bytes if point_bytes else 0
        else:  # binary_compressed: open3d checks the compressed size itself
            return
    if found < declared:
        raise CloudError(f"{path}: the file holds {found} of the {declared} points its header declares (cut short?)")


def _read_open3d(path: Path) -> np.ndarray:
    import open3d as o3d

    if path.suffix.lower() == ".pcd":
        _check_pcd_complete(path)

    cloud = o3d.io.read_point_cloud(str(path), remove_nan_points=False, remove_infinite_points=False)
    points = np.asarray(cloud.points, dtype=np.float32)
    if len(points) == 0:
        raise CloudError(f"{path}: no points read (empty or unreadable {path.suffix} file)")
    return points
