"""dCAP's calibration pair on our vehicles: the tractor's front sensor and the trailer's rear sensor.

dCAP (Mind the Hitch, Eq. 1) evaluates T_F->B = inv(T_B) @ T_F, the transform from the tractor's
front camera to the trailer's rear camera. We place those two virtual sensors on the unit boxes of
``Params().vehicles``: F at the centre of the truck box's front face, at the top of the cab;
B at the centre of the trailer box's rear face, at its top. Both the truth and the estimate use
the same mounts, so the error reflects only the estimated unit poses (x, y, z, yaw).
"""

from __future__ import annotations

import numpy as np

from i2v_loc.params import VehicleConfig


def _translation(x: float, y: float, z: float) -> np.ndarray:
    t = np.eye(4)
    t[:3, 3] = (x, y, z)
    return t


def truck_front_mount(vehicle: VehicleConfig) -> np.ndarray:
    """Front sensor in the truck's box frame: front face centre, top of the cab."""
    return _translation(vehicle.truck.length_m / 2.0, 0.0, vehicle.truck.height_m / 2.0)


def trailer_rear_mount(vehicle: VehicleConfig) -> np.ndarray:
    """Rear sensor in the trailer's box frame: rear face centre, top of the box."""
    return _translation(-vehicle.trailer.length_m / 2.0, 0.0, vehicle.trailer.height_m / 2.0)


def front_to_rear(truck_poses: np.ndarray, trailer_poses: np.ndarray, vehicle: VehicleConfig) -> np.ndarray:
    """T_F->B (N, 4, 4) for stacked yard poses of the truck and trailer boxes."""
    t_yard_front = np.asarray(truck_poses) @ truck_front_mount(vehicle)
    t_yard_rear = np.asarray(trailer_poses) @ trailer_rear_mount(vehicle)
    return np.linalg.inv(t_yard_rear) @ t_yard_front


def straight_trailer_in_truck_frame(vehicle: VehicleConfig) -> np.ndarray:
    """Pose of the trailer box in the truck box frame at hitch angle 0, from the geometry.

    Along the vehicle axis from the truck's rear axle: the truck box centre is at
    wheelbase + front overhang - length/2; the hitch at -hitch_behind_rear_axle; the trailer
    front face hitch_to_front ahead of the hitch, its box centre half a trailer length behind that.
    """
    truck, trailer = vehicle.truck, vehicle.trailer
    truck_centre_x = truck.wheelbase_m + truck.front_overhang_m - truck.length_m / 2.0
    trailer_centre_x = -truck.hitch_behind_rear_axle_m + trailer.hitch_to_front_m - trailer.length_m / 2.0
    dz = (trailer.floor_m + trailer.height_m / 2.0) - (truck.floor_m + truck.height_m / 2.0)
    return _translation(trailer_centre_x - truck_centre_x, 0.0, dz)


def static_front_to_rear(vehicle: VehicleConfig) -> np.ndarray:
    """dCAP's "static calibration" baseline: T_F->B with the trailer rigidly straight behind."""
    truck = np.eye(4)[None]
    trailer = straight_trailer_in_truck_frame(vehicle)[None]
    return front_to_rear(truck, trailer, vehicle)[0]
