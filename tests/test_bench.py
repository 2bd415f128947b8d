"""The benchmark command runs the pipeline and reports per-stage figures (no timing assertions)."""

from __future__ import annotations

import itertools
import json
import os

import numpy as np
import pytest
from conftest import SAMPLES

from i2v_loc.cli import main
from i2v_loc.commands.bench import _scaled_scan, _scaled_sensors, busy_host_warning, open3d_recipe, summarize
from i2v_loc.params import load_params
from i2v_loc.pipelines import build_pipeline
from i2v_loc.recording import Recording


def test_summarize_orders_stages_and_computes_percentiles():
    lat = [{"region": float(i), "clustering": 2.0 * i, "total": 3.0 * i} for i in range(1, 101)]
    out = summarize(lat)
    assert list(out) == ["region", "clustering", "total"]
    assert out["region"]["mean"] == 50.5
    assert out["total"]["p50"] == 151.5
    assert out["clustering"]["max"] == 200.0


@pytest.mark.parametrize("method", ["default", "paper"])
def test_bench_reports_the_stages_of_the_pipeline_in_its_order(method, tmp_path, capsys):
    recording = SAMPLES / "twizy_single_turn"
    out = tmp_path / "bench.json"
    args = ["bench", str(recording), "--method", method, "--warmup", "40", "--json", str(out)]
    assert main([*args, "--scaling", "none", "--no-open3d", "--realdata", "none"]) == 0
    report = json.loads(out.read_text())
    rec = Recording(recording)
    frames = list(rec.frames())
    stages = list(build_pipeline(load_params(rec.sensors_file), method).process(frames[0]).latency_ms)
    assert list(report["latency_ms"]) == stages and stages[-1] == "total"
    assert (report["frames"], report["warmup_frames"], report["method"]) == (len(frames) - 40, 40, method)
    assert report["points_per_frame"] == pytest.approx(
        np.mean([sum(len(s.points) for s in f.scans.values()) for f in frames])
    )
    assert set(report["startup"]) == {
        "version_s",
        "import_s",
        "build_s",
        "first_frame_ms",
        "process_start_to_first_frame_s",
    }
    assert "total" in capsys.readouterr().out
    assert report["host"]["cores"] == os.cpu_count() and report["host"]["load_1min_end"] == pytest.approx(
        os.getloadavg()[0], abs=2.0
    )


def test_a_busy_host_is_named_in_the_report():
    assert busy_host_warning({"cores": 2, "load_1min_end": 1.4}, 1) is None
    assert busy_host_warning({"cores": 2, "load_1min_end": None}, 1) is None
    warning = busy_host_warning({"cores": 2, "load_1min_end": 3.2}, 1)
    assert "busy" in warning and "3.2 on 2 cores" in warning


def test_bench_refuses_a_folder_that_is_not_a_recording(tmp_path, capsys):
    assert main(["bench", str(tmp_path), "--scaling", "none", "--no-open3d", "--realdata", "none"]) == 2
    assert "not a recording" in capsys.readouterr().err


def test_bench_refuses_an_unknown_method(capsys):
    assert main(["bench", str(SAMPLES / "twizy_single_turn"), "--method", "fastest"]) == 2
    assert "unknown method" in capsys.readouterr().err


def test_scaled_sweeps_copy_each_point_to_the_extra_beams_and_columns_at_the_same_range():
    rec = Recording(SAMPLES / "twizy_single_turn")
    params = load_params(rec.sensors_file)
    frame = next(iter(rec.frames()))
    base = params.sensors[0]
    sensors = _scaled_sensors(params.sensors, 2 * len(params.sensors), 128, 2048)
    assert [s.name for s in sensors] == [f"s{k}" for k in range(len(sensors))]
    original = frame.scans[base.name].points
    factor = (128 // base.beams) * (2048 // base.columns)
    for k in (0, len(params.sensors)):  # the first sensor and its copy half a column further
        scan = _scaled_scan(frame, params.sensors, k, sensors[k], 128, 2048)
        assert len(scan.points) == factor * len(original) == len(scan.time_offset_s)
        ranges = np.linalg.norm(scan.points, axis=1).reshape(factor, -1)
        assert np.allclose(ranges, np.linalg.norm(original, axis=1), atol=1e-3)
    fewer = _scaled_scan(frame, params.sensors, 0, sensors[0].model_copy(update={"columns": 512}), base.beams, 512)
    assert len(fewer.points) == (len(original) + 1) // 2


def test_open3d_recipe_times_every_frame_given():
    pytest.importorskip("open3d")
    rec = Recording(SAMPLES / "twizy_single_turn")
    frames = list(itertools.islice(rec.frames(), 3))
    times = open3d_recipe(frames, load_params(rec.sensors_file))
    assert len(times) == 3 and min(times) > 0


def test_default_recording_is_generated_once_into_the_cache_or_falls_back_to_the_sample(tmp_path, monkeypatch):
    from i2v_loc.commands import bench

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    calls = []

    def fake_generate(path):
        calls.append(path)
        (path / "scans").mkdir(parents=True)
        (path / "meta.yaml").write_text("format_version: 1\n")

    monkeypatch.setattr(bench, "generate_bench_recording", fake_generate)
    first, source = bench._recording(None)
    assert first == tmp_path / "i2v-loc" / "bench" / bench.BENCH_NAME and "now cached" in source
    again, source = bench._recording(None)
    assert again == first and "cached in" in source and len(calls) == 1  # generated once

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "elsewhere"))

    def failing(path):
        raise OSError("read-only cache")

    monkeypatch.setattr(bench, "generate_bench_recording", failing)
    sample, source = bench._recording(None)
    assert sample.name == "man_tgx_docking" and "committed 6 s sample" in source
