"""Damaged recordings (a sensor file missing, cut short, or holding fewer frames): the sensors
that work keep working, in ``run`` and in the service's replay, and the damage is reported."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
from conftest import SAMPLES
from test_service_support import serve, wait_for

from i2v_loc.cli import main
from i2v_loc.recording import Recording, RecordingError

pytestmark = pytest.mark.timeout(120)
SAMPLE = SAMPLES / "man_tgx_docking"


def damaged_copy(tmp_path, broken=("l2", "l3", "l4")):
    """The sample with l2's file deleted, l3 holding its first 3 frames only, l4's file cut in half."""
    rec = tmp_path / "rec"
    shutil.copytree(SAMPLE, rec, ignore=shutil.ignore_patterns("*.png"))
    scans = rec / "scans"
    if "l2" in broken:
        (scans / "l2.npz").unlink()
    if "l3" in broken:
        with np.load(scans / "l3.npz") as data:
            arrays = {k: data[k] for k in data.files}
        arrays["range_mm"], arrays["stamp_ns"] = arrays["range_mm"][:3], arrays["stamp_ns"][:3]
        np.savez_compressed(scans / "l3.npz", **arrays)
    if "l4" in broken:
        data = (scans / "l4.npz").read_bytes()
        (scans / "l4.npz").write_bytes(data[: len(data) // 2])
    if "l1" in broken:
        (scans / "l1.npz").write_bytes(b"not a zip file")
    return rec


def test_recording_leaves_damaged_sensors_out_and_says_why(tmp_path):
    recording = Recording(damaged_copy(tmp_path))
    with pytest.raises(RecordingError, match="missing scan file of sensor l2"):
        recording.frame(0)  # strict by default
    first = recording.frame(0, skip_damaged=True)
    assert sorted(first.scans) == ["l1", "l3"]
    assert sorted(recording.frame(5, skip_damaged=True).scans) == ["l1"]
    whole = Recording(SAMPLE).frame(5)
    np.testing.assert_array_equal(recording.frame(5, skip_damaged=True).scans["l1"].points, whole.scans["l1"].points)
    damaged = recording.damaged
    assert sorted(damaged) == ["l2", "l3", "l4"]
    assert "missing scan file of sensor l2" in damaged["l2"]
    assert "holds 3 of the 60 frames; frames 3-59 of this sensor are missing" in damaged["l3"]
    assert "unreadable scan file of sensor l4" in damaged["l4"]


def test_run_writes_every_frame_from_the_working_sensors_and_says_what_it_skipped(tmp_path, capsys):
    out = tmp_path / "out.jsonl"
    code = main(["run", str(damaged_copy(tmp_path)), "--out", str(out), "--frames", "6", "--quiet"])
    err = capsys.readouterr().err
    assert code == 1
    lines = [json.loads(line) for line in out.read_text().splitlines()]
    assert [line["frame"] for line in lines] == [0, 1, 2, 3, 4, 5]
    for line in lines:
        expected = {"l2": "missing", "l4": "missing"} | ({"l3": "missing"} if line["frame"] >= 3 else {})
        assert line["faults"] == expected
    skipped = [line for line in err.splitlines() if line.startswith("skipped sensor ")]
    assert [line.split(":")[0] for line in skipped] == ["skipped sensor l2", "skipped sensor l4", "skipped sensor l3"]


def test_run_on_a_recording_no_sensor_of_which_can_be_read_is_one_line_exit_2(tmp_path, capsys):
    rec = damaged_copy(tmp_path, broken=("l1", "l2", "l4"))
    (rec / "scans" / "l3.npz").unlink()
    code = main(["run", str(rec), "--out", str(tmp_path / "out.jsonl"), "--frames", "4", "--quiet"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "no sensor can be read" in err and len(err.splitlines()) == 1


def test_service_replay_keeps_the_working_sensors_and_reports_the_damage(tmp_path):
    server, service = serve(damaged_copy(tmp_path, broken=("l2", "l4")), realtime=False, loop=True)
    with server:
        wait_for(lambda: service.runner.frames_processed >= 3, what="frames from the working sensors")
        health = service.health()
    assert health["status"] == "degraded"
    assert health["sensors"]["l1"]["status"] == "ok" and health["sensors"]["l3"]["status"] == "ok"
    reasons = "\n".join(health["reasons"])
    assert "sensor l2: fault:missing" in reasons and "missing scan file of sensor l2" in reasons
    assert "sensor l4: fault:missing" in reasons and "unreadable scan file of sensor l4" in reasons
    assert health["frames_dropped"]["source_error"] == 0


def test_service_replay_of_a_recording_no_sensor_of_which_works_has_failed(tmp_path):
    rec = damaged_copy(tmp_path, broken=("l1", "l2", "l4"))
    (rec / "scans" / "l3.npz").unlink()
    server, service = serve(rec, realtime=False, loop=True)
    with server:
        wait_for(lambda: service.runner.frames_processed >= 3, what="frames processed")
        health = service.health()
    assert health["status"] == "failed" and health["reasons"][0] == "no sensor delivers"
