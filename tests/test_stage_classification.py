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


def test_far_trailer_wall_apart_from_the_seen_part_joins_the_trailer_with_complete_width():
    """The roof seen only near one wall: the far wall is 1.2 m from the rest, joined to the cab
    (40 deg hitch angle). Without complete_width part of it is left to the truck; with it, the
    trailer is whole and the truck is the cab."""
    params = Params()
    v = params.vehicles["man_tgx"]
    (tc, ty), (rc, ry) = articulated_poses(v, (0.0, 0.0), 0.0, 40.0)
    truck, _ = articulated_points(v, (0.0, 0.0), 0.0, 40.0)
    length, width, height = v.trailer.length_m, v.trailer.width_m, v.trailer.height_m
    u, z = np.arange(-length / 2, length / 2, 0.1), np.arange(0.0, height, 0.2)
    near_wall = np.array(np.meshgrid(u, [width / 2], z, indexing="ij")).reshape(3, -1).T
    roof_strip = (
        np.array(np.meshgrid(u, np.arange(width / 2 - 1.6, width / 2, 0.1), [height], indexing="ij")).reshape(3, -1).T
    )
    far_wall = np.array(np.meshgrid(u, [-width / 2], z, indexing="ij")).reshape(3, -1).T  # on the cab's side
    seen = place(np.vstack([near_wall, roof_strip]), *rc, ry, v.trailer.floor_m)
    far = place(far_wall, *rc, ry, v.trailer.floor_m)
    cluster = np.vstack([truck, seen, far])
    cab = truck[truck[:, 2] > v.trailer.floor_m]
    plain = TruckTrailerClassifier(params.classification, params.vehicles).process(cluster, ["man_tgx"])
    assert plain.vehicle == "man_tgx" and min_dist(far, plain.truck).min() == 0.0  # part of the far wall is "truck"
    complete = TruckTrailerClassifier(
        params.classification.model_copy(update={"complete_width": True}), params.vehicles
    ).process(cluster, ["man_tgx"])
    assert complete.vehicle == "man_tgx"
    assert min_dist(far, complete.trailer).max() == 0.0  # the whole far wall is trailer
    # the cab, but for its corner inside the widened footprint, is the truck
    assert (min_dist(cab, complete.truck) == 0).mean() > 0.9
    assert np.hypot(*(complete.truck[:, :2].mean(axis=0) - tc)) < 1.0
    assert np.hypot(*(plain.truck[:, :2].mean(axis=0) - tc)) > 2.0


def test_a_car_is_no_twizy_when_the_trailer_must_reach_its_height():
    """A 3.3 x 1.7 x 1.5 m car (or the 3.3 m of a car seen past an occlusion): its body above the
    Twizy trailer's floor (6 m3, 3.3 m long) fits the Twizy trailer's gates (10.9 +- 7 m3, at most
    3.5 m long) and its bumpers stick out of that footprint (a "truck").
    Its top (1.5 m) is far below the trailer's (0.35 + 2.5 m): min_height_fraction 0.6 rejects it,
    while a real Twizy (trailer top 2.85 m) is still found."""
    params = Params()
    body = box_surface(3.3, 1.7, 1.3) + [0.0, 0.0, 0.2]
    bumpers = np.array([[s * 1.85, y, z] for s in (-1, 1) for y in np.arange(-0.8, 0.81, 0.1) for z in (0.3, 0.4)])
    car = place(np.vstack([body, bumpers]), 5.0, 2.0, 30.0, 0.0)
    plain = TruckTrailerClassifier(params.classification, params.vehicles)
    assert plain.process(car, ["twizy"]).vehicle == "twizy"  # what happened on the docking loop
    strict = TruckTrailerClassifier(
        params.classification.model_copy(update={"min_height_fraction": 0.6}), params.vehicles
    )
    assert strict.process(car, ["twizy"]).vehicle is None
    truck, trailer = articulated_points(params.vehicles["twizy"], (3.0, 4.0), 40.0, 20.0)
    assert strict.process(np.vstack([truck, trailer]), ["twizy"]).vehicle == "twizy"
    # the ground height counts: the same car on a ground 1.5 m lower still is no trailer
    assert strict.process(car - [0, 0, 1.5], ["twizy"], ground_z_m=-1.5).vehicle is None


def test_known_heading_puts_the_truck_at_the_trailer_front_not_at_the_busier_end():
    """A docked MAN with dock bumpers and a person behind the trailer (more points than the cab's
    visible part): the majority rule takes them for the truck; the trailer's known heading does not."""
    params = Params()
    v = params.vehicles["man_tgx"]
    truck, trailer = articulated_points(v, (0.0, 0.0), 0.0, 0.0)
    cab = truck[truck[:, 0] > 2.0][::4]  # the cab's front half, thinned (seen from afar)
    (_, _), (rc, _) = articulated_poses(v, (0.0, 0.0), 0.0, 0.0)
    rear_x = rc[0] - v.trailer.length_m / 2
    clutter = place(box_surface(0.4, 2.6, 0.8, 0.05), rear_x - 0.35, 0.0, 0.0, 0.3)  # bumpers, below the floor
    cluster = np.vstack([cab, trailer, clutter])
    assert len(clutter) > len(cab)
    stage = TruckTrailerClassifier(params.classification.model_copy(update={"truck_one_end": True}), params.vehicles)
    busier = stage.process(cluster, ["man_tgx"])
    assert busier.truck[:, 0].mean() < rear_x  # the clutter
    known = stage.process(cluster, ["man_tgx"], heading_rad=0.0)
    assert min_dist(cab, known.truck).max() == 0.0 and known.truck[:, 0].min() > rear_x + 1.0
