"""``i2v-loc eval``: run the pipeline on recordings and report the paper's and dCAP's metrics."""

from __future__ import annotations

import itertools
from pathlib import Path

from i2v_loc.cli import UserError
from i2v_loc.params import DEFAULT_METHOD


def register(sub) -> None:
    p = sub.add_parser(
        "eval",
        help="evaluate methods on recordings or suites against the ground truth",
        description="Evaluate on recordings (or suites = folders of recordings); writes "
        "report.md, metrics.json, per_frame.csv and plots to --out.",
    )
    p.add_argument("inputs", nargs="+", metavar="REC_OR_SUITE", help="recording folders or folders of recordings")
    p.add_argument("--out", required=True, help="report folder")
    p.add_argument(
        "--method",
        default=DEFAULT_METHOD,
        help=f"comma-separated methods, e.g. paper,default (default: {DEFAULT_METHOD})",
    )
    p.add_argument("--subsets", action="store_true", help="also evaluate all 15 non-empty subsets of the LiDARs")
    p.add_argument(
        "--params",
        action="append",
        default=[],
        metavar="FILE",
        help="parameter file merged after the defaults and each recording's sensors.yaml, as in "
        "`i2v-loc run` (repeatable; a sensors section here replaces the recording's sensors)",
    )
    p.add_argument(
        "--labels",
        help="ground truth other than ground_truth.jsonl: OpenLABEL or labelCloud labels "
        "(file or folder); only with a single recording",
    )
    p.add_argument("--gate-m", type=float, default=4.0, help="association gate of estimated to GT vehicles (m)")
    add_calibration_options(p)
    p.add_argument("--workers", type=int, default=1, help="parallel processes (or Dask workers of a local cluster)")
    p.add_argument("--executor", choices=["local", "dask"], default="local")
    p.add_argument("--address", help="Dask scheduler, e.g. tcp://10.0.0.5:8786 (default: a local cluster)")
    p.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def add_calibration_options(p) -> None:
    p.add_argument(
        "--true-extrinsics",
        action="store_true",
        help="run with each recording's true sensors.yaml instead of calibrating from its "
        "sensors_guess.yaml first (diagnosis only)",
    )
    p.add_argument(
        "--calibration-cache",
        metavar="DIR",
        help="where calibrations are cached (default ~/.cache/i2v-loc/calibration)",
    )


def calibrate(recordings: list[Path], patch: dict, args) -> dict[str, dict]:
    """Each recording's calibration (cached), its loud problems printed to stderr."""
    import sys

    from i2v_loc.evaluation.calibration import LOUD, calibrate_recordings

    calibrations = calibrate_recordings(
        recordings,
        patch,
        args.true_extrinsics,
        args.calibration_cache,
        workers=args.workers,
        executor=args.executor,
        address=args.address,
        progress=not args.quiet,
    )
    for c in calibrations.values():
        if c["status"] in LOUD:
            print(f"WARNING {c['recording']}: {c['message']}", file=sys.stderr)
        if c.get("warning"):
            print(f"WARNING {c['recording']}: {c['warning']}", file=sys.stderr)
    return calibrations


def find_recordings(inputs: list[str]) -> list[Path]:
    """Recordings (any layout of `i2v-loc sources`) given directly or one level inside suite folders."""
    from i2v_loc.formats import looks_like_recording

    found: list[Path] = []
    for item in inputs:
        path = Path(item)
        if not path.is_dir():
            raise UserError(f"{path}: no such folder")
        if looks_like_recording(path):
            found.append(path)
            continue
        inner = sorted(d for d in path.iterdir() if d.is_dir() and looks_like_recording(d))
        if not inner:
            raise UserError(f"{path}: neither a recording (any layout of `i2v-loc sources`) nor a suite of recordings")
        found += inner
    return found


def parse_methods(text: str) -> list[str]:
    methods = [m.strip() for m in text.split(",") if m.strip()]
    if not methods:
        raise UserError("--method needs at least one method name")
    return list(dict.fromkeys(methods))


def check_methods(methods: list[str]) -> None:
    """A clear error for an unknown method, before any work is started."""
    from i2v_loc.pipelines import method_name

    for method in methods:
        try:
            method_name(method)
        except ValueError as err:
            raise UserError(str(err)) from err


def sensor_subsets(names: list[str]) -> list[tuple[str, ...]]:
    """All non-empty subsets, singles first (the paper's Tables 3-5 order)."""
    return [combo for k in range(1, len(names) + 1) for combo in itertools.combinations(names, k)]


def build_tasks(
    recordings: list[Path],
    methods: list[str],
    subsets: bool,
    params: dict,
    labels: str | None,
    gate_m: float,
    calibrations: dict[str, dict] | None = None,
) -> list:
    """One task per recording, method and sensor subset; a recording's calibrated sensors (if
    any, ``calibrations`` keyed by its path) come before the --params patch."""
    from i2v_loc.evaluation.calibration import task_patch
    from i2v_loc.evaluation.runner import Task
    from i2v_loc.formats import open_recording
    from i2v_loc.recording import RecordingError

    tasks = []
    for rec_path in recordings:
        try:
            names = open_recording(rec_path).sensor_names
        except RecordingError as err:
            raise UserError(str(err)) from err
        choices = sensor_subsets(names) if subsets else [None]
        patch = task_patch(params, (calibrations or {}).get(str(rec_path), {}))
        for method in methods:
            for sensors in choices:
                tasks.append(Task(str(rec_path), method, sensors, patch, labels, gate_m))
    return tasks


def run(args) -> int:
    from i2v_loc.evaluation.report import collect, write_report
    from i2v_loc.evaluation.runner import EvaluationError, base_params, run_tasks

    recordings = find_recordings(args.inputs)
    methods = parse_methods(args.method)
    if args.labels and len(recordings) != 1:
        raise UserError("--labels applies to a single recording")
    if args.workers < 1:
        raise UserError("--workers must be >= 1")
    check_methods(methods)
    params = base_params(args.params)
    try:
        calibrations = calibrate(recordings, params, args)
        tasks = build_tasks(recordings, methods, args.subsets, params, args.labels, args.gate_m, calibrations)
        results = run_tasks(
            tasks, workers=args.workers, executor=args.executor, address=args.address, progress=not args.quiet
        )
    except EvaluationError as err:
        raise UserError(str(err).split("\nTraceback")[0]) from err
    summary = collect(results)
    summary["calibration"] = calibrations
    files = write_report(summary, args.out, plots=not args.no_plots)
    print_summary(summary)
    print(f"report: {files['report']}")
    return 0


def print_summary(summary: dict) -> None:
    primary = summary["primary_subset"]
    for c in (summary.get("calibration") or {}).values():
        errors = [r for r in c["per_sensor"] if r.get("error_cm") is not None]
        worst = (
            f"; worst sensor error {max(r['error_cm'] for r in errors):.2f} cm / "
            f"{max(r['error_deg'] for r in errors):.3f} deg"
            if errors
            else ""
        )
        print(f"extrinsics {c['recording']}: {c['status']}{' (cached)' if c.get('cached') else ''}{worst}")
    for method in summary["methods"]:
        for vehicle, s in summary["results"][method][primary]["by_vehicle"].items():
            if not s["gt_vehicle_frames"]:
                print(
                    f"{method:>10} {vehicle:>10}: not in the ground truth; {s['false_vehicles']} false detections "
                    f"({s['false_vehicle_s']:.1f} vehicle-s)"
                )
                continue

            def f(key, digits=2, s=s):
                v = s.get(key)
                return "-" if v is None or v != v else f"{v:.{digits}f}"

            print(
                f"{method:>10} {vehicle:>10}: frames {s['gt_vehicle_frames']}, success {f('success_rate', 3)}, "
                f"both units {f('both_units_rate', 3)}, false {f('false_vehicle_s', 1)} vehicle-s; "
                f"over reported frames: truck {f('truck_pos_rmse_m')} m / "
                f"{f('truck_yaw_rmse_deg')} deg, trailer {f('trailer_pos_rmse_m')} m / {f('trailer_yaw_rmse_deg')} deg, "
                f"HAE {f('hitch_rmse_deg')} deg, flips {f('heading_flip_rate', 3)}, ΔT {f('delta_T_m', 3)} m, "
                f"RRA {f('rra_rad', 4)} rad, latency p50 {f('latency_ms_p50', 1)} ms"
            )
