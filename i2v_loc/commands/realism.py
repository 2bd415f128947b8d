"""``i2v-loc realism``: rebuild a real labelled frame as a scene, simulate it and compare point
counts object by object (docs/simulator.md, "Calibrated against real scans")."""

from __future__ import annotations

import json
from pathlib import Path

from i2v_loc.cli import UserError

TARGET_MEDIAN = (0.75, 1.33)
TARGET_SHARE_WITHIN = 0.7


def register(sub) -> None:
    p = sub.add_parser("realism", help="compare the simulated sensor with a real labelled frame, object by object")
    p.add_argument("cloud", metavar="CLOUD", help="real frame: PCD with x y z ring (and t) per point")
    p.add_argument("labels", metavar="LABELS", help="its OpenLABEL cuboids (TUMTraf layout; num_points if present)")
    p.add_argument("--json", metavar="OUT", help="write objects, median_ratio and the beam table here")
    p.set_defaults(func=run)


def run(args) -> int:
    from i2v_loc.sim.realism import RealismError, compare, summary

    try:
        results, table = compare(args.cloud, args.labels)
    except RealismError as err:
        raise UserError(str(err)) from None
    report = summary(results)
    print(
        f"beam table: {table.beams} rings x {table.columns} columns, altitude {table.altitude_deg[0]:.2f} to "
        f"{table.altitude_deg[-1]:.2f} deg ({table.source})"
    )
    print(f"{'type':<11} {'range m':>8} {'real':>6} {'sim':>7} {'ratio':>6}  blocked by clutter")
    for o in report["objects"]:
        print(
            f"{o['type']:<11} {o['range_m']:>8.1f} {o['real_points']:>6d} {o['sim_points']:>7.1f} {o['ratio']:>6.2f}  {o['blocked_by_clutter']:.1f}"
        )
    within = report["share_within_half_to_double"]
    print(
        f"median sim/real {report['median_ratio']:.2f} (target {TARGET_MEDIAN[0]}-{TARGET_MEDIAN[1]}), "
        f"{within:.0%} of {len(results)} objects within 0.5-2x (target >= {TARGET_SHARE_WITHIN:.0%})"
    )
    if args.json:
        report["beam_altitude_deg"] = [round(float(a), 4) for a in table.altitude_deg]
        report["beam_azimuth_offset_deg"] = [round(float(a), 4) for a in table.azimuth_offset_deg]
        report["columns"] = table.columns
        Path(args.json).write_text(json.dumps(report, indent=1))
    return 0
