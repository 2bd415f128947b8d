"""``i2v-loc detect``: one point-cloud file through the single-frame stages; clusters and units as JSON."""

from __future__ import annotations

import json

import numpy as np

from i2v_loc.cli import UserError


def register(sub) -> None:
    p = sub.add_parser("detect", help="detect vehicles in one point-cloud file (PCD, PLY, NPY, KITTI or nuScenes BIN)")
    p.add_argument(
        "cloud",
        metavar="CLOUD",
        help="point-cloud file in its sensor's frame (level, the ground found from the points, unless --sensor)",
    )
    p.add_argument("--params", action="append", default=[], metavar="FILE", help="parameter file(s) over the defaults")
    p.add_argument("--sensor", help="apply this configured sensor's extrinsics (the cloud is in its frame)")
    p.add_argument(
        "--merged",
        action="store_true",
        help="the cloud merges several sensors' returns in a level frame (no ray runs from its origin to them)",
    )
    p.add_argument("--method", default=None, help="paper or default (default: default)")
    p.add_argument("--bin-layout", choices=["kitti", "nuscenes"], help="a .bin's layout when its content does not tell")
    p.set_defaults(func=run)


def single_sweep(params, method: str):
    """``params`` for one sweep: whatever is found in it is reported (no history, no background,
    no motion: the default starts a vehicle by its shape alone); its ground fitted with as many
    RANSAC triples as the levelling's (a street's walls and crowns outnumber its ground)."""
    from i2v_loc.params import apply_patch
    from i2v_loc.stages.region import LEVELLING_RANSAC_ITERATIONS

    iterations = max(params.region.ransac_iterations, LEVELLING_RANSAC_ITERATIONS)
    params = apply_patch(params, {"region": {"ransac_iterations": iterations}}, source="one sweep")

    if method == "paper":
        return params.model_copy(update={"tracking": params.tracking.model_copy(update={"min_hits": 1})})
    patch = {"background": {"enabled": False}, "articulated": {"start_frames": 1, "start_travel_m": 0.0}}
    return apply_patch(params, patch, source="one sweep")


def run(args) -> int:
    from i2v_loc.clouds import CloudError, read_cloud
    from i2v_loc.frame import Frame, SensorScan
    from i2v_loc.params import DEFAULT_METHOD, Extrinsics, SensorConfig, load_params
    from i2v_loc.pipelines import build_pipeline, method_name
    from i2v_loc.stages.region import ground_below_origin_m

    params = load_params(*args.params)
    try:
        points = read_cloud(args.cloud, args.bin_layout)
    except CloudError as err:
        raise UserError(str(err)) from err
    if args.sensor:
        names = [s.name for s in params.sensors]
        if args.sensor not in names:
            raise UserError(f"no sensor named {args.sensor!r}; known: {', '.join(names)}")
        sensor = params.sensor(args.sensor)
    else:
        # a level cloud whose origin may be anywhere above its ground (a car's roof, a pole)
        lift = Extrinsics(z_m=ground_below_origin_m(points, params.region) or 0.0)
        sensor = SensorConfig(name="cloud", extrinsics=lift, min_range_m=0.0, max_range_m=300.0)
    try:
        method = method_name(args.method or DEFAULT_METHOD)
    except ValueError as err:
        raise UserError(str(err)) from err
    params = single_sweep(params.model_copy(update={"sensors": [sensor]}), method)
    scan = SensorScan(sensor.name, 0.0, points, None, from_sensor=not args.merged)
    result = build_pipeline(params, method).process(Frame(0, {sensor.name: scan}))
    line = result.to_json()
    # one sweep: faults name the sensor; the counts of what was dropped are the state line's
    report = {
        "file": args.cloud,
        "points": int(len(points)),
        "finite_points": int(np.isfinite(points).all(axis=1).sum()),
        "ground_below_origin_m": round(sensor.extrinsics.z_m, 3),
        "ground_found": result.ground_found,
        "latency_ms": line["latency_ms"],
        "faults": line["faults"],
        "dropped": line["dropped"],
        "clusters": line["clusters"],
        "vehicles": [
            {k: v[k] for k in ("vehicle", "kind", "truck", "trailer", "hitch_deg") if k in v} for v in line["vehicles"]
        ],
    }
    print(json.dumps(report, indent=2))
    return 0
