"""JSON Schema of the state line (docs/formats.md): ``i2v-loc run`` JSONL and the WebSocket
``state`` messages (which add ``params_version`` and, for the dashboard, ``foreground``).
Published by ``i2v-loc params schema --state``, next to the parameter schema."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

Vector3 = list[float]
FAULTS = Literal["missing", "empty", "nan_points", "out_of_sync", "unknown_sensor", "disabled"]


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid")


class UnitState(_Strict):
    track_id: int
    center: Vector3 = Field(min_length=3, max_length=3, description="Box centre in the yard frame, m")
    yaw_deg: float | None = Field(description="Counter-clockwise from +x, (-180, 180]")
    dimensions: Vector3 = Field(min_length=3, max_length=3, description="Length, width, height, m")
    points: int = Field(ge=0)
    # the default (articulated) method adds this; the paper's method does not
    dimensions_seen: list[bool] | None = Field(
        None,
        min_length=3,
        max_length=3,
        description="Whether length, width, height were measured from the points (else the catalogue's or a stand-in)",
    )


class VehicleState(_Strict):
    id: int
    vehicle: str
    hitch_deg: float | None = Field(description="Trailer yaw minus truck yaw; null unless both units have a yaw")
    truck: UnitState | None
    trailer: UnitState | None
    tractor_to_trailer: list[list[float]] | None = Field(description="4x4 row-major: truck frame -> trailer frame")
    # the default (articulated) method adds these four; the paper's method does not
    kind: Literal["articulated", "rigid"] | None = Field(None, description="Two hinged units, or one rigid unit")
    hitch_std_deg: float | None = Field(None, ge=0.0, description="Standard deviation of hitch_deg (filter)")
    jackknife: bool | None = Field(None, description="|hitch| or its rate above the configured limits")
    speed_m_s: float | None = Field(None, description="Signed speed of the tractor; negative when reversing")


class ClusterState(_Strict):
    points: int = Field(ge=0)
    center: Vector3 = Field(min_length=3, max_length=3)
    volume_m3: float
    status: str = Field(pattern=r"^(vehicle:.+|too_large|too_small|unmatched)$")


class Foreground(_Strict):
    xy: list[float] = Field(description="Flat x0, y0, x1, y1, ... of foreground points (WebSocket only)")


class StateLine(_Strict):
    type: Literal["state"]
    frame: int = Field(ge=0)
    stamp_s: float | None = Field(description="Common-clock time of the frame; null when no sweep was usable")
    latency_ms: dict[str, float]
    faults: dict[str, FAULTS]
    dropped: dict[str, int]
    clusters: list[ClusterState]
    vehicles: list[VehicleState]
    params_version: int | None = Field(None, description="Parameter version the frame ran with (service only)")
    foreground: Foreground | None = Field(None, description="Dashboard points (WebSocket only)")
    frame_in_unix_s: float | None = Field(
        None, description="Wall-clock time (Unix s) the service took the frame from its source (service only)"
    )
    sent_unix_s: float | None = Field(
        None, description="Wall-clock time (Unix s) this message was sent (WebSocket only)"
    )


def state_json_schema() -> dict:
    schema = StateLine.model_json_schema()
    schema["$schema"] = "https://json-schema.org/draft/2020-12/schema"
    schema["title"] = "i2v-loc state line"
    return schema
