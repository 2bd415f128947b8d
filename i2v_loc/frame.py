"""Data passed from a source into the pipeline: one sweep per sensor, grouped into frames."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np


@dataclass
class SensorScan:
    """One sweep of one sensor.

    ``points`` are in the sensor's own frame; ``time_offset_s`` is each point's capture time
    relative to ``stamp_s`` (the sweep start on the sensor's clock). ``from_sensor`` False: the
    points were gathered elsewhere (a cloud file already in the yard frame): no ray is known to run
    from the sensor's position to them. ``unreturned``: the unit directions (sensor frame) of the
    sweep's rays that returned nothing (an Ouster's zero ranges; None: not known, as in a cloud), or
    what gives them when first asked (``unreturned_directions``): only a vehicle's start asks, and
    picking them out of a recording's four sweeps cost 1.3 ms a frame.
    """

    sensor: str
    stamp_s: float
    points: np.ndarray  # (N, 3) float32
    time_offset_s: np.ndarray  # (N,) float32
    from_sensor: bool = True
    unreturned: np.ndarray | Callable[[], np.ndarray] | None = None  # (M, 3) float32

    def __post_init__(self) -> None:
        self.points = np.asarray(self.points, dtype=np.float32).reshape(-1, 3)
        if self.unreturned is not None and not callable(self.unreturned):
            self.unreturned = _directions(self.unreturned)
        if self.time_offset_s is None:
            self.time_offset_s = np.zeros(len(self.points), dtype=np.float32)
        self.time_offset_s = np.asarray(self.time_offset_s, dtype=np.float32).reshape(-1)
        if len(self.time_offset_s) != len(self.points):
            raise ValueError(
                f"sensor {self.sensor}: {len(self.points)} points but {len(self.time_offset_s)} time offsets"
            )

    def unreturned_directions(self) -> np.ndarray | None:
        """The directions of the rays that returned nothing (None: not known), picked out now if
        they were deferred."""
        if callable(self.unreturned):
            self.unreturned = _directions(self.unreturned())
        return self.unreturned


def _directions(values) -> np.ndarray:
    return np.asarray(values, dtype=np.float32).reshape(-1, 3)


@dataclass
class Frame:
    """The sweeps of all sensors that belong to one output time step."""

    index: int
    scans: dict[str, SensorScan] = field(default_factory=dict)
