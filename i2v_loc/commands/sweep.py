"""``i2v-loc sweep``: grid search over parameters on recordings, ranked by hitch-angle RMSE."""

from __future__ import annotations

from i2v_loc.cli import UserError
from i2v_loc.params import DEFAULT_METHOD


def register(sub) -> None:
    from i2v_loc.commands.eval import add_calibration_options

    p = sub.add_parser(
        "sweep",
        help="grid search over parameters, ranked by hitch RMSE",
        description="Runs every combination of the grid (YAML: dotted parameter path -> list "
        "of values) on every recording; writes sweep.md, sweep.csv, sweep.json and "
        "best_params.yaml to --out.",
    )
    p.add_argument("inputs", nargs="+", metavar="REC_OR_SUITE", help="recording folders or folders of recordings")
    p.add_argument("--grid", required=True, help="YAML grid, e.g. 'tracking.max_distance_m: [0.5, 1.0, 2.0]'")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--method", default=DEFAULT_METHOD, help=f"the pipeline method (default: {DEFAULT_METHOD})")
    p.add_argument(
        "--params",
        action="append",
        default=[],
        metavar="FILE",
        help="parameter file merged after the defaults and each recording's sensors.yaml, before the "
        "grid values (repeatable)",
    )
    p.add_argument("--gate-m", type=float, default=4.0, help="association gate of estimated to GT vehicles (m)")
    add_calibration_options(p)
    p.add_argument("--workers", type=int, default=1)
    p.add_argument("--executor", choices=["local", "dask"], default="local")
    p.add_argument("--address", help="Dask scheduler address (default: a local cluster)")
    p.add_argument(
        "--rank-by",
        choices=["hitch_rmse_deg", "success_rate"],
        default="hitch_rmse_deg",
        help="hitch RMSE (ascending; it ignores missed frames) or success rate (descending)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def run(args) -> int:
    from i2v_loc.commands.eval import calibrate, check_methods, find_recordings
    from i2v_loc.evaluation import sweep
    from i2v_loc.evaluation.calibration import task_patch
    from i2v_loc.evaluation.runner import EvaluationError, Task, base_params, run_tasks
    from i2v_loc.params import deep_merge, load_params

    recordings = find_recordings(args.inputs)
    if "," in args.method:
        raise UserError("sweep takes one --method")
    if args.workers < 1:
        raise UserError("--workers must be >= 1")
    check_methods([args.method])
    patch = base_params(args.params)
    base = load_params(*args.params)
    grid = sweep.load_grid(args.grid, base)
    if any(key.startswith("calibration.") for key in grid):
        raise UserError("calibration parameters cannot be swept: each recording is calibrated once before the sweep")
    combos = sweep.combinations(grid, base)
    try:
        calibrations = calibrate(recordings, patch, args)
        tasks = [
            Task(
                str(rec),
                args.method,
                None,
                task_patch(deep_merge(patch, sweep.nested_patch(flat)), calibrations[str(rec)]),
                None,
                args.gate_m,
                tag=f"c{i}",
            )
            for i, (flat, _) in enumerate(combos)
            for rec in recordings
        ]
        results = run_tasks(
            tasks,
            workers=args.workers,
            executor=args.executor,
            address=args.address,
            progress=not args.quiet,
            desc="sweeping",
        )
    except EvaluationError as err:
        raise UserError(str(err).split("\nTraceback")[0]) from err
    rows = sweep.rank(combos, sweep.summarize_by_tag(results, len(combos)), args.rank_by)
    files = sweep.write_sweep(
        rows, combos, args.out, [r.name for r in recordings], with_sensors="sensors" in patch, ranked_by=args.rank_by
    )
    best = rows[0]
    print(
        f"best of {len(rows)}: {best['values']} -> hitch RMSE {best['metrics'].get('hitch_rmse_deg')}, "
        f"success rate {best['metrics'].get('success_rate')}"
    )
    print(f"best parameters: {files['best_params']}; table: {files['md']}")
    return 0
