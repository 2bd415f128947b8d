"""``detect`` on one sweep of a car-mounted sensor (tests/car_mounted.py): a vehicle seen by one
face only (a bus's side, a trailer's rear, an oncoming tractor's front; no roof) is one rigid
vehicle behind that face; walls, trees and signs of the same size are none."""

from __future__ import annotations

import json

import car_mounted as cm
import numpy as np
import pytest

from i2v_loc.cli import main
from i2v_loc.params import Params
from i2v_loc.sim.meshes import box_center_in_axle_frame


def _detect(tmp_path, capsys, parts, top_deg: float | None = None, seed: int = 0) -> list[dict]:
    np.save(tmp_path / "sweep.npy", cm.sweep(parts, top_deg, seed))
    (tmp_path / "roof.yaml").write_text(cm.params_yaml())
    args = ["detect", str(tmp_path / "sweep.npy"), "--params", str(tmp_path / "roof.yaml"), "--sensor", "roof"]
    assert main(args) == 0
    return json.loads(capsys.readouterr().out)["vehicles"]


def _yaw_error_deg(yaw_deg: float, true_deg: float) -> float:
    """Modulo 180 deg: one face does not show which end is the front."""
    return abs((yaw_deg - true_deg + 90.0) % 180.0 - 90.0)


def test_a_buss_side_seen_alone_is_one_rigid_vehicle_of_its_length(tmp_path, capsys):
    (v,) = _detect(tmp_path, capsys, cm.bus(3.0, 8.0, 0.0))
    assert v["kind"] == "rigid" and v["trailer"] is None
    length, width, height = v["truck"]["dimensions"]
    assert abs(length - 12.0) < 0.2
    # the box stands on its body's lower edge, 0.3 m up (the rays under it cross no box)
    assert abs(height - 2.9) < 0.1 and abs(v["truck"]["center"][2] - (0.3 + 2.9 / 2)) < 0.1
    # its far side is not seen: the body is placed behind the near one, as wide as a coach
    assert np.hypot(v["truck"]["center"][0] - 3.0, v["truck"]["center"][1] - 8.0) < 0.15
    assert _yaw_error_deg(v["truck"]["yaw_deg"], 0.0) < 1.0
    assert v["truck"]["dimensions_seen"] == [True, False, True]  # its width is a stand-in


@pytest.mark.parametrize("x, y, yaw", [(0.0, 22.0, 0.0), (22.0, 0.0, np.pi / 2), (10.0, 20.0, -0.4)])
def test_a_buss_side_22_m_away_is_found_though_few_rays_pass_under_it(tmp_path, capsys, x, y, yaw):
    """From 1.8 m up, a ray passes under a body 0.3 m up only where it comes down to its clearance
    at the side's line: 22 m away, a few beams do so, each in a column or two, spread along its
    length (a body on wheels) but far from half of its columns. It is found, where it stands."""
    (v,) = _detect(tmp_path, capsys, cm.bus(x, y, yaw))
    assert v["kind"] == "rigid"
    assert np.hypot(v["truck"]["center"][0] - x, v["truck"]["center"][1] - y) < 0.1
    assert abs(v["truck"]["dimensions"][0] - 12.0) < 0.2
    assert _yaw_error_deg(v["truck"]["yaw_deg"], np.degrees(yaw)) < 1.0


def test_a_rigid_truck_seen_from_a_side_and_an_end_is_fitted_on_its_own_axes(tmp_path, capsys):
    """A 9 m body seen at a slant shows one side and one end: an L, whose hull's smallest rectangle
    lies along the hypotenuse (15 deg off). Its box is fitted on the axes the points hug, and a
    16.5 m MAN, whose faces the L also fits but whose points would not cover it, is not chosen."""
    yaw = np.radians(-126.26)
    (v,) = _detect(tmp_path, capsys, cm.bus(-6.93, 12.90, yaw, length_m=9.0, width_m=2.5))
    assert v["kind"] == "rigid"
    assert np.hypot(v["truck"]["center"][0] + 6.93, v["truck"]["center"][1] - 12.90) < 0.1
    assert _yaw_error_deg(v["truck"]["yaw_deg"], np.degrees(yaw)) < 1.0
    assert np.allclose(v["truck"]["dimensions"][:2], [9.0, 2.5], atol=0.1)
    assert v["truck"]["dimensions_seen"] == [True, True, True]


@pytest.mark.parametrize("x", [30.0, -22.0], ids=["rear_of_a_trailer_ahead", "front_of_an_oncoming_tractor"])
def test_a_tractor_and_trailer_seen_end_on_is_one_rigid_vehicle_behind_its_end(tmp_path, capsys, x):
    """Straight ahead, or coming straight at the car: its end face (and the trailer's front above
    the cab) is all that shows. It is reported rigid (no hinge is seen), as wide as the end, inside
    the vehicle's true extent, its axis along the road."""
    parts = cm.articulated("man_tgx", x, 0.0, 0.0)
    (v,) = _detect(tmp_path, capsys, parts)
    assert v["kind"] == "rigid" and v["hitch_deg"] is None
    vehicle = Params().vehicles["man_tgx"]
    xs = np.concatenate([p.vertices[:, 0] for p in parts])
    assert xs.min() + 1.0 < v["truck"]["center"][0] < xs.max() - 1.0
    assert abs(v["truck"]["center"][1]) < 0.3
    assert abs(v["truck"]["dimensions"][1] - max(vehicle.truck.width_m, vehicle.trailer.width_m)) < 0.15
    assert _yaw_error_deg(v["truck"]["yaw_deg"], 0.0) < 2.0
    assert v["truck"]["dimensions_seen"] == [False, True, True]  # its length is a stand-in


def test_vehicles_whose_tops_the_sensor_does_not_see_are_found(tmp_path, capsys):
    """Beams reaching 2 deg up (an HDL-64E's) see a truck's side 8-16 m away up to 2.0-2.3 m, below
    the heights a start asks of a tractor-trailer or a face; the highest return of the sweep tells
    where its view ends. A Volvo FH at 20 deg and a bus's side are found, the bus's height marked
    as not seen."""
    volvo, bus = Params().vehicles["volvo_fh"], cm.bus(3.0, -8.0, 0.0)
    found = _detect(tmp_path, capsys, cm.articulated("volvo_fh", 8.0, 15.0, np.radians(20.0)) + bus, top_deg=2.0)
    assert sorted(v["kind"] for v in found) == ["articulated", "rigid"]
    (truck,) = [v for v in found if v["kind"] == "articulated"]
    assert truck["vehicle"] == "volvo_fh" and abs(truck["hitch_deg"]) < 1.0
    assert _yaw_error_deg(truck["truck"]["yaw_deg"], 20.0) < 1.0
    yaw = np.radians(20.0)
    cab = box_center_in_axle_frame(volvo.truck, is_truck=True)[:2]
    cab_centre = np.array([8.0, 15.0]) + [cab[0] * np.cos(yaw) - cab[1] * np.sin(yaw), cab[0] * np.sin(yaw)]
    assert np.hypot(*(np.array(truck["truck"]["center"][:2]) - cab_centre)) < 0.15
    (rigid,) = [v for v in found if v["kind"] == "rigid"]
    assert np.hypot(rigid["truck"]["center"][0] - 3.0, rigid["truck"]["center"][1] + 8.0) < 0.15
    assert rigid["truck"]["dimensions_seen"] == [True, False, False]


@pytest.mark.parametrize("top_deg", [None, 2.0], ids=["os1_64", "fan_to_2_deg"])
def test_walls_trees_and_signs_of_a_vehicles_size_are_no_vehicles(tmp_path, capsys, top_deg):
    """A 10 m wall 3 m tall and a 2.5 m wide one (both stand on the ground: no ray passes under
    them), a round crown 2.6 m across on a trunk (not flat), a 2.5 m wide board on posts (its foot
    2.2 m up): each passes the size and height of a one-face vehicle (with the fan to 2 deg, no
    top is seen: any height passes); and a 13.4 m wall with a 2.3 m one across it fits a rigid
    vehicle's box, which stands on the ground."""
    parts = (
        cm.wall(-5.0, -12.0, 5.0, -12.0, 3.0)
        + cm.wall(14.0, 9.0, 14.0, 11.5, 3.5)
        + cm.tree(-15.0, -6.0)
        + cm.sign(-12.0, 7.0, 0.3)
        + cm.wall(30.29, -16.94, 21.23, -6.99, 2.83)  # a wall and a short one across it: a box
        + cm.wall(26.26, -11.67, 28.30, -10.60, 3.69)  # of a rigid vehicle's size
    )
    assert _detect(tmp_path, capsys, parts, top_deg) == []


def test_a_board_beside_a_wall_is_no_vehicle(tmp_path, capsys):
    """A 7.4 m wall and a board on posts at its end form one face of a coach's length; rays pass
    under the board, in 4 of the face's 29 columns: a body's clearance runs along it, a board's does not."""
    parts = cm.wall(1.41, -13.85, 5.47, -7.68, 2.81) + cm.sign(1.23, -13.62, 2.695)
    assert _detect(tmp_path, capsys, parts) == []


@pytest.mark.parametrize("name", ["man_tgx", "volvo_fh"])
def test_a_container_set_down_before_a_parked_trailer_is_no_tractor(tmp_path, capsys, name):
    """A 10-ft container 0.8 m before a parked trailer's front looks like a cab in one sweep; its
    faces reach down to the ground (the rays end on them right above it), a cab's bumper does not:
    no tractor and trailer. The same vehicle's own tractor there is one."""
    x, y, yaw = 16.0, 10.0, -2.2
    trailer = Params().vehicles[name].trailer
    along = trailer.length_m / 2 + 0.8 + 2.99 / 2
    parked = cm.parked_trailer(name, x, y, yaw) + cm.container(x + along * np.cos(yaw), y + along * np.sin(yaw), yaw)
    assert not [v for v in _detect(tmp_path, capsys, parked) if v["kind"] == "articulated"]
    vehicle = Params().vehicles[name]
    axle = along - 2.99 / 2 + vehicle.truck.wheelbase_m  # its rear axle about where the container stands
    (v,) = _detect(tmp_path, capsys, cm.articulated(name, x + axle * np.cos(yaw), y + axle * np.sin(yaw), yaw))
    assert v["kind"] == "articulated" and v["vehicle"] == name


def test_a_sweep_given_as_it_is_is_levelled_and_seen_from_its_origin(tmp_path, capsys):
    """A new user's sweep: no sensor configured, the cloud in its sensor's frame, the ground 1.8 m
    below its origin. The ground is found from the points and the rays run from the origin: the
    bus's side is found as with its sensor configured. Given as a merged cloud (``--merged``: no
    rays), one face is no vehicle."""
    np.save(tmp_path / "sweep.npy", cm.sweep(cm.bus(3.0, 8.0, 0.0)))
    assert main(["detect", str(tmp_path / "sweep.npy")]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["ground_below_origin_m"] == pytest.approx(cm.SENSOR_HEIGHT_M, abs=0.03)
    (v,) = report["vehicles"]
    assert v["kind"] == "rigid" and abs(v["truck"]["dimensions"][0] - 12.0) < 0.2
    assert np.hypot(v["truck"]["center"][0] - 3.0, v["truck"]["center"][1] - 8.0) < 0.15
    assert main(["detect", str(tmp_path / "sweep.npy"), "--merged"]) == 0
    assert json.loads(capsys.readouterr().out)["vehicles"] == []


def test_a_bus_beside_a_car_is_taken_apart_from_it(tmp_path, capsys):
    """The start's 0.8 m voxels bridge a cab's gap, and a lane's too: a bus 1.0 m beside a car is
    one seed 12 m by 5 m that no model explains. In one sweep (no frame to come in which they drive
    apart) it is taken apart at 0.3 m and the bus found; the car is no vehicle (too short)."""
    (v,) = _detect(tmp_path, capsys, cm.bus(10.0, -3.0, 0.0, length_m=11.6, width_m=2.5) + cm.car(9.5, 0.65, 0.0))
    assert v["kind"] == "rigid"
    assert np.hypot(v["truck"]["center"][0] - 10.0, v["truck"]["center"][1] + 3.0) < 0.1
    assert np.allclose(v["truck"]["dimensions"][:2], [11.6, 2.5], atol=0.15)


@pytest.mark.parametrize(
    "parts",
    [
        cm.parked_trailer("volvo_fh", -6.0, 14.0, 1.4),
        cm.parked_trailer("man_tgx", 12.0, -5.0, 2.0),
        cm.parked_trailer("volvo_fh", 15.0, 8.0, -0.4),
        cm.container(6.0, 5.0, 0.3, 6.06),
    ],
    ids=["volvo_trailer_side_and_front", "man_trailer_side_and_rear", "volvo_trailer_side", "container_20ft"],
)
def test_a_semitrailer_standing_alone_or_a_container_is_no_rigid_vehicle(tmp_path, capsys, parts):
    """A semitrailer without its tractor stands on thin legs at its front, its floor 1.2 m up, and
    has wheels at the rear only; a container's faces reach the ground. Neither is a vehicle, in one
    sweep either (each was reported as a rigid one)."""
    assert _detect(tmp_path, capsys, parts) == []


def test_a_parked_trailer_with_a_container_at_its_end_is_no_rigid_vehicle(tmp_path, capsys):
    """A 20-ft container 1.4 m off a parked trailer's end: one face to the sensor, low at both ends
    (the trailer's wheels, the container), rays passing under the trailer's floor in 19 of its 42
    columns, spread over 25. Its columns along the container reach the ground (27): no body on wheels."""
    x, y, yaw = 10.21, 9.72, -1.10
    along = Params().vehicles["volvo_fh"].trailer.length_m / 2 + 1.44 + 6.06 / 2
    container = cm.container(x + along * np.cos(yaw), y + along * np.sin(yaw), yaw, 6.06)
    assert _detect(tmp_path, capsys, cm.parked_trailer("volvo_fh", x, y, yaw) + container, seed=17) == []


def test_a_bus_where_a_parked_trailer_stands_is_a_rigid_vehicle(tmp_path, capsys):
    """The control of the parked trailers: a 9 m bus (wheels under both ends, its body 0.3 m up)."""
    (v,) = _detect(tmp_path, capsys, cm.bus(-6.0, 14.0, 1.4, length_m=9.0, width_m=2.5))
    assert v["kind"] == "rigid" and np.hypot(v["truck"]["center"][0] + 6.0, v["truck"]["center"][1] - 14.0) < 0.1


def test_a_person_beside_a_rigid_truck_does_not_widen_or_turn_its_box(tmp_path, capsys):
    """A person 0.75 m from a box truck's side joins its group: the group's rectangle is 3.4 m wide
    and its box was fitted 0.45 m off. The box is fitted again on the footprint of the points its
    first fit explains."""
    yaw = np.radians(91.0)
    beside = (
        np.array([-4.5, 15.0])
        + 2.5 * np.array([np.cos(yaw), np.sin(yaw)])
        + 2.0 * np.array([np.sin(yaw), -np.cos(yaw)])
    )
    (v,) = _detect(tmp_path, capsys, cm.box_truck(-4.5, 15.0, yaw) + cm.person(*beside))
    assert v["kind"] == "rigid"
    assert np.hypot(v["truck"]["center"][0] + 4.5, v["truck"]["center"][1] - 15.0) < 0.2
    assert _yaw_error_deg(v["truck"]["yaw_deg"], 91.0) < 1.0
    assert abs(v["truck"]["dimensions"][1] - 2.5) < 0.2 and abs(v["truck"]["dimensions"][0] - 10.0) < 0.35


def test_a_rigid_truck_whose_two_unit_fit_is_refuted_is_one_rigid_vehicle(tmp_path, capsys):
    """A box truck with a 0.8 m gap behind its cab, as a new user gives its sweep (no parameters): a
    MAN the wrong way round fits it best (its cab's box on the cargo box's rear) and the start's
    checks refute it; in one sweep the rigid box that explains the points is tried next (before,
    nothing was reported)."""
    parts = cm.box_truck(-4.5, 15.0, np.radians(91.0), length_m=10.2, gap_m=0.8, floor_m=1.2, box_width_m=2.9)
    np.save(tmp_path / "sweep.npy", cm.sweep(parts))
    assert main(["detect", str(tmp_path / "sweep.npy")]) == 0
    (v,) = json.loads(capsys.readouterr().out)["vehicles"]
    assert v["kind"] == "rigid" and v["trailer"] is None
    assert np.hypot(v["truck"]["center"][0] + 4.5, v["truck"]["center"][1] - 15.0) < 0.1
    assert abs(v["truck"]["dimensions"][0] - 10.2) < 0.2
