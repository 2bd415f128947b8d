"""State lines → ASAM OpenLABEL 1.0, in the TUMTraf conventions: one TRUCK and one TRAILER object
per tracked vehicle, 3D cuboids ``val = [x, y, z, qx, qy, qz, qw, length, width, height]`` in the
yard frame, and a relation ``isTowing`` (truck → trailer) in every frame that has both units.
Readable by ``i2v_loc.evaluation.groundtruth.load_openlabel`` (``eval --labels``)."""

from __future__ import annotations

import json
from collections.abc import Iterable
from pathlib import Path

import numpy as np

SCHEMA_VERSION = "1.0.0"
RELATION = "isTowing"


def _quaternion_z(yaw_deg: float) -> list[float]:
    half = np.radians(yaw_deg) / 2.0
    return [0.0, 0.0, float(np.sin(half)), float(np.cos(half))]


def _cuboid(unit: dict, vehicle: dict) -> dict:
    attributes = {
        "num": [{"name": "num_points", "val": unit.get("points")}],
        "text": [{"name": "vehicle", "val": vehicle.get("vehicle")}],
    }
    if vehicle.get("hitch_deg") is not None:
        attributes["num"].append({"name": "hitch_deg", "val": vehicle["hitch_deg"]})
    return {
        "name": "shape3D",
        "val": [*unit["center"], *_quaternion_z(unit["yaw_deg"]), *unit["dimensions"]],
        "attributes": attributes,
    }


def states_to_openlabel(states: Iterable[dict], annotator: str = "i2v-loc run") -> dict:
    """OpenLABEL dict of state lines (``i2v-loc run`` output); frames without a stamp are skipped."""
    objects: dict[str, dict] = {}
    relations: dict[str, dict] = {}
    frames: dict[str, dict] = {}
    numbers = []
    for line in states:
        if line.get("stamp_s") is None:
            continue
        frame_objects, frame_relations = {}, {}
        for v in line.get("vehicles", []):
            uids = {}
            for unit, kind in (("truck", "TRUCK"), ("trailer", "TRAILER")):
                if v.get(unit) is None or v[unit].get("yaw_deg") is None:
                    continue
                uid = str(2 * int(v["id"]) - (1 if unit == "truck" else 0))
                uids[unit] = uid
                objects.setdefault(
                    uid,
                    {
                        "name": f"{kind}_{v['id']}",
                        "type": kind,
                        "object_data": {"text": [{"name": "vehicle", "val": v.get("vehicle")}]},
                    },
                )
                frame_objects[uid] = {
                    "object_data": {"name": f"{kind}_{v['id']}", "type": kind, "cuboid": _cuboid(v[unit], v)}
                }
            if len(uids) == 2:
                rid = str(v["id"])
                relations.setdefault(
                    rid,
                    {
                        "name": f"towing_{v['id']}",
                        "type": RELATION,
                        "rdf_subjects": [{"uid": uids["truck"], "type": "object"}],
                        "rdf_objects": [{"uid": uids["trailer"], "type": "object"}],
                    },
                )
                frame_relations[rid] = {}
        frame = {"frame_properties": {"timestamp": line["stamp_s"]}, "objects": frame_objects}
        if frame_relations:
            frame["relations"] = frame_relations
        frames[str(line["frame"])] = frame
        numbers.append(int(line["frame"]))
    return {
        "openlabel": {
            "metadata": {"schema_version": SCHEMA_VERSION, "annotator": annotator},
            "coordinate_systems": {"yard": {"type": "scene_cs", "parent": "", "children": []}},
            "objects": objects,
            "relations": relations,
            "frames": frames,
            "frame_intervals": [{"frame_start": min(numbers), "frame_end": max(numbers)}] if numbers else [],
        }
    }


def write_openlabel(states: Iterable[dict], out: str | Path) -> Path:
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(states_to_openlabel(states)))
    return out
