"""Measurement of the articulated estimator: the two-box hinged model fitted to a vehicle's points
(docs/pipeline.md, Articulated estimator).

Parameters: tractor rear-axle x, y, tractor yaw ψ1 and hitch angle γ = ψ2 − ψ1 (rigid vehicles:
x, y, ψ1 of the box centre). Each point is explained by the nearest face of either box — a
vertical face (signed distance to its plane; a face segment is chosen by the distance to the
segment) or the roof (a point at roof height inside the footprint) — and the sum of a Cauchy
loss of those distances is minimised by iteratively reweighted Gauss-Newton steps with the
analytic Jacobian, warm-started from the prior on an evenly thinned subset of the points, in one
compiled loop (``kernels.irls``, the arithmetic of the numpy loop it replaced: the same poses to the
bit). (``scipy.optimize.least_squares`` with the same residuals, Jacobian and loss reaches the same
poses, but its own overhead is about 1 ms per call, the whole budget of a vehicle's frame.) A weak prior term (one
pseudo-point per parameter) keeps unobserved directions (the hitch when the trailer is hidden)
at the prediction. What the filter fuses is what the points measured: the pose directions whose
information, less the weak prior's, exceeds the prior's (``Measurement.observed``); the prior's own
pseudo-measurement, fused every frame, would pin an unseen direction to the prediction (a cab hidden
behind its trailer while reversing: its yaw followed the prediction's curvature, 60 deg off).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from i2v_loc.geometry import wrap_rad
from i2v_loc.params import ArticulatedParams
from i2v_loc.stages import kernels
from i2v_loc.stages.primitives import voxel_keys
from i2v_loc.stages.vehicle_model import VehicleModel

WEAK_PRIOR_SIGMAS = np.array([2.0, 2.0, np.radians(20.0), np.radians(30.0)])  # m, m, rad, rad
WEAK_PRIOR_SIGMAS.flags.writeable = False  # fits use slices of it
WEAK_LENGTH_SIGMA_M, WEAK_KINGPIN_SIGMA_M = 4.0, 0.5
FRONT, REAR, LEFT, RIGHT = 0, 1, 2, 3  # face numbers of a unit (the face table's rows modulo 4)
TRAILER_LENGTH_RANGE_M = (2.0, 16.5)
KINGPIN_RANGE_M = (-1.5, 1.5)
_RANGES = np.array([*TRAILER_LENGTH_RANGE_M, *KINGPIN_RANGE_M])
CAB_LENGTH_RANGE_M = (1.0, 4.0)
_HINGE_RANGES = np.array([*_RANGES, *CAB_LENGTH_RANGE_M])
MIN_UNIT_SHARE = 0.1  # of the fit's thinned sample, for each unit that has as many points
UNIT_SAMPLE_MARGIN_M = 0.5
ROOF_STEP_CELL_M, ROOF_STEP_BAND_M = 0.5, 0.2  # a rigid body's upper surface (``explained_share``)
CHASSIS_GAP_M = 0.1  # a low point farther behind a tracked cab's rear face is its chassis (nearest_faces)
CAB_REAR_MIN_POINTS = 3  # on the cab's rear face, in a turn's frames together, before its length is fitted


@dataclass(frozen=True)
class Prior:
    """What the fit starts from: the predicted tractor pose and hitch, the vehicle's model, the
    ground height under it and how far the trailer's rear may lie behind the model's (its length
    is not known yet)."""

    x_m: float
    y_m: float
    yaw_rad: float
    hitch_rad: float
    model: VehicleModel
    ground_z_m: float = 0.0
    trailer_slack_m: float = 0.0
    free_trailer_length: bool = False  # fit the trailer's length too (its rear face moves)
    free_kingpin: bool = False  # fit the kingpin's offset and the trailer's front from it (seen at a hitch angle)
    # a start's hypothesis: where its cab is, is what is tested, and no point behind it is excused as
    # its chassis (excused, a parked object beside a trailer started as a cab bent 34 deg)
    hypothesis: bool = False

    @property
    def vector(self) -> np.ndarray:
        v = [self.x_m, self.y_m, self.yaw_rad]
        return np.array(v + [self.hitch_rad] if self.model.articulated else v)

    @property
    def chassis_gap_m(self) -> float:
        return math.inf if self.hypothesis else CHASSIS_GAP_M

    @property
    def fits_length(self) -> bool:
        return self.free_trailer_length and self.model.articulated

    @property
    def fits_kingpin(self) -> bool:
        return self.free_kingpin and self.model.articulated

    @property
    def extra(self) -> list[float]:
        """Start values of the fitted model dimensions, after the pose: trailer length; kingpin offset
        and trailer front (straight, they trade with each other: both or neither)."""
        model = self.model
        length = [model.trailer.length_m] if self.fits_length else []
        return length + ([model.kingpin_behind_axle_m, model.trailer.front_m] if self.fits_kingpin else [])


@dataclass(frozen=True)
class Measurement:
    x_m: float
    y_m: float
    yaw_rad: float
    hitch_rad: float | None  # None for a rigid vehicle
    covariance: np.ndarray  # (4, 4) or (3, 3) over (x, y, yaw[, hitch])
    points: np.ndarray  # (n, 3) the thinned points fitted
    unit: np.ndarray  # (n,) int8 per fitted point: 0 tractor, 1 trailer, -1 not explained
    cost: float  # mean Cauchy loss per fitted point (m^2)
    trailer_length_m: float | None = None  # fitted (Prior.free_trailer_length), else None
    trailer_length_std_m: float | None = None  # its standard deviation (how well the points pin it)
    kingpin_m: float | None = None  # fitted (Prior.free_kingpin), else None
    trailer_front_m: float | None = None  # fitted (Prior.free_kingpin), else None
    rear_points: int = 0  # explained points on the trailer's rear face
    face: np.ndarray | None = None  # (n,) int8: the face (FRONT, REAR, LEFT, RIGHT) whose plane it is on, else -1
    # the directions of (x, y, yaw[, hitch]) the points measured, as rows (k, 4 or 3), and their noise (k, k)
    observed: tuple[np.ndarray, np.ndarray] | None = None

    @property
    def vector(self) -> np.ndarray:
        v = [self.x_m, self.y_m, self.yaw_rad]
        return np.array(v + [self.hitch_rad] if self.hitch_rad is not None else v)

    @property
    def explained(self) -> np.ndarray:
        return self.unit >= 0


@dataclass
class _Faces:
    """Nearest-face residuals and Jacobian rows of points for one parameter vector."""

    residual: np.ndarray  # (N,) signed distance to the face's plane (what the fit minimises)
    jacobian: np.ndarray  # (N, P)
    unit: np.ndarray  # (N,) 0 / 1
    distance: np.ndarray  # (N,) to the face itself (beyond its ends too; inf above every roof)
    face: np.ndarray  # (N,) 0 front, 1 rear, 2 left, 3 right, -1 on the roof or under the floor


def thin(points: np.ndarray, max_points: int) -> np.ndarray:
    """An even stride down to ``max_points`` (the pipeline's points are voxel centroids already:
    the stride over their voxel order thins them evenly in space)."""
    if len(points) > max_points:
        points = points[np.linspace(0, len(points) - 1, max_points).astype(np.int64)]
    return np.asarray(points, dtype=float)


def thin_by_unit(points: np.ndarray, max_points: int, prior: Prior) -> np.ndarray:
    """``thin``, unless the points in the prior's tractor box (grown by ``UNIT_SAMPLE_MARGIN_M``) or
    the others would get less than ``MIN_UNIT_SHARE`` of the sample: then the two are thinned
    apart, the smaller keeping that share (or all its points). One sensor that sees a cab behind
    its trailer has a few dozen points on it among thousands, and an even stride kept 3 of them.
    (Thinning the two apart always moved the fits of a car-sized tractor, whose box explains its
    points less well: a Twizy's hitch RMSE went from 1.85 to 2.72 deg on held-out seeds.)"""
    model = prior.model
    if len(points) <= max_points or model.trailer is None:
        return thin(points, max_points)
    # folded, the boxes overlap: a hidden cab's box holds the trailer's points, which are the trailer's
    on_tractor = np.empty(len(points), dtype=bool)
    n_tractor = kernels.in_first_box_only(
        np.ascontiguousarray(points), *_unit_box_rows(prior, UNIT_SAMPLE_MARGIN_M), on_tractor
    )
    floor = int(MIN_UNIT_SHARE * max_points)
    share = round(max_points * n_tractor / len(points))
    if floor <= share <= max_points - floor:  # both units well represented: the even stride
        return thin(points, max_points)
    k_tractor = min(n_tractor, max(share, floor), max_points - min(len(points) - n_tractor, floor))
    return np.asarray(points[kernels.strided_pick(on_tractor, k_tractor, max_points - k_tractor)], dtype=float)


def in_unit_box(
    points: np.ndarray, prior: Prior, unit: int, grow_m: float, grow_along_m: float | None = None
) -> np.ndarray:
    """Which of ``points`` lie (xy) in the prior's box of ``unit`` (0 tractor, 1 trailer) grown by
    ``grow_m`` (along its length by ``grow_along_m`` instead, if given)."""
    inside = np.empty(len(points), dtype=bool)
    kernels.in_upright_box(np.ascontiguousarray(points), _unit_box_rows(prior, grow_m, grow_along_m)[unit], inside)
    return inside


def _unit_box_rows(prior: Prior, grow_m: float, grow_along_m: float | None = None) -> list[np.ndarray]:
    """Each unit's box of the prior grown by ``grow_m`` (along its length by ``grow_along_m`` if
    given) as ``kernels.in_upright_box`` takes it."""
    along = grow_m if grow_along_m is None else grow_along_m
    centres = prior.model.box_centers(prior.x_m, prior.y_m, prior.yaw_rad, prior.hitch_rad)
    rows = []
    for unit, (centre, box) in enumerate(zip(centres, prior.model.boxes)):
        yaw = prior.yaw_rad + (prior.hitch_rad if unit else 0.0)
        rows.append(
            np.array([*centre, math.cos(yaw), math.sin(yaw), box.length_m / 2 + along, box.width_m / 2 + grow_m])
        )
    return rows


def _geometry(v: np.ndarray, model: VehicleModel, trailer_slack_m: float) -> np.ndarray:
    """The kernel's description of the pose and the boxes (``kernels.nearest_faces``): tractor x, y,
    yaw, hitch, kingpin behind the axle, trailer slack, then per box front, length, width, floor, height."""
    hitch = float(v[3]) if model.articulated else 0.0
    values = [float(v[0]), float(v[1]), float(v[2]), hitch, model.kingpin_behind_axle_m, trailer_slack_m]
    for box in model.boxes:
        values += [box.front_m, box.length_m, box.width_m, box.floor_m, box.height_m]
    return np.array(values, dtype=float)


def faces(
    v: np.ndarray,
    xy: np.ndarray,
    z_rel: np.ndarray,
    model: VehicleModel,
    top_band_m: float,
    trailer_slack_m: float = 0.0,
    chassis_gap_m: float = CHASSIS_GAP_M,
) -> _Faces:
    """The nearest faces of the pose ``v`` (x, y, yaw[, hitch])."""
    xy = np.ascontiguousarray(xy, dtype=float)
    z_rel = np.ascontiguousarray(z_rel, dtype=float)
    geometry = _geometry(v, model, trailer_slack_m)
    return _Faces(*kernels.nearest_faces(xy, z_rel, geometry, float(top_band_m), len(v), float(chassis_gap_m)))


def fit(
    points: np.ndarray,
    prior: Prior,
    params: ArticulatedParams,
    iterations: int | None = None,
    start_scale_m: float | None = None,
) -> Measurement | None:
    """The hinged model fitted to ``points`` (N, 3, yard frame) from ``prior`` in at most ``iterations``
    steps (default ``fit_iterations``), the loss scale starting at ``start_scale_m`` (default
    ``fit_start_scale_m``); None when fewer than ``fit_min_points`` remain after thinning."""
    sample = thin_by_unit(points, params.fit_max_points, prior)
    if len(sample) < params.fit_min_points:
        return None
    xy, z_rel = np.ascontiguousarray(sample[:, :2]), sample[:, 2] - prior.ground_z_m
    v0 = np.concatenate([prior.vector, prior.extra])
    scale = params.fit_loss_scale_m
    sigmas = _weak_prior_sigmas(prior)
    prior_weights = (scale / sigmas) ** 2  # the diagonal of the weak prior's information
    n_pose = 4 if prior.model.articulated else 3
    # graduated: a wide loss first so that faces a prediction misses by decimetres still pull
    v, *found = kernels.irls(
        xy, np.ascontiguousarray(z_rel), _geometry(v0, prior.model, 0.0 if prior.extra else prior.trailer_slack_m),
        float(params.fit_top_band_m), n_pose, prior.fits_length, prior.fits_kingpin, v0, prior_weights,
        float(scale), float(start_scale_m or params.fit_start_scale_m), int(iterations or params.fit_iterations),
        _RANGES, prior.chassis_gap_m,
    )  # fmt: skip
    at = _Faces(*found)
    cost = kernels.cauchy_cost(at.residual, float(scale)) * scale**2 / 2
    full = _covariance(at, sigmas, params)
    marginal = np.ascontiguousarray(full[:n_pose, :n_pose])  # (one compiled layout for the kernels)
    floor = _floor(params, n_pose)
    covariance = marginal + np.diag(floor**2)
    # explained: on a face, not only on its plane (a wall running on past a box's corner is no side of it)
    unit, face, rear = kernels.fit_labels(at.unit, at.face, at.distance, at.residual, params.fit_inlier_m, REAR)
    hitch = float(wrap_rad(v[3])) if prior.model.articulated else None
    length = (float(v[4]), math.sqrt(full[4, 4])) if prior.fits_length else (None, None)
    kingpin = (float(v[-2]), float(v[-1])) if prior.fits_kingpin else (None, None)
    return Measurement(
        float(v[0]),
        float(v[1]),
        float(wrap_rad(v[2])),
        hitch,
        covariance,
        sample,
        unit,
        cost,
        *length,
        *kingpin,
        rear,
        face,
        _observed(marginal, sigmas[:n_pose], floor),
    )


def explained_share(m: Measurement, model: VehicleModel) -> float:
    """The share of the fit's points it explains; for a rigid box, also those inside its footprint
    that are the highest of their ``ROOF_STEP_CELL_M`` column (within ``ROOF_STEP_BAND_M``): a
    body's upper surface steps, and the box's roof is only its highest step (a nuScenes rigid
    truck's cab roof, 1 m below its cargo box's, left its box explaining 79.95 % of its points).
    A crown's inside is not the top of its column."""
    if model.articulated:
        return float(np.mean(m.explained))
    inside = in_unit_box(m.points, Prior(m.x_m, m.y_m, m.yaw_rad, 0.0, model), 0, 0.0)
    cells = voxel_keys(np.floor(m.points[:, :2] / ROOF_STEP_CELL_M), 1.0)  # a grid through the origin
    _, column = np.unique(cells, return_inverse=True)
    highest = np.full(column.max() + 1, -np.inf)
    np.maximum.at(highest, column, m.points[:, 2])
    step = inside & (m.points[:, 2] >= highest[column] - ROOF_STEP_BAND_M)
    return float(np.mean(m.explained | step))


def rear_sigma_m(m: Measurement, model: VehicleModel, params: ArticulatedParams) -> float:
    """How well the fit ``m`` alone places the trailer's rear face along the trailer's axis."""
    g, marginal = _rear_along(m, model, params)
    return float(np.sqrt(max(g @ marginal @ g, 0.0)))


def with_rear_end(
    m: Measurement, model: VehicleModel, offset_m: float, sigma_m: float, params: ArticulatedParams
) -> Measurement:
    """The fit ``m`` with the trailer's rear end seen ``offset_m`` further along the trailer's axis
    than its box puts it (standard deviation ``sigma_m``): the pose and its covariance fused with
    that one linear measurement (information form), the observed directions again from them."""
    g, marginal = _rear_along(m, model, params)
    covariance = np.linalg.inv(np.linalg.inv(marginal) + np.outer(g, g) / sigma_m**2)
    covariance = np.ascontiguousarray((covariance + covariance.T) / 2)
    x, y, yaw, hitch = m.vector + covariance @ g * (offset_m / sigma_m**2)
    floor = _floor(params, len(g))
    return replace(
        m, x_m=float(x), y_m=float(y), yaw_rad=float(wrap_rad(yaw)), hitch_rad=float(wrap_rad(hitch)),
        covariance=covariance + np.diag(floor**2), observed=_observed(covariance, WEAK_PRIOR_SIGMAS, floor),
    )  # fmt: skip


def without_hitch(m: Measurement, params: ArticulatedParams) -> Measurement:
    """The fit ``m`` measuring the tractor's pose only: its hitch is left out (marginalised: the
    pose's covariance block), for a trailer whose own points do not show where it is."""
    floor, marginal = _floor(params, 4), _without_floor(m, params)
    rows, noise = _observed(np.ascontiguousarray(marginal[:3, :3]), WEAK_PRIOR_SIGMAS[:3], floor[:3])
    return replace(m, observed=(np.column_stack([rows, np.zeros(len(rows))]), noise))


def trailer_pose_only(m: Measurement, model: VehicleModel, params: ArticulatedParams) -> Measurement:
    """The fit ``m`` measuring the trailer's pose only (its kingpin's place and its yaw), for a cab
    whose own points do not show where it is: the cab turned about the kingpin moves no trailer
    point, and what a fit gives that direction comes from its warm start and from whatever else
    it claims there. The directions the points measured of the trailer's pose (``_observed`` on
    its covariance, through the Jacobian) as rows of (x, y, yaw, hitch)."""
    floor, marginal = _floor(params, 4), _without_floor(m, params)
    jacobian = _trailer_pose_jacobian(m.yaw_rad, model.kingpin_behind_axle_m)
    prior_sigmas = np.sqrt(np.diag(jacobian @ np.diag(WEAK_PRIOR_SIGMAS**2) @ jacobian.T))
    rows, noise = _observed(np.ascontiguousarray(jacobian @ marginal @ jacobian.T), prior_sigmas, floor[:3])
    return replace(m, observed=(rows @ jacobian, noise))


def _trailer_pose_jacobian(yaw_rad: float, kingpin_behind_axle_m: float) -> np.ndarray:
    """d(kingpin x, kingpin y, trailer yaw) / d(x, y, yaw, hitch): the kingpin lies
    ``kingpin_behind_axle_m`` behind the rear axle (x, y) along the tractor's yaw."""
    arm = kingpin_behind_axle_m
    return np.array(
        [
            [1.0, 0.0, arm * math.sin(yaw_rad), 0.0],
            [0.0, 1.0, -arm * math.cos(yaw_rad), 0.0],
            [0.0, 0.0, 1.0, 1.0],
        ]
    )


def _rear_along(m: Measurement, model: VehicleModel, params: ArticulatedParams) -> tuple[np.ndarray, np.ndarray]:
    """How the trailer's rear face moves along the trailer's axis with the pose (x, y, yaw, hitch:
    the kingpin swings about the rear axle with the yaw), and the fit's covariance without its floor."""
    along = m.yaw_rad + m.hitch_rad
    kingpin = _trailer_pose_jacobian(m.yaw_rad, model.kingpin_behind_axle_m)[:2]
    return np.array([math.cos(along), math.sin(along)]) @ kingpin, _without_floor(m, params)


def _without_floor(m: Measurement, params: ArticulatedParams) -> np.ndarray:
    """The fit's pose covariance without the floor ``fit`` added to it (what its points measured)."""
    return m.covariance - np.diag(_floor(params, len(m.covariance)) ** 2)


def _weak_prior_sigmas(prior: Prior) -> np.ndarray:
    pose = WEAK_PRIOR_SIGMAS[: 4 if prior.model.articulated else 3]
    if not (prior.fits_length or prior.fits_kingpin):
        return pose
    extra = [WEAK_LENGTH_SIGMA_M] * int(prior.fits_length) + [WEAK_KINGPIN_SIGMA_M] * 2 * int(prior.fits_kingpin)
    return np.concatenate([pose, extra])


def _covariance(at: _Faces, sigmas: np.ndarray, params: ArticulatedParams) -> np.ndarray:
    """Gauss-Newton covariance of the pose and the model's fitted dimensions (after it) with the
    Cauchy weights of the residuals, the noise from the explained residuals and the weak prior."""
    scale = params.fit_loss_scale_m
    return kernels.fit_covariance(
        at.residual,
        at.jacobian,
        1.0 / sigmas**2,
        scale,
        params.fit_inlier_m,
        scale**2,
        params.fit_noise_floor_m**2,
    )


def _floor(params: ArticulatedParams, n_pose: int) -> np.ndarray:
    """The standard deviations added to the pose's (neighbouring points are not independent)."""
    position, angle = params.fit_position_floor_m, math.radians(params.fit_angle_floor_deg)
    return np.array([position, position, angle, angle][:n_pose])


def _observed(marginal: np.ndarray, prior_sigmas: np.ndarray, floor: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The pose directions the points measured and their noise: the marginal information less the
    weak prior's, in the prior's units (so that metres and radians compare), kept where it exceeds
    the prior's own; the floor added to the noise (``kernels.observed_directions``)."""
    # the prior's sigmas may be a slice of the read-only WEAK_PRIOR_SIGMAS: a writable copy, one kernel type
    return kernels.observed_directions(marginal, np.array(prior_sigmas, dtype=float), floor)


def on_face_below_roof(
    m: Measurement, model: VehicleModel, unit: int, face: int, ground_z_m: float, top_band_m: float
) -> np.ndarray:
    """Which of the fit's points it put on ``face`` of ``unit`` below that unit's roof band
    (``top_band_m`` deep, above the ground at ``ground_z_m``): points in the band are the roof's
    edge running on past the face, or another body's showing above the unit."""
    roof_below = ground_z_m + model.boxes[unit].top_m - top_band_m
    return (m.unit == unit) & (m.face == face) & (m.points[:, 2] < roof_below)


@dataclass(frozen=True)
class TurnFrame:
    """One frame of a turn kept for the joint hinge fit (``fit_hinge``): its fit's thinned points,
    the ground under them, its pose (x, y, yaw, hitch) and how many of the points it explained
    lie on the cab's rear face below the cab's roof."""

    points: np.ndarray
    ground_z_m: float
    pose: np.ndarray
    cab_rear_points: int

    @classmethod
    def of(cls, m: Measurement, ground_z_m: float, model: VehicleModel, top_band_m: float) -> TurnFrame:
        """The frame of the fit ``m``, made with ``model``; the points it put on the cab's rear face
        below its roof band (``top_band_m`` deep: points there are its roof's edge, or a trailer's
        front showing above the cab, as ``unit_frames.face_seen`` has it) counted."""
        on_rear = int(np.count_nonzero(on_face_below_roof(m, model, 0, REAR, ground_z_m, top_band_m)))
        return cls(m.points, ground_z_m, m.vector, on_rear)


@dataclass(frozen=True)
class Hinge:
    """The kingpin's offset behind the rear axle and the trailer's front ahead of it, fitted to
    several frames at once, their standard deviations given the cab's length, the cab's length when
    it was fitted too and its standard deviation (else None and inf), and the frames' poses at the
    solution."""

    kingpin_m: float
    trailer_front_m: float
    std_m: np.ndarray  # (2,)
    poses: np.ndarray  # (frames, 4)
    cab_length_m: float | None = None
    cab_std_m: float = math.inf


def fit_hinge(
    frames: list[TurnFrame],
    model: VehicleModel,
    params: ArticulatedParams,
    iterations: int = 10,
    cab_prior: tuple[float, float] | None = None,
) -> Hinge:
    """The hinge that explains the ``frames`` of a turn together (``kernels.joint_hinge_irls``):
    each frame has its own pose, all share the kingpin and the front, with the model's trailer
    length (free in each frame, the first frames of a sloped 10.5 m trailer's docking put its front
    1.48-1.60 m ahead of the kingpin, 1.2; with the length 1.23-1.29 m). One frame pins only where
    its two units' axes cross, and a side's error moves that point along the other axis by the
    error over the hitch's sine: frames at different hitch angles disagree but for the one point
    fixed in both units. (An unknown 6.5 m trailer's reverse docking seen by `l1`: single frames'
    best kingpins spread from -0.1 to -0.8 m, their sum's lay at the truth, -0.70 m.)
    With ``cab_prior`` (its mean and standard deviation) the cab's length is shared too: a frame
    that shows the cab's rear face and not its front pins the kingpin against that face, and the
    model's cab length moves the kingpin by its error (an unknown 13.6 m trailer's tractor, its cab
    0.27 m shorter than the catalogue's, seen from behind by one sensor: kingpin 0.26 m off; once
    its front showed, its yaw ran 2-2.5 deg off for 5 s, until the window turned over). Frames
    showing either face then pin the kingpin given the length, frames showing both the length.
    Only once the frames show ``CAB_REAR_MIN_POINTS`` on the cab's rear face below its roof: else
    nothing measures the length, and a cab grown back into the gap takes the trailer's front for
    its own (an unknown 16 m trailer's tractor seen from ahead by one sensor, the trailer's front
    showing above the cab: the cab grew from 2.77 to 3.66 m (true 2.7), claimed within 1.5 cm; its
    roof explained those points, and its rear face one of them a frame, above the roof)."""
    if sum(f.cab_rear_points for f in frames) < CAB_REAR_MIN_POINTS:
        cab_prior = None
    poses = np.array([f.pose for f in frames], dtype=float)
    if poses.ndim != 2 or poses.shape[1] != 4:
        raise ValueError(f"a turn frame's pose is x, y, yaw and hitch; got shape {poses.shape}")
    xy = np.ascontiguousarray(np.concatenate([f.points[:, :2] for f in frames]), dtype=float)
    z_rel = np.concatenate([f.points[:, 2] - f.ground_z_m for f in frames])
    starts = np.cumsum([0] + [len(f.points) for f in frames]).astype(np.int64)
    geometries = np.array([_geometry(f.pose, model, 0.0) for f in frames])
    scale = params.fit_loss_scale_m
    local_weights = (scale / WEAK_PRIOR_SIGMAS) ** 2
    shared0 = [model.kingpin_behind_axle_m, model.trailer.front_m]
    sigmas = [WEAK_KINGPIN_SIGMA_M] * 2
    if cab_prior is not None:
        shared0.append(cab_prior[0])
        sigmas.append(cab_prior[1])
    shared_weights = (scale / np.array(sigmas)) ** 2
    shared, fitted, information, residual = kernels.joint_hinge_irls(
        xy, z_rel, starts, geometries, poses, np.array(shared0), local_weights, shared_weights,
        float(scale), float(params.fit_start_scale_m), iterations, _HINGE_RANGES, CHASSIS_GAP_M,
        float(params.fit_top_band_m),
    )  # fmt: skip
    noise2 = kernels.inlier_noise2(residual, params.fit_inlier_m, scale**2, params.fit_noise_floor_m**2)
    total = information / noise2 + np.diag(shared_weights / scale**2)  # the weak prior's, in its own units
    given_cab = np.sqrt(np.diag(np.linalg.inv(total[:2, :2])))
    if cab_prior is None:
        return Hinge(float(shared[0]), float(shared[1]), given_cab, fitted)
    cab_std = float(np.sqrt(np.linalg.inv(total)[2, 2]))
    return Hinge(float(shared[0]), float(shared[1]), given_cab, fitted, float(shared[2]), cab_std)
