"""``i2v-loc calibrate``: refine the sensors' extrinsics of a recording by ICP (docs/pipeline.md)."""

from __future__ import annotations

from pathlib import Path

from i2v_loc.cli import UserError


def register(sub) -> None:
    p = sub.add_parser(
        "calibrate", help="refine sensor extrinsics from REC/sensors_guess.yaml by ICP; write a params YAML"
    )
    p.add_argument("recording", metavar="REC", help="recording folder with sensors_guess.yaml")
    p.add_argument("--out", required=True, help="parameter file to write (section 'sensors')")
    p.add_argument("--guess", help="initial guess other than REC/sensors_guess.yaml")
    p.add_argument(
        "--params", action="append", default=[], metavar="FILE", help="parameter files (calibration section)"
    )
    p.add_argument("--threads", type=int, default=1, help="open3d worker threads (default 1)")
    p.set_defaults(func=run)


def run(args) -> int:
    import sys

    import numpy as np

    from i2v_loc.evaluation.calibration import (
        accepted_sensors,
        calibrated_sensors,
        refused_message,
        run_calibration,
        sensor_errors,
        weak_warning,
    )
    from i2v_loc.formats import open_recording
    from i2v_loc.params import dump_yaml, load_params
    from i2v_loc.recording import RecordingError

    rec_path = Path(args.recording)
    try:
        recording = open_recording(rec_path)
    except RecordingError as err:
        raise UserError(str(err)) from err
    guess_file = Path(args.guess) if args.guess else recording.sensors_guess_file
    params = load_params(guess_file, *args.params)
    _set_threads(args.threads)
    print(f"calibrating {len(params.sensors)} sensors from {guess_file} ...", file=sys.stderr)

    def progress(result) -> None:
        print(f"  {result.name} registered against {result.target}", file=sys.stderr)

    try:
        results, _ = run_calibration(recording, params, progress)
    except ValueError as err:
        raise UserError(str(err)) from err
    truth = load_params(recording.sensors_file).sensors if recording.sensors_file.is_file() else []
    calibrated = calibrated_sensors(params.sensors, results)
    errors = {row["sensor"]: row for row in sensor_errors(calibrated, truth)}
    print(
        f"{'sensor':8} {'fitness':>8} {'at_guess':>8} {'rmse_m':>8} {'weakest':>8}  against"
        + ("   error_cm  error_deg" if truth else "")
    )
    for r in results:
        weakest = f"{r.constraint_points:8.0f}" if np.isfinite(r.constraint_points) else f"{'-':>8}"
        line = f"{r.name:8} {r.fitness:8.3f} {r.guess_fitness:8.3f} {r.inlier_rmse_m:8.4f} {weakest}  {r.target:10}"
        if errors[r.name]["error_cm"] is not None:
            line += f" {errors[r.name]['error_cm']:8.2f} {errors[r.name]['error_deg']:10.3f}"
        print(line)
    sensors, refused = accepted_sensors(params.sensors, results, params.calibration.min_fitness)
    warning = weak_warning(results, params.calibration.min_constraint_points)
    if warning:
        print(f"WARNING: {warning}", file=sys.stderr)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(dump_yaml(params.model_copy(update={"sensors": sensors}), ["sensors"]))
    print(f"wrote {out}")
    if refused:  # written, but not done: the refused sensors need a better guess or more overlap
        raise UserError(f"{refused_message(refused, params.calibration.min_fitness)}: in {out}")
    return 0


def _set_threads(n: int) -> None:
    import open3d as o3d

    if hasattr(o3d.utility, "set_max_threads"):  # Open3D >= 0.20 (TBB); OMP_NUM_THREADS has no effect
        o3d.utility.set_max_threads(max(1, n))
