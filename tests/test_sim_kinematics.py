"""Tractor-trailer kinematics: steady circle against the closed form, reversing, maneuvers."""

import math

import numpy as np
import pytest

from i2v_loc.geometry import wrap_rad
from i2v_loc.params import Params
from i2v_loc.sim import kinematics as kin
from i2v_loc.sim import maneuvers as mv


def closed_form_hitch_deg(radius_m: float, hitch_behind_m: float, trailer_m: float) -> float:
    """Forward left turn, rear axle on a circle of radius R about C; truck heading +x at the origin,
    so C = (0, R) and the hitch H = (-M, 0) lies on radius R_h = sqrt(R² + M²). The trailer axle P2
    lies on radius sqrt(R_h² - L2²): the triangle C-P2-H has its right angle at P2 (P2's velocity,
    along the trailer, is perpendicular to C-P2). So the direction H->P2 is the direction H->C
    turned (counter-clockwise, i.e. backwards) by acos(L2 / R_h), and the trailer points P2->H."""
    r_h = math.hypot(radius_m, hitch_behind_m)
    dir_h_to_c = math.atan2(radius_m, hitch_behind_m)
    dir_h_to_p2 = dir_h_to_c + math.acos(trailer_m / r_h)
    trailer_yaw = dir_h_to_p2 + math.pi
    return math.degrees((trailer_yaw + math.pi) % (2 * math.pi) - math.pi)


def _drive_circle(art: kin.Articulation, radius_m: float, speed_mps: float, distance_m: float) -> np.ndarray:
    state = np.zeros(4)
    steer = kin.steady_turn_steer_rad(radius_m, art)
    dt = 0.005
    for _ in range(int(distance_m / abs(speed_mps) / dt)):
        state = kin.step(state, speed_mps, steer, art, dt)
    return state


@pytest.mark.parametrize(
    "wheelbase, hitch_behind, trailer, radius",
    [
        (3.60, -0.35, 7.90, 12.0),  # MAN TGX: fifth wheel ahead of the rear axle
        (1.69, 0.45, 2.40, 4.0),  # Twizy: drawbar behind the rear axle
    ],
)
def test_steady_circle_hitch_matches_closed_form(wheelbase, hitch_behind, trailer, radius):
    art = kin.Articulation(wheelbase, hitch_behind, trailer)
    state = _drive_circle(art, radius, 1.5, distance_m=12 * trailer + 60)
    hitch_deg = math.degrees(wrap_rad(state[3] - state[2]))
    assert hitch_deg == pytest.approx(closed_form_hitch_deg(radius, hitch_behind, trailer), abs=0.1)
    # The rear axle stays on the circle about (0, R) (the start is on it with the right heading).
    assert math.hypot(state[0], state[1] - radius) == pytest.approx(radius, abs=1e-3)


def test_closed_form_reduces_to_the_on_axle_result():
    # With the hitch on the axle (M = 0) the classic result is hitch = -asin(L2 / R).
    assert closed_form_hitch_deg(10.0, 0.0, 6.0) == pytest.approx(-math.degrees(math.asin(0.6)), abs=1e-9)


def test_reverse_moves_backwards_with_truck_and_trailer_consistent():
    art = kin.Articulation(3.6, -0.35, 7.9)
    state = np.array([0.0, 0.0, 0.0, 0.0])
    for _ in range(400):  # 2 s straight back at 1 m/s
        state = kin.step(state, -1.0, 0.0, art, 0.005)
    assert state[0] == pytest.approx(-2.0, abs=1e-6)
    assert state[2] == pytest.approx(0.0) and state[3] == pytest.approx(0.0)
    # The trailer axle stays L2 behind the hitch whatever the motion.
    assert np.linalg.norm(kin.hitch_point(state, art) - kin.trailer_axle_point(state, art)) == pytest.approx(7.9)


@pytest.mark.parametrize("vehicle", ["man_tgx", "twizy", "volvo_fh"])
def test_hitch_controller_tracks_its_reference_while_reversing(vehicle):
    art = kin.Articulation.from_vehicle(Params().vehicles[vehicle])
    state = np.zeros(4)
    reference = math.radians(-15.0)
    hitch = []
    for _ in range(int(12.0 / 0.005)):
        steer = float(np.clip(kin.steer_for_hitch(state, -1.0, reference, art), -math.radians(35), math.radians(35)))
        state = kin.step(state, -1.0, steer, art, 0.005)
        hitch.append(math.degrees(wrap_rad(state[3] - state[2])))
    assert max(abs(h) for h in hitch) < 20.0  # bounded: no jackknife
    assert hitch[-1] == pytest.approx(-15.0, abs=0.5)
    # Reversing with a steady negative hitch turns the trailer clockwise.
    assert state[3] < -0.1


def test_open_loop_reversing_is_unstable_which_is_why_the_controller_exists():
    art = kin.Articulation(3.6, -0.35, 7.9)
    state = np.array([0.0, 0.0, 0.0, math.radians(1.0)])
    for _ in range(int(20.0 / 0.005)):
        state = kin.step(state, -1.0, 0.0, art, 0.005)
    assert abs(math.degrees(state[3] - state[2])) > 10.0


@pytest.mark.parametrize("scenario", mv.SCENARIOS)
def test_every_scenario_fills_the_duration_with_smooth_speed_and_known_labels(scenario):
    art = kin.Articulation.from_vehicle(Params().vehicles["man_tgx"])
    traj = mv.build_trajectory(scenario, art, 30.0)
    assert traj.time_s[0] == pytest.approx(0.0, abs=mv.DT_S) and traj.time_s[-1] >= 30.0
    assert np.all(np.abs(np.diff(traj.speed_mps)) <= art.max_accel_mps2 * mv.DT_S + 1e-9)  # no jumps
    assert np.all(np.abs(traj.speed_mps) <= 3.0 + 1e-9)
    labels = {mv.LABELS[i] for i in traj.label_index}
    assert labels <= set(mv.LABELS)
    if scenario != "docking":
        assert scenario in labels
    else:
        assert labels == {"straight", "single_turn", "reverse_docking", "standstill"}
    hitch = np.degrees(traj.trailer_yaw_rad - traj.yaw_rad)
    assert np.all(np.abs(hitch) < 75.0)


def test_reverse_docking_turns_the_trailer_into_the_bay_going_backwards():
    art = kin.Articulation.from_vehicle(Params().vehicles["man_tgx"])
    traj = mv.build_trajectory("reverse_docking", art, 30.0)
    reversing = traj.label_index == mv.LABELS.index("reverse_docking")
    assert np.all(traj.speed_mps[reversing] <= 1e-9)
    assert math.degrees(traj.trailer_yaw_rad[-1]) == pytest.approx(-80.0, abs=5.0)
