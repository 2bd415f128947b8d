"""The evaluation's parameter order: defaults -> REC/sensors.yaml -> --params files (as ``i2v-loc run``)."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from i2v_loc.cli import main
from i2v_loc.evaluation.runner import EvaluationError, base_params, recording_params
from i2v_loc.params import ParamsError, load_params

SAMPLE = Path(__file__).resolve().parents[1] / "samples" / "volvo_fh_u_turn"


def test_without_params_the_recording_sensors_are_used():
    params = recording_params(base_params([]), str(SAMPLE), None)
    assert params.sensors == load_params(SAMPLE / "sensors.yaml").sensors
    assert params.sensor("l1").time_offset_s != 0.0  # the sample's true clock offsets came through


def test_params_files_win_over_the_recording_sensors():
    """``eval REC --params cal.yaml`` must score cal.yaml's extrinsics, not the recording's true ones."""
    params = recording_params(base_params([SAMPLE / "sensors_guess.yaml"]), str(SAMPLE), None)
    guess, true = load_params(SAMPLE / "sensors_guess.yaml"), load_params(SAMPLE / "sensors.yaml")
    assert params.sensor("l2").extrinsics == guess.sensor("l2").extrinsics != true.sensor("l2").extrinsics
    assert params.sensor("l2").time_offset_s == 0.0


def test_params_without_sensors_keep_the_recording_sensors(tmp_path):
    first, second = tmp_path / "a.yaml", tmp_path / "b.yaml"
    first.write_text(yaml.safe_dump({"tracking": {"max_distance_m": 1.5}}))
    second.write_text(yaml.safe_dump({"tracking": {"max_distance_m": 2.5}}))
    patch = base_params([first, second])
    assert "sensors" not in patch
    params = recording_params(patch, str(SAMPLE), ("l1", "l3"))
    assert params.tracking.max_distance_m == 2.5  # later files win
    assert [s.name for s in params.sensors] == ["l1", "l3"]
    assert params.sensor("l3") == load_params(SAMPLE / "sensors.yaml").sensor("l3")


def test_bad_params_and_unknown_sensors_are_clear_errors(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text(yaml.safe_dump({"tracking": {"max_distance_m": -1.0}}))
    with pytest.raises(ParamsError, match="max_distance_m"):
        base_params(str(bad))
    with pytest.raises(EvaluationError, match="l9"):
        recording_params({}, str(SAMPLE), ("l1", "l9"))


def test_eval_command_reports_a_bad_params_file(tmp_path, capsys):
    assert main(["eval", str(SAMPLE), "--out", str(tmp_path / "r"), "--params", str(tmp_path / "missing.yaml")]) == 2
    assert "missing.yaml" in capsys.readouterr().err
