"""The evaluation calibrates each recording from its guess once (cached) and measures the
calibration's error against the truth."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from i2v_loc.evaluation import calibration as cal
from i2v_loc.evaluation.report import render_markdown
from i2v_loc.evaluation.runner import recording_params
from i2v_loc.params import Extrinsics, SensorConfig, load_params
from i2v_loc.stages.calibration import SensorCalibration

SAMPLE = Path(__file__).resolve().parents[1] / "samples" / "volvo_fh_u_turn"
TRUTH = load_params(SAMPLE / "sensors.yaml")
GUESS = load_params(SAMPLE / "sensors_guess.yaml")


def _perturbed(extrinsics: Extrinsics, dx=0.0, dy=0.0, dyaw=0.0) -> Extrinsics:
    return extrinsics.model_copy(
        update={"x_m": extrinsics.x_m + dx, "y_m": extrinsics.y_m + dy, "yaw_deg": extrinsics.yaw_deg + dyaw}
    )


@pytest.fixture
def fake_calibration(monkeypatch):
    """The ICP replaced by a counter returning the truth with l2 off by (3, -4) cm and 1.5 deg."""
    calls = []
    fitness = {"l3": 0.9}
    constraint = {}  # weakest horizontal direction in points, per sensor (none: unconstrained figure)
    at_guess = {}  # fitness at the guess, per sensor (none: 1.0, no result below min_fitness beats it)

    def fake(recording, params, progress=None):
        calls.append(params.calibration.windows)
        results = []
        for sensor in params.sensors:
            true = TRUTH.sensor(sensor.name).extrinsics
            ext = _perturbed(true, 0.03, -0.04, 1.5) if sensor.name == "l2" else true
            quality = (fitness.get(sensor.name, 0.9), 0.05, "reference", constraint.get(sensor.name, 1000.0))
            results.append(SensorCalibration(sensor.name, ext, *quality, at_guess.get(sensor.name, 1.0)))
        return results, any(not r.accepted(params.calibration.min_fitness) for r in results)

    monkeypatch.setattr(cal, "run_calibration", fake)
    fake.constraint = constraint
    fake.at_guess = at_guess
    return calls, fitness


def test_extrinsics_error_of_a_known_perturbation():
    true = TRUTH.sensor("l3").extrinsics
    cm, deg = cal.extrinsics_error(_perturbed(true, 0.03, -0.04, 1.5), true)
    assert cm == pytest.approx(5.0) and deg == pytest.approx(1.5)
    tilted = true.model_copy(update={"roll_deg": true.roll_deg + 2.0, "z_m": true.z_m + 0.12})
    cm, deg = cal.extrinsics_error(tilted, true)
    assert cm == pytest.approx(12.0) and deg == pytest.approx(2.0)


def test_sensor_errors_include_the_clock_offset():
    used = [SensorConfig(name="l1", extrinsics=TRUTH.sensor("l1").extrinsics, time_offset_s=0.0)]
    (row,) = cal.sensor_errors(used, TRUTH.sensors)
    assert row["error_cm"] == pytest.approx(0.0) and row["error_deg"] == pytest.approx(0.0, abs=1e-6)
    assert row["clock_error_ms"] == pytest.approx(-1000.0 * TRUTH.sensor("l1").time_offset_s)


def test_calibration_is_cached_and_its_errors_measured(fake_calibration, tmp_path):
    calls, _ = fake_calibration
    first = cal.calibrate_recording(str(SAMPLE), {}, tmp_path)
    second = cal.calibrate_recording(str(SAMPLE), {}, tmp_path)
    assert len(calls) == 1  # the second evaluation read the cache
    assert first["status"] == second["status"] == cal.CALIBRATED
    assert not first["cached"] and second["cached"]
    assert second["sensors"] == first["sensors"]
    rows = {r["sensor"]: r for r in second["per_sensor"]}
    assert rows["l2"]["error_cm"] == pytest.approx(5.0) and rows["l2"]["error_deg"] == pytest.approx(1.5)
    assert rows["l3"]["error_cm"] == pytest.approx(0.0, abs=1e-6)
    # the sample's guess is 30 cm off on each axis for l2..l4
    assert rows["l3"]["guess_error_cm"] == pytest.approx(100 * math.sqrt(3 * 0.3**2))
    # other calibration parameters are another calibration
    cal.calibrate_recording(str(SAMPLE), {"calibration": {"windows": 3}}, tmp_path)
    assert calls == [30, 3]


def test_tasks_run_with_the_calibrated_sensors_and_the_guess_clock_offsets(fake_calibration, tmp_path):
    from i2v_loc.commands.eval import build_tasks

    calibrations = cal.calibrate_recordings([SAMPLE], {}, cache_dir=tmp_path, progress=False)
    (task,) = build_tasks([SAMPLE], ["default"], False, {}, None, 4.0, calibrations)
    params = recording_params(task.params, task.recording, task.sensors)
    assert params.sensor("l2").extrinsics == _perturbed(TRUTH.sensor("l2").extrinsics, 0.03, -0.04, 1.5)
    assert params.sensor("l3").extrinsics == TRUTH.sensor("l3").extrinsics
    assert params.sensor("l3").time_offset_s == GUESS.sensor("l3").time_offset_s == 0.0
    # --params files still come last and win
    (task,) = build_tasks([SAMPLE], ["default"], False, {"tracking": {"max_distance_m": 2.5}}, None, 4.0, calibrations)
    params = recording_params(task.params, task.recording, task.sensors)
    assert params.tracking.max_distance_m == 2.5 and params.sensor("l3").extrinsics == TRUTH.sensor("l3").extrinsics


def test_a_refused_sensor_is_left_out_the_others_calibrated_and_it_is_said(fake_calibration, tmp_path):
    _, fitness = fake_calibration
    fitness["l3"] = 0.1
    result = cal.calibrate_recording(str(SAMPLE), {}, tmp_path)
    assert (
        result["status"] == cal.REFUSED
        and "l3 (0.10, 1.00 at the guess, weakest direction 1000.0 points)" in result["message"]
    )
    used = {s["name"]: s for s in result["sensors"]}
    # the refused one: its guess, left out of the frames
    assert used["l3"] == GUESS.sensor("l3").model_copy(update={"enabled": False}).model_dump(mode="json")
    assert used["l2"]["extrinsics"] != GUESS.sensor("l2").model_dump(mode="json")["extrinsics"]
    assert [name for name, s in used.items() if not s["enabled"]] == ["l3"]
    rows = {r["sensor"]: r for r in result["per_sensor"]}
    assert rows["l3"]["error_cm"] == pytest.approx(rows["l3"]["guess_error_cm"])  # the guess is what is used
    assert rows["l2"]["error_cm"] == pytest.approx(rows["l2"]["calibrated_error_cm"]) == pytest.approx(5.0)
    text = _report(result)
    assert "WARNING — volvo_fh_u_turn: CALIBRATION REFUSED" in text and "**REFUSED**" in text
    assert "l3 (0.10, 1.00 at the guess, weakest direction 1000.0 points)): left out" in result["message"]


def test_calibrate_writes_the_sensors_it_could_calibrate_and_fails_naming_the_refused_one(
    fake_calibration, tmp_path, capsys
):
    from i2v_loc.cli import main

    _, fitness = fake_calibration
    fitness["l3"] = 0.1
    out = tmp_path / "calibrated.yaml"
    assert main(["calibrate", str(SAMPLE), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert (
        "REFUSED" in err and "l3 (0.10, 1.00 at the guess, weakest direction 1000.0 points)" in err and str(out) in err
    )
    written = load_params(out)
    assert written.sensor("l3").extrinsics == GUESS.sensor("l3").extrinsics and not written.sensor("l3").enabled
    assert all(written.sensor(name).enabled for name in ("l1", "l2", "l4"))
    # calibrated again from that file, l3 accepted this time: enabled again
    fitness["l3"] = 0.9
    again = tmp_path / "again.yaml"
    assert main(["calibrate", str(SAMPLE), "--guess", str(out), "--out", str(again)]) == 0
    assert all(load_params(again).sensor(name).enabled for name in ("l1", "l2", "l3", "l4"))
    assert written.sensor("l2").extrinsics == _perturbed(TRUTH.sensor("l2").extrinsics, 0.03, -0.04, 1.5)
    assert written.sensor("l4").extrinsics == TRUTH.sensor("l4").extrinsics


def test_a_low_fitness_better_than_the_guess_is_accepted_unless_a_direction_is_undetermined(fake_calibration, tmp_path):
    """A result below ``min_fitness`` that fits better than the guess is used, when every horizontal
    direction holds a point's information at least: one sensor seeing little structure calibrated
    to 0.4 cm at 0.26 (0.18 at its guess, 52 cm off); another slid 1.75 m along a direction with
    none, at 0.27 (0.19 at its guess)."""
    _, fitness = fake_calibration
    at_guess, constraint = cal.run_calibration.at_guess, cal.run_calibration.constraint
    fitness["l2"], at_guess["l2"], constraint["l2"] = 0.26, 0.18, 89.0
    result = cal.calibrate_recording(str(SAMPLE), {}, tmp_path)
    assert result["status"] == cal.CALIBRATED
    rows = {r["sensor"]: r for r in result["per_sensor"]}
    assert rows["l2"]["error_cm"] == pytest.approx(5.0) and rows["l2"]["guess_fitness"] == 0.18
    constraint["l2"] = 0.4  # no structure across one horizontal direction
    refused = cal.calibrate_recording(str(SAMPLE), {"calibration": {"windows": 4}}, tmp_path)
    assert (
        refused["status"] == cal.REFUSED
        and "l2 (0.26, 0.18 at the guess, weakest direction 0.4 points)" in refused["message"]
    )
    constraint["l2"], at_guess["l2"] = 89.0, 0.30  # the guess fits better
    worse = cal.calibrate_recording(str(SAMPLE), {"calibration": {"windows": 5}}, tmp_path)
    assert worse["status"] == cal.REFUSED


def test_a_weakly_constrained_sensor_is_calibrated_with_a_warning(fake_calibration, tmp_path):
    constraint = cal.run_calibration.constraint
    constraint["l2"] = 7.0
    result = cal.calibrate_recording(str(SAMPLE), {}, tmp_path)
    assert result["status"] == cal.CALIBRATED and "l2 (7)" in result["warning"] and "l3" not in result["warning"]
    assert {r["sensor"]: r["constraint_points"] for r in result["per_sensor"]}["l2"] == 7.0
    assert cal.calibrate_recording(str(SAMPLE), {}, tmp_path)["warning"] == result["warning"]  # cached with it
    text = _report(result)
    assert "WARNING — volvo_fh_u_turn: weakly constrained calibration for l2 (7)" in text
    constraint["l2"] = 1000.0
    assert cal.calibrate_recording(str(SAMPLE), {"calibration": {"windows": 4}}, tmp_path)["warning"] is None


def test_true_extrinsics_skip_the_calibration(fake_calibration, tmp_path):
    calls, _ = fake_calibration
    calibrations = cal.calibrate_recordings([SAMPLE], {}, true_extrinsics=True, cache_dir=tmp_path, progress=False)
    assert calls == [] and calibrations[str(SAMPLE)]["status"] == cal.TRUE
    assert cal.task_patch({}, calibrations[str(SAMPLE)]) == {}  # REC/sensors.yaml as before


def test_the_real_calibration_of_the_sample_is_within_centimetres(tmp_path):
    result = cal.calibrate_recording(str(SAMPLE), {}, tmp_path)
    assert result["status"] == cal.CALIBRATED
    for row in result["per_sensor"]:  # measured: 0.4-0.7 cm, <= 0.02 deg; the guess is 52 cm / 3.5 deg off
        assert row["error_cm"] < 2.0 and row["error_deg"] < 0.1, row
    assert max(r["guess_error_cm"] for r in result["per_sensor"]) > 50.0


def _report(calibration: dict) -> str:
    """The report of an evaluation with no frames and this calibration of the sample."""
    summary = {
        "recordings": ["volvo_fh_u_turn"],
        "methods": ["default"],
        "subsets": ["all"],
        "primary_subset": "all",
        "results": {"default": {"all": _empty_groups()}},
        "calibration": {str(SAMPLE): calibration},
    }
    return render_markdown(summary, [])


def _empty_groups() -> dict:
    from i2v_loc.evaluation.summary import summarize

    s = summarize([], [])
    return {"overall": s, "by_vehicle": {}, "by_maneuver": {}, "by_recording": {}}
