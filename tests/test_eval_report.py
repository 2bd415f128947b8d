"""Report, metrics.json, CSV and plots from synthetic runs; local processes and Dask agree."""

from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest
from conftest import REQUIRED

from i2v_loc.evaluation.groundtruth import wrap_deg
from i2v_loc.evaluation.report import collect, write_report
from i2v_loc.evaluation.runner import compare_task, run_tasks
from i2v_loc.params import Params


def _unit(x, y, yaw, z=1.5, dims=(3.0, 2.5, 2.5)):
    return {"center": [x, y, z], "dimensions": list(dims), "yaw_deg": yaw, "points": 400}


def synthetic_item(vehicle: str, maneuver: str, yaw_bias_deg: float, method: str, recording: str, n: int = 40) -> dict:
    """A vehicle turning on a circle; the estimate has a yaw bias on the trailer only."""
    gt, states = [], []
    for k in range(n):
        a = math.radians(3 * k)
        truck = _unit(20 * math.cos(a), 20 * math.sin(a), wrap_deg(math.degrees(a) + 90))
        trailer = _unit(20 * math.cos(a - 0.3), 20 * math.sin(a - 0.3), wrap_deg(math.degrees(a - 0.3) + 90))
        gt.append(
            {
                "frame": k,
                "stamp_s": k / 10,
                "vehicles": [
                    {
                        "id": 1,
                        "vehicle": vehicle,
                        "maneuver": maneuver,
                        "hitch_deg": wrap_deg(trailer["yaw_deg"] - truck["yaw_deg"]),
                        "truck": truck,
                        "trailer": trailer,
                    }
                ],
            }
        )
        est_trailer = dict(trailer, yaw_deg=wrap_deg(trailer["yaw_deg"] + yaw_bias_deg), track_id=2)
        states.append(
            {
                "type": "state",
                "frame": k,
                "stamp_s": k / 10,
                "latency_ms": {"clustering": 1.0, "total": 5.0},
                "vehicles": [
                    {
                        "id": 3,
                        "vehicle": vehicle,
                        "hitch_deg": None,
                        "truck": dict(truck, track_id=1),
                        "trailer": est_trailer,
                    }
                ],
            }
        )
    task = {"method": method, "subset": "all", "recording": recording, "tag": ""}
    return {"states": states, "ground_truth": gt, "params": Params().model_dump(mode="json"), "task": task}


@pytest.fixture
def items():
    return [
        synthetic_item("man_tgx", "long_curve", 1.0, "paper", "rec_a"),
        synthetic_item("volvo_fh", "u_turn", 2.0, "paper", "rec_b"),
        synthetic_item("man_tgx", "long_curve", 3.0, "default", "rec_a"),
        synthetic_item("volvo_fh", "u_turn", 4.0, "default", "rec_b"),
    ]


def test_report_files_and_values(items, tmp_path):
    summary = collect(run_tasks(items, func=compare_task, progress=False))
    files = write_report(summary, tmp_path)
    metrics = json.loads(files["metrics"].read_text())
    man = metrics["vehicles"]["paper"]["man_tgx"]
    for key in REQUIRED:
        assert key in man, key
    assert man["trailer_yaw_rmse_deg"] == pytest.approx(1.0)
    assert man["hitch_rmse_deg"] == pytest.approx(1.0)
    assert man["truck_pos_rmse_m"] == pytest.approx(0.0)
    assert man["rra_rad"] == pytest.approx(math.radians(1.0))
    assert metrics["vehicles"]["default"]["volvo_fh"]["hitch_rmse_deg"] == pytest.approx(4.0)
    assert metrics["results"]["paper"]["all"]["by_maneuver"]["u_turn"]["hitch_rmse_deg"] == pytest.approx(2.0)
    assert man["latency_ms_p50"] == pytest.approx(5.0)
    # the static baseline ignores the 17 deg articulation of this turn
    assert man["static_rra_rad"] == pytest.approx(math.radians(17.19), abs=0.01)
    report = files["report"].read_text()
    assert "| paper | default |" in report  # methods side by side
    assert "0.15 / 1.57" in report and "published (real data)" in report  # the paper's Man TGX row
    assert "1.284" in report  # dCAP's static calibration row
    with open(files["per_frame"]) as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 4 * 40
    assert {"method", "recording", "frame", "hitch_err_deg", "dcap_dT_m"} <= set(rows[0])
    pngs = sorted((tmp_path / "plots").glob("*.png"))
    assert len(pngs) == 5  # two recordings x (bird's-eye, hitch) + histograms
    assert all(p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and p.stat().st_size > 5000 for p in pngs)


def test_nan_becomes_null_in_metrics_json(tmp_path):
    item = synthetic_item("twizy", "straight", 0.0, "paper", "rec", n=3)
    for s in item["states"]:
        s["vehicles"] = []
    files = write_report(collect([compare_task(item)]), tmp_path, plots=False)
    text = files["metrics"].read_text()
    assert "NaN" not in text
    twizy = json.loads(text)["vehicles"]["paper"]["twizy"]
    assert twizy["hitch_rmse_deg"] is None and twizy["truck_detection_rate"] == 0.0


def _numbers(summary):
    """Everything but the latency (which a real pipeline measures differently per run)."""
    return json.dumps({m: s for m, s in summary["results"].items()}, sort_keys=True, default=str)


def test_local_processes_and_dask_give_the_same_results(items):
    distributed = pytest.importorskip("distributed", reason="Dask distributed (extra 'distributed') not installed")
    inline = collect(run_tasks(items, func=compare_task, progress=False))
    local = collect(run_tasks(items, func=compare_task, workers=2, progress=False))
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        dask = collect(
            run_tasks(items, func=compare_task, executor="dask", address=cluster.scheduler_address, progress=False)
        )
    assert _numbers(local) == _numbers(inline)
    assert _numbers(dask) == _numbers(inline)
    assert np.isfinite(dask["vehicles"]["paper"]["man_tgx"]["hitch_rmse_deg"])


def _plot_records(method_offset_m: float) -> list[dict]:
    rows = []
    for frame in range(5):
        row = {
            "kind": "gt",
            "frame": frame,
            "recording": "rec",
            "gt_id": 1,
            "stamp_s": frame / 10,
            "hitch_gt_deg": 10.0,
            "hitch_est_deg": 10.0 + method_offset_m,
        }
        for unit, x in (("truck", 5.0), ("trailer", -3.0)):
            row.update(
                {
                    f"{unit}_x_gt": x + frame,
                    f"{unit}_y_gt": 0.0,
                    f"{unit}_yaw_gt": 0.0,
                    f"{unit}_length_gt": 4.0,
                    f"{unit}_width_gt": 2.5,
                    f"{unit}_x_est": x + frame + method_offset_m,
                    f"{unit}_y_est": 0.0,
                    f"{unit}_yaw_est": 0.0,
                    f"{unit}_length_est": float("nan"),
                    f"{unit}_width_est": float("nan"),
                    f"{unit}_pos_err_m": method_offset_m,
                    f"{unit}_yaw_err_deg": 0.0,
                }
            )
        row.update({"hitch_err_deg": method_offset_m, "dcap_dT_m": float("nan")})
        rows.append(row)
    return rows


def test_plots_draw_every_method_side_by_side(tmp_path):
    from matplotlib.image import imread

    from i2v_loc.evaluation.report import write_plots

    def widths(methods):
        summary = {
            "methods": methods,
            "primary_subset": "all",
            "_records": {(m, "all"): _plot_records(0.1 * i) for i, m in enumerate(methods)},
        }
        files = write_plots(summary, tmp_path / "_".join(methods))
        assert sorted(f.name for f in files) == ["error_histograms.png", "rec_bev.png", "rec_hitch.png"]
        return {f.name: imread(f).shape[1] for f in files}

    one, two = widths(["paper"]), widths(["paper", "default"])
    assert two["rec_bev.png"] == 2 * one["rec_bev.png"] and two["rec_hitch.png"] == 2 * one["rec_hitch.png"]


def test_sensor_subset_tables_show_coverage_beside_the_rmse():
    """A subset that reports the vehicle in only some frames shows that share next to its RMSEs."""
    from i2v_loc.evaluation.report import _subset_tables

    def stats(success, both):
        return {
            "gt_vehicle_frames": 100,
            "success_rate": success,
            "both_units_rate": both,
            "truck_pos_rmse_m": 0.05,
            "truck_yaw_rmse_deg": 0.4,
            "trailer_pos_rmse_m": 0.04,
            "trailer_yaw_rmse_deg": 0.2,
            "hitch_rmse_deg": 0.5,
            "latency_ms_mean": 9.0,
        }

    res = {"default": {"l1": {"by_vehicle": {"man_tgx": stats(0.3, 0.42)}}, "all": {"by_vehicle": {}}}}
    lines = _subset_tables(res, ["default"], ["l1", "all"])
    header = next(line for line in lines if line.startswith("| l1 |"))
    row = next(line for line in lines if "ours: default" in line)
    cells = [c.strip() for c in row.strip("|").split("|")]
    columns = [c.strip() for c in header.strip("|").split("|")]
    assert cells[columns.index("Success")] == "30.0 %"
    assert cells[columns.index("Coverage both")] == "42.0 %"
    assert cells[columns.index("RMSE HAE [deg]")] == "0.50"
    published = next(line for line in lines if "*published" in line)
    assert len(published.strip("|").split("|")) == len(columns)
