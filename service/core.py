"""The service object: source, pipeline runner, parameters, auth, metrics and WebSocket hub."""

from __future__ import annotations

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

DEFAULT_POINTS_CAP = 2000


def real_pipeline(params: Params):
    from i2v_loc.pipeline import Pipeline  # heavy imports only when the service starts

    return Pipeline(params)


@dataclass
class Service:
    store: ParamStore
    runner: PipelineRunner
    hub: Hub
    metrics: ServiceMetrics
    auth: AuthConfig
    source_info: dict

    def start(self) -> None:
        if self.store.path is not None and not self.store.path.exists():
            self.store.save()  # the file exists from the start, holding the parameters in force
        self.runner.start()

    def stop(self) -> None:
        """Stop the pipeline thread and save the parameters in force."""
        self.runner.stop()
        self.store.save()

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
            "source": self.source_info,
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
    pipeline_factory: Callable[[Params], object] = real_pipeline,
    realtime: bool = True,
    points_cap: int = DEFAULT_POINTS_CAP,
    clock: Callable[[], float] = time.monotonic,
) -> Service:
    metrics = ServiceMetrics()
    hub = Hub(on_drop=metrics.ws_dropped.inc, on_count=metrics.ws_clients.set)
    pipeline = pipeline_factory(params)
    expected = [s.name for s in params.sensors]
    runner = PipelineRunner(source, pipeline, hub, metrics, expected, realtime=realtime,
                            points_cap=points_cap, clock=clock)
    store = ParamStore(params, params_file, on_change=runner.submit)
    describe = getattr(source, "describe", None)
    info = describe() if callable(describe) else {"source": repr(source), "rate_hz": source.rate_hz}
    return Service(store=store, runner=runner, hub=hub, metrics=metrics, auth=auth or AuthConfig(), source_info=info)
