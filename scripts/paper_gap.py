"""Where `paper` loses accuracy, frame by frame: reads an eval's per_frame.csv and prints, per
maneuver, what the maneuver asks (speed, yaw rate, hitch range) and where the hitch error comes
from (missed units, heading flips, yaw lag in turns). Used for docs/evaluation.md, "A faithful
paper baseline".

    python scripts/paper_gap.py REPORT_DIR/per_frame.csv [--method paper]
"""

from __future__ import annotations

import argparse
import csv
from collections import defaultdict

import numpy as np

TURNING_DEG_S = 3.0  # a unit turning faster than this is "in a turn"


def wrap_deg(a):
    return (np.asarray(a, float) + 180.0) % 360.0 - 180.0


def read_frames(path: str, method: str) -> list[dict[str, np.ndarray]]:
    """GT-vehicle rows of one method (all sensors), one dict of columns per recording and vehicle."""
    groups = defaultdict(list)
    with open(path, newline="") as fh:
        for row in csv.DictReader(fh):
            if row["method"] == method and row["kind"] == "gt" and row["subset"] == "all":
                groups[(row["recording"], row["gt_id"])].append(row)
    out = []
    for rows in groups.values():
        rows.sort(key=lambda r: float(r["stamp_s"]))
        cols = {k: np.array([_value(r[k]) for r in rows], dtype=object) for k in rows[0]}
        for k, v in cols.items():
            try:
                cols[k] = v.astype(float)
            except (TypeError, ValueError):
                pass
        out.append(with_rates(cols))
    return out


def _value(text: str):
    if text in ("True", "False"):
        return float(text == "True")
    try:
        return float(text) if text != "" else np.nan
    except ValueError:
        return text


def with_rates(rec: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Speed (m/s) and yaw rates (deg/s) of the true units, from consecutive frames."""
    dt = np.gradient(rec["stamp_s"]) if len(rec["stamp_s"]) > 1 else np.array([np.nan])
    dt = np.where(dt > 0, dt, np.nan)
    rec["speed_mps"] = np.hypot(np.gradient(rec["trailer_x_gt"]), np.gradient(rec["trailer_y_gt"])) / dt
    for unit in ("truck", "trailer"):
        yaw = np.degrees(np.unwrap(np.radians(rec[f"{unit}_yaw_gt"])))
        rec[f"{unit}_yaw_rate_deg_s"] = np.gradient(yaw) / dt
    return rec


def lag_s(rec: dict[str, np.ndarray], unit: str) -> float:
    """The delay that explains the unit's yaw error best as (true yaw rate x delay): a PCA over a
    history of past centroids points along where the unit was heading some time ago."""
    err = wrap_deg(rec[f"{unit}_yaw_est"] - rec[f"{unit}_yaw_gt"])
    rate = rec[f"{unit}_yaw_rate_deg_s"]
    ok = (rec[f"{unit}_reported"] > 0) & np.isfinite(err) & (np.abs(rate) > TURNING_DEG_S) & (np.abs(err) < 90)
    if ok.sum() < 10 or not np.any(rate[ok]):
        return float("nan")
    return float(-np.sum(err[ok] * rate[ok]) / np.sum(rate[ok] ** 2))


def maneuver_rows(recordings: list[dict[str, np.ndarray]]) -> list[dict]:
    by_maneuver = defaultdict(list)
    for rec in recordings:
        for maneuver in np.unique(rec["maneuver"]):
            keep = rec["maneuver"] == maneuver
            by_maneuver[(str(rec["vehicle"][0]), str(maneuver))].append({k: v[keep] for k, v in rec.items()})
    rows = []
    for (vehicle, maneuver), parts in sorted(by_maneuver.items()):
        g = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
        both = g["both_reported"] > 0
        err = np.abs(wrap_deg(g["hitch_err_deg"][both]))
        sq = err**2
        turning = np.abs(g["truck_yaw_rate_deg_s"][both]) > TURNING_DEG_S
        lags = {u: np.nanmedian([lag_s(p, u) for p in parts]) for u in ("truck", "trailer")}
        rows.append(
            {
                "vehicle": vehicle,
                "maneuver": maneuver,
                "frames": len(both),
                "speed p90 m/s": np.nanpercentile(g["speed_mps"], 90),
                "yaw rate p90 deg/s": np.nanpercentile(np.abs(g["truck_yaw_rate_deg_s"]), 90),
                "max hitch deg": np.nanmax(np.abs(g["hitch_gt_deg"])),
                "both reported": both.mean(),
                "hitch RMSE deg": np.sqrt(np.mean(sq)) if len(sq) else np.nan,
                "share of sq. error in turns": sq[turning].sum() / sq.sum() if sq.sum() > 0 else np.nan,
                "flip frames": int((err > 90).sum()),
                "truck lag s": lags["truck"],
                "trailer lag s": lags["trailer"],
            }
        )
    return rows


def print_markdown(rows: list[dict]) -> None:
    keys = list(rows[0])
    print("| " + " | ".join(keys) + " |")
    print("|" + "---|" * len(keys))
    for row in rows:
        cells = [f"{v:.3g}" if isinstance(v, float) else str(v) for v in row.values()]
        print("| " + " | ".join(cells) + " |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("per_frame_csv")
    parser.add_argument("--method", default="paper")
    args = parser.parse_args()
    print_markdown(maneuver_rows(read_frames(args.per_frame_csv, args.method)))


if __name__ == "__main__":
    main()
