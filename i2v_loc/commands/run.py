"""``i2v-loc run``: the pipeline over a recording, one state line (docs/formats.md) per frame."""

from __future__ import annotations

import contextlib
import json
import sys
from pathlib import Path

from i2v_loc.cli import UserError
from i2v_loc.params import DEFAULT_METHOD


def register(sub) -> None:
    p = sub.add_parser(
        "run",
        help="run the localization pipeline on a recording, write state lines (JSONL)",
        description="Exit status: 0, or 1 when damaged sensors were left out (the output holds "
        "every frame, from the sensors that could be read; stderr says what was skipped), "
        "2 for bad input.",
    )
    p.add_argument("recording", metavar="REC", help="recording in any layout of `i2v-loc sources` (docs/formats.md)")
    p.add_argument("--out", required=True, help="output file of state lines (missing parent folders are created)")
    p.add_argument(
        "--format",
        default="jsonl",
        choices=["jsonl", "openlabel", "rosbag2", "mcap"],
        help="jsonl: one state line per frame (default); openlabel: ASAM OpenLABEL (TRUCK/TRAILER cuboids); "
        "rosbag2/mcap: a ROS 2 bag folder with the lines as std_msgs/String on /i2v_loc/states",
    )
    p.add_argument(
        "--bin-layout", choices=["kitti", "nuscenes"], help="layout of .bin clouds when their content fits both"
    )
    p.add_argument("--method", default=DEFAULT_METHOD, help=f"pipeline method (default: {DEFAULT_METHOD})")
    p.add_argument("--sensors", help="comma-separated subset of the sensors, e.g. l1,l4 (default: all)")
    p.add_argument("--vehicles", help="comma-separated subset of the configured vehicles to look for (default: all)")
    p.add_argument(
        "--params",
        action="append",
        default=[],
        metavar="FILE",
        help="parameter file merged after the defaults and REC/sensors.yaml (repeatable)",
    )
    p.add_argument("--frames", type=int, metavar="N", help="only the first N frames (N >= 1)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def parse_list(text: str | None, known: list[str], what: str) -> list[str] | None:
    if text is None:
        return None
    names = [n.strip() for n in text.split(",") if n.strip()]
    unknown = [n for n in names if n not in known]
    if not names or unknown:
        raise UserError(f"unknown {what} {', '.join(unknown) or '(none given)'}; known: {', '.join(known)}")
    return names


def restricted_params(params, sensors: list[str] | None, vehicles: list[str] | None):
    update = {}
    if sensors:
        update["sensors"] = [s for s in params.sensors if s.name in sensors]
    if vehicles:
        update["vehicles"] = {k: v for k, v in params.vehicles.items() if k in vehicles}
    return params.model_copy(update=update) if update else params


def run(args) -> int:
    from tqdm import tqdm

    from i2v_loc.formats import open_recording
    from i2v_loc.params import load_params
    from i2v_loc.pipelines import build_pipeline, method_name
    from i2v_loc.recording import RecordingError

    rec_path = Path(args.recording)
    if args.frames is not None and args.frames < 1:
        raise UserError(f"--frames must be at least 1, got {args.frames}")
    try:
        method_name(args.method)
    except ValueError as err:
        raise UserError(str(err)) from err
    try:
        recording = open_recording(rec_path, bin_layout=args.bin_layout)
    except RecordingError as err:
        raise UserError(str(err)) from err
    params = load_params(recording.sensors_file, *args.params)
    sensors = parse_list(args.sensors, recording.sensor_names, "sensor")
    vehicles = parse_list(args.vehicles, list(params.vehicles), "vehicle")
    params = restricted_params(params, sensors, vehicles)
    pipeline = build_pipeline(params, args.method)
    n_frames = len(recording) if args.frames is None else min(args.frames, len(recording))
    if n_frames == 0:
        raise UserError(f"{rec_path}: the recording has no frames")
    first = recording.frame(0, sensors, skip_damaged=True)
    if not first.scans:
        raise UserError(f"{rec_path}: no sensor can be read: " + "; ".join(recording.damaged.values()))
    out = Path(args.out)
    if args.format in ("rosbag2", "mcap") and out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise UserError(f"{out}: exists and is not an empty folder; a bag is written into a new folder")
    out.parent.mkdir(parents=True, exist_ok=True)
    summary = Summary()
    lines = []
    with out.open("w") if args.format == "jsonl" else contextlib.nullcontext() as f:
        for index in tqdm(range(n_frames), desc=rec_path.name, unit="frame", disable=args.quiet, file=sys.stderr):
            try:
                frame = first if index == 0 else recording.frame(index, sensors, skip_damaged=True)
            except RecordingError as err:  # a file of the recording that is read per frame
                raise UserError(str(err)) from err
            line = pipeline.process(frame).to_json()
            if args.format == "jsonl":
                f.write(json.dumps(line, separators=(",", ":")) + "\n")
            else:
                lines.append(line)
            summary.add(line)
    if args.format == "openlabel":
        from i2v_loc.formats.openlabel_out import write_openlabel

        write_openlabel(lines, out)
    elif args.format in ("rosbag2", "mcap"):
        from i2v_loc.formats.rosbag import write_states_bag

        try:
            write_states_bag(lines, out, storage="mcap" if args.format == "mcap" else "sqlite3")
        except RecordingError as err:
            raise UserError(str(err)) from err
    print(summary.text(out, pipeline.counters))
    source_counts = {k: v for k, v in getattr(recording, "counters", {}).items() if v and not k.endswith(".packets")}
    if source_counts:  # e.g. lost or foreign packets of an Ouster pcap
        print("source: " + ", ".join(f"{k} {v}" for k, v in sorted(source_counts.items())))
    for name, reason in recording.damaged.items():
        print(f"skipped sensor {name}: {reason}", file=sys.stderr)
    return 1 if recording.damaged else 0


class Summary:
    def __init__(self):
        self.frames = 0
        self.both_units = 0
        self.any_vehicle = 0
        self.latency: dict[str, float] = {}

    def add(self, line: dict) -> None:
        self.frames += 1
        vehicles = line["vehicles"]
        self.any_vehicle += bool(vehicles)
        self.both_units += any(v["truck"] and v["trailer"] for v in vehicles)
        for stage, ms in line["latency_ms"].items():
            self.latency[stage] = self.latency.get(stage, 0.0) + ms

    def text(self, out: Path, counters) -> str:
        n = max(self.frames, 1)
        mean = {k: v / n for k, v in self.latency.items()}
        stages = ", ".join(f"{k} {v:.2f}" for k, v in mean.items() if k != "total")
        faults = ", ".join(f"{k} {v}" for k, v in sorted(counters.items()) if k != "frames" and v) or "none"
        return (
            f"{out}: {self.frames} frames, {self.any_vehicle} with a vehicle, {self.both_units} with both units\n"
            f"mean latency {mean.get('total', 0.0):.2f} ms ({stages})\n"
            f"counters: {faults}"
        )
