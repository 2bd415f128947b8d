"""Recordings on disk (docs/formats.md, "Recording directory"): writer and reader.

A recording holds one range image per sensor and frame (``scans/<sensor>.npz``), the sensor
models in ``meta.yaml``, the true and guessed extrinsics, and one ground-truth line per frame.
"""

from __future__ import annotations

import json
import zipfile
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import numpy as np
import yaml

from i2v_loc.frame import Frame, SensorScan

FORMAT_VERSION = 1
RANGE_UNIT_M = 0.001  # range_mm
MAX_RANGE_MM = np.iinfo(np.uint16).max


class RecordingError(ValueError):
    """A recording directory is missing, incomplete or inconsistent."""


@dataclass
class SensorScans:
    """All sweeps of one sensor in a recording (the content of ``scans/<sensor>.npz``)."""

    range_mm: np.ndarray  # (F, beams, columns) uint16, 0 = no return
    stamp_ns: np.ndarray  # (F,) int64, sweep start on the sensor's clock
    column_time_ns: np.ndarray  # (columns,) int64, offset of each column from the sweep start
    beam_altitude_deg: np.ndarray  # (beams,) float32
    beam_azimuth_offset_deg: np.ndarray  # (beams,) float32

    def __post_init__(self) -> None:
        self.range_mm = np.asarray(self.range_mm, dtype=np.uint16)
        self.stamp_ns = np.asarray(self.stamp_ns, dtype=np.int64).reshape(-1)
        self.column_time_ns = np.asarray(self.column_time_ns, dtype=np.int64).reshape(-1)
        self.beam_altitude_deg = np.asarray(self.beam_altitude_deg, dtype=np.float32).reshape(-1)
        self.beam_azimuth_offset_deg = np.asarray(self.beam_azimuth_offset_deg, dtype=np.float32).reshape(-1)
        if self.range_mm.ndim != 3:
            raise RecordingError(f"range_mm must be (frames, beams, columns), got shape {self.range_mm.shape}")
        n_frames, beams, columns = self.range_mm.shape
        checks = {
            "stamp_ns": (len(self.stamp_ns), n_frames),
            "column_time_ns": (len(self.column_time_ns), columns),
            "beam_altitude_deg": (len(self.beam_altitude_deg), beams),
            "beam_azimuth_offset_deg": (len(self.beam_azimuth_offset_deg), beams),
        }
        for name, (got, expected) in checks.items():
            if got != expected:
                raise RecordingError(f"{name} has {got} entries, expected {expected} (range_mm {self.range_mm.shape})")

    @property
    def n_frames(self) -> int:
        return int(self.range_mm.shape[0])

    def unit_directions(self) -> np.ndarray:
        """(beams, columns, 3) unit ray directions in the sensor frame (Ouster convention)."""
        return beam_directions(self.beam_altitude_deg, self.beam_azimuth_offset_deg, self.range_mm.shape[2])

    def points(self, frame: int, directions: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Points (N, 3) float32 in the sensor frame and their time offsets (N,) float32 in s."""
        if directions is None:
            directions = self.unit_directions()
        ranges = self.range_mm[frame]
        beam_idx, col_idx = np.nonzero(ranges)
        r_m = ranges[beam_idx, col_idx].astype(np.float64) * RANGE_UNIT_M
        pts = directions[beam_idx, col_idx] * r_m[:, None]
        offsets = self.column_time_ns[col_idx].astype(np.float64) * 1e-9
        return pts.astype(np.float32), offsets.astype(np.float32)

    def unreturned(self, frame: int, directions: np.ndarray) -> np.ndarray:
        """The unit directions (M, 3) float32, sensor frame, of the rays of ``frame`` that returned
        nothing (``directions``: float32 ones are taken as they are, not copied again)."""
        return directions[self.range_mm[frame] == 0].astype(np.float32, copy=False)


def beam_directions(beam_altitude_deg: np.ndarray, beam_azimuth_offset_deg: np.ndarray, columns: int) -> np.ndarray:
    """Unit rays (beams, columns, 3): azimuth = 2*pi*(1 - c/columns) + offset, clockwise sweep."""
    alt = np.radians(np.asarray(beam_altitude_deg, dtype=np.float64))[:, None]
    az = (
        2.0 * np.pi * (1.0 - np.arange(columns) / columns)[None, :]
        + np.radians(np.asarray(beam_azimuth_offset_deg, dtype=np.float64))[:, None]
    )
    cos_alt = np.cos(alt)
    return np.stack([cos_alt * np.cos(az), cos_alt * np.sin(az), np.broadcast_to(np.sin(alt), az.shape)], axis=-1)


def meters_to_range_mm(range_m: np.ndarray) -> np.ndarray:
    """Ranges in metres to uint16 millimetres; NaN, non-positive and too long ranges become 0."""
    r = np.asarray(range_m, dtype=np.float64)
    mm = np.rint(np.nan_to_num(r, nan=0.0, posinf=0.0) / RANGE_UNIT_M)
    mm[(mm <= 0) | (mm > MAX_RANGE_MM)] = 0
    return mm.astype(np.uint16)


# --------------------------------------------------------------------------- writing


def write_scans(path: str | Path, sensor: str, scans: SensorScans) -> Path:
    out = Path(path) / "scans" / f"{sensor}.npz"
    out.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(
        out,
        range_mm=scans.range_mm,
        stamp_ns=scans.stamp_ns,
        column_time_ns=scans.column_time_ns,
        beam_altitude_deg=scans.beam_altitude_deg,
        beam_azimuth_offset_deg=scans.beam_azimuth_offset_deg,
    )
    return out


def write_recording(
    path: str | Path,
    meta: dict,
    scans: dict[str, SensorScans],
    ground_truth: Sequence[dict],
    sensors_yaml: str,
    sensors_guess_yaml: str,
    openlabel: dict | None = None,
) -> Path:
    """Write a whole recording directory. ``meta`` must list the sensors in ``meta['sensors']``
    (dicts with at least ``name``); ``n_frames`` and ``format_version`` are filled in here."""
    path = Path(path)
    names = [s["name"] for s in meta.get("sensors", [])]
    if sorted(names) != sorted(scans):
        raise RecordingError(f"meta lists sensors {names} but scans are given for {sorted(scans)}")
    frame_counts = {name: s.n_frames for name, s in scans.items()}
    if len(set(frame_counts.values())) > 1:
        raise RecordingError(f"sensors have different frame counts: {frame_counts}")
    n_frames = next(iter(frame_counts.values()), 0)
    if len(ground_truth) != n_frames:
        raise RecordingError(f"{len(ground_truth)} ground-truth lines for {n_frames} frames")
    path.mkdir(parents=True, exist_ok=True)
    meta = {"format_version": FORMAT_VERSION, **meta, "n_frames": n_frames}
    (path / "meta.yaml").write_text(yaml.safe_dump(_plain(meta), sort_keys=False))
    (path / "sensors.yaml").write_text(sensors_yaml)
    (path / "sensors_guess.yaml").write_text(sensors_guess_yaml)
    for name, sensor_scans in scans.items():
        write_scans(path, name, sensor_scans)
    with open(path / "ground_truth.jsonl", "w") as fh:
        for line in ground_truth:
            fh.write(json.dumps(_plain(line), separators=(",", ":")) + "\n")
    if openlabel is not None:
        (path / "ground_truth.openlabel.json").write_text(json.dumps(_plain(openlabel)))
    return path


def _plain(obj):
    """numpy scalars and arrays to plain Python for YAML / JSON."""
    if isinstance(obj, dict):
        return {str(k): _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _plain(obj.tolist())
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.floating):
        return float(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    return obj


# --------------------------------------------------------------------------- reading


class RecordingFiles:
    """What every recording layout shares: frames in order and the ground-truth side files of
    ``folder`` (a subclass sets ``_ground_truth = None`` and has ``frame()`` and ``len()``)."""

    folder: Path

    def frames(self, sensors: Sequence[str] | None = None) -> Iterator[Frame]:
        for i in range(len(self)):
            yield self.frame(i, sensors)

    def ground_truth(self) -> list[dict]:
        if self._ground_truth is None:
            file = self.folder / "ground_truth.jsonl"
            if not file.is_file():
                raise RecordingError(f"{file}: missing")
            lines = [json.loads(line) for line in file.read_text().splitlines() if line.strip()]
            if len(lines) != len(self):
                raise RecordingError(f"{file}: {len(lines)} lines but the recording has {len(self)} frames")
            self._ground_truth = lines
        return self._ground_truth

    def openlabel(self) -> dict | None:
        file = self.folder / "ground_truth.openlabel.json"
        return json.loads(file.read_text()) if file.is_file() else None


class Recording(RecordingFiles):
    """Read access to a recording directory (scans are loaded lazily, once per sensor)."""

    @property
    def folder(self) -> Path:
        return self.path

    def __init__(self, path: str | Path):
        self.path = Path(path)
        meta_file = self.path / "meta.yaml"
        if not self.path.is_dir():
            raise RecordingError(f"{self.path}: no such recording directory")
        if not meta_file.is_file():
            raise RecordingError(f"{self.path}: not a recording (meta.yaml missing)")
        self.meta: dict = yaml.safe_load(meta_file.read_text()) or {}
        try:
            self.sensor_names: list[str] = [s["name"] for s in self.meta["sensors"]]
        except (KeyError, TypeError) as err:
            raise RecordingError(f"{meta_file}: no 'sensors' list with names") from err
        self._scans: dict[str, SensorScans] = {}
        self._directions: dict[str, np.ndarray] = {}
        self._directions32: dict[str, np.ndarray] = {}  # the unreturned rays' (cast once, not per frame)
        self._ground_truth: list[dict] | None = None
        # What ``frame(..., skip_damaged=True)`` left out: sensor -> why (file missing or unreadable,
        # or fewer frames than meta.yaml says).
        self.damaged: dict[str, str] = {}

    def __len__(self) -> int:
        return int(self.meta.get("n_frames", 0))

    def __repr__(self) -> str:
        return f"Recording({str(self.path)!r}, frames={len(self)}, sensors={self.sensor_names})"

    @property
    def rate_hz(self) -> float:
        return float(self.meta.get("rate_hz", 10.0))

    @property
    def sensors_file(self) -> Path:
        return self.path / "sensors.yaml"

    @property
    def sensors_guess_file(self) -> Path:
        return self.path / "sensors_guess.yaml"

    def scans(self, sensor: str) -> SensorScans:
        """All sweeps of one sensor (loaded on first use); RecordingError if its file is missing,
        unreadable or holds another number of frames than meta.yaml says."""
        scans = self._loaded(sensor)
        if scans.n_frames != len(self):
            raise RecordingError(f"{self._file(sensor)}: {scans.n_frames} frames but meta.yaml says {len(self)}")
        return scans

    def _file(self, sensor: str) -> Path:
        return self.path / "scans" / f"{sensor}.npz"

    def _loaded(self, sensor: str) -> SensorScans:
        if sensor not in self.sensor_names:
            raise KeyError(f"no sensor {sensor!r} in {self.path}; known: {self.sensor_names}")
        if sensor not in self._scans:
            file = self._file(sensor)
            if not file.is_file():
                raise RecordingError(f"{file}: missing scan file of sensor {sensor}")
            try:
                with np.load(file) as data:
                    missing = {
                        "range_mm",
                        "stamp_ns",
                        "column_time_ns",
                        "beam_altitude_deg",
                        "beam_azimuth_offset_deg",
                    } - set(data.files)
                    if missing:
                        raise RecordingError(f"{file}: missing arrays {sorted(missing)}")
                    scans = SensorScans(**{k: data[k] for k in data.files if k in SensorScans.__dataclass_fields__})
            except (OSError, EOFError, ValueError, zipfile.BadZipFile) as err:  # RecordingError is a ValueError
                if isinstance(err, RecordingError):
                    raise
                raise RecordingError(f"{file}: unreadable scan file of sensor {sensor}: {err}") from err
            self._scans[sensor] = scans
            self._directions[sensor] = scans.unit_directions()
            self._directions32[sensor] = self._directions[sensor].astype(np.float32)
        return self._scans[sensor]

    def frame(self, index: int, sensors: Sequence[str] | None = None, skip_damaged: bool = False) -> Frame:
        """The sweeps of frame ``index``. A damaged sensor raises RecordingError, or, with
        ``skip_damaged``, is left out of the frame (the pipeline then marks it missing) and
        recorded in ``damaged``; a sensor whose file holds fewer frames is left out past its end."""
        n = len(self)
        if not -n <= index < n:
            raise IndexError(f"frame {index} out of range: the recording has {n} frames")
        index %= n
        names = list(sensors) if sensors is not None else self.sensor_names
        frame = Frame(index=index)
        for name in names:
            scans = self._usable(name, index) if skip_damaged else self.scans(name)
            if scans is None:
                continue
            points, offsets = scans.points(index, self._directions[name])
            frame.scans[name] = SensorScan(
                sensor=name,
                stamp_s=float(scans.stamp_ns[index]) * 1e-9,
                points=points,
                time_offset_s=offsets,
                unreturned=partial(scans.unreturned, index, self._directions32[name]),
            )
        return frame

    def _usable(self, sensor: str, index: int) -> SensorScans | None:
        """The sweeps of ``sensor`` if it has frame ``index``, else None (the reason in ``damaged``)."""
        if sensor in self.damaged and sensor not in self._scans:
            return None
        try:
            scans = self._loaded(sensor)
        except RecordingError as err:
            self.damaged[sensor] = str(err)
            return None
        if scans.n_frames > len(self):
            self.damaged[sensor] = f"{self._file(sensor)}: {scans.n_frames} frames but meta.yaml says {len(self)}"
            del self._scans[sensor]
            return None
        if index >= scans.n_frames:
            self.damaged[sensor] = (
                f"{self._file(sensor)}: holds {scans.n_frames} of the {len(self)} frames; "
                f"frames {scans.n_frames}-{len(self) - 1} of this sensor are missing"
            )
            return None
        return scans
