"""``i2v-loc sim``: generate a simulated yard recording (or the whole benchmark suite)."""

from __future__ import annotations

from pathlib import Path

from i2v_loc.resources import suites_dir

SUITES_DIR = suites_dir()


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
    p.add_argument(
        "--vehicles-file",
        metavar="FILE",
        help="extra vehicles for the simulator only (format of params/vehicles.yaml); the recording "
        "does not give the pipeline their dimensions and the ground truth names them unknown_<name>",
    )
    p.add_argument("--columns", type=int, choices=[512, 1024, 2048], help="columns of every sensor")
    p.add_argument("--slope-deg", type=float, default=0.0, help="ground grade along +x in degrees")
    p.add_argument("--no-distractors", action="store_true", help="no car and pedestrians")
    p.add_argument(
        "--clutter-near", action="store_true", help="containers and parked trailers right beside the vehicles' paths"
    )
    p.add_argument(
        "--preview",
        nargs="?",
        const="",
        metavar="PNG",
        help="write a bird's-eye-view PNG of the middle frame here (no value: preview.png in each recording)",
    )
    p.add_argument(
        "--format",
        default="native",
        choices=["native", "pcap", "rosbag2", "mcap", "pcd"],
        help="layout of --out (docs/formats.md; default native: meta.yaml + scans/*.npz)",
    )
    p.add_argument(
        "--suite", help="generate every entry of a suite (name in samples/suites/ or a YAML file) into --out"
    )
    p.add_argument(
        "--seed-offset",
        type=int,
        default=0,
        help="with --suite: add this to every entry's seed (the same recordings under other random draws: a held-out check)",
    )
    p.set_defaults(func=_run)


def _run(args) -> int:
    from i2v_loc.cli import UserError
    from i2v_loc.params import load_params

    params = load_params(args.sensors) if args.sensors else load_params()
    if args.suite:
        if args.format != "native":
            raise UserError("--format applies to one recording; convert suite entries with `i2v-loc sources --convert`")
        return _run_suite(args, params)
    if args.seed_offset:
        raise UserError("--seed-offset applies to --suite; give one recording its seed with --seed")
    extra = _extra_vehicles(args.vehicles_file, params)
    vehicles = [v.strip() for v in (args.vehicles or args.vehicle).split(",") if v.strip()]
    unknown = [v for v in vehicles if v not in params.vehicles and v not in extra]
    if unknown:
        raise UserError(f"unknown vehicle(s) {', '.join(unknown)}; known: {', '.join([*params.vehicles, *extra])}")
    _check_ranges(args.duration, args.slope_deg, "--duration", "--slope-deg")
    entry = {
        "vehicles": vehicles,
        "scenario": args.scenario,
        "seed": args.seed,
        "duration_s": args.duration,
        "start_s": args.start,
        "columns": args.columns,
        "slope_deg": args.slope_deg,
        "distractors": not args.no_distractors,
        "clutter_near": args.clutter_near,
        "extra_vehicles": extra,
    }
    preview = args.preview or (str(Path(args.out) / "preview.png") if args.preview == "" else None)
    if args.format != "native":
        from i2v_loc.commands.sources import converted_output

        with converted_output(Path(args.out), args.format) as native:
            _generate(entry, params, native, preview)
        return 0
    _generate(entry, params, Path(args.out), preview)
    return 0


def _check_ranges(duration_s, slope_deg, duration_name: str, slope_name: str) -> None:
    from i2v_loc.cli import UserError

    if not isinstance(duration_s, (int, float)) or not 0 < duration_s <= 600:
        raise UserError(f"{duration_name} must be in (0, 600] seconds, got {duration_s}")
    if not isinstance(slope_deg, (int, float)) or abs(slope_deg) > 10:
        raise UserError(f"{slope_name} must be within ±10 degrees, got {slope_deg}")


def _extra_vehicles(path, params) -> dict:
    from i2v_loc.sim.generate import load_vehicles_file

    return load_vehicles_file(path, known=params.vehicles) if path else {}


def _generate(entry: dict, params, out: Path, preview: str | None, position: int = 0) -> None:
    from tqdm import tqdm

    from i2v_loc.cli import UserError
    from i2v_loc.recording import Recording
    from i2v_loc.sim.generate import SimConfig, run
    from i2v_loc.sim.preview import render_preview

    cfg = SimConfig(params=params, **entry)
    label = f"{'+'.join(cfg.vehicles)} {cfg.scenario}"
    with tqdm(
        total=int(round(cfg.duration_s * params.sensors[0].rate_hz)), desc=label, unit="frame", position=position
    ) as bar:
        try:
            sim, path = run(cfg, out, progress=bar.update)
        except ValueError as err:
            raise UserError(str(err)) from err
    if preview:
        render_preview(Recording(path), preview)
    print(
        f"wrote {path} ({sim.n_frames} frames, {len(sim.lidars)} sensors)" + (f", preview {preview}" if preview else "")
    )


def _run_suite(args, params) -> int:
    import yaml

    from i2v_loc.cli import UserError

    suite_file = Path(args.suite)
    if not suite_file.is_file():
        suite_file = SUITES_DIR / f"{args.suite}.yaml"
    if not suite_file.is_file():
        known = sorted(p.stem for p in SUITES_DIR.glob("*.yaml") if "\nrecordings:" in "\n" + p.read_text())
        raise UserError(f"no suite {args.suite!r} (a YAML file or one of: {', '.join(known)})")
    suite = yaml.safe_load(suite_file.read_text()) or {}
    entries = suite.get("recordings")
    if not isinstance(entries, list) or not entries:
        raise UserError(f"{suite_file}: expected a non-empty list under 'recordings'")
    out = Path(args.out)
    cases = [suite_case(suite_file, i, entry, params, args.vehicles_file) for i, entry in enumerate(entries)]
    names = [name for name, _, _ in cases]
    if len(set(names)) != len(names):
        raise UserError(
            f"{suite_file}: recording names must be unique, got {', '.join(sorted({n for n in names if names.count(n) > 1}))}"
        )
    for name, clean, case_params in cases:
        clean["seed"] = clean.get("seed", 0) + args.seed_offset
        _generate(clean, case_params, out / name, str(out / name / "preview.png") if args.preview is not None else None)
    print(f"suite {suite_file.stem}: {len(entries)} recordings in {out}")
    return 0


SUITE_KEYS = {
    "vehicles",
    "scenario",
    "seed",
    "duration_s",
    "start_s",
    "columns",
    "slope_deg",
    "distractors",
    "clutter_near",
}
SUITE_FILE_KEYS = {"sensors", "vehicles_file"}  # paths relative to the suite file


def suite_case(suite_file: Path, i: int, entry, params, vehicles_file: str | None = None) -> tuple[str, dict, object]:
    """Recording name, SimConfig arguments and sensor parameters of one suite entry, checked:
    unknown keys, missing files and unknown vehicles are errors naming the suite file and entry."""
    from i2v_loc.cli import UserError
    from i2v_loc.params import load_params
    from i2v_loc.sim.maneuvers import SCENARIOS

    allowed = SUITE_KEYS | SUITE_FILE_KEYS | {"vehicle", "name"}
    if not isinstance(entry, dict) or set(entry) - allowed or "scenario" not in entry:
        got = sorted(entry) if isinstance(entry, dict) else entry
        raise UserError(f"{suite_file}: entry {i} needs 'scenario' and may have {sorted(allowed)}; got {got}")
    if entry["scenario"] not in SCENARIOS:
        raise UserError(
            f"{suite_file}: entry {i}: unknown scenario {entry['scenario']!r}; choose one of {', '.join(SCENARIOS)}"
        )
    where = f"{suite_file}: entry {i}:"
    _check_ranges(
        entry.get("duration_s", 30.0), entry.get("slope_deg", 0.0), f"{where} duration_s", f"{where} slope_deg"
    )
    files = {k: suite_file.parent / entry[k] for k in SUITE_FILE_KEYS if k in entry}
    if "sensors" in files:
        params = load_params(files["sensors"])
    extra = _extra_vehicles(files.get("vehicles_file") or vehicles_file, params)
    vehicles = entry.get("vehicles") or [entry.get("vehicle", "man_tgx")]
    unknown = [v for v in vehicles if v not in params.vehicles and v not in extra]
    if unknown:
        raise UserError(
            f"{suite_file}: entry {i}: unknown vehicle(s) {', '.join(unknown)}; known: {', '.join([*params.vehicles, *extra])}"
        )
    name = entry.get("name") or f"{'_'.join(vehicles)}_{entry['scenario']}"
    clean = {k: v for k, v in entry.items() if k in SUITE_KEYS}
    clean["vehicles"] = vehicles
    clean["extra_vehicles"] = extra
    return name, clean, params
