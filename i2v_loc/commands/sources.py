"""``i2v-loc sources``: the recording layouts and live sources the service reads (docs/formats.md),
what a given path is recognised as, and conversion of a recording into another layout."""

from __future__ import annotations

import argparse
import contextlib
import shutil
import tempfile
from pathlib import Path

from i2v_loc.cli import UserError

TABLE = """\
Recordings (for `run`, `eval`, `calibrate`, `bench`, and `serve --source replay:PATH`); the layout
is recognised from the files:
  REC/                      the project's recording: meta.yaml + scans/<sensor>.npz   (numpy)
  DIR/ or FILE.pcap         Ouster: <sensor>.pcap + <sensor>.json metadata per sensor (ouster-sdk)
  BAG/                      ROS 2 bag, sqlite3 (.db3) or MCAP storage, sensor_msgs/PointCloud2 one
                            topic per sensor, extrinsics from /tf_static or sensors.yaml  (rosbags)
  FILE.bag                  ROS 1 bag with PointCloud2                                   (rosbags)
  DIR/<sensor>/*.pcd        point-cloud files per sensor (or files in DIR, the sensor after the
  DIR/*.ply|*.npy|*.bin     timestamp in the name); PCD ascii/binary/binary_compressed (pypcd4),
                            PLY (open3d), NPY (N,3+), BIN: KITTI x y z i or nuScenes x y z i ring,
                            recognised by content, else set with `run --bin-layout kitti|nuscenes`
  stamps: DIR/<sensor>/timestamps.txt, else SEC_NSEC / SEC.FRACTION file names, else frame / 10 Hz
  side files used when present: sensors.yaml (extrinsics, clock offsets), ground_truth.jsonl,
  ground_truth.openlabel.json

Live sources (`serve --source ...`):
  sim[:SCENARIO]            the simulated yard (generated once, cached, loops)
  replay:PATH               any recording above (`--loop` to repeat)
  ouster-udp:DIR[@PORT,...] Ouster lidar packets on UDP (sensor metadata DIR/<sensor>.json; ports
                            default to each metadata's udp_port_lidar)

Outputs: `run --format jsonl|openlabel`; `sim --format native|pcap|rosbag2|mcap|pcd`;
`i2v-loc sources --convert REC --to FORMAT --out DIR` for an existing recording."""


def register(sub) -> None:
    p = sub.add_parser(
        "sources",
        help="list the recording layouts and live sources; check or convert a recording",
        description=TABLE,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--check", metavar="PATH", help="say which layout PATH is, its sensors, frames and rate")
    p.add_argument("--convert", metavar="REC", help="a recording (meta.yaml folder) to write in another layout")
    p.add_argument("--to", choices=["pcap", "rosbag2", "mcap", "pcd"], help="layout for --convert")
    p.add_argument("--out", help="output folder for --convert (must not exist or be empty)")
    p.add_argument("--bin-layout", choices=["kitti", "nuscenes"], help="layout of .bin clouds for --check")
    p.set_defaults(func=run)


def run(args) -> int:
    from i2v_loc.formats import convert_recording, open_recording
    from i2v_loc.recording import Recording, RecordingError

    if args.check:
        try:
            rec = open_recording(args.check, bin_layout=args.bin_layout)
            first = rec.frame(0)
        except RecordingError as err:
            raise UserError(str(err)) from err
        layout = getattr(rec, "layout", "recording")
        points = ", ".join(f"{n} {len(s.points)}" for n, s in first.scans.items())
        print(
            f"{args.check}: {layout}, {len(rec)} frames at {rec.rate_hz:g} Hz, sensors {', '.join(rec.sensor_names)}; "
            f"frame 0 points: {points}; parameters from {rec.sensors_file}"
        )
        return 0
    if args.convert:
        if not args.to or not args.out:
            raise UserError("--convert needs --to FORMAT and --out DIR")
        _check_out(Path(args.out))
        try:
            path = convert_recording(Recording(args.convert), args.out, args.to)
        except RecordingError as err:
            raise UserError(str(err)) from err
        print(f"wrote {path} ({args.to})")
        return 0
    print(TABLE)
    return 0


def _check_out(out: Path) -> None:
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise UserError(f"{out}: exists and is not an empty folder")


@contextlib.contextmanager
def converted_output(out: Path, fmt: str):
    """For ``sim --format``: yields a scratch folder for the native recording, then writes it to
    ``out`` in ``fmt``."""
    from i2v_loc.formats import convert_recording
    from i2v_loc.recording import Recording

    _check_out(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    scratch = Path(tempfile.mkdtemp(prefix=".native-", dir=out.parent))
    try:
        yield scratch / "rec"
        convert_recording(Recording(scratch / "rec"), out, fmt)
        print(f"converted to {fmt}: {out}")
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
