"""Ouster sensors through ``ouster-sdk`` 1.x: pcap + metadata JSON (what ``ouster-cli`` records),
written from a recording as genuine packets, and read back with the SDK's decoder and ``XYZLut``.

Layout: ``<sensor>.pcap`` and ``<sensor>.json`` per sensor in one folder (plus ``sensors.yaml`` and
the ground truth, when written from a simulated recording).

The metadata is built from the recording's own beam tables: ``beam_altitude_angles`` = the
altitude table, ``beam_azimuth_angles`` = minus the azimuth offsets (Ouster adds -azimuth to the
encoder angle), and identity beam/lidar transforms with a zero beam-origin offset, because the
recording's sensor frame is the frame its extrinsics refer to. ``XYZLut`` then reproduces the
recording's points exactly (ranges are integer millimetres in both).
"""

from __future__ import annotations

import json
import struct
import time
from pathlib import Path

import numpy as np

from i2v_loc.formats.base import FormatError, PointRecording, copy_side_files
from i2v_loc.frame import SensorScan

PROFILE = "RNG19_RFL8_SIG16_NIR16"
LIDAR_PORT = 7502
IMU_PORT = 7503
SERIAL_BASE = 992100000000  # serial numbers of the simulated sensors: base + position
FRAME_ID_MODULO = 1 << 16  # frame_id is 16 bits in the packet header
UNIT_LOOKUP_MM = 100_000  # a pixel's direction: its point at 100 m, the beam's origin offset (mm) aside


def _sdk():
    try:
        from ouster.sdk import core, pcap
    except ImportError as err:  # pragma: no cover - a dependency of the package
        raise FormatError(f"reading Ouster data needs ouster-sdk (pip install ouster-sdk): {err}") from err
    return core, pcap


# --------------------------------------------------------------------------- metadata


def sensor_info(beam_altitude_deg, beam_azimuth_offset_deg, columns: int, rate_hz: float, serial: int, init_id: int):
    """An Ouster ``SensorInfo`` for a sensor with these beam tables (see the module doc)."""
    core, _ = _sdk()
    mode = getattr(core.LidarMode, f"_{columns}x{int(rate_hz)}", None)
    if mode is None:
        raise FormatError(f"no Ouster lidar mode {columns}x{rate_hz:g}")
    beams = len(beam_altitude_deg)
    profile = getattr(core.UDPProfileLidar, PROFILE)
    info = core.SensorInfo.from_default(mode)
    azimuth = -np.asarray(beam_azimuth_offset_deg, dtype=np.float64)
    fmt = info.format
    fmt.udp_profile_lidar = profile
    fmt.pixels_per_column = beams
    fmt.pixel_shift_by_row = np.rint((azimuth - azimuth.min()) * columns / 360.0).astype(int).tolist()
    info.format = fmt
    info.beam_altitude_angles = np.asarray(beam_altitude_deg, dtype=np.float64).tolist()
    info.beam_azimuth_angles = azimuth.tolist()
    info.beam_to_lidar_transform = np.eye(4)
    info.lidar_origin_to_beam_origin_mm = 0.0
    info.lidar_to_sensor_transform = np.eye(4)
    info.prod_line = f"OS-1-{beams}"
    info.sn = int(serial)
    info.init_id = int(init_id)
    cfg = info.config
    cfg.udp_profile_lidar = profile
    cfg.udp_port_lidar = LIDAR_PORT
    cfg.udp_port_imu = IMU_PORT
    info.config = cfg
    return info


def read_metadata(path: Path):
    core, _ = _sdk()
    try:
        text = Path(path).read_text()
        info = core.SensorInfo(text)
    except (OSError, RuntimeError, ValueError) as err:
        issues = [line.strip() for line in str(err).splitlines() if line.strip()]
        detail = "; ".join(issues[1:4] if len(issues) > 1 else issues) or type(err).__name__
        raise FormatError(f"{path}: not Ouster sensor metadata: {detail}") from None
    if info.w <= 0 or info.h <= 0 or len(info.beam_altitude_angles) != info.h:
        raise FormatError(f"{path}: Ouster metadata without a usable lidar data format ({info.h} x {info.w})")
    return info


# --------------------------------------------------------------------------- writing


def frame_packets(info, range_mm: np.ndarray, column_stamp_ns: np.ndarray, frame_id: int) -> list:
    """The lidar packets the sensor sends for one sweep (the SDK's own encoder)."""
    core, _ = _sdk()
    from ouster.sdk.util import frame_to_packets

    lf = core.LidarFrame(info)
    lf.field("RANGE")[:] = range_mm
    lf.timestamp[:] = column_stamp_ns
    lf.status[:] = 1  # column valid
    lf.frame_id = frame_id % FRAME_ID_MODULO
    packets = frame_to_packets(lf, info)
    per_packet = info.format.columns_per_packet
    for i, packet in enumerate(packets):  # host time = capture time of the packet's last column
        packet.host_timestamp = int(column_stamp_ns[min((i + 1) * per_packet, len(column_stamp_ns)) - 1])
    return packets


def write_ouster(recording, out: str | Path) -> Path:
    """``<sensor>.pcap`` + ``<sensor>.json`` per sensor of ``recording`` (a native Recording),
    with the side files (sensors.yaml, ground truth)."""
    _, pcap = _sdk()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    for position, name in enumerate(recording.sensor_names):
        scans = recording.scans(name)
        columns = scans.range_mm.shape[2]
        info = sensor_info(
            scans.beam_altitude_deg,
            scans.beam_azimuth_offset_deg,
            columns,
            recording.rate_hz,
            serial=SERIAL_BASE + position + 1,
            init_id=1000 + position,
        )
        (out / f"{name}.json").write_text(info.to_json_string())
        packets = [
            p
            for k in range(scans.n_frames)
            for p in frame_packets(info, scans.range_mm[k], scans.stamp_ns[k] + scans.column_time_ns, k)
        ]
        pcap.record(packets, str(out / f"{name}.pcap"), lidar_port=LIDAR_PORT, imu_port=IMU_PORT)
    copy_side_files(recording, out)
    return out


# --------------------------------------------------------------------------- reading


class SweepDecoder:
    """Packets of one sensor → sweeps (points in the sensor frame, per-point time offsets), with
    the SDK's ``FrameBatcher`` and ``XYZLut``. Counts packets of another sensor and lost columns."""

    def __init__(self, info, name: str):
        core, _ = _sdk()
        self.core = core
        self.info = info
        self.name = name
        self.batcher = core.FrameBatcher(info)
        self.lut = core.XYZLut(info, use_extrinsics=False)
        self.directions = _unit(self.lut(np.full((info.h, info.w), UNIT_LOOKUP_MM, dtype=np.uint32)))
        self.frame = core.LidarFrame(info)
        self.column_period_ns = 1e9 / (info.format.fps * info.w)
        self.per_packet = info.format.columns_per_packet
        self.packet_format = core.PacketFormat.from_info(info)
        self.counters = {"packets": 0, "foreign_packets": 0, "lost_packets": 0, "incomplete_sweeps": 0}

    def add(self, packet) -> tuple[int, SensorScan] | None:
        """Feed one lidar packet; returns (frame_id, sweep) when a sweep is complete."""
        self.counters["packets"] += 1
        if packet.validate(self.info) != self.core.PacketValidationFailure.NONE:
            self.counters["foreign_packets"] += 1
            return None
        if not self.batcher.batch(packet, self.frame):
            return None
        done, self.frame = self.frame, self.core.LidarFrame(self.info)
        return self._sweep(done)

    def add_bytes(self, data) -> tuple[int, SensorScan] | None:
        """Feed one UDP payload (bytes); a payload of another size is another sensor's."""
        if len(data) != self.packet_format.lidar_packet_size:
            self.counters["packets"] += 1
            self.counters["foreign_packets"] += 1
            return None
        packet = self.core.LidarPacket(self.packet_format)
        packet.buf[:] = data
        packet.host_timestamp = time.time_ns()
        return self.add(packet)

    def flush(self) -> tuple[int, SensorScan] | None:
        """The sweep in progress when the stream ends (its last packets never came)."""
        if not (np.asarray(self.frame.status) & 1).any():
            return None
        done, self.frame = self.frame, self.core.LidarFrame(self.info)
        return self._sweep(done)

    def _sweep(self, lf) -> tuple[int, SensorScan] | None:
        valid_columns = (np.asarray(lf.status) & 1).astype(bool)
        missing = int((~valid_columns).sum())
        if missing:
            self.counters["incomplete_sweeps"] += 1
            self.counters["lost_packets"] += -(-missing // self.per_packet)
        if not valid_columns.any():
            return None
        stamps = np.asarray(lf.timestamp, dtype=np.int64)
        first = int(np.argmax(valid_columns))
        start_ns = int(stamps[first] - round(first * self.column_period_ns))
        ranges = np.asarray(lf.field("RANGE"))
        hit = (ranges > 0) & valid_columns[None, :]
        xyz = self.lut(lf)[hit]
        offsets = (stamps[None, :] - start_ns).repeat(lf.h, axis=0)[hit] * 1e-9
        unreturned = self.directions[(ranges == 0) & valid_columns[None, :]]
        scan = SensorScan(self.name, start_ns * 1e-9, xyz, offsets, unreturned=unreturned)
        return int(lf.frame_id), scan


def _unit(xyz: np.ndarray) -> np.ndarray:
    """(h, w, 3) points as float32 unit vectors."""
    return (xyz / np.linalg.norm(xyz, axis=-1, keepdims=True)).astype(np.float32)


def _pcap_packets(path: Path, info, rejected: dict):
    """The lidar packets of a pcap file, through the SDK's pcap reader; the packets it rejects
    (another sensor's serial / init id, another size) are counted into ``rejected``."""
    core, pcap = _sdk()
    try:
        source = pcap.PcapPacketSource(str(path), sensor_info=[info])
    except (RuntimeError, ValueError) as err:
        raise FormatError(
            f"{path}: not a readable pcap: {str(err).splitlines()[0] if str(err) else type(err).__name__}"
        ) from None
    try:
        try:
            for _, packet in source:
                if isinstance(packet, core.LidarPacket):
                    yield packet
        except RuntimeError as err:
            raise FormatError(f"{path}: cannot read the pcap: {' '.join(str(err).split())[:300]}") from None
        rejected["id"] = int(source.id_error_count)
        rejected["size"] = int(source.size_error_count)
    finally:
        source.close()


def _check_pcap_complete(path: Path) -> None:
    """A pcap cut short (copy aborted, disk full) ends inside a record: libpcap stops silently
    there, so the record headers are walked here (seeking, not reading the packets) to say so."""
    size = path.stat().st_size
    with path.open("rb") as fh:
        magic = fh.read(4)
        if size < 24:
            raise FormatError(f"{path}: truncated pcap ({size} bytes, shorter than the 24-byte file header)")
        order = {
            b"\xd4\xc3\xb2\xa1": "<",
            b"\xa1\xb2\xc3\xd4": ">",
            b"\x4d\x3c\xb2\xa1": "<",
            b"\xa1\xb2\x3c\x4d": ">",
        }.get(magic)
        if order is None:
            raise FormatError(f"{path}: not a pcap file (magic {magic.hex()})")
        offset, records = 24, 0
        while offset < size:
            if offset + 16 > size:
                raise FormatError(
                    f"{path}: truncated pcap: the file ends inside the header of packet {records + 1} (byte {offset})"
                )
            fh.seek(offset + 8)
            (caplen,) = struct.unpack(f"{order}I", fh.read(4))
            if offset + 16 + caplen > size:
                raise FormatError(
                    f"{path}: truncated pcap: packet {records + 1} needs {caplen} bytes, {size - offset - 16} are left"
                )
            offset += 16 + caplen
            records += 1


class OusterRecording(PointRecording):
    """A folder of ``<sensor>.pcap`` + ``<sensor>.json`` (or one pcap with its JSON)."""

    layout = "ouster-pcap"

    def __init__(self, path: str | Path, pairs: dict[str, tuple[Path, Path]]):
        self._sweeps: dict[str, dict[int, SensorScan]] = {}
        self.infos = {}
        counters: dict[str, int] = {}
        rates = set()
        for name, (pcap_file, json_file) in pairs.items():
            info = read_metadata(json_file)
            self.infos[name] = info
            rates.add(info.format.fps)
            self._sweeps[name], decoded = self._decode(name, pcap_file, json_file, info)
            for key, value in decoded.items():
                counters[f"{name}.{key}"] = value
        if len(rates) > 1:
            raise FormatError(f"{path}: sensors run at different rates {sorted(rates)} Hz")
        n_frames = max((max(s) + 1 for s in self._sweeps.values() if s), default=0)
        super().__init__(path, list(pairs), n_frames, float(rates.pop()))
        self.counters = counters
        self.meta["ouster"] = {
            name: {"serial": int(i.sn), "prod_line": i.prod_line, "mode": f"{i.w}x{i.format.fps}"}
            for name, i in self.infos.items()
        }

    def _decode(self, name: str, pcap_file: Path, json_file: Path, info) -> tuple[dict[int, SensorScan], dict]:
        _check_pcap_complete(pcap_file)
        decoder = SweepDecoder(info, name)
        sweeps: dict[int, SensorScan] = {}
        first_id = None
        rejected = {"id": 0, "size": 0}
        for done in (*map(decoder.add, _pcap_packets(pcap_file, info, rejected)), decoder.flush()):
            if done is None:
                continue
            frame_id, scan = done
            first_id = frame_id if first_id is None else first_id
            sweeps[(frame_id - first_id) % FRAME_ID_MODULO] = scan
        counters = decoder.counters
        counters["foreign_packets"] += rejected["id"]
        if not sweeps:
            if counters["foreign_packets"]:
                raise FormatError(
                    f"{pcap_file}: its {counters['foreign_packets']} lidar packets are from another sensor "
                    f"than {json_file.name} describes (serial {info.sn}, init id {info.init_id})"
                )
            raise FormatError(
                f"{pcap_file}: no lidar packet matches {json_file.name} "
                f"({info.prod_line}, {info.h} beams, {info.format.udp_profile_lidar}, port {info.config.udp_port_lidar})"
            )
        return sweeps, counters

    def _scan(self, sensor: str, index: int) -> SensorScan | None:
        return self._sweeps[sensor].get(index)


def ouster_pairs(path: Path) -> dict[str, tuple[Path, Path]] | None:
    """Sensor name → (pcap, metadata JSON) when ``path`` is a pcap or a folder of them."""
    if path.is_file():
        if path.suffix != ".pcap":
            return None
        candidates = [path.with_suffix(".json"), *sorted(path.parent.glob("*.json"))]
        meta = next((c for c in candidates if c.is_file() and _looks_like_ouster_json(c)), None)
        if meta is None:
            raise FormatError(
                f"{path}: an Ouster pcap needs its sensor metadata: {path.with_suffix('.json').name} is missing"
            )
        return {path.stem: (path, meta)}
    pcaps = sorted(path.glob("*.pcap"))
    if not pcaps:
        return None
    pairs = {}
    for p in pcaps:
        meta = p.with_suffix(".json")
        if not meta.is_file():
            raise FormatError(f"{p}: an Ouster pcap needs its sensor metadata: {meta.name} is missing")
        pairs[p.stem] = (p, meta)
    return pairs


def _looks_like_ouster_json(path: Path) -> bool:
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError):
        return False
    return isinstance(data, dict) and ("beam_intrinsics" in data or "lidar_data_format" in data)
