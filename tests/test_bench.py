"""The benchmark command runs the pipeline and reports per-stage figures (no timing assertions)."""

from __future__ import annotations

import json

from conftest import SAMPLES

from i2v_loc.cli import main
from i2v_loc.commands.bench import summarize


def test_summarize_orders_stages_and_computes_percentiles():
    lat = [{"region": float(i), "clustering": 2.0 * i, "total": 3.0 * i} for i in range(1, 101)]
    out = summarize(lat)
    assert list(out) == ["region", "clustering", "total"]
    assert out["region"]["mean"] == 50.5
    assert out["total"]["p50"] == 151.5
    assert out["clustering"]["max"] == 200.0


def test_bench_command_reports_every_stage(capsys):
    assert main(["bench", str(SAMPLES / "twizy_single_turn"), "--warmup", "40", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["frames"] == 10
    assert {"merge", "front_end", "candidates", "vehicles", "total"} == set(report["latency_ms"])
    assert report["latency_ms"]["total"]["p95"] >= report["latency_ms"]["total"]["p50"] > 0


def test_bench_refuses_a_folder_that_is_not_a_recording(tmp_path, capsys):
    assert main(["bench", str(tmp_path)]) == 2
    assert "not a recording" in capsys.readouterr().err
