"""Metric primitives, each a small vectorised function checked against hand-computed values.

Angles are in degrees and every difference is wrapped to (-180, 180] before it is squared, so
an estimate of 179 deg against a truth of -179 deg is a 2 deg error, not 358 deg.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment

from i2v_loc.geometry import rotation_angle_rad, wrap_deg

HEADING_FLIP_DEG = 90.0
# A frame is a success when both units are within these of the truth and the hitch too.
SUCCESS_POSITION_M = 0.3
SUCCESS_YAW_DEG = 2.0
SUCCESS_HITCH_DEG = 2.0
_TOLERANCE = 1e-9  # the thresholds are inclusive; float differences like 10.3 - 10.0 stay within


def angle_error_deg(estimate_deg, truth_deg) -> np.ndarray:
    """Estimate minus truth, wrapped to (-180, 180]."""
    return np.asarray(wrap_deg(np.asarray(estimate_deg, float) - np.asarray(truth_deg, float)), float)


def rmse(errors) -> float:
    """Root mean square of the finite errors; NaN when there are none."""
    e = np.asarray(errors, float)
    e = e[np.isfinite(e)]
    return float(np.sqrt(np.mean(e**2))) if e.size else float("nan")


def position_rmse_m(estimate_xy, truth_xy) -> float:
    """Paper Eq. 14: sqrt(mean(dx^2 + dy^2)) over the rows of (N, 2) arrays."""
    d = np.asarray(estimate_xy, float).reshape(-1, 2) - np.asarray(truth_xy, float).reshape(-1, 2)
    return rmse(np.hypot(d[:, 0], d[:, 1]))


def orientation_rmse_deg(estimate_deg, truth_deg) -> float:
    """Paper Eq. 15 with wrapped differences."""
    return rmse(angle_error_deg(estimate_deg, truth_deg))


def hitch_rmse_deg(est_truck_deg, est_trailer_deg, gt_truck_deg, gt_trailer_deg) -> float:
    """Paper Eq. 16: error of (trailer yaw - truck yaw) against the truth, wrapped."""
    est = angle_error_deg(est_trailer_deg, est_truck_deg)
    gt = angle_error_deg(gt_trailer_deg, gt_truck_deg)
    return rmse(angle_error_deg(est, gt))


def heading_flip_rate(yaw_errors_deg) -> float:
    """Share of finite yaw errors whose magnitude exceeds 90 deg (the box faces backwards)."""
    e = np.asarray(yaw_errors_deg, float)
    e = e[np.isfinite(e)]
    return float(np.mean(np.abs(e) > HEADING_FLIP_DEG)) if e.size else float("nan")


def within_success(position_errors_m, yaw_errors_deg, hitch_error_deg) -> bool:
    """Every unit within SUCCESS_POSITION_M and SUCCESS_YAW_DEG (inclusive) and the hitch within
    SUCCESS_HITCH_DEG; a missing (NaN) error fails."""
    pos = np.abs(np.asarray(position_errors_m, float))
    yaw = np.abs(np.asarray(yaw_errors_deg, float))
    hitch = abs(float(hitch_error_deg))
    return bool(
        np.all(pos <= SUCCESS_POSITION_M + _TOLERANCE)
        and np.all(yaw <= SUCCESS_YAW_DEG + _TOLERANCE)
        and hitch <= SUCCESS_HITCH_DEG + _TOLERANCE
    )


def flip_count(yaw_errors_deg) -> int:
    """Frames whose |yaw error| exceeds 90 deg (the box faces backwards)."""
    e = np.asarray(yaw_errors_deg, float)
    return int((np.abs(e[np.isfinite(e)]) > HEADING_FLIP_DEG).sum())


def transform_errors(estimate: np.ndarray, truth: np.ndarray) -> dict[str, np.ndarray]:
    """dCAP's per-frame errors of stacked 4x4 transforms (N, 4, 4): translation error vector
    (N, 3), its L2 norm (N,) and the geodesic rotation angle between the rotations (N,) in rad."""
    est = np.asarray(estimate, float).reshape(-1, 4, 4)
    gt = np.asarray(truth, float).reshape(-1, 4, 4)
    dt = est[:, :3, 3] - gt[:, :3, 3]
    rra = rotation_angle_rad(est[:, :3, :3], gt[:, :3, :3])
    return {"delta": dt, "delta_T": np.linalg.norm(dt, axis=1), "rra": rra}


def dcap_summary(estimate: np.ndarray, truth: np.ndarray) -> dict[str, float]:
    """dCAP Table 2 columns: mean ΔT, mean |Δx|, |Δy|, |Δz| (m) and mean RRA (rad)."""
    if len(np.asarray(estimate).reshape(-1, 16)) == 0:
        nan = float("nan")
        return {"delta_T_m": nan, "delta_x_m": nan, "delta_y_m": nan, "delta_z_m": nan, "rra_rad": nan}
    e = transform_errors(estimate, truth)
    ad = np.abs(e["delta"]).mean(axis=0)
    return {
        "delta_T_m": float(e["delta_T"].mean()),
        "delta_x_m": float(ad[0]),
        "delta_y_m": float(ad[1]),
        "delta_z_m": float(ad[2]),
        "rra_rad": float(e["rra"].mean()),
    }


def latency_stats(values_ms) -> dict[str, float]:
    """Mean, median and 95th percentile of the finite values (ms)."""
    v = np.asarray(values_ms, float)
    v = v[np.isfinite(v)]
    if not v.size:
        return {"mean": float("nan"), "p50": float("nan"), "p95": float("nan")}
    return {"mean": float(v.mean()), "p50": float(np.percentile(v, 50)), "p95": float(np.percentile(v, 95))}


def associate(cost: np.ndarray, gate: float) -> list[tuple[int, int]]:
    """Minimum-cost one-to-one assignment (Hungarian) keeping only pairs with cost <= gate.

    ``cost`` is (n_truth, n_estimate); entries that are inf or NaN can never be paired."""
    cost = np.asarray(cost, float)
    if cost.size == 0:
        return []
    big = 1e9
    finite = np.where(np.isfinite(cost), cost, big)
    rows, cols = linear_sum_assignment(finite)
    return [(int(r), int(c)) for r, c in zip(rows, cols) if finite[r, c] <= gate]


def id_switches(track_ids) -> int:
    """Changes of the matched track id along a GT object's frames (CLEAR-MOT style): frames
    where it is unmatched (None) do not break the chain, a different id afterwards counts."""
    switches = 0
    last = None
    for tid in track_ids:
        if tid is None or (isinstance(tid, float) and not np.isfinite(tid)):
            continue
        if last is not None and tid != last:
            switches += 1
        last = tid
    return switches
