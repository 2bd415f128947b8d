"""Response models of the REST API: they document the answers in the OpenAPI document.

The state line and the vehicles follow docs/formats.md; fields added there later pass through
(``extra="allow"``), so a response never loses data to its model.
"""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, ConfigDict


class Open(BaseModel):
    model_config = ConfigDict(extra="allow")


class Unit(Open):
    track_id: int
    center: list[float]
    yaw_deg: float | None
    dimensions: list[float]
    points: int


class Vehicle(Open):
    id: int
    vehicle: str
    hitch_deg: float | None
    truck: Unit | None
    trailer: Unit | None
    tractor_to_trailer: list[list[float]] | None


class State(Open):
    type: Literal["state"]
    frame: int
    stamp_s: float | None
    latency_ms: dict[str, float]
    faults: dict[str, str]
    dropped: dict[str, int]
    clusters: list[dict[str, Any]]
    vehicles: list[Vehicle]
    params_version: int


class Vehicles(BaseModel):
    frame: int | None
    stamp_s: float | None
    vehicles: list[Vehicle]


class SensorStatus(Open):
    name: str
    status: str
    rate_hz: float
    last_stamp_s: float | None
    last_seen_ago_s: float | None
    drops: int
    last_fault: str | None
    configured: bool
    enabled: bool | None = None  # configured: fused into the frames (a refused calibration writes false)
    position: dict[str, float] | None = None
    nominal_rate_hz: float | None = None


class Sensors(BaseModel):
    sensors: list[SensorStatus]


class Health(Open):
    status: Literal["ok", "degraded", "starting", "stalled", "failed", "finished"]
    reasons: list[str]
    live: bool
    ready: bool
    error: str | None
    source: dict[str, Any]
    method: str | None
    uptime_s: float | None
    last_frame_age_s: float | None
    frames_processed: int
    frames_dropped: dict[str, int]
    frame_drop_rate: float
    last_frame_error: dict[str, Any] | None
    frame_rate_hz: float
    params_version: int
    websocket_clients: int
    websocket: list[dict[str, Any]]
    sensors: dict[str, dict[str, Any]]


class ParamsInForce(BaseModel):
    version: int
    applied_version: int
    params: dict[str, Any]


class VersionSummary(BaseModel):
    version: int
    time_s: float
    source: str
    patch: dict[str, Any]


class History(BaseModel):
    current: int
    versions: list[VersionSummary]


class ChangeAccepted(BaseModel):
    version: int
    source: str
    patch: dict[str, Any]
    params: dict[str, Any]
