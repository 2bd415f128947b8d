"""``i2v-loc sim``: generate a simulated yard recording (or the whole benchmark suite)."""

from __future__ import annotations

from pathlib import Path

SUITES_DIR = Path(__file__).resolve().parents[2] / "samples" / "suites"


def register(sub) -> None:
    from i2v_loc.sim.maneuvers import SCENARIOS

    p = sub.add_parser("sim", help="generate a simulated recording of vehicles in the yard")
    p.add_argument("--vehicle", default="man_tgx", help="vehicle name from the parameters (default man_tgx)")
    p.add_argument("--vehicles", help="several vehicles at once, comma separated (overrides --vehicle)")
    p.add_argument("--scenario", default="docking", choices=SCENARIOS)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--duration", type=float, default=30.0, help="seconds to record (default 30)")
    p.add_argument("--start", type=float, default=0.0, help="skip this many seconds of the maneuver")
    p.add_argument("--out", required=True, help="recording directory to write")
    p.add_argument("--sensors", help="parameter file with the sensors (default: the paper's field)")
    p.add_argument("--columns", type=int, choices=[512, 1024, 2048], help="columns of every sensor")
    p.add_argument("--slope-deg", type=float, default=0.0, help="ground grade along +x in degrees")
    p.add_argument("--no-distractors", action="store_true", help="no car and pedestrians")
    p.add_argument("--preview", help="write a bird's-eye-view PNG of the middle frame here")
    p.add_argument("--format", default="native", choices=["native", "pcap", "rosbag2", "mcap", "pcd"],
                   help="layout of --out (docs/formats.md; default native: meta.yaml + scans/*.npz)")
    p.add_argument("--suite", help="generate every entry of a suite (name in samples/suites/ or a YAML file) into --out")
    p.set_defaults(func=_run)


def _run(args) -> int:
    from i2v_loc.cli import UserError
    from i2v_loc.params import load_params

    params = load_params(args.sensors) if args.sensors else load_params()
    if args.suite:
        if args.format != "native":
            raise UserError("--format applies to one recording; convert suite entries with `i2v-loc sources --convert`")
        return _run_suite(args, params)
    vehicles = [v.strip() for v in (args.vehicles or args.vehicle).split(",") if v.strip()]
    unknown = [v for v in vehicles if v not in params.vehicles]
    if unknown:
        raise UserError(f"unknown vehicle(s) {', '.join(unknown)}; known: {', '.join(params.vehicles)}")
    if args.duration <= 0 or args.duration > 600:
        raise UserError(f"--duration must be in (0, 600] seconds, got {args.duration}")
    if abs(args.slope_deg) > 10:
        raise UserError(f"--slope-deg must be within ±10 degrees, got {args.slope_deg}")
    entry = {"vehicles": vehicles, "scenario": args.scenario, "seed": args.seed, "duration_s": args.duration,
             "start_s": args.start, "columns": args.columns, "slope_deg": args.slope_deg, "distractors": not args.no_distractors}
    if args.format != "native":
        from i2v_loc.commands.sources import converted_output

        with converted_output(Path(args.out), args.format) as native:
            _generate(entry, params, native, args.preview)
        return 0
    _generate(entry, params, Path(args.out), args.preview)
    return 0


def _generate(entry: dict, params, out: Path, preview: str | None, position: int = 0) -> None:
    from tqdm import tqdm

    from i2v_loc.cli import UserError
    from i2v_loc.recording import Recording
    from i2v_loc.sim.generate import SimConfig, run
    from i2v_loc.sim.preview import render_preview

    cfg = SimConfig(params=params, **entry)
    label = f"{'+'.join(cfg.vehicles)} {cfg.scenario}"
    with tqdm(total=int(round(cfg.duration_s * params.sensors[0].rate_hz)), desc=label, unit="frame", position=position) as bar:
        try:
            sim, path = run(cfg, out, progress=bar.update)
        except ValueError as err:
            raise UserError(str(err)) from err
    if preview:
        render_preview(Recording(path), preview)
    print(f"wrote {path} ({sim.n_frames} frames, {len(sim.lidars)} sensors)" + (f", preview {preview}" if preview else ""))


def _run_suite(args, params) -> int:
    import yaml

    from i2v_loc.cli import UserError

    suite_file = Path(args.suite)
    if not suite_file.is_file():
        suite_file = SUITES_DIR / f"{args.suite}.yaml"
    if not suite_file.is_file():
        known = sorted(p.stem for p in SUITES_DIR.glob("*.yaml"))
        raise UserError(f"no suite {args.suite!r} (a YAML file or one of: {', '.join(known)})")
    suite = yaml.safe_load(suite_file.read_text()) or {}
    entries = suite.get("recordings")
    if not isinstance(entries, list) or not entries:
        raise UserError(f"{suite_file}: expected a non-empty list under 'recordings'")
    out = Path(args.out)
    allowed = {"vehicles", "scenario", "seed", "duration_s", "start_s", "columns", "slope_deg", "distractors"}
    for i, entry in enumerate(entries):
        extra = set(entry) - allowed - {"vehicle", "name"}
        if extra or "scenario" not in entry:
            raise UserError(f"{suite_file}: entry {i} needs 'scenario' and may have {sorted(allowed | {'vehicle', 'name'})}; got {sorted(entry)}")
        vehicles = entry.get("vehicles") or [entry.get("vehicle", "man_tgx")]
        name = entry.get("name") or f"{'_'.join(vehicles)}_{entry['scenario']}"
        clean = {k: v for k, v in entry.items() if k in allowed}
        clean["vehicles"] = vehicles
        _generate(clean, params, out / name, str(out / name / "preview.png") if args.preview else None)
    print(f"suite {suite_file.stem}: {len(entries)} recordings in {out}")
    return 0
