"""Prometheus metrics of one service instance (its own registry, so instances never clash)."""

from __future__ import annotations

from prometheus_client import CollectorRegistry, Counter, Gauge, Histogram, disable_created_metrics, generate_latest

# No *_created series: they double the output and no dashboard of ours reads them. The switch is
# process-wide in prometheus_client (there is no per-registry one); the service owns its process.
disable_created_metrics()

LATENCY_BUCKETS_S = (0.0005, 0.001, 0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0)


class ServiceMetrics:
    def __init__(self) -> None:
        self.registry = CollectorRegistry(auto_describe=True)
        r = self.registry
        self.frames_processed = Counter("i2v_loc_frames_processed", "Frames run through the pipeline", registry=r)
        self.frames_dropped = Counter(
            "i2v_loc_frames_dropped",
            "Frames not processed, by reason (source_error, pipeline_error, late)",
            ["reason"],
            registry=r,
        )
        self.pipeline_events = Counter(
            "i2v_loc_pipeline_events",
            "The pipeline's own counters: dropped sweeps and refused clusters, by reason",
            ["reason"],
            registry=r,
        )
        self.stage_latency = Histogram(
            "i2v_loc_stage_latency_seconds",
            "Pipeline stage latency",
            ["stage"],
            buckets=LATENCY_BUCKETS_S,
            registry=r,
        )
        self.sensor_rate = Gauge(
            "i2v_loc_sensor_rate_hz", "Sweeps received per second, per sensor", ["sensor"], registry=r
        )
        self.sensor_drops = Counter(
            "i2v_loc_sensor_drops",
            "Frames in which a sensor was missing or faulty",
            ["sensor"],
            registry=r,
        )
        self.sensor_last_stamp = Gauge(
            "i2v_loc_sensor_last_stamp_seconds", "Stamp of the last sweep", ["sensor"], registry=r
        )
        self.vehicles = Gauge("i2v_loc_vehicles", "Vehicles in the latest frame", registry=r)
        self.ws_clients = Gauge("i2v_loc_websocket_clients", "Connected WebSocket clients", registry=r)
        self.ws_dropped = Counter(
            "i2v_loc_websocket_messages_dropped",
            "Messages replaced by a newer one before a slow client took them",
            registry=r,
        )
        self.params_version = Gauge("i2v_loc_params_version", "Version of the parameters in force", registry=r)
        for reason in ("source_error", "pipeline_error", "late"):
            self.frames_dropped.labels(reason)

    def render(self) -> bytes:
        return generate_latest(self.registry)
