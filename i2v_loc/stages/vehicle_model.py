"""The geometry of one tracked vehicle as the articulated estimator sees it (docs/pipeline.md,
Articulated estimator).

A tractor box in the tractor's frame (origin: rear-axle centre on the ground, x forward) and, for
an articulated vehicle, a trailer box in the trailer's frame (origin: the kingpin or drawbar eye,
x forward), the kingpin ``kingpin_behind_axle_m`` (M) behind the tractor's rear axle. Hitch angle
γ = ψ2 − ψ1 (trailer yaw minus tractor yaw). A rigid vehicle (bus, rigid truck, van) is the
tractor box alone with its origin at the box centre.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from i2v_loc.params import VehicleConfig

MAX_VEHICLE_HEIGHT_M = 4.6  # 4.0 m in the EU, 4.3 m in the US, plus the roof's clutter and noise
RIGID_MAX_LENGTH_M = 15.0  # the longest rigid vehicles: three-axle coaches (EU 15 m; rigid trucks 12 m)


@dataclass(frozen=True)
class Box:
    """An upright box in its unit's frame: x from ``front_m - length_m`` to ``front_m``, centred in y."""

    front_m: float
    length_m: float
    width_m: float
    floor_m: float
    height_m: float

    @property
    def rear_m(self) -> float:
        return self.front_m - self.length_m

    @property
    def top_m(self) -> float:
        return self.floor_m + self.height_m

    @property
    def center_x_m(self) -> float:
        return self.front_m - self.length_m / 2

    @property
    def dims(self) -> tuple[float, float, float]:
        return (self.length_m, self.width_m, self.height_m)


@dataclass(frozen=True)
class VehicleModel:
    name: str  # nearest catalogue vehicle, or "unknown"
    tractor: Box
    trailer: Box | None = None  # None: a rigid vehicle
    kingpin_behind_axle_m: float = 0.0  # M
    trailer_axle_m: float = 1.0  # L2: kingpin to the trailer's effective axle

    @property
    def articulated(self) -> bool:
        return self.trailer is not None

    @property
    def boxes(self) -> list[Box]:
        """The units' boxes: the tractor's, then the trailer's if any."""
        return [self.tractor] + ([self.trailer] if self.trailer is not None else [])

    @classmethod
    def from_config(cls, name: str, v: VehicleConfig) -> VehicleModel:
        t, r = v.truck, v.trailer
        tractor = Box(t.wheelbase_m + t.front_overhang_m, t.length_m, t.width_m, t.floor_m, t.height_m)
        trailer = Box(r.hitch_to_front_m, r.length_m, r.width_m, r.floor_m, r.height_m)
        return cls(name, tractor, trailer, t.hitch_behind_rear_axle_m, r.hitch_to_axle_m)

    @classmethod
    def rigid(cls, name: str, length_m: float, width_m: float, height_m: float, floor_m: float = 0.0) -> VehicleModel:
        return cls(name, Box(length_m / 2, length_m, width_m, floor_m, height_m))

    def with_boxes(self, tractor: Box, trailer: Box | None) -> VehicleModel:
        return replace(self, tractor=tractor, trailer=trailer)

    def kingpin_xy(self, x_m: float, y_m: float, yaw_rad: float) -> np.ndarray:
        return np.array(self._kingpin(x_m, y_m, np.cos(yaw_rad), np.sin(yaw_rad)))

    def _kingpin(self, x_m: float, y_m: float, cos_yaw: float, sin_yaw: float) -> tuple[float, float]:
        return x_m - self.kingpin_behind_axle_m * cos_yaw, y_m - self.kingpin_behind_axle_m * sin_yaw

    def box_centers(
        self, x_m: float, y_m: float, yaw_rad: float, hitch_rad: float = 0.0
    ) -> tuple[np.ndarray, np.ndarray | None]:
        """xy centres of the tractor's and (or None) the trailer's boxes for a tractor pose and hitch.
        (In scalars: the same values as in small arrays, at a fifth of the cost; it runs several
        times per vehicle and frame.)"""
        c, s = np.cos(yaw_rad), np.sin(yaw_rad)
        reach = self.tractor.center_x_m
        tractor = np.array([x_m + reach * c, y_m + reach * s])
        if self.trailer is None:
            return tractor, None
        yaw2 = yaw_rad + hitch_rad
        kx, ky = self._kingpin(x_m, y_m, c, s)
        reach = self.trailer.center_x_m
        return tractor, np.array([kx + reach * np.cos(yaw2), ky + reach * np.sin(yaw2)])
