"""The pipeline thread: pace the source in real time, run the pipeline, publish every state.

Nothing here waits for an HTTP or WebSocket client: results are handed to the ``Hub`` (which
never blocks) and kept as the latest state for the REST API. A parameter change is handed to the
pipeline at once (so the pipeline can refuse it before the store commits it) and takes effect
between two frames. A frame that fails to load, to process or to publish is counted, logged and
skipped: nothing about one frame can stop the thread. When the pipeline falls behind real time,
it jumps to the newest frame (the skipped ones are counted as dropped, reason ``late``), as a
live system would.
"""

from __future__ import annotations

import json
import logging
import queue
import threading
import time
from collections import deque
from collections.abc import Callable

import numpy as np

from i2v_loc.geometry import extrinsics_matrix, transform_points
from service.hub import Hub, Message
from service.metrics import ServiceMetrics
from service.params_store import Version, merge_patch_diff

log = logging.getLogger("i2v_loc.service")

STALE_AFTER_S = 1.0
RATE_WINDOW_S = 5.0
OUTCOME_WINDOW = 100  # frames over which the drop rate is measured


class SensorStats:
    """Per-sensor rate (sweeps per wall-clock second), last stamp, and drops."""

    def __init__(self, names: list[str]):
        self._names = list(names)
        self._arrivals: dict[str, deque] = {n: deque(maxlen=200) for n in names}
        self._last_stamp: dict[str, float | None] = {n: None for n in names}
        self._drops: dict[str, int] = {n: 0 for n in names}
        self._last_fault: dict[str, str | None] = {n: None for n in names}
        self._lock = threading.Lock()

    def observe(
        self, present: dict[str, float], faults: dict[str, str], expected: list[str], now_s: float
    ) -> list[str]:
        """Record one frame: ``present`` maps sensor to stamp; returns the sensors that dropped."""
        dropped = []
        with self._lock:
            for name in dict.fromkeys([*expected, *present]):
                if name not in self._arrivals:
                    self._names.append(name)
                    self._arrivals[name] = deque(maxlen=200)
                    self._last_stamp[name], self._drops[name], self._last_fault[name] = None, 0, None
                if name in present:
                    self._arrivals[name].append(now_s)
                    self._last_stamp[name] = present[name]
                fault = faults.get(name) or (None if name in present else "missing")
                self._last_fault[name] = fault
                if fault:
                    self._drops[name] += 1
                    dropped.append(name)
        return dropped

    def snapshot(self, now_s: float) -> dict[str, dict]:
        with self._lock:
            return {name: self._one(name, now_s) for name in self._names}

    def _one(self, name: str, now_s: float) -> dict:
        arrivals = [t for t in self._arrivals[name] if now_s - t <= RATE_WINDOW_S]
        rate = (
            (len(arrivals) - 1) / (arrivals[-1] - arrivals[0])
            if len(arrivals) >= 2 and arrivals[-1] > arrivals[0]
            else 0.0
        )
        last = self._arrivals[name][-1] if self._arrivals[name] else None
        if last is None:  # never delivered: faulty if the frames so far said why
            status = f"fault:{self._last_fault[name]}" if self._last_fault[name] else "waiting"
        elif now_s - last > STALE_AFTER_S:
            status = "stale"
        elif self._last_fault[name]:
            status = f"fault:{self._last_fault[name]}"
        else:
            status = "ok"
        return {
            "status": status,
            "rate_hz": round(rate, 2),
            "last_stamp_s": self._last_stamp[name],
            "last_seen_ago_s": None if last is None else round(now_s - last, 3),
            "drops": self._drops[name],
            "last_fault": self._last_fault[name],
        }


def foreground_xy(result, cap: int) -> np.ndarray | None:
    """At most ``cap`` foreground points (x, y) of a pipeline result, evenly decimated."""
    points = getattr(result, "foreground", None)
    if points is None or cap <= 0:
        return None
    return _decimated_xy(np.asarray(points), cap)


def _decimated_xy(points: np.ndarray, cap: int) -> np.ndarray | None:
    if points.ndim != 2 or points.shape[1] < 2 or len(points) == 0:
        return None
    step = max(1, int(np.ceil(len(points) / cap)))
    return points[::step, :2]


ABOVE_GROUND_M = 0.3


class ApproximateForeground:
    """Display-only foreground when the pipeline result carries none: a decimated sample of
    every sweep in yard coordinates, inside the region of interest and above a flat ground."""

    def __init__(self, params):
        self.region = params.region
        self.poses = {s.name: extrinsics_matrix(s.extrinsics) for s in params.sensors}

    def xy(self, frame, cap: int) -> np.ndarray | None:
        total = sum(len(s.points) for s in frame.scans.values())
        if cap <= 0 or total == 0:
            return None
        step = max(1, total // (10 * cap))  # most points are ground or outside: sample 10x the cap
        parts = [
            transform_points(self.poses[name], scan.points[::step].astype(np.float64))
            for name, scan in frame.scans.items()
            if name in self.poses
        ]
        if not parts:
            return None
        pts = np.concatenate(parts)
        r = self.region
        keep = (
            (pts[:, 0] >= r.x_min_m)
            & (pts[:, 0] <= r.x_max_m)
            & (pts[:, 1] >= r.y_min_m)
            & (pts[:, 1] <= r.y_max_m)
            & (pts[:, 2] > ABOVE_GROUND_M)
            & (pts[:, 2] <= r.z_max_m)
        )
        return _decimated_xy(pts[keep], cap)


def _json_default(obj):
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    raise TypeError(f"{type(obj).__name__} is not JSON serialisable")


def dumps(obj) -> str:
    return json.dumps(obj, separators=(",", ":"), default=_json_default, allow_nan=False)


def _finite(obj):
    """Replace NaN / inf (not valid JSON) by None, recursively, numpy values included."""
    if isinstance(obj, np.ndarray):
        obj = obj.tolist()
    elif isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float):
        return obj if np.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite(v) for v in obj]
    return obj


class PipelineRunner:
    def __init__(
        self,
        source,
        pipeline,
        hub: Hub,
        metrics: ServiceMetrics,
        expected_sensors: list[str],
        realtime: bool = True,
        points_cap: int = 2000,
        clock: Callable[[], float] = time.monotonic,
    ):
        self.source = source
        self.pipeline = pipeline
        self.hub = hub
        self.metrics = metrics
        self.expected_sensors = list(expected_sensors)
        self.realtime = realtime
        self.points_cap = points_cap
        self.clock = clock
        self.sensors = SensorStats(self.expected_sensors)
        self.params_version = 0
        self.frames_processed = 0
        self.frames_dropped: dict[str, int] = {"source_error": 0, "pipeline_error": 0, "late": 0}
        self.last_frame_error: dict | None = None  # {frame, reason, error} of the last skipped frame
        self.finished = False
        self.error: str | None = None
        self.started_s: float | None = None
        self.last_frame_s: float | None = None
        self._latest: dict | None = None
        self._latest_lock = threading.Lock()
        self._frame_times: deque = deque(maxlen=50)
        self._outcomes: deque = deque(maxlen=OUTCOME_WINDOW)  # True: processed, False: dropped
        self._updates: queue.SimpleQueue = queue.SimpleQueue()
        # Held while the thread takes the queued versions and processes a frame, and while a new
        # version is handed to the pipeline: a frame's params_version is then always the version
        # the pipeline processed it with.
        self._apply_lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="i2v-loc-pipeline", daemon=True)
        self._pipeline_counters: dict[str, int] = {}
        self._approximate: ApproximateForeground | None = None
        self._approximate_version = -1

    # ------------------------------------------------------------------ control (any thread)

    def start(self) -> None:
        self.started_s = self.clock()
        self._thread.start()

    def stop(self, timeout_s: float = 5.0) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout_s)

    @property
    def alive(self) -> bool:
        return self._thread.is_alive()

    @property
    def method(self) -> str | None:
        return getattr(self.pipeline, "method", None)

    def submit(self, version: Version) -> None:
        """Hand a parameter version to the pipeline, in force from the next frame on.

        The pipeline checks it at once and raises ``ParamsError`` (a ValueError) if it refuses it;
        then nothing changes. It gets the whole parameters (as the merge patch from its own), so it
        always ends up with exactly the store's parameters.
        """
        with self._apply_lock:
            current = self.pipeline.params.model_dump(mode="json")
            self.pipeline.update_params(merge_patch_diff(current, version.params.model_dump(mode="json")))
            self._updates.put(version)

    @property
    def latest(self) -> dict | None:
        with self._latest_lock:
            return self._latest

    def drop_rate(self) -> float:
        """Share of the last OUTCOME_WINDOW frames that were dropped (late, unreadable, failed)."""
        outcomes = list(self._outcomes)
        return outcomes.count(False) / len(outcomes) if outcomes else 0.0

    def frame_rate_hz(self) -> float:
        times = list(self._frame_times)
        if len(times) < 2 or times[-1] <= times[0]:
            return 0.0
        return (len(times) - 1) / (times[-1] - times[0])

    # ------------------------------------------------------------------ the thread

    def _run(self) -> None:
        try:
            self._loop()
        except Exception as err:  # a bug, not bad data: report it on /health and in the log
            self.error = f"{type(err).__name__}: {err}"
            log.exception("the pipeline thread stopped")

    def _loop(self) -> None:
        period_s = 1.0 / float(self.source.rate_hz)
        total = self.source.n_frames
        k = 0
        t0 = self.clock()
        while not self._stop.is_set():
            with self._apply_lock:
                self._apply_updates()  # also while idle (finished, or waiting for a frame's time)
            if total is not None and k >= total:
                self.finished = True
                self._stop.wait(0.05)
                continue
            if self.realtime:
                now = self.clock()
                due = t0 + k * period_s
                if now < due:
                    self._stop.wait(min(due - now, period_s))
                    continue
                newest = int((now - t0) / period_s)
                if total is not None:
                    newest = min(newest, total - 1)
                if newest > k:
                    self._drop("late", newest - k)
                    k = newest
            self._step(k)
            k += 1

    def _apply_updates(self) -> None:
        """Take the versions handed to the pipeline since the last frame; call with _apply_lock."""
        while True:
            try:
                version = self._updates.get_nowait()
            except queue.Empty:
                return
            self.params_version = version.version
            self.metrics.params_version.set(version.version)
            try:
                message = {
                    "type": "params",
                    "version": version.version,
                    "source": version.source,
                    "patch": version.patch,
                    "params": version.params.model_dump(mode="json"),
                }
                text = dumps(_finite(message))
            except Exception as err:  # should not happen (validated parameters): log, keep running
                log.error("the message of parameter version %d could not be built: %s", version.version, err)
                continue
            self.hub.publish(Message("params", text, text))

    def _drop(self, reason: str, n: int = 1) -> None:
        self.frames_dropped[reason] = self.frames_dropped.get(reason, 0) + n
        self._outcomes.extend([False] * min(n, OUTCOME_WINDOW))
        self.metrics.frames_dropped.labels(reason).inc(n)

    def _step(self, k: int) -> None:
        try:
            frame = self.source.frame(k)
        except Exception as err:
            self._skip(k, "source_error", err)
            return
        taken_s = time.time()  # frame in: the state carries it, the WebSocket adds the send time
        try:
            with self._apply_lock:
                self._apply_updates()
                if self.source.starts_lap(k):  # its vehicles jump back to their start: the scene starts over
                    self.pipeline.forget_vehicles()
                result = self.pipeline.process(frame)
            self._publish(frame, result, taken_s)
        except Exception as err:  # any part of one frame: process, serialise, record, publish
            self._skip(k, "pipeline_error", err)

    def _skip(self, k: int, reason: str, err: Exception) -> None:
        self._drop(reason)
        detail = f"{type(err).__name__}: {err}"
        self.last_frame_error = {"frame": k, "reason": reason, "error": detail[:500]}
        log.warning("frame %d was skipped (%s): %s", k, reason, detail)

    def _publish(self, frame, result, taken_s: float) -> None:
        state = _finite(result.to_json())
        state["params_version"] = self.params_version
        state["frame_in_unix_s"] = round(taken_s, 6)
        plain = dumps(state)
        with_points = None
        xy = self._foreground(result, frame)
        if xy is not None:
            flat = _finite(np.round(np.asarray(xy, dtype=np.float64), 2).ravel())
            with_points = plain[:-1] + ',"foreground":{"xy":' + dumps(flat) + "}}"
        self._record(frame, state, self.clock())
        with self._latest_lock:
            self._latest = state
        self.hub.publish(Message("state", plain, with_points))

    def _foreground(self, result, frame) -> np.ndarray | None:
        if not self.points_cap or not self.hub.client_count:
            return None
        xy = foreground_xy(result, self.points_cap)
        if xy is None and getattr(result, "foreground", None) is None:
            if self._approximate is None or self._approximate_version != self.params_version:
                self._approximate = ApproximateForeground(self.pipeline.params)
                self._approximate_version = self.params_version
            xy = self._approximate.xy(frame, self.points_cap)
        return xy

    def _record(self, frame, state: dict, now: float) -> None:
        m = self.metrics
        for stage, ms in (state.get("latency_ms") or {}).items():
            if isinstance(ms, (int, float)):
                m.stage_latency.labels(stage).observe(ms / 1000.0)
        present = {name: scan.stamp_s for name, scan in frame.scans.items()}
        faults = {str(k): str(v) for k, v in (state.get("faults") or {}).items()}
        for name in self.sensors.observe(present, faults, self.expected_sensors, now):
            m.sensor_drops.labels(name).inc()
        for name, info in self.sensors.snapshot(now).items():
            m.sensor_rate.labels(name).set(info["rate_hz"])
            if info["last_stamp_s"] is not None:
                m.sensor_last_stamp.labels(name).set(info["last_stamp_s"])
        m.vehicles.set(len(state.get("vehicles") or []))
        counters = getattr(self.pipeline, "counters", None) or {}
        for reason, value in counters.items():
            if reason != "frames" and isinstance(value, (int, float)):
                delta = value - self._pipeline_counters.get(reason, 0)
                if delta > 0:
                    m.pipeline_events.labels(str(reason)).inc(delta)
                self._pipeline_counters[reason] = value
        self.frames_processed += 1  # last: a frame that failed above counts as dropped only
        self.last_frame_s = now
        self._frame_times.append(now)
        self._outcomes.append(True)
        m.frames_processed.inc()

    # ------------------------------------------------------------------ summaries

    def status(self) -> dict:
        latest = self.latest or {}
        vehicles = [
            {"id": v.get("id"), "vehicle": v.get("vehicle"), "hitch_deg": v.get("hitch_deg")}
            for v in latest.get("vehicles") or []
        ]
        return {
            "frames_processed": self.frames_processed,
            "frames_dropped": dict(self.frames_dropped),
            "last_frame_error": self.last_frame_error,
            "frame_rate_hz": round(self.frame_rate_hz(), 2),
            "frame_drop_rate": round(self.drop_rate(), 3),
            "vehicles": vehicles,
            "frame": latest.get("frame"),
            "stamp_s": latest.get("stamp_s"),
            "params_version": self.params_version,
            "method": self.method,
        }
