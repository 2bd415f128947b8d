"""Aggregate per-frame records into the reported metrics, overall and per vehicle / maneuver."""

from __future__ import annotations

from collections import defaultdict

import numpy as np

from i2v_loc.evaluation import metrics as m
from i2v_loc.sim.maneuvers import LABELS

TASK_KEYS = ("method", "subset", "recording")
LENGTH_SETTLE_S = 10.0  # the learned lengths are scored after a vehicle's track is this old
EARLY_S = 5.0  # false vehicles cluster in the first seconds (no background, no track history yet)
MANEUVERS = LABELS  # the maneuver taxonomy, in the simulator's order


def column(records: list[dict], key: str) -> np.ndarray:
    return np.array([np.nan if r.get(key) is None else r.get(key) for r in records], dtype=float)


def _flag(records: list[dict], key: str) -> np.ndarray:
    return np.array([bool(r.get(key)) for r in records], dtype=bool)


def _rate(numerator: np.ndarray, denominator: np.ndarray) -> float:
    n = int(denominator.sum())
    return float((numerator & denominator).sum() / n) if n else float("nan")


def _within_2std(error: np.ndarray, std: np.ndarray) -> float:
    """Share of the frames with an error and a reported standard deviation where the error is
    within two of them: about 0.95 if the reported uncertainty is honest and the errors normal."""
    both = np.isfinite(error) & np.isfinite(std)
    return float(np.mean(np.abs(error[both]) <= 2.0 * std[both])) if both.any() else float("nan")


def _switches(records: list[dict]) -> dict[str, int]:
    """ID switches per GT object, summed: the vehicle id and each unit's track id."""
    chains: dict[tuple, list[dict]] = defaultdict(list)
    for r in records:
        if r["kind"] == "gt":
            chains[tuple(r.get(k) for k in TASK_KEYS) + (r["gt_id"],)].append(r)
    out = {"vehicle_id_switches": 0, "truck_id_switches": 0, "trailer_id_switches": 0}
    for chain in chains.values():
        chain.sort(key=lambda r: r["frame"])
        out["vehicle_id_switches"] += m.id_switches([r["est_id"] for r in chain])
        out["truck_id_switches"] += m.id_switches([r["truck_track_id"] for r in chain])
        out["trailer_id_switches"] += m.id_switches([r["trailer_track_id"] for r in chain])
    return out


def _false_seconds(false: list[dict]) -> dict[str, float]:
    """Vehicle-seconds of false vehicles (each false record lasts one frame period), of those
    reported under the type of a GT vehicle they sit on, and of those in the first EARLY_S."""
    seconds = column(false, "false_s")
    wrong = np.array([r.get("wrong_type_of") is not None for r in false], bool)
    early = column(false, "since_start_s") < EARLY_S

    def total(mask):
        return float(seconds[mask].sum()) if mask.any() else 0.0

    return {
        "false_vehicle_s": total(np.ones(len(false), bool)),
        "wrong_type_vehicle_s": total(wrong),
        "false_vehicle_s_first_5s": total(early),
    }


def _length_error_m(gt: list[dict], unit: str) -> float:
    """Median of estimated minus true length over the frames whose vehicle track is at least
    ``LENGTH_SETTLE_S`` old (NaN when there are none)."""
    error = column(gt, f"{unit}_length_est") - column(gt, f"{unit}_length_gt")
    settled = column(gt, "track_age_s") >= LENGTH_SETTLE_S
    ok = settled & np.isfinite(error)
    return float(np.median(error[ok])) if ok.any() else float("nan")


def _latency(frame_rows: list[dict]) -> dict[str, float]:
    stages = sorted({k for row in frame_rows for k in row if k.startswith("latency_")})
    out = {}
    for key in stages:
        stage = key[len("latency_") : -len("_ms")]
        stats = m.latency_stats(column(frame_rows, key))
        prefix = "latency_ms" if stage == "total" else f"latency_{stage}_ms"
        for stat, value in stats.items():
            out[f"{prefix}_{stat}"] = value
    return out


def summarize(records: list[dict], frame_rows: list[dict]) -> dict:
    """All metrics of a group of records; ``frame_rows`` are the frames the group covers."""
    gt = [r for r in records if r["kind"] == "gt"]
    out: dict = {"gt_vehicle_frames": len(gt), "frames": len(frame_rows)}
    out["frames_outside_truth"] = sum(1 for row in frame_rows if row.get("scored") is False)
    flip_errors = []
    for unit in ("truck", "trailer"):
        yaw_err = column(gt, f"{unit}_yaw_err_deg")
        flip_errors.append(yaw_err)
        out[f"{unit}_frames_in_gt"] = int(_flag(gt, f"{unit}_in_gt").sum())
        out[f"{unit}_frames_reported"] = int((_flag(gt, f"{unit}_reported") & _flag(gt, f"{unit}_in_gt")).sum())
        out[f"{unit}_detection_rate"] = _rate(_flag(gt, f"{unit}_reported"), _flag(gt, f"{unit}_eligible"))
        out[f"{unit}_pos_rmse_m"] = m.rmse(column(gt, f"{unit}_pos_err_m"))
        out[f"{unit}_yaw_rmse_deg"] = m.rmse(yaw_err)
        out[f"{unit}_heading_flip_rate"] = m.heading_flip_rate(yaw_err)
        out[f"{unit}_flip_frames"] = m.flip_count(yaw_err)
        out[f"{unit}_coverage"] = _rate(_flag(gt, f"{unit}_reported"), _flag(gt, f"{unit}_in_gt"))
        out[f"{unit}_length_error_m"] = _length_error_m(gt, unit)
    out["both_units_rate"] = _rate(_flag(gt, "both_reported"), _flag(gt, "both_in_gt"))
    visible = _flag(gt, "visible")
    out["visible_frames"] = int(visible.sum())
    out["success_frames"] = int((_flag(gt, "success") & visible).sum())
    out["success_rate"] = _rate(_flag(gt, "success"), visible)
    out["heading_flip_rate"] = m.heading_flip_rate(np.concatenate(flip_errors)) if gt else float("nan")
    hitch = column(gt, "hitch_err_deg")
    out["hitch_rmse_deg"] = m.rmse(hitch)
    out["hitch_frames"] = int(np.isfinite(hitch).sum())
    # the frames where both units were seen (each had its points; with a sensor subset, the subset's)
    out["hitch_rmse_seen_deg"] = m.rmse(hitch[visible])
    out["hitch_within_2std_rate"] = _within_2std(hitch, column(gt, "hitch_std_deg"))
    for prefix, label in (("dcap", ""), ("static", "static_")):
        dt = column(gt, f"{prefix}_dT_m")
        ok = np.isfinite(dt)
        out[f"{label}dcap_frames"] = int(ok.sum())

        def mean(a, ok=ok):
            return float(np.mean(np.abs(a[ok]))) if ok.any() else float("nan")

        out[f"{label}delta_T_m"] = mean(dt)
        for axis in "xyz":
            out[f"{label}delta_{axis}_m"] = mean(column(gt, f"{prefix}_d{axis}_m"))
        out[f"{label}rra_rad"] = mean(column(gt, f"{prefix}_rra_rad"))
    out.update(_switches(records))
    out["false_vehicles"] = sum(1 for r in records if r["kind"] == "false")
    out["false_vehicles_per_frame"] = out["false_vehicles"] / len(frame_rows) if frame_rows else float("nan")
    out.update(_false_seconds([r for r in records if r["kind"] == "false"]))
    out.update(_latency(frame_rows))
    return out


def _frame_key(row: dict) -> tuple:
    return tuple(row.get(k) for k in TASK_KEYS) + (row.get("frame"),)


def summarize_groups(records: list[dict], frame_rows: list[dict]) -> dict:
    """``overall``, ``by_vehicle``, ``by_maneuver`` and ``by_recording`` summaries."""
    frames_by_key = {_frame_key(r): r for r in frame_rows}

    def group(key: str) -> dict:
        buckets: dict[str, list[dict]] = defaultdict(list)
        for r in records:
            buckets[str(r.get(key))].append(r)
        out = {}
        for name, recs in sorted(buckets.items()):
            keys = {_frame_key(r) for r in recs}
            out[name] = summarize(recs, [frames_by_key[k] for k in keys if k in frames_by_key])
        return out

    by_recording = defaultdict(list)
    for row in frame_rows:
        by_recording[row.get("recording")].append(row)
    recs_by_recording = defaultdict(list)
    for r in records:
        recs_by_recording[r.get("recording")].append(r)
    return {
        "overall": summarize(records, frame_rows),
        "by_vehicle": group("vehicle"),
        "by_maneuver": group("maneuver"),
        "by_recording": {
            str(k): summarize(recs_by_recording.get(k, []), rows) for k, rows in sorted(by_recording.items())
        },
    }
