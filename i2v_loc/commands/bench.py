"""``i2v-loc bench``: per-stage latency of the pipeline on a recording, on one core by default."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from i2v_loc.cli import UserError
from i2v_loc.params import DEFAULT_METHOD
from i2v_loc.resources import sample_recording

DEFAULT_RECORDING = sample_recording("man_tgx_docking")


def register(sub) -> None:
    p = sub.add_parser("bench", help="measure the per-stage latency of the pipeline on a recording")
    p.add_argument(
        "recording",
        nargs="?",
        default=str(DEFAULT_RECORDING),
        help="recording directory (default: the committed MAN TGX docking sample)",
    )
    p.add_argument("--method", default=DEFAULT_METHOD)
    p.add_argument("--params", action="append", default=[], help="parameter files merged over the recording's sensors")
    p.add_argument("--threads", type=int, default=1, help="threads for numpy/BLAS and open3d (default 1: one core)")
    p.add_argument("--repeat", type=int, default=1, help="passes over the recording (a fresh pipeline each pass)")
    p.add_argument("--warmup", type=int, default=5, help="frames of each pass left out of the figures")
    p.add_argument("--json", action="store_true", help="print the figures as JSON")
    p.set_defaults(func=run)


def _limit_threads(threads: int):
    from threadpoolctl import threadpool_limits

    try:
        import open3d as o3d

        if hasattr(o3d.utility, "set_max_threads"):
            o3d.utility.set_max_threads(threads)
    except ImportError:
        pass
    return threadpool_limits(limits=threads)


def summarize(latencies: list[dict[str, float]]) -> dict[str, dict[str, float]]:
    stages = list(dict.fromkeys(k for lat in latencies for k in lat))  # pipeline order
    stages.sort(key=lambda k: k == "total")
    out = {}
    for stage in stages:
        values = np.array([lat[stage] for lat in latencies if stage in lat], dtype=float)
        out[stage] = {
            "mean": float(values.mean()),
            "p50": float(np.percentile(values, 50)),
            "p95": float(np.percentile(values, 95)),
            "max": float(values.max()),
        }
    return out


def run(args) -> int:
    from i2v_loc.formats import open_recording
    from i2v_loc.params import load_params
    from i2v_loc.pipelines import build_pipeline
    from i2v_loc.recording import RecordingError

    rec_path = Path(args.recording)
    try:
        recording = open_recording(rec_path)
    except RecordingError as err:
        raise UserError(str(err)) from err
    params = load_params(recording.sensors_file, *args.params)
    frames = list(recording.frames())
    if len(frames) <= args.warmup:
        raise UserError(f"{rec_path} has {len(frames)} frames; need more than --warmup {args.warmup}")
    points = [sum(len(s.points) for s in f.scans.values()) for f in frames]

    latencies = []
    with _limit_threads(args.threads):
        for _ in range(args.repeat):
            pipeline = build_pipeline(params, args.method)
            for i, frame in enumerate(frames):
                result = pipeline.process(frame).to_json()
                if i >= args.warmup:
                    latencies.append(result["latency_ms"])
    figures = summarize(latencies)
    if args.json:
        print(
            json.dumps(
                {
                    "recording": str(rec_path),
                    "method": args.method,
                    "threads": args.threads,
                    "frames": len(latencies),
                    "mean_points": float(np.mean(points)),
                    "latency_ms": figures,
                },
                indent=2,
            )
        )
        return 0
    print(
        f"{rec_path.name}: {len(latencies)} frames, {np.mean(points):.0f} points per frame "
        f"({len(recording.sensor_names)} sensors), method {args.method}, {args.threads} thread(s)"
    )
    print(f"{'stage':<16}{'mean':>9}{'p50':>9}{'p95':>9}{'max':>9}  [ms]")
    for stage, f in figures.items():
        print(f"{stage:<16}{f['mean']:>9.2f}{f['p50']:>9.2f}{f['p95']:>9.2f}{f['max']:>9.2f}")
    sys.stdout.flush()
    return 0
