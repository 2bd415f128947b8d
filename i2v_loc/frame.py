"""Data passed from a source into the pipeline: one sweep per sensor, grouped into frames."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class SensorScan:
    """One sweep of one sensor.

    ``points`` are in the sensor's own frame; ``time_offset_s`` is each point's capture time
    relative to ``stamp_s`` (the sweep start on the sensor's clock). ``from_sensor`` False: the
    points were gathered elsewhere (a cloud file already in the yard frame): no ray is known to run
    from the sensor's position to them. ``unreturned``: the unit directions (sensor frame) of the
    sweep's rays that returned nothing (an Ouster's zero ranges; None: not known, as in a cloud).
    """

    sensor: str
    stamp_s: float
    points: np.ndarray  # (N, 3) float32
    time_offset_s: np.ndarray  # (N,) float32
    from_sensor: bool = True
    unreturned: np.ndarray | None = None  # (M, 3) float32

    def __post_init__(self) -> None:
        self.points = np.asarray(self.points, dtype=np.float32).reshape(-1, 3)
        if self.unreturned is not None:
            self.unreturned = np.asarray(self.unreturned, dtype=np.float32).reshape(-1, 3)
        if self.time_offset_s is None:
            self.time_offset_s = np.zeros(len(self.points), dtype=np.float32)
        self.time_offset_s = np.asarray(self.time_offset_s, dtype=np.float32).reshape(-1)
        if len(self.time_offset_s) != len(self.points):
            raise ValueError(
                f"sensor {self.sensor}: {len(self.points)} points but {len(self.time_offset_s)} time offsets"
            )


@dataclass
class Frame:
    """The sweeps of all sensors that belong to one output time step."""

    index: int
    scans: dict[str, SensorScan] = field(default_factory=dict)
