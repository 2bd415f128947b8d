"""The tractor's rear axle, the point that does not slip sideways, learned from its fits along an
arc (``vehicle_dimensions._learn_axle``)."""

from __future__ import annotations

from collections import deque
from types import SimpleNamespace

import numpy as np
import pytest

from i2v_loc.params import Params
from i2v_loc.sim.kinematics import Articulation, step
from i2v_loc.stages import vehicle_dimensions
from i2v_loc.stages.vehicle_model import VehicleModel

PARAMS = Params()
VOLVO = PARAMS.vehicles["volvo_fh"]
ART = Articulation.from_vehicle(VOLVO)
NOISE = np.array([0.02, 0.02, np.radians(0.3), np.radians(0.3)])  # a whole fit's


def learn(behind_m: float, steer_at, seconds: float, seed: int, speed: float = 3.0, rows: int = 4):
    """A Volvo driven at ``speed`` with the steering ``steer_at(t)``, its fits (``NOISE``) giving the
    pose of a point ``behind_m`` ahead of its rear axle, each measuring ``rows`` pose directions:
    the axle the track learned and its number of pairs."""
    rng = np.random.default_rng(seed)
    track = SimpleNamespace(
        model=VehicleModel.from_config("volvo_fh", VOLVO),
        axle_fits=deque(maxlen=60),
        axle=vehicle_dimensions._axle_extent(),
        filter=SimpleNamespace(axle_behind_m=0.0),
    )
    observed = None if rows == 4 else (np.eye(4)[:rows], np.eye(rows))
    truth = np.zeros(4)
    for k in range(int(seconds * 10)):
        truth = step(truth, speed, steer_at(k * 0.1), ART, 0.1)
        ahead = behind_m * np.array([np.cos(truth[2]), np.sin(truth[2])])
        z = np.array([truth[0] + ahead[0], truth[1] + ahead[1], truth[2], truth[3] - truth[2]])
        fit = SimpleNamespace(vector=z + rng.normal(0.0, NOISE), observed=observed)
        vehicle_dimensions._learn_axle(track, fit, k * 0.1)
    return track.filter.axle_behind_m, len(track.axle.values)


def steady(curvature_1_m: float):
    steer = float(np.arctan(curvature_1_m * ART.wheelbase_m))
    return lambda t: steer


@pytest.mark.parametrize("behind_m", [0.35, 0.0, -0.3])
@pytest.mark.parametrize("seed", [0, 1])
def test_the_axle_is_learned_in_a_steady_turn(behind_m, seed):
    learned, pairs = learn(behind_m, steady(0.11), 15.0, seed)
    assert pairs >= vehicle_dimensions.AXLE_MIN_SAMPLES
    assert learned == pytest.approx(behind_m, abs=0.08)


def test_reversing_along_an_arc_shows_it_as_well():
    learned, _ = learn(0.35, steady(-0.15), 15.0, 2, speed=-1.5)
    assert learned == pytest.approx(0.35, abs=0.08)


def test_driving_straight_or_fits_that_missed_the_cab_teach_nothing():
    assert learn(0.35, steady(0.0), 15.0, 3) == (0.0, 0)
    assert learn(0.35, steady(0.11), 15.0, 3, rows=3) == (0.0, 0)


def winding(t: float) -> float:
    """Into a turn and out again, the steering wound up to 25 deg and down at 20 deg/s."""
    return float(np.radians(np.clip(20.0 * t, 0.0, 25.0) - np.clip(20.0 * (t - 2.0), 0.0, 25.0)))


@pytest.mark.parametrize("seed", [0, 1])
def test_a_turn_winding_up_and_down_does_not_move_the_axle(monkeypatch, seed):
    """Where the curvature changes the chord bends: only pairs along one arc count (the heading
    halfway between them halfway); with every pair, a known Volvo's axle comes out 0.2-0.6 m off."""
    learned, _ = learn(0.0, winding, 10.0, seed)
    assert abs(learned) < 0.1
    monkeypatch.setattr(vehicle_dimensions, "AXLE_STEADY_SHARE", np.inf)
    every_pair, _ = learn(0.0, winding, 10.0, seed)
    assert abs(every_pair) > 0.2
