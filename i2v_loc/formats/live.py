"""Live Ouster sensors over UDP: lidar packets → the SDK's ``FrameBatcher`` / ``XYZLut`` → frames.

``OusterUdpSource(metadata_dir, ports)`` listens on one UDP port per sensor (``<sensor>.json`` in
``metadata_dir``; the port is the metadata's ``udp_port_lidar`` unless given). A receiver thread
batches the packets into sweeps; ``frame(k)`` returns the k-th sweep of every sensor (k counted
from each sensor's first sweep by the packets' frame id), waiting up to ``timeout_s`` for it. Lost
packets leave columns empty: each sweep with missing columns is counted (``incomplete_sweeps``,
``lost_packets``) and the sweep is used with the points it has; packets that arrive out of order
inside a sweep are placed by their measurement id; packets of another sensor are counted
(``foreign_packets``) and ignored; a sweep that never comes is a ``missing`` sensor for the pipeline.
"""

from __future__ import annotations

import selectors
import socket
import threading
import time
from pathlib import Path

from i2v_loc.formats.base import FormatError
from i2v_loc.formats.ouster import FRAME_ID_MODULO, SweepDecoder, _looks_like_ouster_json, _sdk, read_metadata
from i2v_loc.frame import Frame, SensorScan

RECEIVE_BUFFER_BYTES = 8 << 20
MAX_PACKET_BYTES = 65536
KEEP_SWEEPS = 50  # sweeps kept per sensor for frame(k) (5 s at 10 Hz)


class OusterUdpSource:
    def __init__(
        self,
        metadata_dir: str | Path,
        ports: list[int] | None = None,
        host: str = "127.0.0.1",
        timeout_s: float = 1.0,
        label: str | None = None,
        in_order: bool = False,
    ):
        core, _ = _sdk()
        self._core = core
        folder = Path(metadata_dir)
        files = sorted(f for f in folder.glob("*.json") if _looks_like_ouster_json(f)) if folder.is_dir() else []
        if not files:
            raise FormatError(f"{folder}: no sensor metadata <sensor>.json for ouster-udp")
        infos = {f.stem: read_metadata(f) for f in files}
        if ports is not None and len(ports) != len(infos):
            raise FormatError(f"ouster-udp: {len(ports)} ports for {len(infos)} sensors ({', '.join(infos)})")
        self.folder = folder
        self.label = label or f"ouster-udp:{folder}"
        self.timeout_s = timeout_s
        self.in_order = in_order
        self.decoders = {name: SweepDecoder(info, name) for name, info in infos.items()}
        self.rates = {info.format.fps for info in infos.values()}
        self._sweeps: dict[str, dict[int, SensorScan]] = {name: {} for name in infos}
        self._first_id: dict[str, int] = {}
        self._delivered = dict.fromkeys(infos, -1)
        self._late = dict.fromkeys(infos, 0)
        self._cond = threading.Condition()
        self._selector = selectors.DefaultSelector()
        self.ports: dict[str, int] = {}
        for i, (name, info) in enumerate(infos.items()):
            port = ports[i] if ports is not None else int(info.config.udp_port_lidar or 0)
            sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RECEIVE_BUFFER_BYTES)
            try:
                sock.bind((host, port))
            except OSError as err:
                self.close()
                raise FormatError(
                    f"ouster-udp: cannot listen on {host}:{port} for sensor {name}: {err.strerror}"
                ) from None
            sock.setblocking(False)
            self.ports[name] = sock.getsockname()[1]
            self._selector.register(sock, selectors.EVENT_READ, name)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._receive, name="ouster-udp", daemon=True)
        self._thread.start()

    # ------------------------------------------------------------------ the source interface
    @property
    def rate_hz(self) -> float:
        return float(max(self.rates))

    @property
    def sensor_names(self) -> list[str]:
        return list(self.decoders)

    @property
    def sensors_file(self) -> Path | None:
        file = self.folder / "sensors.yaml"
        return file if file.is_file() else None

    @property
    def n_frames(self) -> None:
        return None  # a live stream has no end

    def starts_lap(self, k: int) -> bool:
        """A live stream never starts over."""
        return False

    @property
    def counters(self) -> dict[str, int]:
        counts = {f"{name}.{k}": v for name, d in self.decoders.items() for k, v in d.counters.items()}
        return counts | {f"{name}.late_sweeps": n for name, n in self._late.items()}

    def frame(self, k: int) -> Frame:
        """Live (``in_order`` False, the service): the newest sweep of every sensor that has not
        been delivered yet, waiting up to the timeout for each sensor to send one; older undelivered
        sweeps are skipped and counted (``late_sweeps``), so a slow consumer stays current.
        ``in_order``: the k-th sweep of every sensor (k counted from each sensor's first sweep by
        the packets' frame id), for reading a replay completely. A sensor without a sweep in time
        is left out of the frame (the pipeline reports it ``missing``)."""
        deadline = time.monotonic() + self.timeout_s
        with self._cond:
            while not self._ready(k) and deadline - time.monotonic() > 0:
                self._cond.wait(deadline - time.monotonic())
            scans = self._take(k)
        return Frame(index=k, scans=scans)

    def _ready(self, k: int) -> bool:
        if self.in_order:
            return all(k in s or any(i > k for i in s) for s in self._sweeps.values())
        return all(any(i > self._delivered[n] for i in s) for n, s in self._sweeps.items())

    def _take(self, k: int) -> dict[str, SensorScan]:
        scans = {}
        for name, sweeps in self._sweeps.items():
            if self.in_order:
                if k in sweeps:
                    scans[name] = sweeps[k]
                stale = [i for i in sweeps if i <= k - KEEP_SWEEPS]
            else:
                fresh = [i for i in sweeps if i > self._delivered[name]]
                if fresh:
                    newest = max(fresh)
                    scans[name] = sweeps[newest]
                    self._late[name] += len(fresh) - 1
                    self._delivered[name] = newest
                stale = [i for i in sweeps if i <= self._delivered[name]]
            for i in stale:
                del sweeps[i]
        return scans

    def describe(self) -> dict:
        return {
            "source": self.label,
            "ports": dict(self.ports),
            "frames": None,
            "rate_hz": self.rate_hz,
            "loop": False,
            "counters": self.counters,
        }

    def close(self) -> None:
        stop = getattr(self, "_stop", None)
        if stop is not None:
            stop.set()
            self._thread.join(timeout=2.0)
        for key in list(self._selector.get_map().values()):
            self._selector.unregister(key.fileobj)
            key.fileobj.close()

    # ------------------------------------------------------------------ the receiver thread
    def _receive(self) -> None:
        buffers = {name: bytearray(MAX_PACKET_BYTES) for name in self.decoders}
        while not self._stop.is_set():
            for key, _ in self._selector.select(timeout=0.1):
                name = key.data
                while True:
                    try:
                        size = key.fileobj.recv_into(buffers[name])
                    except BlockingIOError:
                        break
                    self._packet(name, memoryview(buffers[name])[:size])

    def _packet(self, name: str, data) -> None:
        done = self.decoders[name].add_bytes(data)
        if done is None:
            return
        frame_id, scan = done
        with self._cond:
            first = self._first_id.setdefault(name, frame_id)
            self._sweeps[name][(frame_id - first) % FRAME_ID_MODULO] = scan
            self._cond.notify_all()


def parse_spec(arg: str) -> tuple[str, list[int] | None]:
    """``DIR`` or ``DIR@PORT,PORT,...`` of ``ouster-udp:``."""
    folder, _, ports = arg.partition("@")
    if not folder:
        raise FormatError("ouster-udp needs the folder of the sensors' metadata: ouster-udp:DIR[@PORT,...]")
    if not ports:
        return folder, None
    try:
        return folder, [int(p) for p in ports.split(",")]
    except ValueError:
        raise FormatError(f"ouster-udp: ports must be integers, got {ports!r}") from None


def open_udp_source(arg: str) -> OusterUdpSource:
    """``serve --source ouster-udp:DIR[@PORT,...]``; a bad folder or port is a SourceError."""
    from i2v_loc.sources import SourceError

    try:
        folder, ports = parse_spec(arg)
        return OusterUdpSource(folder, ports)
    except FormatError as err:
        raise SourceError(str(err)) from err
