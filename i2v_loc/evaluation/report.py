"""The evaluation report: report.md (the paper's tables with its published figures beside ours),
metrics.json, per-frame CSVs and PNG plots."""

from __future__ import annotations

import csv
import json
import math
from collections import defaultdict
from pathlib import Path

import numpy as np

from i2v_loc.evaluation import published as pub
from i2v_loc.evaluation.calibration import LOUD, TRUE
from i2v_loc.evaluation.metrics import SUCCESS_HITCH_DEG, SUCCESS_POSITION_M, SUCCESS_YAW_DEG
from i2v_loc.evaluation.summary import MANEUVERS, summarize_groups
from i2v_loc.geometry import box_corners

STAGE_ORDER = ["concatenation", "region", "clustering", "classification", "centroid", "tracking", "orientation"]
LEAD_COLUMNS = [
    "method",
    "subset",
    "recording",
    "tag",
    "frame",
    "stamp_s",
    "kind",
    "gt_id",
    "vehicle",
    "maneuver",
    "est_id",
    "est_vehicle",
]


# --------------------------------------------------------------------------- results


def collect(task_results: list[dict]) -> dict:
    """Summaries per method and sensor subset from the results of ``run_task``."""
    records: dict[tuple, list] = defaultdict(list)
    frames: dict[tuple, list] = defaultdict(list)
    recordings, methods, subsets = [], [], []
    for result in task_results:
        t = result["task"]
        key = (t["method"], t["subset"])
        records[key] += result["records"]
        frames[key] += result["frames"]
        for seq, value in ((recordings, t["recording"]), (methods, t["method"]), (subsets, t["subset"])):
            if value not in seq:
                seq.append(value)
    subsets.sort(key=lambda s: (s == "all", s.count("+"), s))
    results = {
        m: {s: summarize_groups(records[(m, s)], frames[(m, s)]) for s in subsets if (m, s) in records} for m in methods
    }
    primary = subsets[-1]
    return {
        "recordings": recordings,
        "methods": methods,
        "subsets": subsets,
        "primary_subset": primary,
        "vehicles": {m: results[m][primary]["by_vehicle"] for m in methods if primary in results[m]},
        "results": results,
        "_records": records,
        "_frames": frames,
    }


def _clean(obj):
    """NaN and inf to null (strict JSON)."""
    if isinstance(obj, dict):
        return {str(k): _clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    if isinstance(obj, (float, np.floating)):
        return float(obj) if math.isfinite(obj) else None
    if isinstance(obj, np.integer):
        return int(obj)
    return obj


def write_report(summary: dict, out_dir: str | Path, plots: bool = True) -> dict[str, Path]:
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    files = {
        "metrics": out / "metrics.json",
        "per_frame": out / "per_frame.csv",
        "frames": out / "frame_latency.csv",
        "report": out / "report.md",
    }
    public = {k: v for k, v in summary.items() if not k.startswith("_")}
    files["metrics"].write_text(json.dumps(_clean(public), indent=1))
    all_records = [r for recs in summary["_records"].values() for r in recs]
    all_frames = [r for rows in summary["_frames"].values() for r in rows]
    _write_csv(files["per_frame"], all_records)
    _write_csv(files["frames"], all_frames)
    plot_files = write_plots(summary, out / "plots") if plots else []
    files["report"].write_text(render_markdown(summary, [p.relative_to(out) for p in plot_files]))
    return files


def _write_csv(path: Path, rows: list[dict]) -> None:
    keys = [k for k in LEAD_COLUMNS if any(k in r for r in rows[:1])]
    seen = set(keys)
    for row in rows:
        for k in row:
            if k not in seen:
                keys.append(k)
                seen.add(k)
    with open(path, "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=keys, extrasaction="ignore")
        writer.writeheader()
        for row in rows:
            writer.writerow(
                {k: ("" if v is None or (isinstance(v, float) and math.isnan(v)) else v) for k, v in row.items()}
            )


# --------------------------------------------------------------------------- markdown


def _f(value, digits: int = 2) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "–"
    return f"{value:.{digits}f}"


def _pct(value) -> str:
    return "–" if value is None or not math.isfinite(value) else f"{100 * value:.1f} %"


def _pair(a, b, digits=2) -> str:
    return f"{_f(a, digits)} / {_f(b, digits)}"


def _name(vehicle: str) -> str:
    return pub.PAPER_NAMES.get(vehicle, vehicle)


def render_markdown(summary: dict, plot_files: list[Path]) -> str:
    methods, primary = summary["methods"], summary["primary_subset"]
    res = summary["results"]
    lines = [
        "# i2v-loc evaluation report",
        "",
        f"Recordings ({len(summary['recordings'])}): {', '.join(summary['recordings'])}  ",
        f"Methods: {', '.join(methods)}; sensor subset of the main tables: `{primary}`.",
        "",
        "**Ours** are measured on the recordings above. Rows marked **published** are copied from the",
        "papers for reference only: the paper's (Justo et al.) are on *real* recordings of its test",
        "field, dCAP's on camera-based trailer poses in CARLA (STT4AT); they are not the same data.",
        "",
    ]
    calibration = summary.get("calibration") or {}
    lines += _extrinsics_banner(calibration)
    lines += _headline_table(res, methods, primary)
    lines += _calibration_table(calibration)
    lines += _method_comparison(res, methods, primary)
    lines += _table2(res, methods, primary)
    lines += _detection_table(res, methods, primary)
    lines += _dcap_table(res, methods, primary)
    lines += _maneuver_table(res, methods, primary)
    lines += _latency_table(res, methods, primary)
    if len(summary["subsets"]) > 1:
        lines += _subset_tables(res, methods, summary["subsets"])
    if plot_files:
        lines += ["## Plots", ""] + [f"![{p.stem}]({p.as_posix()})" for p in plot_files] + [""]
    lines += [
        "## Definitions",
        "",
        "- RMSE per paper Eq. 14-16; every angle difference wrapped to (-180, 180]. Ground truth is",
        "  interpolated to each state's `stamp_s`. Heading flip: |yaw error| > 90 deg (counted in the RMSE).",
        "- **Every RMSE is over the reported frames only**: a frame where the unit (for the hitch: either",
        "  unit) is missing is excluded from it. Read it beside the coverage: the share of GT frames where",
        "  the unit was reported (for the hitch, both units: `both_units_rate`).",
        f"- Success: both units reported, each within {SUCCESS_POSITION_M} m and {SUCCESS_YAW_DEG} deg and the hitch within",
        f"  {SUCCESS_HITCH_DEG} deg (inclusive), of the frames where the vehicle is visible (both units with >= 30 GT points).",
        "- A vehicle reported under a type it is not is no match: it is a false vehicle and the true one is",
        "  missed. False vehicle-seconds: unmatched reported vehicles x frame period, summed over frames.",
        "- Estimated vehicles are matched to GT vehicles of the same type by the Hungarian method on the",
        "  mean distance of their unit centres, within a gate; unmatched estimates are false vehicles.",
        "- Detection rate: frames where the unit is reported, of those where the GT gives it >= 30 points.",
        "- dCAP metrics on T_F->B (tractor front sensor -> trailer rear sensor, docs/evaluation.md):",
        "  ΔT mean translation error (m), |Δx| |Δy| |Δz| in the rear sensor's frame, RRA mean geodesic",
        "  rotation error (rad). Static calibration: the trailer rigidly straight behind (hitch 0).",
        "",
    ]
    return "\n".join(lines)


_COMPARE_ROWS = [
    ("success rate", "success_rate", None),
    ("truck coverage", "truck_coverage", None),
    ("trailer coverage", "trailer_coverage", None),
    ("both units (hitch coverage)", "both_units_rate", None),
    ("truck position RMSE [m], reported frames only", "truck_pos_rmse_m", 3),
    ("truck yaw RMSE [deg], reported frames only", "truck_yaw_rmse_deg", 2),
    ("trailer position RMSE [m], reported frames only", "trailer_pos_rmse_m", 3),
    ("trailer yaw RMSE [deg], reported frames only", "trailer_yaw_rmse_deg", 2),
    ("hitch angle RMSE [deg], both-reported frames only", "hitch_rmse_deg", 2),
    ("hitch error within 2 reported std (0.95 if honest)", "hitch_within_2std_rate", None),
    ("heading flips", "heading_flip_rate", None),
    ("truck flip frames", "truck_flip_frames", 0),
    ("trailer flip frames", "trailer_flip_frames", 0),
    ("truck detection rate", "truck_detection_rate", None),
    ("trailer detection rate", "trailer_detection_rate", None),
    ("ΔT [m]", "delta_T_m", 3),
    ("RRA [rad]", "rra_rad", 4),
    ("false vehicles", "false_vehicles", 0),
    ("false vehicle-seconds", "false_vehicle_s", 1),
    ("  of which wrong type", "wrong_type_vehicle_s", 1),
    ("  of which in the first 5 s", "false_vehicle_s_first_5s", 1),
    ("vehicle id switches", "vehicle_id_switches", 0),
    ("latency mean [ms]", "latency_ms_mean", 1),
    ("latency p95 [ms]", "latency_ms_p95", 1),
]


def _extrinsics_banner(calibration: dict) -> list[str]:
    if not calibration:
        return []
    entries = list(calibration.values())
    if all(c["status"] == TRUE for c in entries):
        return [
            "**Sensor extrinsics: the recordings' TRUE extrinsics and clock offsets (`--true-extrinsics`,",
            "diagnosis only; a deployment calibrates).**",
            "",
        ]
    lines = [
        "Sensor extrinsics: each recording calibrated from its `sensors_guess.yaml` as a deployment would",
        "(`i2v-loc calibrate`, clock offsets as in the guess); errors against the truth below the first table.",
        "",
    ]
    for c in entries:
        if c["status"] in LOUD:
            lines += [f"> **WARNING — {c['recording']}: {c['message']}**", ""]
        if c.get("warning"):
            lines += [f"> **WARNING — {c['recording']}: {c['warning']}**", ""]
    return lines


def _pct_of(s: dict, key: str) -> str:
    return _pct(s.get(key))


def _headline_table(res, methods, primary) -> list[str]:
    lines = [
        "## Summary per vehicle",
        "",
        f"Success: both units within {SUCCESS_POSITION_M} m / {SUCCESS_YAW_DEG}° and the hitch within "
        f"{SUCCESS_HITCH_DEG}°, of the frames the vehicle is visible. Coverage: GT frames with the unit reported. "
        "**RMSEs exclude the frames where the unit was missed** (the hitch: either unit). False vehicle-s: "
        "vehicles reported under this name that match no GT vehicle, in any recording.",
        "",
        "| Vehicle | Method | Success | Coverage truck / trailer / both | Hitch RMSE [deg] (reported only) "
        "| Hitch error within 2 reported std "
        "| Yaw RMSE truck / trailer [deg] (reported only) | Position RMSE truck / trailer [m] (reported only) "
        "| Flip frames truck / trailer | Length error truck / trailer [m] (track ≥ 10 s) | False vehicle-s |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for vehicle, m, s in _vehicle_summaries(res, methods, primary):
        if not s["gt_vehicle_frames"]:
            lines.append(
                f"| {_name(vehicle)} (not in the truth) | {m} | – | – | – | – | – | – | – | – | {_f(s['false_vehicle_s'], 1)} |"
            )
            continue
        lines.append(_headline_row(_name(vehicle), m, s))
    for m in methods:
        lines.append(_headline_row("**all**", m, res[m][primary]["overall"]))
    return lines + [""]


def _headline_row(name: str, method: str, s: dict) -> str:
    return (
        f"| {name} | {method} | {_pct_of(s, 'success_rate')} ({s['success_frames']}/{s['visible_frames']}) "
        f"| {_pct_of(s, 'truck_coverage')} / {_pct_of(s, 'trailer_coverage')} / {_pct_of(s, 'both_units_rate')} "
        f"| {_f(s['hitch_rmse_deg'])} | {_pct_of(s, 'hitch_within_2std_rate')} "
        f"| {_pair(s['truck_yaw_rmse_deg'], s['trailer_yaw_rmse_deg'])} "
        f"| {_pair(s['truck_pos_rmse_m'], s['trailer_pos_rmse_m'], 3)} "
        f"| {s['truck_flip_frames']} / {s['trailer_flip_frames']} "
        f"| {_pair(s['truck_length_error_m'], s['trailer_length_error_m'], 2)} | {_f(s['false_vehicle_s'], 1)} |"
    )


def _calibration_table(calibration: dict) -> list[str]:
    entries = [c for c in calibration.values() if c["status"] != TRUE]
    if not entries:
        return []
    lines = [
        "## Calibration: each sensor's error against the truth",
        "",
        "Used = the extrinsics the evaluation ran with (the calibrated ones; a refused sensor was left out: its guess).",
        "",
        "Weakest = information of the sensor's weakest horizontal direction, in overlapping structure points.",
        "",
        "| Recording | Status | Sensor | Fitness | Weakest | Used: error [cm] / [deg] | Calibrated [cm] / [deg] "
        "| Guess [cm] / [deg] | Clock offset error [ms] |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for c in entries:
        status = c["status"] + (" (cached)" if c.get("cached") else "")
        if c["status"] in LOUD:
            status = f"**{c['status'].upper()}**"
        if not c["per_sensor"]:
            lines.append(f"| {c['recording']} | {status} | – | – | – | – | – | – | – |")
        for row in c["per_sensor"]:
            lines.append(
                f"| {c['recording']} | {status} | {row['sensor']} | {_f(row.get('fitness'), 3)} "
                f"| {_f(row.get('constraint_points'), 0)} | {_pair(row.get('error_cm'), row.get('error_deg'))} "
                f"| {_pair(row.get('calibrated_error_cm'), row.get('calibrated_error_deg'))} "
                f"| {_pair(row.get('guess_error_cm'), row.get('guess_error_deg'))} | {_f(row.get('clock_error_ms'), 2)} |"
            )
    return lines + [""]


def _method_comparison(res, methods, primary) -> list[str]:
    lines = [
        "## Methods side by side (all vehicles)",
        "",
        "| metric | " + " | ".join(methods) + " |",
        "|---|" + "---|" * len(methods),
    ]
    for label, key, digits in _COMPARE_ROWS:
        cells = []
        for m in methods:
            v = res[m].get(primary, {}).get("overall", {}).get(key)
            cells.append(_pct(v) if digits is None else _f(v, digits))
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    return lines + [""]


def _vehicles(res, methods, primary) -> list[str]:
    names = {v for m in methods for v in res[m].get(primary, {}).get("by_vehicle", {})}
    order = list(pub.PAPER_NAMES)
    return sorted(names, key=lambda v: (order.index(v) if v in order else len(order), v))


def _vehicle_summaries(res, methods, primary):
    """(vehicle, method, summary) for every vehicle and method that has a summary."""
    for vehicle in _vehicles(res, methods, primary):
        for m in methods:
            s = res[m][primary]["by_vehicle"].get(vehicle)
            if s is not None:
                yield vehicle, m, s


def _table2(res, methods, primary) -> list[str]:
    lines = [
        "## Table 2 layout: overall metrics per vehicle",
        "",
        "RMSEs over the frames where the unit (hitch: both units) was reported only; coverage in the first table.",
        "",
        "| Platform | Source | Frames | Truck RMSE pos [m] / orient [deg] | Trailer RMSE pos [m] / orient [deg] "
        "| RMSE HAE [deg] | Inference time [ms] | Heading flips |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for vehicle in _vehicles(res, methods, primary):
        for m in methods:
            s = res[m][primary]["by_vehicle"].get(vehicle)
            if s is None or not s["gt_vehicle_frames"]:  # only false detections under this name
                continue
            lines.append(
                f"| {_name(vehicle)} | ours: {m} | {s['gt_vehicle_frames']} "
                f"| {_pair(s['truck_pos_rmse_m'], s['truck_yaw_rmse_deg'])} "
                f"| {_pair(s['trailer_pos_rmse_m'], s['trailer_yaw_rmse_deg'])} | {_f(s['hitch_rmse_deg'])} "
                f"| {_f(s.get('latency_ms_mean'), 1)} | {_pct(s['heading_flip_rate'])} |"
            )
        p = pub.TABLE2.get(vehicle)
        if p:
            lines.append(
                f"| {_name(vehicle)} | *published (real data)* | {p['frames']} | {_pair(*p['truck'])} "
                f"| {_pair(*p['trailer'])} | {_f(p['hitch'])} | {p['ms']} | – |"
            )
    return lines + [""]


def _detection_table(res, methods, primary) -> list[str]:
    lines = [
        "## Detection and tracking per vehicle",
        "",
        "| Vehicle | Method | Truck detected | Trailer detected | Truck flips | Trailer flips | ID switches "
        "(vehicle / truck / trailer) | False vehicles |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for vehicle, m, s in _vehicle_summaries(res, methods, primary):
        lines.append(
            f"| {_name(vehicle)} | {m} | {_pct(s['truck_detection_rate'])} | {_pct(s['trailer_detection_rate'])} "
            f"| {_pct(s['truck_heading_flip_rate'])} | {_pct(s['trailer_heading_flip_rate'])} "
            f"| {s['vehicle_id_switches']} / {s['truck_id_switches']} / {s['trailer_id_switches']} "
            f"| {s['false_vehicles']} |"
        )
    return lines + [""]


def _dcap_row(label: str, values) -> str:
    return f"| {label} | " + " | ".join(_f(v, 3) for v in values) + " |"


def _dcap_table(res, methods, primary) -> list[str]:
    lines = [
        "## dCAP metrics: tractor front -> trailer rear transform",
        "",
        "| Method | Frames | ΔT [m] | Δx [m] | Δy [m] | Δz [m] | RRA [rad] |",
        "|---|---|---|---|---|---|---|",
    ]
    first = res[methods[0]][primary]["overall"]
    keys = ("delta_T_m", "delta_x_m", "delta_y_m", "delta_z_m", "rra_rad")
    lines.append(
        f"| ours: static calibration (hitch 0) | {first['static_dcap_frames']} | "
        + " | ".join(_f(first[f"static_{k}"], 3) for k in keys)
        + " |"
    )
    for m in methods:
        s = res[m][primary]["overall"]
        lines.append(f"| ours: {m} | {s['dcap_frames']} | " + " | ".join(_f(s[k], 3) for k in keys) + " |")
    for label, values in pub.DCAP_TABLE2.items():
        lines.append(
            f"| *published (dCAP, CARLA cameras)*: {label} | – | " + " | ".join(_f(v, 3) for v in values) + " |"
        )
    lines += [
        "",
        "Per vehicle (ours):",
        "",
        "| Vehicle | Method | ΔT [m] | Δx [m] | Δy [m] | Δz [m] | RRA [rad] |",
        "|---|---|---|---|---|---|---|",
    ]
    for vehicle in _vehicles(res, methods, primary):
        s0 = res[methods[0]][primary]["by_vehicle"].get(vehicle)
        if s0:
            lines.append(f"| {_name(vehicle)} | static | " + " | ".join(_f(s0[f"static_{k}"], 3) for k in keys) + " |")
        for m in methods:
            s = res[m][primary]["by_vehicle"].get(vehicle)
            if s:
                lines.append(f"| {_name(vehicle)} | {m} | " + " | ".join(_f(s[k], 3) for k in keys) + " |")
    return lines + [""]


def _maneuver_table(res, methods, primary) -> list[str]:
    lines = [
        "## Per maneuver",
        "",
        "| Maneuver | Method | Frames | Success | Both units | Truck pos / orient | Trailer pos / orient "
        "| HAE [deg] | Flips | ΔT [m] | RRA [rad] | Truck / trailer detected | False vehicle-s |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    names = {k for m in methods for k in res[m][primary]["by_maneuver"]}
    order = list(MANEUVERS)
    for man in sorted(names, key=lambda k: (order.index(k) if k in order else len(order), k)):
        for m in methods:
            s = res[m][primary]["by_maneuver"].get(man)
            if s is None or not s["gt_vehicle_frames"]:
                continue
            lines.append(
                f"| {man} | {m} | {s['gt_vehicle_frames']} | {_pct(s['success_rate'])} | {_pct(s['both_units_rate'])} "
                f"| {_pair(s['truck_pos_rmse_m'], s['truck_yaw_rmse_deg'])} "
                f"| {_pair(s['trailer_pos_rmse_m'], s['trailer_yaw_rmse_deg'])} | {_f(s['hitch_rmse_deg'])} "
                f"| {_pct(s['heading_flip_rate'])} | {_f(s['delta_T_m'], 3)} | {_f(s['rra_rad'], 4)} "
                f"| {_pct(s['truck_detection_rate'])} / {_pct(s['trailer_detection_rate'])} "
                f"| {_f(s['false_vehicle_s'], 1)} |"
            )
    return lines + [""]


def _latency_table(res, methods, primary) -> list[str]:
    lines = ["## Latency per stage [ms] (mean / p50 / p95)", ""]
    for m in methods:
        s = res[m][primary]["overall"]
        found = {
            k[len("latency_") : -len("_ms_mean")] for k in s if k.startswith("latency_") and k.endswith("_ms_mean")
        }
        found.discard("")  # latency_ms_mean is the total
        stages = sorted(found, key=lambda st: (STAGE_ORDER.index(st) if st in STAGE_ORDER else len(STAGE_ORDER), st))
        if not stages and "latency_ms_mean" not in s:
            lines += [f"{m}: no latency in the state lines.", ""]
            continue
        lines += [f"**{m}**", "", "| Stage | mean | p50 | p95 |", "|---|---|---|---|"]
        for stage in stages:
            p = f"latency_{stage}_ms"
            lines.append(f"| {stage} | {_f(s.get(p + '_mean'))} | {_f(s.get(p + '_p50'))} | {_f(s.get(p + '_p95'))} |")
        lines.append(
            f"| **total** | {_f(s.get('latency_ms_mean'))} | {_f(s.get('latency_ms_p50'))} "
            f"| {_f(s.get('latency_ms_p95'))} |"
        )
        lines.append("")
    return lines


def _subset_tables(res, methods, subsets) -> list[str]:
    sensors = sorted({name for s in subsets if s != "all" for name in s.split("+")})
    lines = [
        "## Tables 3-5 layout: sensor subsets",
        "",
        "RMSEs over the frames where the unit (hitch: both units) was reported; beside them the success rate "
        "and the share of GT frames with both units reported (the published rows give neither), and the hitch "
        "RMSE over the frames where both units were also seen (had points from the subset's sensors).",
        "",
    ]
    vehicles = sorted(
        {v for m in methods for s in subsets for v in res[m].get(s, {}).get("by_vehicle", {})},
        key=lambda v: (list(pub.PAPER_NAMES).index(v) if v in pub.PAPER_NAMES else 9, v),
    )
    for vehicle in vehicles:
        number = pub.SUBSET_TABLE_NUMBER.get(vehicle)
        title = f"Table {number} layout" if number else "Sensor subsets"
        lines += [
            f"### {title}: {_name(vehicle)}",
            "",
            "| " + " | ".join(sensors) + " | Source | Success | Coverage both | Truck pos / orient "
            "| Trailer pos / orient | RMSE HAE [deg] | RMSE HAE where seen [deg] | Inference time [ms] |",
            "|" + "---|" * (len(sensors) + 8),
        ]
        for subset in subsets:
            members = set(subset.split("+")) if subset != "all" else set(sensors)
            marks = " | ".join("✓" if s in members else "-" for s in sensors)
            for m in methods:
                s = res[m].get(subset, {}).get("by_vehicle", {}).get(vehicle)
                if s and s["gt_vehicle_frames"]:
                    lines.append(
                        f"| {marks} | ours: {m} | {_pct_of(s, 'success_rate')} | {_pct_of(s, 'both_units_rate')} "
                        f"| {_pair(s['truck_pos_rmse_m'], s['truck_yaw_rmse_deg'])} "
                        f"| {_pair(s['trailer_pos_rmse_m'], s['trailer_yaw_rmse_deg'])} "
                        f"| {_f(s['hitch_rmse_deg'])} | {_f(s.get('hitch_rmse_seen_deg'))} "
                        f"| {_f(s.get('latency_ms_mean'), 1)} |"
                    )
            p = pub.SUBSET_TABLES.get(vehicle, {}).get(tuple(sorted(members)))
            if p:
                lines.append(
                    f"| {marks} | *published (real data)* | – | – | {_pair(p['truck_pos'], p['truck_yaw'])} "
                    f"| {_pair(p['trailer_pos'], p['trailer_yaw'])} | {_f(p['hitch'])} | – | {p['ms']} |"
                )
        lines.append("")
    return lines


# --------------------------------------------------------------------------- plots


def write_plots(summary: dict, out_dir: Path, max_recordings: int = 30) -> list[Path]:
    """Per recording a bird's-eye view and a hitch plot with one panel per method side by side,
    and the error histograms of every method overlaid."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir.mkdir(parents=True, exist_ok=True)
    methods, subset = summary["methods"], summary["primary_subset"]
    by_method = {m: summary["_records"].get((m, subset), []) for m in methods}
    by_rec: dict[str, dict[str, list[dict]]] = defaultdict(lambda: {m: [] for m in methods})
    for m, records in by_method.items():
        for r in records:
            by_rec[r["recording"]][m].append(r)
    files = []
    for name in list(by_rec)[:max_recordings]:
        for suffix, draw, size in (("bev", _draw_bev, (7, 6.5)), ("hitch", _draw_hitch, (7, 3.5))):
            fig, axes = plt.subplots(1, len(methods), figsize=(size[0] * len(methods), size[1]), squeeze=False)
            for ax, m in zip(axes[0], methods):
                draw(ax, by_rec[name][m], f"{name} ({m}, {subset})")
            files.append(_save(plt, fig, out_dir / f"{name}_{suffix}.png", 90))
    files.append(_plot_histograms(plt, by_method, out_dir / "error_histograms.png", subset))
    return files


def _save(plt, fig, path: Path, dpi: int) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return path


def _draw_bev(ax, records: list[dict], title: str) -> None:
    from matplotlib.patches import Polygon

    gt = sorted((r for r in records if r["kind"] == "gt"), key=lambda r: r["frame"])
    step = max(1, len(gt) // 12)
    styles = {("truck", "gt"): "red", ("trailer", "gt"): "red", ("truck", "est"): "green", ("trailer", "est"): "gold"}
    for i, r in enumerate(gt):
        for unit in ("truck", "trailer"):
            for tag in ("gt", "est"):
                x, y = r[f"{unit}_x_{tag}"], r[f"{unit}_y_{tag}"]
                if i % step or not (math.isfinite(x) and math.isfinite(r[f"{unit}_yaw_{tag}"])):
                    continue
                length, width = r[f"{unit}_length_{tag}"], r[f"{unit}_width_{tag}"]
                if not math.isfinite(length):
                    length, width = r[f"{unit}_length_gt"], r[f"{unit}_width_gt"]
                if not math.isfinite(length):
                    continue
                corners = box_corners((x, y), length, width, math.radians(r[f"{unit}_yaw_{tag}"]))
                ax.add_patch(
                    Polygon(
                        corners, closed=True, fill=False, edgecolor=styles[(unit, tag)], lw=1.6 if tag == "gt" else 1.0
                    )
                )
    for unit, colour in (("truck", "green"), ("trailer", "gold")):
        xs = [r[f"{unit}_x_gt"] for r in gt]
        ys = [r[f"{unit}_y_gt"] for r in gt]
        ax.plot(xs, ys, color="red", lw=0.6, alpha=0.6)
        ax.plot(
            [r[f"{unit}_x_est"] for r in gt],
            [r[f"{unit}_y_est"] for r in gt],
            ".",
            color=colour,
            ms=2,
            label=f"{unit} estimate",
        )
    ax.plot([], [], color="red", label="ground truth")
    falses = [r for r in records if r["kind"] == "false"]
    if falses:
        ax.plot(
            [r["truck_x_est"] for r in falses], [r["truck_y_est"] for r in falses], "kx", ms=4, label="false vehicle"
        )
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x east [m]")
    ax.set_ylabel("y north [m]")
    ax.set_title(title)
    ax.legend(loc="best", fontsize=8)
    ax.grid(alpha=0.3)


def _draw_hitch(ax, records: list[dict], title: str) -> None:
    gt = [r for r in records if r["kind"] == "gt"]
    for gid in sorted({r["gt_id"] for r in gt}, key=str):
        rows = sorted((r for r in gt if r["gt_id"] == gid), key=lambda r: r["stamp_s"] or 0.0)
        t = [r["stamp_s"] for r in rows]
        ax.plot(t, [r["hitch_gt_deg"] for r in rows], "r-", lw=1.5, label=f"truth (vehicle {gid})")
        ax.plot(t, [r["hitch_est_deg"] for r in rows], ".", ms=3, label=f"estimate (vehicle {gid})")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("hitch angle [deg]")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)


def _plot_histograms(plt, by_method: dict[str, list[dict]], path: Path, subset: str) -> Path:
    from i2v_loc.evaluation.summary import column

    panels = [
        ("truck_pos_err_m", "truck position error [m]"),
        ("trailer_pos_err_m", "trailer position error [m]"),
        ("truck_yaw_err_deg", "truck yaw error [deg]"),
        ("trailer_yaw_err_deg", "trailer yaw error [deg]"),
        ("hitch_err_deg", "hitch angle error [deg]"),
        ("dcap_dT_m", "dCAP ΔT [m]"),
    ]
    fig, axes = plt.subplots(2, 3, figsize=(11, 6))
    for ax, (key, label) in zip(axes.ravel(), panels):
        drawn = False
        for m, records in by_method.items():
            v = column([r for r in records if r["kind"] == "gt"], key)
            v = v[np.isfinite(v)]
            if v.size:
                ax.hist(v, bins=40, alpha=0.5, label=m)
                drawn = True
        if drawn:
            ax.legend(fontsize=7)
        else:
            ax.text(0.5, 0.5, "no data", ha="center", va="center", transform=ax.transAxes)
        ax.set_xlabel(label)
        ax.set_ylabel("frames")
    fig.suptitle(f"every method, {subset} sensors")
    return _save(plt, fig, path, 80)
