"""What a hinged fit's units show, shared by the vehicle tracker and the start (``vehicle_start``):
points in each unit's frame (tractor: rear axle; trailer: kingpin), the support and faces a fit's
points give its units, and how far a trailer's body reaches."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from i2v_loc.params import ArticulatedParams
from i2v_loc.stages import kernels
from i2v_loc.stages.hinged_fit import (
    TRAILER_LENGTH_RANGE_M,
    Measurement,
    Prior,
    on_face_below_roof,
)
from i2v_loc.stages.vehicle_model import Box, VehicleModel

MAX_TRAILER_LENGTH_M = TRAILER_LENGTH_RANGE_M[1]
REAR_FACE_MIN_POINTS = 3
FACE_SEEN_SPAN = 0.6  # an end face is seen when its points span this share of the unit's width
END_BAND_M = 0.4
MAX_BODY_GAP_M = 1.0
UNIT_SUPPORT = 0.5


def body_band(trailer: Box) -> tuple[float, float]:
    """The heights above the ground within ``END_BAND_M`` of the trailer body's floor to roof."""
    return trailer.floor_m - END_BAND_M, trailer.top_m + END_BAND_M


def reached_back(start_m: float, along: np.ndarray, gap_m: float = MAX_BODY_GAP_M) -> float:
    """The hindmost of the positions ``along`` a unit (its frame's x) reached from ``start_m`` backwards
    without a gap longer than ``gap_m``; ``start_m`` if none is."""
    behind = np.sort(along[along <= start_m])[::-1]
    gaps = np.flatnonzero(-np.diff(np.r_[start_m, behind]) > gap_m)
    reached = behind[: gaps[0]] if len(gaps) else behind
    return float(reached[-1]) if len(reached) else start_m


def body_heights(z_rel: np.ndarray, trailer: Box) -> np.ndarray:
    """Which heights above the ground (``z_rel``) lie in the trailer body's band (``body_band``)."""
    low, high = body_band(trailer)
    return (z_rel >= low) & (z_rel <= high)


def free_length_at(
    m: Measurement, model: VehicleModel, length_m: float, ground_z_m: float, hypothesis: bool = False
) -> Prior:
    """At the pose of the fit ``m``: ``model`` with its trailer ``length_m`` long, the length free."""
    sized = with_trailer_length(model, length_m)
    return Prior(
        m.x_m, m.y_m, m.yaw_rad, m.hitch_rad, sized, ground_z_m, free_trailer_length=True, hypothesis=hypothesis
    )


def face_seen(m: Measurement, model: VehicleModel, unit: int, face: int, ground_z_m: float, top_band_m: float) -> bool:
    """Whether the fit's points show one of a unit's end faces, as the trailer's rear face is
    shown: two or more across its middle (within a quarter of the width of its axis), all of them
    spanning ``FACE_SEEN_SPAN`` of its width. A face's corners are no face: two or three points at
    a trailer's front corners, the ends of its sides, passed for its front face, and the reach
    measured on them came out 0.37-0.42 m short (the trailer's box 0.2-0.3 m back for seconds).
    Nor is the edge of a roof running on past the face (points in the unit's roof band, within
    ``top_band_m`` of its top above the ground at ``ground_z_m``): a trailer's roof seen from a pole,
    its box pulled back 0.3-0.9 m by a dock's door behind it, passed for its front face, and the
    reach learned on it put the trailer 1 m back. ``model``: the one the fit ``m`` was made with
    (its unit's axis is the middle)."""
    on = on_face_below_roof(m, model, unit, face, ground_z_m, top_band_m)
    if np.count_nonzero(on) < 2:
        return False
    across = unit_frames(m.points[on], m.vector, model)[unit][:, 1]
    width = model.boxes[unit].width_m
    return np.count_nonzero(np.abs(across) <= width / 4) >= 2 and float(np.ptp(across)) >= FACE_SEEN_SPAN * width


def supported(
    m: Measurement,
    model: VehicleModel,
    ground_z_m: float,
    top_seen: bool = True,
    hidden_m: Callable[[int, float, float], float] | None = None,
) -> bool:
    """Each unit's explained points span at least ``UNIT_SUPPORT`` of its length (with the length
    ``hidden_m(unit, first, last)`` tells is hidden outside their span, its frame), reach
    ``UNIT_SUPPORT`` of its height above its floor (a car's side on a trailer's faces is no truck;
    unless the sensors' view ends below: ``top_seen`` False)
    and the cab's are at least ``UNIT_SUPPORT`` of its share of the side area (a parked trailer's
    landing gear is no tractor; a trailer's side seen along it from afar has a fifth of the points
    of its cab seen near, yet spans its length and height: asked of the trailer too, a MAN seen by
    one LiDAR was tracked as a rigid box 4.3 m off for 7 s), and at most ``UNIT_SUPPORT`` of them
    lie below its floor (a row of kerbs and parked cars with a lamp post among them is no trailer)."""
    boxes = model.boxes
    z_rel = m.points[:, 2] - ground_z_m
    areas = np.array([box.length_m * box.height_m for box in boxes])
    explained = max(int(np.sum(m.unit >= 0)), 1)
    for u, (box, q) in enumerate(zip(boxes, unit_frames(m.points, m.vector, model))):
        mine = m.unit == u
        if (
            mine.sum() < 3
            or (u == 0 and mine.sum() / explained < UNIT_SUPPORT * areas[u] / areas.sum())
            or (top_seen and z_rel[mine].max() < box.floor_m + UNIT_SUPPORT * box.height_m)
            or np.mean(z_rel[mine] < box.floor_m) > UNIT_SUPPORT
        ):
            return False
        along = q[mine, 0]
        span, need = float(np.ptp(along)), UNIT_SUPPORT * box.length_m
        if span < need and (hidden_m is None or span + hidden_m(u, float(along.min()), float(along.max())) < need):
            return False
    return True


def with_trailer_length(model: VehicleModel, length_m: float | None) -> VehicleModel:
    if length_m is None:
        return model
    return model.with_boxes(model.tractor, replace(model.trailer, length_m=length_m))


def unit_origins(v: np.ndarray, model: VehicleModel) -> list[tuple[np.ndarray, float]]:
    """Origin xy and yaw of each unit's frame (tractor: rear axle; trailer: kingpin) for pose ``v``."""
    frames = [(v[:2], v[2])]
    if model.trailer is not None:
        frames.append((model.kingpin_xy(v[0], v[1], v[2]), v[2] + v[3]))
    return frames


def unit_frames(points: np.ndarray, v: np.ndarray, model: VehicleModel) -> list[np.ndarray]:
    """(N, 2) coordinates of the points in each unit's frame (tractor: rear axle; trailer: kingpin)."""
    return [_in_frame(points, origin, yaw) for origin, yaw in unit_origins(v, model)]


def trailer_frame(points: np.ndarray, v: np.ndarray, model: VehicleModel) -> np.ndarray:
    """``unit_frames``' trailer frame alone."""
    return _in_frame(points, *unit_origins(v, model)[1])


def _in_frame(points: np.ndarray, origin: np.ndarray, yaw: float) -> np.ndarray:
    return kernels.to_frame(np.ascontiguousarray(points), *frame_args(origin, yaw))


def frame_args(origin: np.ndarray, yaw: float) -> tuple[float, float, float, float]:
    """A frame as ``kernels.to_frame`` takes it: origin x, y, cosine and sine of its yaw."""
    return float(origin[0]), float(origin[1]), float(np.cos(yaw)), float(np.sin(yaw))


def prior_boxes(prior: Prior) -> np.ndarray:
    """The prior's boxes as ``kernels.claim_points`` takes them (K, 6): unit frame origin x, y and
    yaw, rear, front, half width; the trailer's box reaches ``trailer_slack_m`` further back."""
    model = prior.model
    return np.array(
        [
            (*origin, yaw, box.rear_m - slack, box.front_m, box.width_m / 2)
            for (origin, yaw), box, slack in zip(
                unit_origins(prior.vector, model), model.boxes, (0.0, prior.trailer_slack_m)
            )
        ],
        dtype=float,
    )


def trailer_reach(m: Measurement, model: VehicleModel, points: np.ndarray, ground_z_m: float, inlier_m: float) -> float:
    """How far behind the trailer's front the start's ``points`` on its body (within its width
    and height band, reached from the front without a gap longer than ``MAX_BODY_GAP_M``) reach
    at the fit ``m``, at most the fitted length: with no rear face, the fitted length is held by
    nothing beyond them (a standing MAN's start kept 14.81 m, its points reaching 13.6, the true
    13.68, and it was named ``unknown`` for 2.6 s). All the start's points, not the fit's thinned
    sample: its hindmost lies up to 1.2 m short (``_side_end``)."""
    trailer = model.trailer
    q = trailer_frame(points, m.vector, model)
    on_body = (
        (np.abs(q[:, 1]) <= trailer.width_m / 2 + inlier_m)
        & body_heights(points[:, 2] - ground_z_m, trailer)
        & (q[:, 0] <= trailer.front_m)
    )
    if not on_body.any():
        return trailer.length_m
    hindmost = reached_back(float(q[on_body, 0].max()), q[on_body, 0])
    return float(min(trailer.front_m - hindmost, trailer.length_m))


def unfolded(m: Measurement, params: ArticulatedParams) -> bool:
    """The fit's hitch within the start's limit (``start_max_hitch_deg``)."""
    return abs(m.hitch_rad) <= np.radians(params.start_max_hitch_deg)
