"""Folders of point-cloud files: PCD (``pypcd4``: ascii, binary, binary_compressed, organized with
NaNs), PLY (open3d), NPY (N, 3+) and BIN (KITTI: 4 float32 x y z intensity; nuScenes: 5 float32
x y z intensity ring).

Layouts: ``REC/<sensor>/*.pcd`` (one subfolder per sensor), or the files directly in ``REC``; then
the sensor is the part of the file name after its timestamp (TUMTraf:
``1646667315_454719936_s110_lidar_ouster_south.pcd``), else the folder's name. Frame k is the k-th
file (sorted) of every sensor. Stamps come from ``timestamps.txt`` in the sensor's folder (one per
file: seconds, or KITTI's ``YYYY-MM-DD hh:mm:ss.fffffffff``), else from the file names (``SEC_NSEC``,
``SEC.FRACTION``, or an integer in ns), else frame number / rate. Stamps more than 1 s or less than
20 ms apart are not a sweep rate: they are replaced by frame number / rate (and said so in ``meta``).
A per-point time field ``t`` (uint32 ns after the sweep start, Ouster) gives the time offsets.
"""

from __future__ import annotations

import re
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from i2v_loc.formats.base import FormatError, PointRecording, copy_side_files
from i2v_loc.frame import SensorScan

SUFFIXES = (".pcd", ".ply", ".npy", ".bin")
BIN_LAYOUTS = {"kitti": 4, "nuscenes": 5}
BIN_OPTION = "--bin-layout kitti|nuscenes"
DEFAULT_RATE_HZ = 10.0
_NAME = re.compile(r"^(?P<sec>\d+)(?:[._](?P<frac>\d+))?(?:[_\-](?P<rest>.+))?$")


# --------------------------------------------------------------------------- single files


def read_cloud_file(path: Path, bin_layout: str | None = None) -> tuple[np.ndarray, np.ndarray | None]:
    """Finite points (N, 3) float32 of one file and, if it has a ``t`` field, offsets in s."""
    suffix = path.suffix.lower()
    try:
        if suffix == ".pcd":
            xyz, t = _read_pcd(path)
        elif suffix == ".bin":
            xyz, t = read_bin(path, bin_layout), None
        elif suffix == ".npy":
            xyz, t = _read_npy(path), None
        elif suffix == ".ply":
            xyz, t = _read_ply(path), None
        else:
            raise FormatError(f"{path}: unknown cloud format {suffix!r}; expected one of {', '.join(SUFFIXES)}")
    except FormatError:
        raise
    except Exception as err:  # the readers raise many kinds on corrupt files
        raise FormatError(
            f"{path}: cannot read the {suffix} file: {str(err).splitlines()[0] if str(err) else type(err).__name__}"
        ) from None
    finite = np.isfinite(xyz).all(axis=1)
    return xyz[finite].astype(np.float32), (t[finite] if t is not None else None)


def _read_pcd(path: Path) -> tuple[np.ndarray, np.ndarray | None]:
    from pypcd4 import PointCloud

    cloud = PointCloud.from_path(path)
    missing = [f for f in ("x", "y", "z") if f not in cloud.fields]
    if missing:
        raise FormatError(f"{path}: PCD without the fields {missing} (has {list(cloud.fields)})")
    xyz = cloud.numpy(("x", "y", "z")).astype(np.float64)
    t = cloud.numpy(("t",))[:, 0].astype(np.float64) * 1e-9 if "t" in cloud.fields else None
    return xyz, t


def _read_npy(path: Path) -> np.ndarray:
    data = np.load(path, allow_pickle=False)
    if data.ndim != 2 or data.shape[1] < 3:
        raise FormatError(f"{path}: expected an (N, 3+) array, got shape {data.shape}")
    return data[:, :3].astype(np.float64)


def _read_ply(path: Path) -> np.ndarray:
    import open3d as o3d

    cloud = o3d.io.read_point_cloud(str(path), remove_nan_points=False, remove_infinite_points=False)
    points = np.asarray(cloud.points, dtype=np.float64)
    if len(points) == 0:
        raise FormatError(f"{path}: no points read (empty or unreadable PLY)")
    return points


def bin_layout_of(path: Path, data: np.ndarray) -> str | None:
    """``kitti`` or ``nuscenes`` when exactly one layout fits the content, else None.

    KITTI rows are x y z intensity with intensity in [0, 1] (or [0, 255]); nuScenes rows are
    x y z intensity ring with intensity in [0, 255] and an integer ring index below 128. Read with
    the wrong width the columns slide, so these checks fail for the other layout."""
    fits = []
    for name, width in BIN_LAYOUTS.items():
        if len(data) % width:
            continue
        rows = data.reshape(-1, width)
        rows = rows[np.isfinite(rows).all(axis=1)]  # a missing return (NaN) says nothing of the layout
        if len(rows) == 0 or (np.abs(rows[:, :3]) > 1000).any():
            continue
        intensity = rows[:, 3]
        if intensity.min() < 0 or intensity.max() > 255:
            continue
        if width == 5:
            ring = rows[:, 4]
            if not (np.all(ring == np.round(ring)) and ring.min() >= 0 and ring.max() < 128):
                continue
        fits.append(name)
    return fits[0] if len(fits) == 1 else None


def read_bin(path: Path, layout: str | None = None) -> np.ndarray:
    """(N, 3) points of a KITTI or nuScenes ``.bin`` (``layout``, else taken from its content:
    ``bin_layout_of``); a row's non-finite values stay."""
    size = path.stat().st_size
    if size == 0:
        raise FormatError(f"{path}: empty file, no points")
    if size % 4:
        raise FormatError(f"{path}: {size} bytes is not a whole number of float32 values: not a KITTI or nuScenes .bin")
    data = np.fromfile(path, dtype=np.float32)
    if layout is None:
        layout = bin_layout_of(path, data)
        if layout is None:
            raise FormatError(
                f"{path}: unknown .bin layout ({size} bytes fits neither or both of KITTI (4 float32 per point) "
                f"and nuScenes (5 float32 per point) by its content); set it with {BIN_OPTION}"
            )
    if layout not in BIN_LAYOUTS:
        raise FormatError(f"{path}: unknown .bin layout {layout!r}; known: {', '.join(BIN_LAYOUTS)}")
    width = BIN_LAYOUTS[layout]
    if len(data) % width:
        raise FormatError(
            f"{path}: {size} bytes is not a multiple of {4 * width} ({layout}: {width} float32 per point)"
        )
    return data.reshape(-1, width)[:, :3].astype(np.float64)


# --------------------------------------------------------------------------- stamps


def _stamp_from_name(stem: str) -> tuple[float | None, str | None]:
    """(seconds, rest of the name) of ``SEC_NSEC_rest``, ``SEC.FRACTION`` or an integer in ns."""
    match = _NAME.match(stem)
    if not match:
        return None, None
    sec, frac, rest = match["sec"], match["frac"], match["rest"]
    if frac is not None:
        return int(sec) + int(frac) / 10 ** len(frac), rest
    value = int(sec)
    return (value * 1e-9 if value >= 10**15 else None), rest  # a small integer is a frame number


def _read_timestamps(file: Path, n: int) -> list[float]:
    lines = [line.strip() for line in file.read_text().splitlines() if line.strip()]
    if len(lines) != n:
        raise FormatError(f"{file}: {len(lines)} timestamps for {n} cloud files")
    stamps = []
    for i, line in enumerate(lines):
        try:
            stamps.append(float(line))
        except ValueError:
            try:  # KITTI raw: 2011-09-26 13:02:25.964389445 (nanoseconds cut to microseconds)
                head, _, frac = line.partition(".")
                base = datetime.strptime(head, "%Y-%m-%d %H:%M:%S").replace(tzinfo=UTC).timestamp()
                stamps.append(base + (int(frac) / 10 ** len(frac) if frac else 0.0))
            except ValueError:
                raise FormatError(f"{file}:{i + 1}: not a timestamp: {line[:40]!r}") from None
    return stamps


# --------------------------------------------------------------------------- folders


def _sensor_name(text: str) -> str:
    name = re.sub(r"[^A-Za-z0-9_\-]", "_", text).strip("_") or "lidar"
    return name[:32]


def _group_files(path: Path) -> dict[str, list[Path]] | None:
    """Sensor name → its sorted cloud files, or None when ``path`` holds no cloud files."""

    def clouds(folder: Path) -> list[Path]:
        return sorted(p for p in folder.iterdir() if p.is_file() and p.suffix.lower() in SUFFIXES)

    if path.is_file():
        return (
            {_sensor_name(_stamp_from_name(path.stem)[1] or path.parent.name): [path]}
            if path.suffix.lower() in SUFFIXES
            else None
        )
    groups: dict[str, list[Path]] = {}
    for sub in sorted(p for p in path.iterdir() if p.is_dir()):
        files = clouds(sub)
        if files:
            groups[_sensor_name(sub.name)] = files
    if groups:
        return groups
    for file in clouds(path):
        rest = _stamp_from_name(file.stem)[1]
        groups.setdefault(_sensor_name(rest) if rest else _sensor_name(path.name), []).append(file)
    return groups or None


class CloudFolderRecording(PointRecording):
    """Point-cloud files per sensor (see the module doc); files are read on demand."""

    def __init__(self, path: Path, groups: dict[str, list[Path]], bin_layout: str | None = None):
        suffixes = {f.suffix.lower() for files in groups.values() for f in files}
        self.layout = "+".join(sorted(s.lstrip(".") for s in suffixes))
        self.files = groups
        self.bin_layout = bin_layout
        self.stamps: dict[str, list[float]] = {}
        notes = []
        for name, files in groups.items():
            stamps, note = self._stamps(files)
            self.stamps[name] = stamps
            if note:
                notes.append(f"{name}: {note}")
        first = next(iter(self.stamps.values()))
        rate = _rate_from(first) or DEFAULT_RATE_HZ
        super().__init__(path, list(groups), max(len(f) for f in groups.values()), rate)
        self.meta["stamps"] = "; ".join(notes) if notes else "from timestamps files or file names"
        if ".bin" in suffixes and bin_layout is None:  # fail now, not at frame 37
            for files in groups.values():
                bins = [f for f in files if f.suffix.lower() == ".bin"]
                if bins:
                    read_cloud_file(bins[0])

    def _stamps(self, files: list[Path]) -> tuple[list[float], str | None]:
        ts_file = files[0].parent / "timestamps.txt"
        if ts_file.is_file():
            stamps = _read_timestamps(ts_file, len(files))
        else:
            stamps = [_stamp_from_name(f.stem)[0] for f in files]
            if any(s is None for s in stamps):
                return [
                    k / DEFAULT_RATE_HZ for k in range(len(files))
                ], f"no timestamps: frame number / {DEFAULT_RATE_HZ:g} Hz"
        if len(stamps) > 1 and _rate_from(stamps) is None:
            period = float(np.median(np.diff(stamps)))
            return (
                [k / DEFAULT_RATE_HZ for k in range(len(files))],
                f"stamps {period:.6g} s apart are not a sweep period: frame number / {DEFAULT_RATE_HZ:g} Hz",
            )
        return stamps, None

    def _scan(self, sensor: str, index: int) -> SensorScan | None:
        files = self.files[sensor]
        if index >= len(files):
            return None
        points, offsets = read_cloud_file(files[index], self.bin_layout)
        return SensorScan(sensor=sensor, stamp_s=self.stamps[sensor][index], points=points, time_offset_s=offsets)

    def generated_sensors(self) -> list[dict]:
        """Sensors at the yard origin (extrinsics zero): set the real poses with --params."""
        rate = 20 if self.rate_hz > 15 else 10
        return [{"name": n, "rate_hz": rate} for n in self.sensor_names]


def _rate_from(stamps: list[float]) -> float | None:
    if len(stamps) < 2:
        return None
    period = float(np.median(np.diff(stamps)))
    return round(1.0 / period, 3) if 0.02 <= period <= 1.0 else None


def open_cloud_folder(path: Path, bin_layout: str | None = None) -> CloudFolderRecording | None:
    groups = _group_files(path)
    if groups is None:
        return None
    return CloudFolderRecording(path, groups, bin_layout=bin_layout)


# --------------------------------------------------------------------------- writing


def write_pcd_folder(recording, out: str | Path, encoding: str = "binary_compressed") -> Path:
    """``<sensor>/<frame>.pcd`` (x y z float32, t uint32 ns) + ``timestamps.txt`` per sensor."""
    from pypcd4 import Encoding, PointCloud

    out = Path(out)
    for name in recording.sensor_names:
        folder = out / name
        folder.mkdir(parents=True, exist_ok=True)
        scans = recording.scans(name)
        for k in range(scans.n_frames):
            points, offsets = scans.points(k)
            t = np.rint(offsets.astype(np.float64) * 1e9).astype(np.uint32)
            cloud = PointCloud.from_points(
                [points[:, 0], points[:, 1], points[:, 2], t],
                ("x", "y", "z", "t"),
                (np.float32, np.float32, np.float32, np.uint32),
            )
            cloud.save(folder / f"{k:06d}.pcd", encoding=Encoding(encoding))
        (folder / "timestamps.txt").write_text(
            "".join(
                f"{int(s) // 10**9}.{int(s) % 10**9:09d}\n" if s >= 0 else f"{s * 1e-9:.9f}\n" for s in scans.stamp_ns
            )
        )
    copy_side_files(recording, out)
    return out
