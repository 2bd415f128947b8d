"""Classification stage: the trailer by a second clustering with its own gate, truck = rest (3.4).

Also home of ``articulated_points``, the constructed truck + trailer used by the pipeline tests.
"""

import numpy as np
import pytest

from i2v_loc.params import ClassificationParams, Params, VehicleConfig
from i2v_loc.stages.classification import TruckTrailerClassifier


def box_surface(length, width, height, spacing=0.1):
    """Points on the four walls and the roof of a box centred at the origin (local frame, z from 0)."""
    u = np.arange(-length / 2, length / 2 + 1e-9, spacing)
    v = np.arange(-width / 2, width / 2 + 1e-9, spacing)
    z = np.arange(0, height + 1e-9, spacing * 2)
    walls = [np.array(np.meshgrid(u, [s * width / 2], z, indexing="ij")).reshape(3, -1).T for s in (-1, 1)]
    ends = [np.array(np.meshgrid([s * length / 2], v, z, indexing="ij")).reshape(3, -1).T for s in (-1, 1)]
    roof = np.array(np.meshgrid(u, v, [height], indexing="ij")).reshape(3, -1).T
    return np.vstack(walls + ends + [roof])


def place(points, x, y, yaw_deg, z0):
    yaw = np.radians(yaw_deg)
    rot = np.array([[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]])
    return np.column_stack([points[:, :2] @ rot.T + [x, y], points[:, 2] + z0])


def articulated_poses(v: VehicleConfig, rear_axle_xy, truck_yaw_deg, hitch_deg):
    """Box centres (x, y) and yaws of truck and trailer from the kinematic figures of params.py."""
    t, tr = v.truck, v.trailer
    fwd = np.array([np.cos(np.radians(truck_yaw_deg)), np.sin(np.radians(truck_yaw_deg))])
    axle = np.asarray(rear_axle_xy, dtype=float)
    truck_center = axle + fwd * (t.wheelbase_m + t.front_overhang_m - t.length_m / 2)
    kingpin = axle - fwd * t.hitch_behind_rear_axle_m
    trailer_yaw = truck_yaw_deg + hitch_deg
    tfwd = np.array([np.cos(np.radians(trailer_yaw)), np.sin(np.radians(trailer_yaw))])
    trailer_center = kingpin + tfwd * (tr.hitch_to_front_m - tr.length_m / 2)
    return (truck_center, truck_yaw_deg), (trailer_center, trailer_yaw)


def articulated_points(v: VehicleConfig, rear_axle_xy=(0.0, 0.0), truck_yaw_deg=0.0, hitch_deg=0.0, spacing=0.1):
    (tc, ty), (rc, ry) = articulated_poses(v, rear_axle_xy, truck_yaw_deg, hitch_deg)
    truck = place(box_surface(v.truck.length_m, v.truck.width_m, v.truck.height_m, spacing), *tc, ty, v.truck.floor_m)
    # chassis rails from the cab's rear face back to the hitch, low (below the trailer floor)
    fwd = np.array([np.cos(np.radians(ty)), np.sin(np.radians(ty))])
    cab_rear = tc - fwd * v.truck.length_m / 2
    hitch = np.asarray(rear_axle_xy) - fwd * v.truck.hitch_behind_rear_axle_m
    rail_len = float(np.hypot(*(cab_rear - hitch)))
    rails = place(
        box_surface(rail_len, 0.9, 0.2, spacing), *((cab_rear + hitch) / 2), ty, 0.1 if v.trailer.floor_m < 0.6 else 0.7
    )
    rails = rails[rails[:, 2] < v.trailer.floor_m]
    trailer = place(
        box_surface(v.trailer.length_m, v.trailer.width_m, v.trailer.height_m, spacing), *rc, ry, v.trailer.floor_m
    )
    return np.vstack([truck, rails]), trailer


def min_dist(a, b):
    from scipy.spatial import cKDTree

    return cKDTree(b).query(a)[0]


@pytest.mark.parametrize(
    "name, hitch_deg", [("man_tgx", 0.0), ("man_tgx", 10.0), ("volvo_fh", 0.0), ("volvo_fh", -30.0), ("twizy", 25.0)]
)
def test_trailer_and_truck_are_separated(name, hitch_deg):
    params = Params()
    truck, trailer = articulated_points(params.vehicles[name], (3.0, 4.0), 40.0, hitch_deg)
    cluster = np.vstack([truck, trailer])
    result = TruckTrailerClassifier(params.classification, params.vehicles).process(cluster, [name])
    assert result.vehicle == name
    # the trailer is the trailer body plus what lies under it (the hitch end of the rails)
    assert len(trailer) <= len(result.trailer) <= len(trailer) + 0.1 * len(truck)
    assert min_dist(result.trailer[:, :2], trailer[:, :2]).max() < 0.35  # inside the footprint
    cab = truck[truck[:, 2] > params.vehicles[name].trailer.floor_m]  # the cab, not the rails under the trailer
    assert min_dist(cab, result.truck).max() == 0.0  # every cab point is in the truck


def test_no_trailer_in_gate_means_no_vehicle():
    params = Params()
    v = params.vehicles["volvo_fh"]
    lone_trailer_sized_box = box_surface(2.0, 2.0, 2.0)  # 8 m3, far below the trailer gate
    result = TruckTrailerClassifier(params.classification, params.vehicles).process(
        lone_trailer_sized_box, ["volvo_fh"]
    )
    assert result.vehicle is None and result.truck is None and result.trailer is None
    just_a_trailer = box_surface(v.trailer.length_m, v.trailer.width_m, v.trailer.height_m) + [0, 0, v.trailer.floor_m]
    assert (
        TruckTrailerClassifier(params.classification, params.vehicles).process(just_a_trailer, ["volvo_fh"]).vehicle
        is None
    )
    assert v.trailer.volume_m3 - v.trailer_volume_tolerance_m3 > 8


def test_a_trailer_candidate_longer_than_the_trailer_is_rejected():
    params = Params()
    stage = TruckTrailerClassifier(ClassificationParams(max_length_excess_m=1.0), params.vehicles)
    long_thin = box_surface(9.0, 2.5, 2.5)  # volume fits the Volvo trailer gate, length 9 > 6.3 + 1
    assert stage.process(long_thin, ["volvo_fh"]).vehicle is None
