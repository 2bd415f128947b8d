"""Grid search over parameters: every combination of the grid on every recording, ranked by
the hitch-angle RMSE (the paper's most telling metric)."""

from __future__ import annotations

import csv
import itertools
import json
import math
from collections import defaultdict
from pathlib import Path

from i2v_loc.params import Params, ParamsError, apply_patch, dump_yaml, read_yaml

RANK_KEYS = {"hitch_rmse_deg": 1.0, "success_rate": -1.0}  # the rank key and its sign (ascending order)
RANK_KEY = "hitch_rmse_deg"
TIE_KEYS = ("hitch_rmse_deg", "trailer_yaw_rmse_deg", "truck_yaw_rmse_deg")
SHOWN = (
    "hitch_rmse_deg",
    "success_rate",
    "both_units_rate",
    "false_vehicle_s",
    "truck_pos_rmse_m",
    "trailer_pos_rmse_m",
    "truck_yaw_rmse_deg",
    "trailer_yaw_rmse_deg",
    "heading_flip_rate",
    "truck_detection_rate",
    "trailer_detection_rate",
    "delta_T_m",
    "rra_rad",
    "false_vehicles",
    "latency_ms_p50",
)


def load_grid(path: str | Path, base: Params) -> dict[str, list]:
    """``{dotted.path: [values]}`` from a YAML file, each path checked against the model."""
    try:
        grid = read_yaml(path)
    except ParamsError as err:
        raise ParamsError(f"grid file: {err}") from err
    if not grid:
        raise ParamsError(f"{path}: the grid is empty; map dotted parameter paths to lists of values")
    dump = base.model_dump(mode="json")
    for key, values in grid.items():
        if not isinstance(values, list) or not values:
            raise ParamsError(f"{path}: {key}: expected a non-empty list of values, got {values!r}")
        node = dump
        for part in str(key).split("."):
            if not isinstance(node, dict) or part not in node:
                raise ParamsError(f"{path}: {key}: no such parameter (at {part!r}); e.g. tracking.max_distance_m")
            node = node[part]
        if isinstance(node, (dict, list)):
            raise ParamsError(f"{path}: {key}: is a section, not a single parameter")
    return {str(k): v for k, v in grid.items()}


def nested_patch(flat: dict[str, object]) -> dict:
    patch: dict = {}
    for key, value in flat.items():
        node = patch
        parts = key.split(".")
        for part in parts[:-1]:
            node = node.setdefault(part, {})
        node[parts[-1]] = value
    return patch


def combinations(grid: dict[str, list], base: Params) -> list[tuple[dict, Params]]:
    """Every combination as (flat values, validated Params); an invalid one names its values."""
    keys = list(grid)
    out = []
    for values in itertools.product(*(grid[k] for k in keys)):
        flat = dict(zip(keys, values))
        out.append((flat, apply_patch(base, nested_patch(flat), source=f"grid combination {flat}")))
    return out


def rank(combos: list[tuple[dict, Params]], summaries: list[dict], by: str = RANK_KEY) -> list[dict]:
    """Rows sorted by ``by`` (hitch RMSE ascending or success rate descending; missing values
    last), ties broken by the hitch and yaw RMSEs."""
    rows = [
        {"combination": i, "values": flat, "metrics": summary}
        for i, ((flat, _), summary) in enumerate(zip(combos, summaries))
    ]
    sign = RANK_KEYS[by]

    def key(row):
        first = _finite_or_inf(None if row["metrics"].get(by) is None else sign * row["metrics"][by])
        return (first,) + tuple(_finite_or_inf(row["metrics"].get(k)) for k in TIE_KEYS)

    rows.sort(key=key)
    for position, row in enumerate(rows, 1):
        row["rank"] = position
    return rows


def _finite_or_inf(value) -> float:
    return float(value) if value is not None and math.isfinite(value) else math.inf


def summarize_by_tag(task_results: list[dict], n_combos: int) -> list[dict]:
    from i2v_loc.evaluation.summary import summarize

    records, frames = defaultdict(list), defaultdict(list)
    for result in task_results:
        tag = result["task"]["tag"]
        records[tag] += result["records"]
        frames[tag] += result["frames"]
    return [summarize(records[f"c{i}"], frames[f"c{i}"]) for i in range(n_combos)]


def write_sweep(
    rows: list[dict],
    combos: list[tuple[dict, Params]],
    out_dir: str | Path,
    recordings: list[str],
    with_sensors: bool = False,
    ranked_by: str = RANK_KEY,
) -> dict:
    """sweep.csv, sweep.json, sweep.md and best_params.yaml. The best parameters leave the sensors
    out unless ``with_sensors`` (the --params files set them): each recording brings its own."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    keys = list(rows[0]["values"]) if rows else []
    with open(out / "sweep.csv", "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(["rank", "combination"] + keys + list(SHOWN))
        for row in rows:
            writer.writerow(
                [row["rank"], row["combination"]]
                + [row["values"][k] for k in keys]
                + [_cell(row["metrics"].get(k)) for k in SHOWN]
            )
    (out / "sweep.json").write_text(
        json.dumps(
            {
                "recordings": recordings,
                "ranked_by": ranked_by,
                "rows": [
                    {k: row[k] for k in ("rank", "combination", "values")}
                    | {"metrics": {k: _json(v) for k, v in row["metrics"].items()}}
                    for row in rows
                ],
            },
            indent=1,
        )
    )
    best = combos[rows[0]["combination"]][1] if rows else None
    if best is not None:
        sections = [k for k in best.model_dump(mode="json") if with_sensors or k != "sensors"]
        (out / "best_params.yaml").write_text(dump_yaml(best, sections))
    lines = [
        f"# Parameter sweep ({len(rows)} combinations x {len(recordings)} recordings), ranked by {ranked_by}",
        "",
        "| rank | " + " | ".join(keys) + " | " + " | ".join(SHOWN) + " |",
        "|---|" + "---|" * (len(keys) + len(SHOWN)),
    ]
    for row in rows:
        lines.append(
            f"| {row['rank']} | "
            + " | ".join(str(row["values"][k]) for k in keys)
            + " | "
            + " | ".join(_cell(row["metrics"].get(k)) for k in SHOWN)
            + " |"
        )
    (out / "sweep.md").write_text("\n".join(lines) + "\n")
    return {"best_params": out / "best_params.yaml", "csv": out / "sweep.csv", "md": out / "sweep.md"}


def _cell(value) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return ""
    return f"{value:.4g}" if isinstance(value, float) else str(value)


def _json(value):
    return None if isinstance(value, float) and not math.isfinite(value) else value
