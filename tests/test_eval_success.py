"""Coverage, success rate, flips per unit, false vehicle-seconds and wrong types on hand-made
ground truth and estimates (no simulator, no pipeline)."""

from __future__ import annotations

import math

import pytest

from i2v_loc.evaluation.matching import match_states
from i2v_loc.evaluation.summary import summarize
from i2v_loc.geometry import wrap_deg
from i2v_loc.params import Params

N = 10  # frames at 10 Hz
TRUCK = (10.0, 5.0, 30.0)  # x, y, yaw
TRAILER = (10.0 - 8.0 * math.cos(math.radians(20.0)), 5.0 - 8.0 * math.sin(math.radians(20.0)), 20.0)


def _unit(x, y, yaw, points=500):
    return {"center": [x, y, 1.5], "dimensions": [6.0, 2.5, 3.5], "yaw_deg": yaw, "points": points}


def _truth(trailer_points=None) -> list[dict]:
    lines = []
    for k in range(N):
        points = trailer_points(k) if trailer_points else 500
        truck, trailer = _unit(*TRUCK), _unit(*TRAILER, points=points)
        lines.append(
            {
                "frame": k,
                "stamp_s": k / 10,
                "vehicles": [
                    {
                        "id": 1,
                        "vehicle": "man_tgx",
                        "maneuver": "u_turn",
                        "truck": truck,
                        "trailer": trailer,
                        "hitch_deg": wrap_deg(trailer["yaw_deg"] - truck["yaw_deg"]),
                    }
                ],
            }
        )
    return lines


def _estimate(k, truck=TRUCK, trailer=TRAILER, vehicle="man_tgx", extra=None) -> dict:
    """State of frame k: one vehicle with the given units (None: not reported), plus ``extra``."""
    v = {
        "id": 7,
        "vehicle": vehicle,
        "hitch_deg": None,
        "truck": None if truck is None else dict(_unit(*truck), track_id=1),
        "trailer": None if trailer is None else dict(_unit(*trailer), track_id=2),
    }
    return {"type": "state", "frame": k, "stamp_s": k / 10, "vehicles": [v] + (extra or [])}


def _summary(states, truth=None) -> dict:
    records, frames = match_states(states, truth or _truth(), Params(), gate_m=4.0)
    return summarize(records, frames)


def test_perfect_estimates_succeed_everywhere():
    s = _summary([_estimate(k) for k in range(N)])
    assert s["success_rate"] == 1.0 and s["success_frames"] == s["visible_frames"] == N
    assert s["truck_coverage"] == s["trailer_coverage"] == s["both_units_rate"] == 1.0
    assert s["false_vehicle_s"] == 0.0 and s["truck_flip_frames"] == s["trailer_flip_frames"] == 0


def test_a_missing_unit_lowers_coverage_and_success_but_not_the_rmse():
    states = [_estimate(k, trailer=None if k in (2, 5, 7) else TRAILER) for k in range(N)]
    s = _summary(states)
    assert s["truck_coverage"] == 1.0
    assert s["trailer_coverage"] == pytest.approx(0.7) and s["both_units_rate"] == pytest.approx(0.7)
    assert s["success_rate"] == pytest.approx(0.7) and s["success_frames"] == 7 and s["visible_frames"] == 10
    assert s["hitch_rmse_deg"] == pytest.approx(0.0, abs=1e-9)  # over the reported frames only
    assert s["hitch_frames"] == 7


def test_a_flip_of_both_units_counts_for_each_unit_and_fails_although_the_hitch_is_right():
    flipped_truck = TRUCK[:2] + (wrap_deg(TRUCK[2] + 180.0),)
    flipped_trailer = TRAILER[:2] + (wrap_deg(TRAILER[2] + 180.0),)
    states = [_estimate(k, truck=flipped_truck, trailer=flipped_trailer) if k < 4 else _estimate(k) for k in range(N)]
    records, frames = match_states(states, _truth(), Params(), gate_m=4.0)
    s = summarize(records, frames)
    assert s["truck_flip_frames"] == 4 and s["trailer_flip_frames"] == 4
    assert s["hitch_rmse_deg"] == pytest.approx(0.0, abs=1e-9)
    assert all(abs(r["hitch_err_deg"]) < 1e-9 for r in records)
    assert s["success_rate"] == pytest.approx(0.6) and s["both_units_rate"] == 1.0


def test_a_false_vehicle_gives_its_vehicle_seconds():
    ghost = {"id": 9, "vehicle": "man_tgx", "truck": _unit(-20.0, -10.0, 0.0), "trailer": None}
    states = [_estimate(k, extra=[ghost] if k in (1, 2, 3, 8) else None) for k in range(N)]
    s = _summary(states)
    assert s["false_vehicles"] == 4
    assert s["false_vehicle_s"] == pytest.approx(0.4)  # 4 frames x 0.1 s
    assert s["false_vehicle_s_first_5s"] == pytest.approx(0.4)
    assert s["wrong_type_vehicle_s"] == 0.0
    assert s["success_rate"] == 1.0  # the true vehicle is still found


def test_a_wrong_type_is_a_false_vehicle_and_a_missed_one():
    """A twizy reported exactly where the MAN TGX is: no match."""
    states = [_estimate(k, vehicle="twizy" if k < 3 else "man_tgx") for k in range(N)]
    records, frames = match_states(states, _truth(), Params(), gate_m=4.0)
    s = summarize(records, frames)
    assert s["truck_coverage"] == pytest.approx(0.7) and s["trailer_coverage"] == pytest.approx(0.7)
    assert s["success_rate"] == pytest.approx(0.7)
    assert s["false_vehicles"] == 3
    assert s["false_vehicle_s"] == pytest.approx(0.3) and s["wrong_type_vehicle_s"] == pytest.approx(0.3)
    false = [r for r in records if r["kind"] == "false"]
    assert {r["vehicle"] for r in false} == {"twizy"} and {r["wrong_type_of"] for r in false} == {"man_tgx"}


def test_an_unnamed_estimate_or_unlabelled_truth_still_matches():
    truth = _truth()
    for line in truth[:5]:
        line["vehicles"][0]["vehicle"] = None
    states = [_estimate(k, vehicle=None if k >= 5 else "twizy") for k in range(N)]
    s = _summary(states, truth)
    assert s["truck_coverage"] == 1.0 and s["false_vehicles"] == 0


@pytest.mark.parametrize(
    ("truck", "trailer", "success"),
    [
        ((TRUCK[0] + 0.3, TRUCK[1], TRUCK[2]), TRAILER, True),  # 0.3 m: on the boundary, inclusive
        ((TRUCK[0] + 0.301, TRUCK[1], TRUCK[2]), TRAILER, False),
        (TRUCK, (TRAILER[0], TRAILER[1] - 0.3, TRAILER[2]), True),
        (TRUCK, (TRAILER[0], TRAILER[1] - 0.301, TRAILER[2]), False),
        (TRUCK, (TRAILER[0], TRAILER[1], TRAILER[2] + 2.0), True),  # trailer yaw and hitch both 2 deg off
        (TRUCK, (TRAILER[0], TRAILER[1], TRAILER[2] + 2.01), False),
        ((TRUCK[0], TRUCK[1], TRUCK[2] + 1.5), (TRAILER[0], TRAILER[1], TRAILER[2] - 0.6), False),  # yaws ok, hitch 2.1
        ((TRUCK[0], TRUCK[1], TRUCK[2] + 1.0), (TRAILER[0], TRAILER[1], TRAILER[2] - 1.0), True),  # hitch 2.0
    ],
)
def test_success_thresholds_at_the_boundary(truck, trailer, success):
    s = _summary([_estimate(k, truck=truck, trailer=trailer) for k in range(N)])
    assert s["success_rate"] == (1.0 if success else 0.0)


def test_frames_where_a_unit_is_hidden_leave_the_success_denominator_not_the_coverage():
    truth = _truth(trailer_points=lambda k: 10 if k < 2 else 500)  # trailer below 30 points in frames 0, 1
    states = [_estimate(k, trailer=None if k < 2 else TRAILER) for k in range(N)]
    s = _summary(states, truth)
    assert s["visible_frames"] == 8 and s["success_frames"] == 8 and s["success_rate"] == 1.0
    assert s["trailer_coverage"] == pytest.approx(0.8) and s["trailer_detection_rate"] == 1.0


def test_sweep_ranks_by_success_rate_descending_or_hitch_rmse_ascending():
    from i2v_loc.evaluation.sweep import rank
    from i2v_loc.params import Params

    combos = [({"a": i}, Params()) for i in range(3)]
    summaries = [
        {"hitch_rmse_deg": 0.5, "success_rate": 0.2},  # few, good frames
        {"hitch_rmse_deg": 1.5, "success_rate": 0.9},
        {"hitch_rmse_deg": 1.0, "success_rate": 0.9},
    ]
    assert [r["combination"] for r in rank(combos, summaries)] == [0, 2, 1]
    assert [r["combination"] for r in rank(combos, summaries, "success_rate")] == [2, 1, 0]


def test_length_errors_are_medians_over_settled_tracks_only():
    """Estimated minus true length, median over the frames of a track at least 10 s old: the
    first 10 s (a wrong start length) do not count; a new track restarts the clock."""
    n = 150  # 15 s at 10 Hz
    truth, states = [], []
    for k in range(n):
        line = _truth()[0]
        line["frame"], line["stamp_s"] = k, k / 10
        truth.append(line)
        state = _estimate(k)
        v = state["vehicles"][0]
        v["truck"]["dimensions"] = [6.0 + (1.0 if k < 100 else 0.2), 2.5, 3.5]  # true length 6.0
        v["trailer"]["dimensions"] = [6.0 - (2.0 if k < 100 else 0.4 + 0.1 * (k % 2)), 2.5, 3.5]
        states.append(state)
    s = _summary(states, truth)
    assert s["truck_length_error_m"] == pytest.approx(0.2)
    assert s["trailer_length_error_m"] == pytest.approx(-0.45)
    for state in states[100:]:
        state["vehicles"][0]["id"] = 8  # a new track at 10 s: never 10 s old
    s = _summary(states, truth)
    assert math.isnan(s["truck_length_error_m"]) and math.isnan(s["trailer_length_error_m"])


def test_the_hitch_where_seen_leaves_out_the_frames_a_unit_was_hidden():
    """Both units reported in every frame, the trailer hidden (10 points) in frames 0 and 1 where
    its reported yaw is 5 deg off (a prediction): the hitch RMSE counts them, the one where seen
    does not."""
    truth = _truth(trailer_points=lambda k: 10 if k < 2 else 500)
    off = (TRAILER[0], TRAILER[1], TRAILER[2] + 5.0)
    s = _summary([_estimate(k, trailer=off if k < 2 else TRAILER) for k in range(N)], truth)
    assert s["hitch_rmse_deg"] == pytest.approx(math.sqrt(2 * 25.0 / N), abs=1e-6)
    assert s["hitch_rmse_seen_deg"] == pytest.approx(0.0, abs=1e-9)


def test_the_hitch_within_two_reported_std_counts_frames_whose_error_the_std_covers():
    """The reported hitch standard deviation is checked against the error: the trailer's yaw 1 deg
    off in every frame (a hitch error of 1 deg), reported with 0.6 deg in frames 0-3 (covered: 1 <=
    1.2), 0.4 deg in frames 4-6 (not: 1 > 0.8) and nothing in frames 7-9 (left out): 4 of 7."""
    off = (TRAILER[0], TRAILER[1], TRAILER[2] + 1.0)
    states = []
    for k in range(N):
        state = _estimate(k, trailer=off)
        state["vehicles"][0]["hitch_std_deg"] = 0.6 if k < 4 else 0.4 if k < 7 else None
        states.append(state)
    s = _summary(states)
    assert s["hitch_rmse_deg"] == pytest.approx(1.0, abs=1e-6)
    assert s["hitch_within_2std_rate"] == pytest.approx(4 / 7)
    assert math.isnan(_summary([_estimate(k) for k in range(N)])["hitch_within_2std_rate"])
