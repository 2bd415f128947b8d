"""The service object: source, pipeline runner, parameters, auth, metrics and WebSocket hub."""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from i2v_loc.params import Params
from service.auth import AuthConfig
from service.hub import Hub
from service.metrics import ServiceMetrics
from service.params_store import ParamStore
from service.runner import PipelineRunner

log = logging.getLogger("i2v_loc.service")

DEFAULT_POINTS_CAP = 2000
DEFAULT_METHOD = "default"


def real_pipeline(params: Params, method: str = DEFAULT_METHOD):
    from i2v_loc.pipeline import Pipeline  # heavy imports only when the service starts

    return Pipeline(params, method=method)


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
        self.runner.stop()
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
            entry = {"name": name, **stats.get(name, {"status": "waiting", "rate_hz": 0.0, "last_stamp_s": None,
                                                      "last_seen_ago_s": None, "drops": 0, "last_fault": None})}
            sensor = configured.get(name)
            entry["configured"] = sensor is not None
            if sensor is not None:
                e = sensor.extrinsics
                entry["position"] = {"x_m": e.x_m, "y_m": e.y_m, "z_m": e.z_m, "yaw_deg": e.yaw_deg}
                entry["nominal_rate_hz"] = sensor.rate_hz
            out.append(entry)
        return out

    def health(self) -> dict:
        runner = self.runner
        now = runner.clock()
        sensors = self.sensors()
        age = None if runner.last_frame_s is None else now - runner.last_frame_s
        period_s = 1.0 / float(runner.source.rate_hz)
        fresh = age is not None and age <= max(1.0, 5 * period_s)
        if runner.error:
            status = "failed"
        elif runner.finished:
            status = "finished"
        elif runner.frames_processed == 0:
            status = "starting"
        elif not fresh:
            status = "stalled"
        elif any(s["status"] != "ok" for s in sensors):
            status = "degraded"
        else:
            status = "ok"
        return {
            "status": status,
            "live": runner.error is None and (runner.alive or not runner.started_s),
            "ready": status in ("ok", "degraded"),
            "error": runner.error,
            "source": {**self.source_info, **({"counters": runner.source.counters} if hasattr(runner.source, "counters") else {})},
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
    runner = PipelineRunner(source, pipeline, hub, metrics, expected, realtime=realtime,
                            points_cap=points_cap, clock=clock)
    store = ParamStore(params, params_file, on_change=runner.submit)
    describe = getattr(source, "describe", None)
    info = describe() if callable(describe) else {"source": repr(source), "rate_hz": source.rate_hz}
    return Service(store=store, runner=runner, hub=hub, metrics=metrics, auth=auth or AuthConfig(), source_info=info)
