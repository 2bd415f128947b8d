"""`i2v-loc detect`'s one-sweep start on random ray-cast scenes seen from a car's roof
(tests/car_mounted.py: an OS1-64 1.8 m up on flat ground, or a fan of 64 beams reaching --top-deg).

    PYTHONPATH=$PWD python scripts/car_mounted_scenes.py vehicles [--first 0] [--count 150] [--top-deg 2]
    PYTHONPATH=$PWD python scripts/car_mounted_scenes.py parked   [--first 0] [--count 60]
    PYTHONPATH=$PWD python scripts/car_mounted_scenes.py yard-parked   [--count 60] [--frames 30]
    PYTHONPATH=$PWD python scripts/car_mounted_scenes.py yard-standing [--count 60] [--frames 30]

``vehicles``: a MAN, Volvo FH, 12 m coach or 9 m rigid truck 8-40 m away, 2-5 walls, trees and boards
elsewhere (12 m clear of it); found = a reported vehicle within 10 m of it, false = every other one.
``parked``: a catalogue semitrailer standing on its legs 8-30 m away, a pole between it and the car,
half the scenes with a 10-ft or 20-ft container 0.5-1.5 m off one of its ends; every vehicle is false.
``yard-parked`` / ``yard-standing``: the same parts seen instead by a yard's OS1-32 on a pole 6 m up for
``--frames`` sweeps from the service's start (the map still learned, frames to come): a parked
semitrailer 8-35 m away, a pole before it and always a 10-ft or 20-ft container 0.5-1.5 m off one
of its ends (every vehicle false); or a MAN or Volvo FH standing straight 8-35 m away (found = the
frame it is first reported in). One line per scene, then the totals. Scenes depend only on their
index.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
import car_mounted as cm  # noqa: E402

from i2v_loc.commands.detect import single_sweep  # noqa: E402
from i2v_loc.frame import Frame, SensorScan  # noqa: E402
from i2v_loc.params import Params  # noqa: E402
from i2v_loc.pipelines import build_pipeline  # noqa: E402
from i2v_loc.sim import meshes as m  # noqa: E402

FOUND_WITHIN_M = 10.0
NEAR_M = 25.0


def _polar(rng: np.random.Generator, low_m: float, high_m: float) -> tuple[float, float]:
    r, a = rng.uniform(low_m, high_m), rng.uniform(-np.pi, np.pi)
    return r * math.cos(a), r * math.sin(a)


def vehicle_scene(index: int) -> tuple[list, str, np.ndarray]:
    """Parts, the vehicle's kind and its centre."""
    rng = np.random.default_rng(index)
    kind = str(rng.choice(["man_tgx", "volvo_fh", "coach", "rigid9"]))
    x, y = _polar(rng, 8.0, 40.0)
    yaw = rng.uniform(-np.pi, np.pi)
    if kind in ("man_tgx", "volvo_fh"):
        parts = cm.articulated(kind, x, y, yaw)
    else:
        parts = cm.bus(x, y, yaw, *((12.0, 2.55) if kind == "coach" else (9.0, 2.5)))
    for _ in range(rng.integers(2, 6)):
        ox, oy = _polar(rng, 6.0, 45.0)
        if math.hypot(ox - x, oy - y) < 12.0:
            continue
        other = rng.choice(["wall", "tree", "sign"])
        if other == "wall":
            length, heading = rng.uniform(2.0, 15.0), rng.uniform(0.0, np.pi)
            end = (ox + length * math.cos(heading), oy + length * math.sin(heading))
            parts += cm.wall(ox, oy, *end, rng.uniform(1.0, 3.5))
        elif other == "tree":
            parts += cm.tree(ox, oy)
        else:
            parts += cm.sign(ox, oy, rng.uniform(0.0, np.pi))
    return parts, kind, np.array([x, y])


def parked_scene(index: int, yard: bool = False) -> tuple[list, str]:
    """Parts and a description: a parked semitrailer, a pole before it, maybe (in the yard: always)
    a container off an end."""
    rng = np.random.default_rng((20_000 if yard else 10_000) + index)
    name = str(rng.choice(["man_tgx", "volvo_fh"]))
    trailer = Params().vehicles[name].trailer
    x, y = _polar(rng, 8.0, 35.0 if yard else 30.0)
    bearing, yaw = math.atan2(y, x), rng.uniform(-np.pi, np.pi)
    centre = m.box_center_in_axle_frame(trailer, is_truck=False)
    parts = [m.transformed(m.shifted(m.trailer_mesh(trailer), (-centre[0], 0.0, 0.0)), cm._pose(x, y, yaw))]
    before = rng.uniform(1.0, 4.0)
    pole = (x - before * math.cos(bearing) + rng.uniform(-3, 3), y - before * math.sin(bearing) + rng.uniform(-3, 3))
    parts.append(m.cylinder((*pole, 2.5), 0.12, 5.0, surface="pole"))
    what = f"{name} trailer {math.hypot(x, y):.0f} m away"
    if yard or rng.random() < 0.5:
        end, gap, length = rng.choice([-1, 1]), rng.uniform(0.5, 1.5), float(rng.choice([6.06, 2.99]))
        along = end * (trailer.length_m / 2 + gap + length / 2)
        parts.append(
            m.box((x + along * math.cos(yaw), y + along * math.sin(yaw), 1.3), (length, 2.44, 2.6), yaw, "concrete")
        )
        what += f", a {length} m container {gap:.1f} m off"
    return parts, what


def standing_scene(index: int) -> tuple[list, str]:
    """Parts and a description: a catalogue tractor and semitrailer standing straight."""
    rng = np.random.default_rng(30_000 + index)
    name = str(rng.choice(["man_tgx", "volvo_fh"]))
    x, y = _polar(rng, 8.0, 35.0)
    yaw = rng.uniform(-np.pi, np.pi)
    return cm.articulated(name, x, y, yaw), f"{name} standing {math.hypot(x, y):.0f} m away"


def detect(pipeline_params, parts, top_deg: float | None, index: int) -> list[dict]:
    points = cm.sweep(parts, top_deg, index)
    scan = SensorScan(cm.SENSOR.name, 0.0, points, None, from_sensor=True)
    return build_pipeline(pipeline_params, "default").process(Frame(0, {cm.SENSOR.name: scan})).to_json()["vehicles"]


def yard(args) -> int:
    """Static yard scenes from the service's start: false vehicles, or the frame a standing one is found."""
    params = cm.pole_params()
    total, firsts = 0, []
    for index in range(args.first, args.first + args.count):
        parts, what = parked_scene(index, yard=True) if args.scenes == "yard-parked" else standing_scene(index)
        counts = [len(r) for r in cm.yard_reports(parts, args.frames, 1000 * index, params)]
        first = next((k for k, n in enumerate(counts) if n), None)
        total, firsts = total + max(counts), firsts + [first]
        print(f"{index} {what}: at most {max(counts)} reported, the first in frame {first}")
    if args.scenes == "yard-parked":
        print(f"false vehicles {total} in {args.count} scenes of {args.frames} frames")
    else:
        found = [k for k in firsts if k is not None]
        print(f"found {len(found)} of {args.count} within {args.frames} frames, {found.count(2)} in frame 2")
    return 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("scenes", choices=["vehicles", "parked", "yard-parked", "yard-standing"])
    parser.add_argument("--first", type=int, default=0)
    parser.add_argument("--count", type=int, default=150)
    parser.add_argument("--top-deg", type=float, default=None, help="a 64-beam fan from here 26.8 deg down")
    parser.add_argument("--frames", type=int, default=30, help="yard scenes: sweeps from the service's start")
    args = parser.parse_args()
    if args.scenes.startswith("yard"):
        return yard(args)
    params = cm.sensor_params()
    params = single_sweep(params.model_copy(update={"sensors": [params.sensor(cm.SENSOR.name)]}), "default")
    found = near = near_found = false = 0
    for index in range(args.first, args.first + args.count):
        if args.scenes == "vehicles":
            parts, kind, centre = vehicle_scene(index)
            reported = detect(params, parts, args.top_deg, index)
            hit = any(np.hypot(*(np.array(v["truck"]["center"][:2]) - centre)) < FOUND_WITHIN_M for v in reported)
            distance = float(np.hypot(*centre))
            found, false = found + hit, false + len(reported) - hit
            near, near_found = near + (distance < NEAR_M), near_found + (hit and distance < NEAR_M)
            print(f"{index} {kind} {distance:.1f} m: {'found' if hit else 'MISSED'}, {len(reported) - hit} false")
        else:
            parts, what = parked_scene(index)
            reported = detect(params, parts, args.top_deg, index)
            false += len(reported)
            print(f"{index} {what}: {[(v['vehicle'], v['kind']) for v in reported] or 'none'}")
    if args.scenes == "vehicles":
        print(f"found {found} of {args.count} (within {NEAR_M:.0f} m: {near_found} of {near}), false vehicles {false}")
    else:
        print(f"false vehicles {false} in {args.count} scenes")
    return 0


if __name__ == "__main__":
    sys.exit(main())
