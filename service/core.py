"""The service object: source, pipeline runner, parameters, auth, metrics and WebSocket hub."""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from i2v_loc.params import DEFAULT_METHOD, Params
from service.auth import AuthConfig
from service.hub import Hub
from service.metrics import ServiceMetrics
from service.params_store import ParamStore
from service.runner import PipelineRunner

log = logging.getLogger("i2v_loc.service")

DEFAULT_POINTS_CAP = 2000
DEGRADED_DROP_RATE = 0.1  # of frames, or of WebSocket messages: above it the service is degraded
FAILED_AFTER_SKIPPED_FRAMES = 20  # skipped in a row from the start: the source does not work
STOP_WAIT_S = 0.5  # for the frame in progress; the thread is a daemon, so a stuck frame cannot hold up the exit


def real_pipeline(params: Params, method: str = DEFAULT_METHOD):
    from i2v_loc.pipelines import build_pipeline  # heavy imports only when the service starts

    return build_pipeline(params, method)


@dataclass
class Service:
    store: ParamStore
    runner: PipelineRunner
    hub: Hub
    metrics: ServiceMetrics
    auth: AuthConfig
    source_info: dict
    save_error: str | None = None  # why the parameter file could not be written at shutdown

    def start(self) -> None:
        if self.store.path is not None and not self.store.path.exists():
            try:
                self.store.save()  # the file exists from the start, holding the parameters in force
            except OSError as err:  # run anyway: every change then answers 507 saying so
                log.error("the parameter file %s cannot be written: %s", self.store.path, err.strerror or err)
        self.runner.start()

    def stop(self) -> None:
        """Stop the pipeline thread and save the parameters in force (a failure is logged and kept)."""
        self.runner.stop(timeout_s=STOP_WAIT_S)
        try:
            self.store.save()
        except OSError as err:
            self.save_error = f"{self.store.path}: {err.strerror or err}"
            log.error("the parameters in force could not be saved: %s", self.save_error)

    def sensors(self) -> list[dict]:
        now = self.runner.clock()
        stats = self.runner.sensors.snapshot(now)
        out = []
        configured = {s.name: s for s in self.store.params.sensors}
        for name in dict.fromkeys([*configured, *stats]):
            entry = {
                "name": name,
                **stats.get(
                    name,
                    {
                        "status": "waiting",
                        "rate_hz": 0.0,
                        "last_stamp_s": None,
                        "last_seen_ago_s": None,
                        "drops": 0,
                        "last_fault": None,
                    },
                ),
            }
            sensor = configured.get(name)
            entry["configured"] = sensor is not None
            if sensor is not None:
                e = sensor.extrinsics
                entry["position"] = {"x_m": e.x_m, "y_m": e.y_m, "z_m": e.z_m, "yaw_deg": e.yaw_deg}
                entry["enabled"] = sensor.enabled
                entry["nominal_rate_hz"] = sensor.rate_hz
            out.append(entry)
        return out

    def _status(self, sensors: list[dict], fresh: bool) -> tuple[str, list[str]]:
        """The overall status and, unless it is ok, why."""
        runner = self.runner
        if runner.error:
            return "failed", [f"the pipeline thread stopped: {runner.error}"]
        if runner.finished:
            return "finished", [f"the source delivered all its {runner.source.n_frames} frames"]
        if runner.frames_processed == 0:
            skipped = sum(runner.frames_dropped.values())
            if skipped >= FAILED_AFTER_SKIPPED_FRAMES:
                last = (runner.last_frame_error or {}).get("error")
                return "failed", [f"no frame processed, {skipped} skipped; last error: {last}"]
            return "starting", ["waiting for the first frame"]
        if not fresh:
            return "stalled", ["no frame processed recently"]
        damaged = getattr(runner.source, "damaged", None) or {}
        faulty = [s for s in sensors if s["status"] != "ok"]
        reasons = [
            f"sensor {s['name']}: {s['status']}" + (f" ({damaged[s['name']]})" if s["name"] in damaged else "")
            for s in faulty
        ]
        if sensors and len(faulty) == len(sensors) and all(s["status"].startswith("fault") for s in faulty):
            return "failed", ["no sensor delivers", *reasons]
        frame_drops, ws_drops = runner.drop_rate(), self.hub.drop_rate()
        if frame_drops > DEGRADED_DROP_RATE:
            reasons.append(f"{frame_drops:.0%} of the last frames dropped (late or unreadable)")
        if ws_drops > DEGRADED_DROP_RATE:
            reasons.append(f"{ws_drops:.0%} of the recent WebSocket messages dropped for slow clients")
        return ("degraded", reasons) if reasons else ("ok", [])

    def health(self) -> dict:
        runner = self.runner
        now = runner.clock()
        sensors = self.sensors()
        age = None if runner.last_frame_s is None else now - runner.last_frame_s
        period_s = 1.0 / float(runner.source.rate_hz)
        fresh = age is not None and age <= max(1.0, 5 * period_s)
        status, reasons = self._status(sensors, fresh)
        return {
            "status": status,
            "reasons": reasons,
            "live": runner.error is None and (runner.alive or not runner.started_s),
            "ready": status in ("ok", "degraded"),
            "error": runner.error,
            "source": {
                **self.source_info,
                **({"counters": runner.source.counters} if hasattr(runner.source, "counters") else {}),
            },
            "method": runner.method,
            "uptime_s": None if runner.started_s is None else round(now - runner.started_s, 3),
            "last_frame_age_s": None if age is None else round(age, 3),
            **runner.status(),
            "websocket_clients": self.hub.client_count,
            "websocket": self.hub.stats(),
            "sensors": {s["name"]: {k: v for k, v in s.items() if k != "name"} for s in sensors},
        }


def build_service(
    source,
    params: Params,
    params_file: str | Path | None = None,
    auth: AuthConfig | None = None,
    pipeline_factory: Callable[[Params, str], object] = real_pipeline,
    realtime: bool = True,
    points_cap: int = DEFAULT_POINTS_CAP,
    clock: Callable[[], float] = time.monotonic,
    method: str = DEFAULT_METHOD,
) -> Service:
    metrics = ServiceMetrics()
    hub = Hub(on_drop=metrics.ws_dropped.inc, on_count=metrics.ws_clients.set)
    pipeline = pipeline_factory(params, method)
    # The method may set parameters of its own (docs/pipeline.md): version 0 is what the pipeline
    # really runs with, so /params shows it and every later version is exact.
    params = getattr(pipeline, "params", None) or params
    expected = [s.name for s in params.sensors]
    runner = PipelineRunner(
        source, pipeline, hub, metrics, expected, realtime=realtime, points_cap=points_cap, clock=clock
    )
    store = ParamStore(params, params_file, on_change=runner.submit)
    describe = getattr(source, "describe", None)
    info = describe() if callable(describe) else {"source": repr(source), "rate_hz": source.rate_hz}
    return Service(store=store, runner=runner, hub=hub, metrics=metrics, auth=auth or AuthConfig(), source_info=info)
