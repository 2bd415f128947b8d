"""Ground truth: our recordings' lines, users' labels (ASAM OpenLABEL as in TUMTraf, labelCloud's
JSON export) converted to the same GT-line dicts (docs/formats.md), and interpolation of the
truth to the states' stamps.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np

from i2v_loc.evaluation.metrics import associate
from i2v_loc.geometry import box_poses, wrap_deg

UNITS = ("truck", "trailer")
UNLABELLED = "unlabelled"


class GroundTruthError(ValueError):
    """A ground-truth or label file cannot be read or converted."""


# --------------------------------------------------------------------------- interpolation


def _unit_pose(unit: dict) -> np.ndarray:
    return box_poses(unit["center"], unit["yaw_deg"])[0]


def tractor_to_trailer(truck: dict, trailer: dict) -> list[list[float]]:
    """inv(T_yard_trailer) @ T_yard_truck of two unit dicts (docs/formats.md)."""
    return (np.linalg.inv(_unit_pose(trailer)) @ _unit_pose(truck)).tolist()


def _blend_unit(u0: dict | None, u1: dict | None, w: float) -> dict | None:
    if u0 is None or u1 is None:
        return None
    near = u0 if w < 0.5 else u1
    out = dict(near)
    out["center"] = [a + w * (b - a) for a, b in zip(u0["center"], u1["center"])]
    out["yaw_deg"] = wrap_deg(u0["yaw_deg"] + w * wrap_deg(u1["yaw_deg"] - u0["yaw_deg"]))
    if u0.get("velocity") is not None and u1.get("velocity") is not None:
        out["velocity"] = [a + w * (b - a) for a, b in zip(u0["velocity"], u1["velocity"])]
    return out


def _blend_vehicle(v0: dict, v1: dict, w: float) -> dict:
    out = dict(v0 if w < 0.5 else v1)
    for unit in UNITS:
        out[unit] = _blend_unit(v0.get(unit), v1.get(unit), w)
    if out["truck"] is not None and out["trailer"] is not None:
        out["hitch_deg"] = wrap_deg(out["trailer"]["yaw_deg"] - out["truck"]["yaw_deg"])
        out["tractor_to_trailer"] = tractor_to_trailer(out["truck"], out["trailer"])
    else:
        out["hitch_deg"] = None
        out["tractor_to_trailer"] = None
    return out


def interpolate_ground_truth(
    lines: list[dict], stamp_s: float, max_gap_s: float | None = None, times: np.ndarray | None = None
) -> dict:
    """The truth at ``stamp_s``: poses linearly interpolated between the two GT lines around it
    (yaw along the shorter arc); labels and point counts from the nearer line. A vehicle must be
    in both lines. Stamps outside the GT span by more than ``max_gap_s`` (default half a frame
    period) have no truth: no vehicles and ``outside_truth``. ``times`` are the lines' stamps, precomputed by callers that
    interpolate many times."""
    if not lines:
        return {"frame": None, "stamp_s": stamp_s, "vehicles": []}
    if times is None:
        times = np.array([line["stamp_s"] for line in lines], float)
    step = float(np.median(np.diff(times))) if len(times) > 1 else 0.1
    gap = step / 2.0 if max_gap_s is None else max_gap_s
    i1 = int(np.searchsorted(times, stamp_s, side="left"))
    if i1 < len(times) and abs(times[i1] - stamp_s) < 1e-9:
        i0 = i1
    elif i1 == 0 or i1 == len(times):
        edge = 0 if i1 == 0 else len(times) - 1
        if abs(times[edge] - stamp_s) > gap:
            return {"frame": None, "stamp_s": stamp_s, "vehicles": [], "outside_truth": True}
        i0 = i1 = edge
    else:
        i0 = i1 - 1
    w = 0.0 if i0 == i1 else (stamp_s - times[i0]) / (times[i1] - times[i0])
    by_id = {v["id"]: v for v in lines[i1].get("vehicles", [])}
    vehicles = [_blend_vehicle(v, by_id[v["id"]], w) for v in lines[i0].get("vehicles", []) if v["id"] in by_id]
    nearer = lines[i0] if w < 0.5 else lines[i1]
    return {"frame": nearer.get("frame"), "stamp_s": stamp_s, "vehicles": vehicles}


def seen_by(lines: list[dict], sensors) -> list[dict]:
    """The GT lines with each unit's ``points`` those of ``sensors`` only (a unit's
    ``points_by_sensor``, as the simulator writes it; a unit without it keeps its count): a
    subset of the LiDARs sees a unit only where its own sensors return points from it."""
    chosen = set(sensors)

    def unit(u):
        if not u or "points_by_sensor" not in u:
            return u
        return {**u, "points": sum(n for name, n in u["points_by_sensor"].items() if name in chosen)}

    def vehicle(v):
        return {**v, **{k: unit(v.get(k)) for k in UNITS if k in v}}

    return [{**line, "vehicles": [vehicle(v) for v in line.get("vehicles", [])]} for line in lines]


# --------------------------------------------------------------------------- loaders


def load_jsonl(path: str | Path) -> list[dict]:
    path = Path(path)
    if not path.is_file():
        raise GroundTruthError(f"{path}: no such ground-truth file")
    lines = []
    for number, text in enumerate(path.read_text().splitlines(), 1):
        if not text.strip():
            continue
        try:
            line = json.loads(text)
        except json.JSONDecodeError as err:
            raise GroundTruthError(f"{path}:{number}: not JSON: {err}") from err
        if "stamp_s" not in line or "vehicles" not in line:
            raise GroundTruthError(f"{path}:{number}: a GT line needs 'stamp_s' and 'vehicles'")
        lines.append(line)
    return lines


def yaw_from_quaternion_deg(qx: float, qy: float, qz: float, qw: float) -> float:
    """Heading (rotation about z) of a quaternion, degrees."""
    return math.degrees(math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz)))


def _unit_kind(label: str) -> str | None:
    name = label.lower()
    if "trailer" in name:
        return "trailer"
    if "truck" in name or "tractor" in name:
        return "truck"
    return None


def pair_units(trucks: list[dict], trailers: list[dict], gate_m: float = 8.0) -> list[tuple[dict | None, dict | None]]:
    """Group labelled units into vehicles: a truck pairs with the trailer whose front face centre
    is nearest to the truck's centre (a semitrailer's front reaches over the tractor), Hungarian,
    within ``gate_m``. Unpaired units become vehicles with the other unit missing."""
    cost = np.full((len(trucks), len(trailers)), np.inf)
    for i, truck in enumerate(trucks):
        for j, trailer in enumerate(trailers):
            yaw = math.radians(trailer["yaw_deg"])
            half = trailer["dimensions"][0] / 2.0
            front = (trailer["center"][0] + half * math.cos(yaw), trailer["center"][1] + half * math.sin(yaw))
            cost[i, j] = math.hypot(truck["center"][0] - front[0], truck["center"][1] - front[1])
    pairs = associate(cost, gate_m)
    used_t = {i for i, _ in pairs}
    used_r = {j for _, j in pairs}
    out: list[tuple[dict | None, dict | None]] = [(trucks[i], trailers[j]) for i, j in pairs]
    out += [(t, None) for i, t in enumerate(trucks) if i not in used_t]
    out += [(None, r) for j, r in enumerate(trailers) if j not in used_r]
    return out


def pair_linked(
    trucks: list[dict], trailers: list[dict], links: list[tuple[str, str]]
) -> list[tuple[dict | None, dict | None]]:
    """Group units by the file's own (truck key, trailer key) links; the others stay alone."""
    by_key = {u["key"]: u for u in trucks + trailers}
    pairs = [(by_key[t], by_key[r]) for t, r in links if t in by_key and r in by_key]
    linked = {id(u) for pair in pairs for u in pair}
    return (
        pairs
        + [(t, None) for t in trucks if id(t) not in linked]
        + [(None, r) for r in trailers if id(r) not in linked]
    )


def _vehicle_line(
    units: list[dict], frame: int, stamp_s: float, ids: dict, gate_m: float, links: list[tuple[str, str]] | None = None
) -> dict:
    """One GT line from labelled units (dicts with kind, key, center, dimensions, yaw_deg, ...),
    paired by ``links`` (truck key, trailer key) when the labels have them, else by distance."""
    trucks = [u for u in units if u["kind"] == "truck"]
    trailers = [u for u in units if u["kind"] == "trailer"]
    vehicles = []
    if links is not None:  # in the file's order
        position = {id(u): i for i, u in enumerate(units)}
        pairs = sorted(
            pair_linked(trucks, trailers, links), key=lambda p: min(position[id(u)] for u in p if u is not None)
        )
    else:
        pairs = pair_units(trucks, trailers, gate_m)
    for truck, trailer in pairs:
        lead = truck if truck is not None else trailer
        vid = ids.setdefault(lead["key"], len(ids) + 1)
        v = {
            "id": vid,
            "vehicle": (truck or {}).get("vehicle") or (trailer or {}).get("vehicle"),
            "maneuver": (truck or {}).get("maneuver") or (trailer or {}).get("maneuver") or UNLABELLED,
            "truck": _unit_dict(truck),
            "trailer": _unit_dict(trailer),
        }
        both = truck is not None and trailer is not None
        v["hitch_deg"] = wrap_deg(trailer["yaw_deg"] - truck["yaw_deg"]) if both else None
        v["tractor_to_trailer"] = tractor_to_trailer(v["truck"], v["trailer"]) if both else None
        vehicles.append(v)
    return {"frame": frame, "stamp_s": stamp_s, "vehicles": vehicles, "distractors": []}


def _unit_dict(unit: dict | None) -> dict | None:
    if unit is None:
        return None
    return {
        "center": [float(c) for c in unit["center"]],
        "dimensions": [float(d) for d in unit["dimensions"]],
        "yaw_deg": wrap_deg(unit["yaw_deg"]),
        "velocity": None,
        "points": unit.get("points"),
    }


def _attribute(attrs: dict, kind: str, name: str):
    for item in attrs.get(kind, []) or []:
        if item.get("name") == name:
            return item.get("val")
    return None


def _apply_transform(unit: dict, transform: np.ndarray | None) -> dict:
    if transform is None:
        return unit
    pose = np.asarray(transform, float) @ _unit_pose(unit)
    unit = dict(unit)
    unit["center"] = pose[:3, 3].tolist()
    unit["yaw_deg"] = math.degrees(math.atan2(pose[1, 0], pose[0, 0]))
    return unit


def load_openlabel(
    path: str | Path,
    rate_hz: float = 10.0,
    transform=None,
    stamp_origin_s: float | None = None,
    pair_gate_m: float = 8.0,
) -> list[dict]:
    """GT lines from ASAM OpenLABEL (TUMTraf style): one file with many frames, or a folder of
    one-frame files. Cuboid ``val`` = [x, y, z, qx, qy, qz, qw, length, width, height]; classes
    TRUCK and TRAILER; ``num_points`` becomes ``points``; optional text attributes ``vehicle`` and
    ``maneuver``. ``stamp_s`` is ``frame_properties.timestamp`` minus ``stamp_origin_s`` (default:
    the first frame's timestamp), else frame number / ``rate_hz``. ``transform`` (4x4) maps the
    label frame into the yard frame."""
    path = Path(path)
    files = sorted(path.glob("*.json")) if path.is_dir() else [path]
    if not files:
        raise GroundTruthError(f"{path}: no OpenLABEL .json files")
    frames: list[tuple[int, float | None, list[dict], list | None]] = []
    label_files = 0
    for file in files:
        data = _read_json(file)
        if "openlabel" not in data:
            if path.is_dir():  # e.g. a calibration file next to the labels
                continue
            raise GroundTruthError(f"{file}: not OpenLABEL (no top-level 'openlabel' key)")
        label_files += 1
        for key, frame in (data["openlabel"].get("frames") or {}).items():
            try:
                number = int(key)
            except ValueError as err:
                raise GroundTruthError(f"{file}: frame key {key!r} is not an integer") from err
            stamp = (frame.get("frame_properties") or {}).get("timestamp")
            static = data["openlabel"].get("objects") or {}
            links = _towing_links(frame, data["openlabel"].get("relations"))
            frames.append((number, stamp, _openlabel_units(frame, static, file, transform), links))
    if not label_files:
        raise GroundTruthError(f"{path}: no OpenLABEL files (none has a top-level 'openlabel' key)")
    frames.sort(key=lambda f: f[0])
    stamps = [s for _, s, _, _ in frames if s is not None]
    origin = stamp_origin_s if stamp_origin_s is not None else (min(stamps) if stamps else 0.0)
    ids: dict = {}
    return [
        _vehicle_line(
            units, number, (float(stamp) - origin) if stamp is not None else number / rate_hz, ids, pair_gate_m, links
        )
        for number, stamp, units, links in frames
    ]


def _towing_links(frame: dict, relations: dict | None) -> list[tuple[str, str]] | None:
    """(truck, trailer) object keys of the frame's relations (``isTowing``: subject tows object);
    None when the file has no relations (units are then paired by distance)."""
    if not relations:
        return None
    links = []
    for rid in frame.get("relations") or {}:
        rel = relations.get(rid) or {}
        subjects, objects = rel.get("rdf_subjects") or [], rel.get("rdf_objects") or []
        if subjects and objects:
            links.append((str(subjects[0]["uid"]), str(objects[0]["uid"])))
    return links


def _openlabel_units(frame: dict, static: dict, file: Path, transform) -> list[dict]:
    """Units of one frame. The class and static attributes may sit in the frame's object (as in
    TUMTraf) or, per the standard, in the top-level ``objects`` under the same key."""
    units = []
    for key, obj in (frame.get("objects") or {}).items():
        data = obj.get("object_data") or {}
        fixed = static.get(key) or {}
        kind = _unit_kind(str(data.get("type") or obj.get("type") or fixed.get("type") or ""))
        cuboid = data.get("cuboid")
        if kind is None or not cuboid:
            continue
        val = cuboid.get("val") if isinstance(cuboid, dict) else None
        if not isinstance(val, list) or len(val) != 10:
            raise GroundTruthError(f"{file}: object {key}: cuboid val must have 10 numbers (x y z qx qy qz qw l w h)")
        attrs = cuboid.get("attributes") or {}
        points = _attribute(attrs, "num", "num_points")
        unit = {
            "kind": kind,
            "key": key,
            "center": val[0:3],
            "dimensions": val[7:10],
            "yaw_deg": yaw_from_quaternion_deg(*val[3:7]),
            "points": int(points) if points is not None else None,
            "vehicle": _attribute(attrs, "text", "vehicle")
            or _attribute(fixed.get("object_data") or {}, "text", "vehicle"),
            "maneuver": _attribute(attrs, "text", "maneuver"),
        }
        units.append(_apply_transform(unit, transform))
    return units


def load_labelcloud(
    path: str | Path, rate_hz: float = 10.0, rotation_unit: str = "auto", transform=None, pair_gate_m: float = 8.0
) -> list[dict]:
    """GT lines from labelCloud's JSON export: one file per point cloud (a folder, or one file).

    Formats: ``centroid_abs`` (rotations in degrees, 0..360), ``centroid_rel`` (radians, -pi..pi)
    and ``vertices`` (8 corners: left back bottom, left front bottom, right front bottom, right
    back bottom, then the same on top). Object ``name`` holds the class: "truck"/"tractor" or
    "trailer", optionally ``class:vehicle`` (e.g. ``truck:man_tgx``). ``rotation_unit`` is "deg",
    "rad" or "auto" (radians only when a rotation is negative, as centroid_abs never is). The
    frame number is the last integer in the file name (else the sorted position); the stamp is
    frame / ``rate_hz``; a vehicle's id follows its order of appearance in each frame."""
    if rotation_unit not in ("auto", "deg", "rad"):
        raise GroundTruthError(f"rotation_unit must be auto, deg or rad, got {rotation_unit!r}")
    path = Path(path)
    files = sorted(path.glob("*.json")) if path.is_dir() else [path]
    if not files:
        raise GroundTruthError(f"{path}: no labelCloud .json files")
    lines = []
    for position, file in enumerate(files):
        data = _read_json(file)
        if not isinstance(data.get("objects"), list):
            raise GroundTruthError(f"{file}: not a labelCloud label (no 'objects' list)")
        numbers = re.findall(r"\d+", file.stem)
        frame = int(numbers[-1]) if numbers else position
        units = [_labelcloud_unit(obj, file, rotation_unit, transform) for obj in data["objects"]]
        units = [u for u in units if u is not None]
        for order, unit in enumerate(u for u in units if u["kind"] == "truck"):
            unit["key"] = ("truck", order)
        for order, unit in enumerate(u for u in units if u["kind"] == "trailer"):
            unit["key"] = ("trailer", order)
        lines.append((frame, units))
    lines.sort(key=lambda item: item[0])
    out = []
    for frame, units in lines:
        ids: dict = {}  # labelCloud has no track ids: number the vehicles per frame
        out.append(_vehicle_line(units, frame, frame / rate_hz, ids, pair_gate_m))
    return out


def _labelcloud_unit(obj: dict, file: Path, rotation_unit: str, transform) -> dict | None:
    name = str(obj.get("name", ""))
    kind = _unit_kind(name.split(":")[0])
    if kind is None:
        return None
    vehicle = name.split(":", 1)[1] if ":" in name else None
    if "vertices" in obj:
        v = np.asarray(obj["vertices"], float)
        if v.shape != (8, 3):
            raise GroundTruthError(f"{file}: object {name!r}: 'vertices' must be 8 points of 3 numbers")
        forward, right, up = v[1] - v[0], v[3] - v[0], v[4] - v[0]
        center = v.mean(axis=0).tolist()
        dims = [float(np.linalg.norm(forward)), float(np.linalg.norm(right)), float(np.linalg.norm(up))]
        yaw = math.degrees(math.atan2(forward[1], forward[0]))
    else:
        try:
            center = [float(obj["centroid"][k]) for k in ("x", "y", "z")]
            dims = [float(obj["dimensions"][k]) for k in ("length", "width", "height")]
            rot_z = float(obj["rotations"]["z"])
        except (KeyError, TypeError, ValueError) as err:
            raise GroundTruthError(
                f"{file}: object {name!r}: needs centroid x/y/z, dimensions length/width/height and rotations z"
            ) from err
        radians = rotation_unit == "rad" or (rotation_unit == "auto" and rot_z < 0)
        yaw = math.degrees(rot_z) if radians else rot_z
    unit = {
        "kind": kind,
        "center": center,
        "dimensions": dims,
        "yaw_deg": yaw,
        "points": None,
        "vehicle": vehicle,
        "maneuver": None,
    }
    return _apply_transform(unit, transform)


def _read_json(file: Path) -> dict:
    try:
        data = json.loads(Path(file).read_text())
    except (OSError, json.JSONDecodeError) as err:
        raise GroundTruthError(f"{file}: cannot read JSON: {err}") from err
    if not isinstance(data, dict):
        raise GroundTruthError(f"{file}: expected a JSON object at the top level")
    return data


def load_ground_truth(path: str | Path, **kwargs) -> list[dict]:
    """Any supported source: a recording folder or ``*.jsonl`` (our lines), an OpenLABEL file or
    folder, or labelCloud labels (file or folder); detected from the content."""
    path = Path(path)
    if path.is_dir() and (path / "ground_truth.jsonl").is_file():
        return load_jsonl(path / "ground_truth.jsonl")
    if path.suffix == ".jsonl":
        return load_jsonl(path)
    samples = [path] if path.is_file() else sorted(path.glob("*.json"))
    if not samples:
        raise GroundTruthError(f"{path}: no ground truth (.jsonl) or label files (.json) found")
    for sample in samples:
        data = _read_json(sample)
        if "openlabel" in data:
            return load_openlabel(path, **kwargs)
        if "objects" in data:
            return load_labelcloud(path, **kwargs)
    raise GroundTruthError(f"{path}: neither OpenLABEL nor a labelCloud export")
