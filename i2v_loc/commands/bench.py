"""``i2v-loc bench``: latency of the pipeline per stage, against the Open3D recipe on the same frames
in the same process, its scaling with the points, start-up, memory, real frames and (``--service``)
the service end to end. One core unless ``--threads``. docs/performance.md explains the figures."""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

from i2v_loc.cli import UserError

BENCH_SCENARIO = {"vehicles": ["man_tgx"], "scenario": "docking", "seed": 0, "duration_s": 20.0}
BENCH_NAME = "man_tgx_docking_20s"
SCALING = {
    "full": {"sensors": (1, 2, 4, 8), "beams": (32, 64, 128), "columns": (1024, 2048), "frames": 12},
    "quick": {"sensors": (1, 4, 8), "beams": (32, 128), "columns": (1024, 2048), "frames": 6},
}
SCALING_WARM_FRAMES = 6  # frames before the timed ones (the map is learned from 3 samples, every frame)
OPEN3D_MAX_FRAMES = 60
MIN_WARMUP_FRAMES = 5


def register(sub) -> None:
    p = sub.add_parser(
        "bench", help="measure the pipeline's latency per stage, against Open3D, its scaling and start-up"
    )
    p.add_argument(
        "recording",
        nargs="?",
        help="recording directory (default: a generated 20 s MAN TGX docking recording, cached in "
        "$XDG_CACHE_HOME/i2v-loc/bench; the committed sample if it cannot be generated)",
    )
    p.add_argument("--method", help="pipeline method (default: params.DEFAULT_METHOD)")
    p.add_argument("--params", action="append", default=[], help="parameter files merged over the recording's sensors")
    p.add_argument("--threads", type=int, default=1, help="threads for numpy/BLAS and Open3D (default 1: one core)")
    p.add_argument("--repeat", type=int, default=1, help="passes over the recording (a fresh pipeline each pass)")
    p.add_argument(
        "--warmup",
        type=int,
        help=f"frames of each pass reported apart (default: until the background map is ready, at least {MIN_WARMUP_FRAMES})",
    )
    p.add_argument(
        "--json", metavar="OUT", help="write the figures as JSON to OUT ('-': standard output, the table to stderr)"
    )
    p.add_argument(
        "--scaling", choices=["quick", "full", "none"], default="quick", help="the scaling table (default quick)"
    )
    p.add_argument("--no-open3d", action="store_true", help="skip the Open3D recipe")
    p.add_argument(
        "--realdata",
        default=str(_default_realdata()),
        help="folder of the real frames (default ../shared/realdata beside the repository; 'none' skips them)",
    )
    p.add_argument("--service", action="store_true", help="also measure the service: frame in to WebSocket message out")
    p.add_argument("--clients", type=int, default=20, help="WebSocket clients of --service (default 20)")
    p.add_argument("--service-seconds", type=float, default=20.0, help="seconds --service listens (default 20)")
    p.set_defaults(func=run)


def _default_realdata() -> Path:
    return Path(__file__).resolve().parents[2].parent / "shared" / "realdata"


def _cache_dir() -> Path:
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "i2v-loc" / "bench"


# ----------------------------------------------------------------------------- the run


def run(args) -> int:
    if args.threads < 1 or args.repeat < 1 or (args.warmup is not None and args.warmup < 0):
        raise UserError("--threads and --repeat must be at least 1, --warmup at least 0")
    os.environ["OMP_NUM_THREADS"] = str(args.threads)  # Open3D reads it when it loads (below)
    from threadpoolctl import threadpool_limits

    from i2v_loc.params import DEFAULT_METHOD
    from i2v_loc.pipelines import method_name

    try:
        method = method_name(args.method or DEFAULT_METHOD)
    except ValueError as err:
        raise UserError(str(err)) from err
    rec_path, source = _recording(args.recording)
    recording, params = _load(rec_path, args.params)
    startup = measure_startup(rec_path, method, args.params)
    with threadpool_limits(limits=args.threads):
        report = bench_recording(recording, params, method, args, source)
        report["startup"] = startup
        if args.realdata != "none":
            report["realdata"] = bench_realdata(Path(args.realdata), method, args.params)
    if args.service:
        from i2v_loc.commands.bench_service import bench_service

        report["service"] = bench_service(rec_path, method, args.clients, args.service_seconds)
    print_report(report, sys.stderr if args.json == "-" else sys.stdout)
    if args.json:
        import json

        text = json.dumps(report, indent=2)
        if args.json == "-":
            print(text)
        else:
            Path(args.json).write_text(text + "\n")
    return 0


def _recording(given: str | None) -> tuple[Path, str]:
    """The recording to time and where it came from."""
    if given:
        return Path(given), "given"
    path = _cache_dir() / BENCH_NAME
    if (path / "meta.yaml").is_file():
        return path, f"generated 20 s docking recording (cached in {path})"
    try:
        generate_bench_recording(path)
        return path, f"generated 20 s docking recording (now cached in {path})"
    except Exception as err:  # no simulator dependencies, read-only cache: time the committed sample
        from i2v_loc.resources import sample_recording

        sample = sample_recording("man_tgx_docking")
        print(f"bench: could not generate the bench recording ({err}); using the committed sample", file=sys.stderr)
        return sample, "committed 6 s sample (the 20 s recording could not be generated)"


def generate_bench_recording(path: Path) -> None:
    """Simulate the 20 s docking recording once (to a temporary folder, then renamed into place)."""
    import shutil
    import tempfile

    from i2v_loc.params import load_params
    from i2v_loc.sim.generate import SimConfig
    from i2v_loc.sim.generate import run as simulate

    path.parent.mkdir(parents=True, exist_ok=True)
    cfg = SimConfig(params=load_params(), **BENCH_SCENARIO)
    total = int(round(cfg.duration_s * cfg.params.sensors[0].rate_hz))
    done = [0]

    def progress(n: int = 1) -> None:
        done[0] += n
        print(f"\rbench: generating the bench recording {done[0]}/{total} frames", end="", file=sys.stderr, flush=True)

    with tempfile.TemporaryDirectory(dir=path.parent) as tmp:
        _, written = simulate(cfg, Path(tmp) / "rec", progress=progress)
        print(file=sys.stderr)
        shutil.move(str(written), str(path))


def _load(rec_path: Path, param_files: list[str]):
    from i2v_loc.formats import open_recording
    from i2v_loc.params import load_params
    from i2v_loc.recording import RecordingError

    try:
        recording = open_recording(rec_path)
    except RecordingError as err:
        raise UserError(str(err)) from err
    return recording, load_params(recording.sensors_file, *param_files)


def bench_recording(recording, params, method: str, args, source: str) -> dict:
    rec_path = Path(recording.path)
    frames = list(recording.frames())
    if len(frames) <= (args.warmup or MIN_WARMUP_FRAMES):
        raise UserError(f"{rec_path} has {len(frames)} frames; need more than the warm-up")
    load_at_start = host_load()
    timed, warm, merged_points = time_pipeline(params, method, frames, args.warmup, args.repeat)
    if not timed:
        raise UserError(f"{rec_path}: every frame was warm-up (the background map never became ready); give --warmup")
    figures = summarize(timed)
    import numpy as np

    report = {
        "recording": str(rec_path),
        "recording_source": source,
        "method": method,
        "threads": args.threads,
        "sensors": len(params.sensors),
        "frames": len(timed),
        "warmup_frames": len(warm) // args.repeat,
        "points_per_frame": float(np.mean([sum(len(s.points) for s in f.scans.values()) for f in frames])),
        "merged_points_per_frame": float(np.mean(merged_points)),
        "latency_ms": figures,
        "warmup_latency_ms": summarize(warm)["total"] if warm else None,
        "p95_over_p50": figures["total"]["p95"] / figures["total"]["p50"],
        "peak_rss_mib": peak_rss_mib(),
        "pipeline_peak_traced_mib": traced_peak_mib(params, method, frames[: 2 * MIN_WARMUP_FRAMES]),
    }
    if not args.no_open3d:
        step = max(1, (len(frames) - report["warmup_frames"]) // OPEN3D_MAX_FRAMES)
        o3d_ms = open3d_recipe(frames[report["warmup_frames"] :: step], params)
        if o3d_ms is not None:
            report["open3d_frames"] = len(o3d_ms)
            report["open3d_ms_p50"] = float(np.percentile(o3d_ms, 50))
            report["speedup_vs_open3d"] = report["open3d_ms_p50"] / figures["total"]["p50"]
    report["host"] = {"cores": os.cpu_count(), "load_1min_start": load_at_start, "load_1min_end": host_load()}
    if args.scaling != "none":
        report["scaling"] = bench_scaling(params, method, frames, SCALING[args.scaling])
    return report


def host_load() -> float | None:
    """The host's 1-minute load average (None where the system does not give it)."""
    try:
        return float(os.getloadavg()[0])
    except (AttributeError, OSError):
        return None


def busy_host_warning(host: dict, threads: int) -> str | None:
    """A warning when the timed runs did not have their threads' cores to themselves: the 1-minute
    load at the end (the bench's own threads included) above the cores (the issue's figures are
    one free core's)."""
    load, cores = host.get("load_1min_end"), host.get("cores")
    if load is None or not cores or load <= cores:
        return None
    return (
        f"the host was busy (1-minute load {load:.1f} on {cores} cores, {threads} of them for the bench): "
        "these times are not those of a free core"
    )


def time_pipeline(params, method: str, frames: list, warmup: int | None, repeat: int):
    """(latency dicts of the timed frames, of the warm-up frames, merged points per frame). The
    warm-up of a pass lasts ``warmup`` frames, or by default until the background map is ready."""
    from i2v_loc.pipelines import build_pipeline

    timed, warm, points = [], [], []
    for _ in range(repeat):
        pipeline = build_pipeline(params, method)
        for i, frame in enumerate(frames):
            if warmup is None:
                background = pipeline.background
                in_warmup = i < MIN_WARMUP_FRAMES or (background is not None and not background.ready)
            else:
                in_warmup = i < warmup
            result = pipeline.process(frame)
            (warm if in_warmup else timed).append(dict(result.latency_ms))
            points.append(result.points)
    return timed, warm, points


def summarize(latencies: list[dict[str, float]]) -> dict[str, dict[str, float]]:
    """p50, p95, mean and max of every stage, in the pipeline's order, the total last."""
    import numpy as np

    stages = list(dict.fromkeys(k for lat in latencies for k in lat))
    stages.sort(key=lambda k: k == "total")
    out = {}
    for stage in stages:
        values = np.array([lat[stage] for lat in latencies if stage in lat], dtype=float)
        out[stage] = {
            "p50": float(np.percentile(values, 50)),
            "p95": float(np.percentile(values, 95)),
            "mean": float(values.mean()),
            "max": float(values.max()),
        }
    return out


# ----------------------------------------------------------------------------- memory and start-up


def peak_rss_mib() -> float:
    """Peak resident memory of this process so far (includes the recording held in memory)."""
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def traced_peak_mib(params, method: str, frames: list) -> float:
    """Peak of the memory Python and numpy allocate for a fresh pipeline over these frames (tracemalloc)."""
    import tracemalloc

    from i2v_loc.pipelines import build_pipeline

    tracemalloc.start()
    try:
        pipeline = build_pipeline(params, method)
        for frame in frames:
            pipeline.process(frame)
        return tracemalloc.get_traced_memory()[1] / 2**20
    finally:
        tracemalloc.stop()


STARTUP_SCRIPT = """
import json, sys, time
t0 = time.perf_counter()
from i2v_loc.formats import open_recording
from i2v_loc.params import load_params
from i2v_loc.pipelines import build_pipeline
t1 = time.perf_counter()
recording = open_recording(sys.argv[1])
params = load_params(recording.sensors_file, *sys.argv[3:])
frame = next(iter(recording.frames()))
t2 = time.perf_counter()
pipeline = build_pipeline(params, sys.argv[2])
t3 = time.perf_counter()
pipeline.process(frame)
t4 = time.perf_counter()
print(json.dumps({"import_s": t1 - t0, "build_s": t3 - t2, "first_frame_ms": (t4 - t3) * 1e3, "done": time.time()}))
"""


def measure_startup(rec_path: Path, method: str, param_files: list[str]) -> dict:
    """In fresh processes: ``i2v-loc --version``; importing the pipeline, building it (compiled
    kernels loaded from the disk cache, or compiled the first time) and its first frame."""
    import json
    import statistics
    import subprocess

    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join(filter(None, [str(_package_root()), os.environ.get("PYTHONPATH")])),
    }
    version_s = []
    for _ in range(5):
        t = time.perf_counter()
        subprocess.run([sys.executable, "-m", "i2v_loc", "--version"], env=env, check=True, capture_output=True)
        version_s.append(time.perf_counter() - t)
    started = time.time()
    out = subprocess.run(
        [sys.executable, "-c", STARTUP_SCRIPT, str(rec_path), method, *param_files],
        env=env,
        check=True,
        capture_output=True,
        text=True,
    )
    figures = json.loads(out.stdout.strip().splitlines()[-1])
    return {
        "version_s": statistics.median(version_s),
        "import_s": figures["import_s"],
        "build_s": figures["build_s"],
        "first_frame_ms": figures["first_frame_ms"],
        "process_start_to_first_frame_s": figures["done"] - started,
    }


def _package_root() -> Path:
    return Path(__file__).resolve().parents[2]


# ----------------------------------------------------------------------------- Open3D


def open3d_recipe(frames: list, params) -> list[float] | None:
    """ms per frame of the Open3D recipe: the sweeps concatenated in the yard frame,
    ``voxel_down_sample`` 0.1, ``segment_plane``, ``cluster_dbscan``, an oriented box per cluster."""
    try:
        import open3d as o3d
    except ImportError:
        print("bench: open3d is not installed; no Open3D comparison", file=sys.stderr)
        return None
    import numpy as np

    from i2v_loc.geometry import extrinsics_matrix

    to_yard = {s.name: extrinsics_matrix(s.extrinsics) for s in params.sensors}
    region, clustering = params.region, params.clustering
    o3d.utility.random.seed(0)
    times = []
    for frame in frames:
        t = time.perf_counter()
        cloud = o3d.geometry.PointCloud()
        for name, scan in frame.scans.items():
            sweep = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(scan.points.astype(np.float64)))
            cloud += sweep.transform(to_yard[name])
        cloud = cloud.remove_non_finite_points().voxel_down_sample(0.1)
        _, ground = cloud.segment_plane(region.ground_distance_threshold_m, 3, region.ransac_iterations)
        rest = cloud.select_by_index(ground, invert=True)
        labels = np.asarray(rest.cluster_dbscan(clustering.tolerance_m, clustering.min_points))
        for k in range(int(labels.max(initial=-1)) + 1):
            try:
                rest.select_by_index(np.flatnonzero(labels == k)).get_oriented_bounding_box()
            except RuntimeError:  # a flat cluster: Open3D's hull fails, as it would for the recipe
                pass
        times.append((time.perf_counter() - t) * 1e3)
    return times


# ----------------------------------------------------------------------------- scaling


def bench_scaling(params, method: str, frames: list, grid: dict) -> list[dict]:
    """ms per frame for sensors x beams x columns: the recording's sweeps replicated in azimuth
    (more columns) and elevation (more beams), extra sensors copies of the recording's turned by
    half a column. The map learns from every frame and is used after 3 samples."""
    import itertools

    import numpy as np

    from i2v_loc.frame import Frame

    bg = params.background.model_copy(update={"min_samples": 3, "learn_every_frames": 1})
    base = frames[len(frames) // 2 : len(frames) // 2 + SCALING_WARM_FRAMES + grid["frames"]]
    rows = []
    for n_sensors, beams, columns in itertools.product(grid["sensors"], grid["beams"], grid["columns"]):
        sensors = _scaled_sensors(params.sensors, n_sensors, beams, columns)
        scaled = params.model_copy(update={"sensors": sensors, "background": bg})
        clouds = [
            Frame(
                f.index, {s.name: _scaled_scan(f, params.sensors, k, s, beams, columns) for k, s in enumerate(sensors)}
            )
            for f in base
        ]
        timed, _, _ = time_pipeline(scaled, method, clouds, SCALING_WARM_FRAMES, 1)
        total = [lat["total"] for lat in timed]
        rows.append(
            {
                "sensors": n_sensors,
                "beams": beams,
                "columns": columns,
                "points": int(np.mean([sum(len(s.points) for s in f.scans.values()) for f in clouds])),
                "ms_p50": float(np.percentile(total, 50)),
                "ms_p95": float(np.percentile(total, 95)),
            }
        )
        print(
            f"\rbench: scaling {len(rows)}/{np.prod([len(grid[k]) for k in ('sensors', 'beams', 'columns')])}",
            end="",
            file=sys.stderr,
            flush=True,
        )
    print(file=sys.stderr)
    return rows


def _scaled_sensors(sensors: list, n: int, beams: int, columns: int) -> list:
    """``n`` sensors of ``beams`` x ``columns``: the recording's, in turn, renamed."""
    model = f"OS1-{beams}"
    return [
        sensors[k % len(sensors)].model_copy(update={"name": f"s{k}", "model": model, "columns": columns})
        for k in range(n)
    ]


def _scaled_scan(frame, base_sensors: list, k: int, sensor, beams: int, columns: int):
    """Sweep of scaled sensor ``k``: its base sensor's sweep with each point copied to the extra
    columns (turned in azimuth) and beams (tilted in elevation), or thinned when there are fewer."""
    import numpy as np

    from i2v_loc.frame import SensorScan

    source = base_sensors[k % len(base_sensors)]
    scan = frame.scans.get(source.name)
    if scan is None:
        return SensorScan(sensor.name, float("nan"), np.zeros((0, 3), dtype=np.float32), None)
    points, offsets = scan.points, scan.time_offset_s
    turn = (k // len(base_sensors)) * np.pi / columns  # a further sensor at the same mount: half a column apart
    col_factor, beam_factor = columns / source.columns, beams / source.beams
    copies = []
    for c in range(max(1, int(col_factor))):
        for b in range(max(1, int(beam_factor))):
            copies.append(_turned(points, turn + 2 * np.pi * c / columns, np.radians(1.4) * b / beam_factor))
    out = np.concatenate(copies)
    offsets = np.tile(offsets, len(copies))
    keep = max(1, int(round(1 / min(1.0, col_factor) / min(1.0, beam_factor))))
    return SensorScan(sensor.name, scan.stamp_s, out[::keep], offsets[::keep])


def _turned(points, azimuth_rad: float, elevation_rad: float):
    import numpy as np

    p = points.astype(np.float64)
    horizontal = np.hypot(p[:, 0], p[:, 1])
    azimuth = np.arctan2(p[:, 1], p[:, 0]) + azimuth_rad
    elevation = np.arctan2(p[:, 2], horizontal) + elevation_rad
    r = np.linalg.norm(p, axis=1)
    flat = r * np.cos(elevation)
    return np.column_stack([flat * np.cos(azimuth), flat * np.sin(azimuth), r * np.sin(elevation)]).astype(np.float32)


# ----------------------------------------------------------------------------- real frames


def bench_realdata(root: Path, method: str, param_files: list[str]) -> dict:
    """The real frames of ``root`` through the pipeline, each set as one sequence, the sensor at its
    height (its first cloud's ground plane below the origin: ``region.ground_below_origin_m``) and the
    default region."""
    if not root.is_dir():
        print(f"bench: no real frames at {root}; skipped", file=sys.stderr)
        return {}
    sets = {
        "tumtraf_s110_south": sorted((root / "tumtraf_s110_south").glob("*.pcd")),
        "roadside80_chengdu": sorted((root / "roadside80_chengdu" / "frames").glob("*.pcd")),
        "roadside80_chengdu_raw_with_nan": [root / "roadside80_chengdu" / "rawdata.pcd"],
    }
    return {
        name: _bench_files(files, method, param_files) for name, files in sets.items() if files and files[0].is_file()
    }


def _bench_files(files: list[Path], method: str, param_files: list[str]) -> dict:
    import numpy as np

    from i2v_loc.clouds import read_cloud
    from i2v_loc.frame import Frame, SensorScan
    from i2v_loc.params import Extrinsics, SensorConfig, load_params
    from i2v_loc.pipelines import build_pipeline
    from i2v_loc.stages.region import ground_below_origin_m

    clouds = [read_cloud(f) for f in files]
    params = load_params(*param_files)
    height_m = ground_below_origin_m(clouds[0], params.region) or 0.0
    sensor = SensorConfig(name="real", extrinsics=Extrinsics(z_m=height_m), min_range_m=0.0, max_range_m=300.0)
    params = params.model_copy(update={"sensors": [sensor]})
    pipeline = build_pipeline(params, method)
    latencies = []
    for i, cloud in enumerate(clouds):
        frame = Frame(i, {"real": SensorScan("real", i * 0.1, cloud, None)})
        latencies.append(dict(pipeline.process(frame).latency_ms))
    figures = summarize(latencies)
    return {
        "frames": len(clouds),
        "points_per_frame": float(np.mean([len(c) for c in clouds])),
        "sensor_height_m": height_m,
        "total_ms_p50": figures["total"]["p50"],
        "total_ms_max": figures["total"]["max"],
        "latency_ms": {k: v["p50"] for k, v in figures.items()},
    }


# ----------------------------------------------------------------------------- output


def print_report(report: dict, out) -> None:
    print(
        f"{Path(report['recording']).name} ({report['recording_source']}): {report['frames']} frames timed, "
        f"{report['warmup_frames']} warm-up, {report['points_per_frame']:.0f} points per frame "
        f"({report['sensors']} sensors), method {report['method']}, {report['threads']} thread(s)",
        file=out,
    )
    print(f"{'stage':<16}{'p50':>9}{'p95':>9}{'mean':>9}{'max':>9}  [ms]", file=out)
    for stage, f in report["latency_ms"].items():
        print(f"{stage:<16}{f['p50']:>9.2f}{f['p95']:>9.2f}{f['mean']:>9.2f}{f['max']:>9.2f}", file=out)
    if report.get("warmup_latency_ms"):
        w = report["warmup_latency_ms"]
        print(f"{'warm-up total':<16}{w['p50']:>9.2f}{w['p95']:>9.2f}{w['mean']:>9.2f}{w['max']:>9.2f}", file=out)
    print(f"p95/p50 {report['p95_over_p50']:.2f}", file=out)
    if "open3d_ms_p50" in report:
        print(
            f"Open3D recipe p50 {report['open3d_ms_p50']:.1f} ms ({report['open3d_frames']} frames): "
            f"speed-up {report['speedup_vs_open3d']:.1f}x",
            file=out,
        )
    host = report.get("host", {})
    if host.get("load_1min_end") is not None:
        print(
            f"host: {host['cores']} cores, 1-minute load {host['load_1min_start']:.2f} at the start, "
            f"{host['load_1min_end']:.2f} after the timed runs",
            file=out,
        )
    warning = busy_host_warning(host, report["threads"])
    if warning:
        print(f"WARNING: {warning}", file=out)
    print(
        f"memory: peak RSS {report['peak_rss_mib']:.0f} MiB (recording in memory), "
        f"pipeline peak {report['pipeline_peak_traced_mib']:.1f} MiB traced",
        file=out,
    )
    s = report.get("startup")
    if s:
        print(
            f"start-up: --version {s['version_s']:.2f} s, import {s['import_s']:.2f} s, build {s['build_s']:.2f} s, "
            f"first frame {s['first_frame_ms']:.0f} ms, process start to first frame {s['process_start_to_first_frame_s']:.2f} s",
            file=out,
        )
    for row in report.get("scaling", []):
        print(
            f"scaling {row['sensors']} x OS1-{row['beams']} x {row['columns']}: {row['points']:>8} points "
            f"{row['ms_p50']:8.2f} ms p50 {row['ms_p95']:8.2f} ms p95",
            file=out,
        )
    for name, r in report.get("realdata", {}).items():
        print(
            f"real {name}: {r['frames']} frames, {r['points_per_frame']:.0f} points, "
            f"p50 {r['total_ms_p50']:.1f} ms, max {r['total_ms_max']:.1f} ms",
            file=out,
        )
    if "service" in report:
        sv = report["service"]
        print(
            f"service: {sv['clients']} clients, {sv['messages']} messages, frame in to message out "
            f"p50 {sv['frame_to_send_ms_p50']:.1f} ms p99 {sv['frame_to_send_ms_p99']:.1f} ms; "
            f"to the client p50 {sv['frame_to_client_ms_p50']:.1f} ms p99 {sv['frame_to_client_ms_p99']:.1f} ms",
            file=out,
        )
    out.flush()
