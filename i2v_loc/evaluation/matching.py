"""Per-frame comparison of state lines with the ground truth: one record per GT vehicle and frame
(plus one per false vehicle), and one row per frame with the latencies."""

from __future__ import annotations

import math

import numpy as np

from i2v_loc.evaluation import dcap
from i2v_loc.evaluation.groundtruth import UNITS, UNLABELLED, interpolate_ground_truth
from i2v_loc.evaluation.metrics import angle_error_deg, associate, within_success
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


def same_type(gt: dict, est: dict) -> bool:
    """False when both name a vehicle type and the names differ: an estimate reported under a
    type the vehicle is not is never a match (it is a false vehicle, the true one is missed). A
    vehicle the catalogue does not hold (``unknown_*`` in the truth) has no type to get wrong: it
    matches an estimate of any type (the nearest catalogue type, or ``unknown``)."""
    truth, estimate = gt.get("vehicle"), est.get("vehicle")
    return not truth or truth == UNLABELLED or truth.startswith("unknown") or not estimate or truth == estimate


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


def _hitch_std(vehicle: dict | None) -> float:
    """The reported hitch angle's standard deviation (NaN: none reported)."""
    std = (vehicle or {}).get("hitch_std_deg")
    return float(std) if std is not None else NAN


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
    return bool(vehicle and all(vehicle.get(u) is not None and vehicle[u].get("yaw_deg") is not None for u in UNITS))


def _front_to_rear(vehicle: dict, config) -> np.ndarray:
    truck, trailer = vehicle["truck"], vehicle["trailer"]
    poses = box_poses([truck["center"], trailer["center"]], [truck["yaw_deg"], trailer["yaw_deg"]])
    return dcap.front_to_rear(poses[:1], poses[1:], config)[0]


def _dcap_fields(prefix: str, estimate: np.ndarray | None, truth: np.ndarray | None) -> dict:
    if estimate is None or truth is None:
        return {
            f"{prefix}_dx_m": NAN,
            f"{prefix}_dy_m": NAN,
            f"{prefix}_dz_m": NAN,
            f"{prefix}_dT_m": NAN,
            f"{prefix}_rra_rad": NAN,
        }
    d = estimate[:3, 3] - truth[:3, 3]
    return {
        f"{prefix}_dx_m": float(d[0]),
        f"{prefix}_dy_m": float(d[1]),
        f"{prefix}_dz_m": float(d[2]),
        f"{prefix}_dT_m": float(np.linalg.norm(d)),
        f"{prefix}_rra_rad": rotation_angle_rad(estimate[:3, :3], truth[:3, :3]),
    }


def _success_fields(rec: dict) -> dict:
    """Visible: every unit has >= MIN_POINTS_FOR_DETECTION GT points (the detection rule, both
    units). Success: both units reported, each within the position and yaw thresholds, and the
    hitch within its threshold (metrics.within_success)."""
    both = all(rec[f"{u}_reported"] for u in UNITS)
    success = both and within_success(
        [rec[f"{u}_pos_err_m"] for u in UNITS], [rec[f"{u}_yaw_err_deg"] for u in UNITS], rec["hitch_err_deg"]
    )
    return {
        "visible": all(rec[f"{u}_eligible"] for u in UNITS),
        "both_in_gt": all(rec[f"{u}_in_gt"] for u in UNITS),
        "both_reported": both,
        "success": bool(success),
    }


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
    rec["hitch_std_deg"] = _hitch_std(est)
    rec.update(_success_fields(rec) if gt is not None else {})
    config = params.vehicles.get(rec["vehicle"]) if gt is not None else None
    truth = _front_to_rear(gt, config) if config is not None and _both_posed(gt) else None
    estimate = _front_to_rear(est, config) if truth is not None and _both_posed(est) else None
    static = dcap.static_front_to_rear(config) if truth is not None else None
    rec.update(_dcap_fields("dcap", estimate, truth))
    rec.update(_dcap_fields("static", static, truth))
    return rec


def match_frame(state: dict, gt_line: dict, params: Params, gate_m: float, period_s: float = NAN) -> list[dict]:
    """Records of one state against the truth at its stamp (nearest-centre Hungarian, gated; a
    pair of different vehicle types is never matched). A false vehicle's record holds the frame
    period (``false_s``) and, when it sits on a GT vehicle of another type, that type
    (``wrong_type_of``)."""
    gts = gt_line.get("vehicles", [])
    ests = state.get("vehicles") or []
    distance = np.array([[vehicle_cost(g, e) for e in ests] for g in gts]).reshape(len(gts), len(ests))
    typed = np.array([[same_type(g, e) for e in ests] for g in gts], bool).reshape(distance.shape)
    pairs = dict(associate(np.where(typed, distance, math.inf), gate_m))
    matched = set(pairs.values())
    records = [vehicle_record(g, ests[pairs[i]] if i in pairs else None, params) for i, g in enumerate(gts)]
    maneuver = gts[0].get("maneuver", "none") if gts else "none"
    for j, e in enumerate(ests):
        if j not in matched:
            rec = vehicle_record(None, e, params)
            rec["maneuver"] = maneuver
            rec["false_s"] = period_s
            near = [i for i in range(len(gts)) if not typed[i, j] and distance[i, j] <= gate_m]
            rec["wrong_type_of"] = gts[min(near, key=lambda i: distance[i, j])].get("vehicle") if near else None
            records.append(rec)
    for rec in records:
        rec["frame"] = state.get("frame")
        rec["stamp_s"] = state.get("stamp_s")
    return records


def frame_row(state: dict, n_gt: int, scored: bool = True) -> dict:
    row = {
        "frame": state.get("frame"),
        "stamp_s": state.get("stamp_s"),
        "scored": scored,
        "n_gt_vehicles": n_gt,
        "n_est_vehicles": len(state.get("vehicles") or []),
    }
    for stage, ms in (state.get("latency_ms") or {}).items():
        row[f"latency_{stage}_ms"] = float(ms) if ms is not None else NAN
    return row


def frame_period_s(gt_times: np.ndarray, state_stamps: list) -> float:
    """The recording's frame period: the median step of the GT stamps (else of the states')."""
    for stamps in (np.asarray(gt_times, float), np.array([np.nan if s is None else s for s in state_stamps], float)):
        steps = np.diff(stamps[np.isfinite(stamps)])
        if steps.size:
            return float(np.median(steps))
    return NAN


def _track_age_s(est_id, stamp, first_seen: dict) -> float:
    """Seconds since the estimated vehicle ``est_id`` was first reported (NaN: none, or no stamp)."""
    if est_id is None or stamp is None:
        return NAN
    return float(stamp) - first_seen.setdefault(est_id, float(stamp))


def match_states(
    states: list[dict], gt_lines: list[dict], params: Params, gate_m: float = 4.0
) -> tuple[list[dict], list[dict]]:
    """Records and frame rows of a whole run. Each state is compared with the truth interpolated
    to its ``stamp_s`` (falling back to the GT line of the same frame when it has no stamp). A state
    stamped outside the truth's span (a last sweep that ends after the last GT line) is not scored:
    no truth there is not a truth of no vehicles; its frame row says ``scored`` False."""
    records, frames = [], []
    by_frame = {line.get("frame"): line for line in gt_lines}
    times = np.array([line["stamp_s"] for line in gt_lines], float)
    period = frame_period_s(times, [s.get("stamp_s") for s in states])
    start = next((float(s["stamp_s"]) for s in states if s.get("stamp_s") is not None), NAN)
    first_seen: dict = {}  # estimated vehicle id -> stamp of its first report
    for state in states:
        stamp = state.get("stamp_s")
        if stamp is not None and np.isfinite(stamp):
            gt = interpolate_ground_truth(gt_lines, float(stamp), times=times)
        else:
            gt = by_frame.get(state.get("frame"), {"vehicles": []})
        if gt.get("outside_truth"):
            frames.append(frame_row(state, 0, scored=False))
            continue
        frame_records = match_frame(state, gt, params, gate_m, period)
        since = float(stamp) - start if stamp is not None else NAN
        for rec in frame_records:
            rec["since_start_s"] = since
            rec["track_age_s"] = _track_age_s(rec.get("est_id"), stamp, first_seen)
        records += frame_records
        frames.append(frame_row(state, len(gt.get("vehicles", []))))
    return records, frames
