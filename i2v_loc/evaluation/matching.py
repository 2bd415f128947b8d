"""Per-frame comparison of state lines with the ground truth: one record per GT vehicle and frame
(plus one per false vehicle), and one row per frame with the latencies."""

from __future__ import annotations

import math

import numpy as np

from i2v_loc.evaluation import dcap
from i2v_loc.evaluation.groundtruth import UNITS, interpolate_ground_truth
from i2v_loc.evaluation.metrics import angle_error_deg, associate
from i2v_loc.geometry import box_poses, rotation_angle_rad, wrap_deg
from i2v_loc.params import Params

MIN_POINTS_FOR_DETECTION = 30
NAN = float("nan")


def _unit_distance(gt: dict | None, est: dict | None) -> float:
    if gt is None or est is None:
        return NAN
    return math.hypot(est["center"][0] - gt["center"][0], est["center"][1] - gt["center"][1])


def vehicle_cost(gt: dict, est: dict) -> float:
    """Mean planar distance between the units both have; inf when they share none."""
    d = [_unit_distance(gt.get(u), est.get(u)) for u in UNITS]
    d = [x for x in d if np.isfinite(x)]
    return float(np.mean(d)) if d else math.inf


def _unit_fields(prefix: str, gt: dict | None, est: dict | None) -> dict:
    out = {}
    points = gt.get("points") if gt else None
    out[f"{prefix}_points_gt"] = points if points is not None else NAN
    out[f"{prefix}_in_gt"] = gt is not None
    out[f"{prefix}_eligible"] = gt is not None and (points is None or points >= MIN_POINTS_FOR_DETECTION)
    out[f"{prefix}_reported"] = est is not None
    out[f"{prefix}_track_id"] = est.get("track_id") if est else None
    for tag, unit in (("gt", gt), ("est", est)):
        c = unit["center"] if unit else (NAN, NAN, NAN)
        d = unit.get("dimensions") or (NAN, NAN, NAN) if unit else (NAN, NAN, NAN)
        yaw = unit.get("yaw_deg") if unit else None
        out[f"{prefix}_x_{tag}"], out[f"{prefix}_y_{tag}"], out[f"{prefix}_z_{tag}"] = (float(v) for v in c[:3])
        out[f"{prefix}_yaw_{tag}"] = float(yaw) if yaw is not None else NAN
        out[f"{prefix}_length_{tag}"], out[f"{prefix}_width_{tag}"] = float(d[0]), float(d[1])
    if gt is not None and est is not None:
        out[f"{prefix}_pos_err_m"] = _unit_distance(gt, est)
        out[f"{prefix}_yaw_err_deg"] = float(angle_error_deg(out[f"{prefix}_yaw_est"], out[f"{prefix}_yaw_gt"]))
    else:
        out[f"{prefix}_pos_err_m"] = NAN
        out[f"{prefix}_yaw_err_deg"] = NAN
    return out


def _hitch(vehicle: dict | None) -> float:
    if vehicle is None:
        return NAN
    if vehicle.get("hitch_deg") is not None:
        return float(vehicle["hitch_deg"])
    truck, trailer = vehicle.get("truck"), vehicle.get("trailer")
    if truck and trailer and truck.get("yaw_deg") is not None and trailer.get("yaw_deg") is not None:
        return wrap_deg(trailer["yaw_deg"] - truck["yaw_deg"])
    return NAN


def _both_posed(vehicle: dict | None) -> bool:
    return bool(
        vehicle
        and all(vehicle.get(u) is not None and vehicle[u].get("yaw_deg") is not None for u in UNITS)
    )


def _front_to_rear(vehicle: dict, config) -> np.ndarray:
    truck, trailer = vehicle["truck"], vehicle["trailer"]
    poses = box_poses([truck["center"], trailer["center"]], [truck["yaw_deg"], trailer["yaw_deg"]])
    return dcap.front_to_rear(poses[:1], poses[1:], config)[0]


def _dcap_fields(prefix: str, estimate: np.ndarray | None, truth: np.ndarray | None) -> dict:
    if estimate is None or truth is None:
        return {f"{prefix}_dx_m": NAN, f"{prefix}_dy_m": NAN, f"{prefix}_dz_m": NAN,
                f"{prefix}_dT_m": NAN, f"{prefix}_rra_rad": NAN}
    d = estimate[:3, 3] - truth[:3, 3]
    return {f"{prefix}_dx_m": float(d[0]), f"{prefix}_dy_m": float(d[1]), f"{prefix}_dz_m": float(d[2]),
            f"{prefix}_dT_m": float(np.linalg.norm(d)), f"{prefix}_rra_rad": rotation_angle_rad(estimate[:3, :3], truth[:3, :3])}


def vehicle_record(gt: dict | None, est: dict | None, params: Params) -> dict:
    """Everything measured on one GT vehicle (or one false vehicle when ``gt`` is None)."""
    rec = {
        "kind": "gt" if gt is not None else "false",
        "gt_id": gt["id"] if gt else None,
        "vehicle": (gt or {}).get("vehicle") or (est or {}).get("vehicle") or "unknown",
        "maneuver": (gt or {}).get("maneuver") or "none",
        "est_id": est.get("id") if est else None,
        "est_vehicle": est.get("vehicle") if est else None,
    }
    for unit in UNITS:
        rec.update(_unit_fields(unit, (gt or {}).get(unit), (est or {}).get(unit)))
    rec["hitch_gt_deg"] = _hitch(gt)
    rec["hitch_est_deg"] = _hitch(est)
    rec["hitch_err_deg"] = float(angle_error_deg(rec["hitch_est_deg"], rec["hitch_gt_deg"]))
    config = params.vehicles.get(rec["vehicle"]) if gt is not None else None
    truth = _front_to_rear(gt, config) if config is not None and _both_posed(gt) else None
    estimate = _front_to_rear(est, config) if truth is not None and _both_posed(est) else None
    static = dcap.static_front_to_rear(config) if truth is not None else None
    rec.update(_dcap_fields("dcap", estimate, truth))
    rec.update(_dcap_fields("static", static, truth))
    return rec


def match_frame(state: dict, gt_line: dict, params: Params, gate_m: float) -> list[dict]:
    """Records of one state against the truth at its stamp (nearest-centre Hungarian, gated)."""
    gts = gt_line.get("vehicles", [])
    ests = state.get("vehicles") or []
    cost = np.array([[vehicle_cost(g, e) for e in ests] for g in gts]).reshape(len(gts), len(ests))
    pairs = dict(associate(cost, gate_m))
    matched = set(pairs.values())
    records = [vehicle_record(g, ests[pairs[i]] if i in pairs else None, params) for i, g in enumerate(gts)]
    maneuver = gts[0].get("maneuver", "none") if gts else "none"
    for j, e in enumerate(ests):
        if j not in matched:
            rec = vehicle_record(None, e, params)
            rec["maneuver"] = maneuver
            records.append(rec)
    for rec in records:
        rec["frame"] = state.get("frame")
        rec["stamp_s"] = state.get("stamp_s")
    return records


def frame_row(state: dict, n_gt: int) -> dict:
    row = {"frame": state.get("frame"), "stamp_s": state.get("stamp_s"),
           "n_gt_vehicles": n_gt, "n_est_vehicles": len(state.get("vehicles") or [])}
    for stage, ms in (state.get("latency_ms") or {}).items():
        row[f"latency_{stage}_ms"] = float(ms) if ms is not None else NAN
    return row


def match_states(states: list[dict], gt_lines: list[dict], params: Params, gate_m: float = 4.0) -> tuple[list[dict], list[dict]]:
    """Records and frame rows of a whole run. Each state is compared with the truth interpolated
    to its ``stamp_s`` (falling back to the GT line of the same frame when it has no stamp)."""
    records, frames = [], []
    by_frame = {line.get("frame"): line for line in gt_lines}
    times = np.array([line["stamp_s"] for line in gt_lines], float)
    for state in states:
        stamp = state.get("stamp_s")
        if stamp is not None and np.isfinite(stamp):
            gt = interpolate_ground_truth(gt_lines, float(stamp), times=times)
        else:
            gt = by_frame.get(state.get("frame"), {"vehicles": []})
        records += match_frame(state, gt, params, gate_m)
        frames.append(frame_row(state, len(gt.get("vehicles", []))))
    return records, frames
