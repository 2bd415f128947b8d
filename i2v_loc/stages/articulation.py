"""Articulated-vehicle geometry from the kinematic figures of ``VehicleConfig`` (no stage state).

Unit boxes are centred on the units (docs/formats.md). The hitch (fifth wheel / kingpin, or the
drawbar coupling) joins them: the truck's box centre lies ``truck_ahead_m`` ahead of it along the
truck's heading, the trailer's ``hitch_ahead_m`` behind it along the trailer's.
"""

from __future__ import annotations

import numpy as np

from i2v_loc.params import VehicleConfig
from i2v_loc.stages.primitives import min_area_rect


def centre_to_hitch_m(vehicle: VehicleConfig) -> tuple[float, float]:
    """(truck box centre ahead of the hitch, hitch ahead of the trailer box centre) in metres."""
    t, r = vehicle.truck, vehicle.trailer
    truck = t.wheelbase_m + t.front_overhang_m - t.length_m / 2 + t.hitch_behind_rear_axle_m
    return truck, r.length_m / 2 - r.hitch_to_front_m


def footprint_corners(vehicle: VehicleConfig, hitch_deg: float) -> np.ndarray:
    """(8, 2) corners of the truck's and the trailer's boxes, hitch at the origin, truck heading +x."""
    truck_ahead, hitch_ahead = centre_to_hitch_m(vehicle)
    h = np.radians(hitch_deg)
    corners = []
    for center, yaw, dims in (
        ((truck_ahead, 0.0), 0.0, vehicle.truck),
        ((-hitch_ahead * np.cos(h), -hitch_ahead * np.sin(h)), h, vehicle.trailer),
    ):
        c, s = np.cos(yaw), np.sin(yaw)
        local = np.array([[1, 1], [1, -1], [-1, -1], [-1, 1]]) * [dims.length_m / 2, dims.width_m / 2]
        corners.append(local @ np.array([[c, s], [-s, c]]) + center)
    return np.vstack(corners)


def max_box_volume_m3(vehicle: VehicleConfig, hitch_range_deg: float, step_deg: float = 5.0) -> float:
    """Largest oriented-box volume (minimum-area rectangle x height) of the whole vehicle at a hitch
    angle up to ``hitch_range_deg``: the box grows with the hitch angle (the clustering's Eq. 5 gate
    must admit it)."""
    top_m = max(u.floor_m + u.height_m for u in (vehicle.truck, vehicle.trailer))
    angles = np.arange(0.0, hitch_range_deg + 1e-9, step_deg)
    return float(max(min_area_rect(footprint_corners(vehicle, a)).area_m2 for a in angles) * top_m)
