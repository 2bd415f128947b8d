"""The committed samples and the benchmark suite file."""

import math
from pathlib import Path

import yaml

from i2v_loc.cli import main
from i2v_loc.params import Params
from i2v_loc.recording import Recording
from i2v_loc.sim.maneuvers import SCENARIOS

SAMPLES = Path(__file__).resolve().parents[1] / "samples"


def test_samples_are_small_and_usable_for_tracking():
    total = sum(f.stat().st_size for f in SAMPLES.rglob("*") if f.is_file())
    assert total <= 20 * 1024 * 1024
    for name in ("man_tgx_docking", "twizy_single_turn", "volvo_fh_u_turn"):
        rec = Recording(SAMPLES / name)
        gt = rec.ground_truth()
        vehicles = [line["vehicles"][0] for line in gt]
        moving = sum(math.hypot(*v["truck"]["velocity"]) > 0.3 for v in vehicles)
        assert moving >= 3, name
        assert max(abs(v["hitch_deg"]) for v in vehicles) > 10.0, name
        assert all(v["truck"]["points"] > 50 and v["trailer"]["points"] > 50 for v in vehicles), name
        assert len(rec.frame(0).scans) == 4


def test_paper_suite_covers_every_vehicle_and_maneuver_for_30_s():
    entries = yaml.safe_load((SAMPLES / "suites" / "paper.yaml").read_text())["recordings"]
    pairs = {(e["vehicle"], e["scenario"]) for e in entries}
    assert pairs == {(v, s) for v in ("twizy", "man_tgx", "volvo_fh") for s in SCENARIOS}
    assert all(e["duration_s"] >= 30 for e in entries) and all(e["vehicle"] in Params().vehicles for e in entries)
    assert len({e["seed"] for e in entries}) == len(entries)


def test_suite_command_writes_one_recording_per_entry(tmp_path):
    suite = tmp_path / "mini.yaml"
    suite.write_text(
        yaml.safe_dump(
            {
                "recordings": [
                    {"vehicle": "twizy", "scenario": "straight", "seed": 1, "duration_s": 0.2, "columns": 512},
                    {"vehicle": "volvo_fh", "scenario": "standstill", "seed": 2, "duration_s": 0.2, "columns": 512},
                ]
            }
        )
    )
    assert main(["sim", "--suite", str(suite), "--out", str(tmp_path / "out")]) == 0
    assert len(Recording(tmp_path / "out" / "twizy_straight")) == 2
    assert (
        Recording(tmp_path / "out" / "volvo_fh_standstill").ground_truth()[0]["vehicles"][0]["maneuver"] == "standstill"
    )
