"""The articulated estimator's vehicle tracks: per vehicle gate -> hinged fit -> kinematic UKF;
unclaimed points seed new vehicles (docs/pipeline.md, Articulated estimator).

What starts (``vehicle_start.VehicleStarts``: model, direction, hitch) becomes a track here. A
vehicle leaves after ``leave_frames`` frames without points. The trailer's length and the units'
widths are re-estimated from the points seen in each unit's frame (the catalogue is the prior;
``vehicle_dimensions``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from functools import lru_cache
from itertools import count

import numpy as np

from i2v_loc.params import ArticulatedParams, VehicleConfig
from i2v_loc.stages import kernels
from i2v_loc.stages.faces import rigid_seen
from i2v_loc.stages.hinged_fit import FRONT, Measurement, Prior, fit, in_unit_box, trailer_pose_only, without_hitch
from i2v_loc.stages.kinematic_filter import FilterState, KinematicFilter
from i2v_loc.stages.primitives import Rect, min_area_rect
from i2v_loc.stages.unit_frames import (
    END_BAND_M,
    MAX_BODY_GAP_M,
    MAX_TRAILER_LENGTH_M,
    frame_args,
    prior_boxes,
    supported,
    unfolded,
    unit_origins,
)
from i2v_loc.stages.vehicle_dimensions import SIDE_MIN_POINTS, WALL_BESIDE_M, DimensionLearner, VehicleTrack
from i2v_loc.stages.vehicle_model import VehicleModel
from i2v_loc.stages.vehicle_start import (
    COARSE_ITERATIONS,
    DIRECTION_COST_RATIO,
    START_HITCHES_DEG,
    START_ITERATIONS,
    START_SCALE_M,
    Background,
    Seed,
    VehicleStarts,
    unit_crossed,
)
from i2v_loc.stages.visibility import Rays

START_SIGMAS = np.array([0.3, 0.3, np.radians(3.0), np.radians(5.0)])  # added to the first fit's covariance
FOLDED_HITCH_RAD = np.radians(90.0)  # no trailer swings further round its kingpin: its box runs through the cab
TRACTOR_LOST_SIGMA_DEG = 1.0  # tracked, the hitch's is 0.2-0.4 deg; the cab hidden behind its trailer, 1-5 deg
CAB_GONE_MIN_RAYS = 2  # through a cab's place, none of its points seen: it is not there
WALL_MIN_POINTS = 5
WALL_MIN_ACROSS_M = 0.2
WALL_MIN_ANGLE_DEG = 30.0
WALL_ANGLE_STEP_DEG = 2.0
WALL_LINE_M = 0.1
SETTLED_SLACK_M = 0.5
RECHECK_MIN_SPEED_M_S = 0.5  # a rigid track is fitted again as every model while it moves this fast
RECHECK_FRAMES = 20  # a moving rigid track is fitted as every model every this many frames (the fits cost ~0.1 s)
MODEL_FOLLOW_MIN_M = 0.02  # a learned change that moves a face less is left to the filter (the fits' own noise)


@dataclass(frozen=True)
class VehicleReport:
    """What the tracker says about one vehicle in one frame."""

    id: int
    model: VehicleModel
    state: FilterState
    tractor_points: int
    trailer_points: int
    measured: bool  # a fit was fused this frame
    travel_m: float  # tractor reference point's distance from where the vehicle started
    dimensions_seen: tuple[tuple[bool, bool, bool], ...]  # per unit: length, width, height measured (else a prior)

    @classmethod
    def of(cls, track: VehicleTrack, measured: bool) -> VehicleReport:
        """``track``'s report this frame (``measured``: a fit of it was fused)."""
        s = track.filter.state
        n0 = int(np.count_nonzero(track.last.unit == 0)) if measured else 0
        n1 = int(np.count_nonzero(track.last.unit == 1)) if measured else 0
        travel = float(np.hypot(s.x_m - track.first_xy[0], s.y_m - track.first_xy[1]))
        return cls(track.id, track.model, s, n0, n1, measured, travel, track.dimensions_seen())


class VehicleTracker:
    def __init__(self, params: ArticulatedParams, catalogue: dict[str, VehicleConfig]):
        self.catalogue = {name: VehicleModel.from_config(name, v) for name, v in catalogue.items()}
        self.starts = VehicleStarts(params, self.catalogue)
        self.dimensions = DimensionLearner(params, self.catalogue)
        self.params = params
        self.tracks: list[VehicleTrack] = []
        self._rays: Rays | None = None  # this frame's
        self._ids = count(1)
        self.rejected = 0  # fits outside a filter's innovation gate

    @property
    def params(self) -> ArticulatedParams:
        return self._params

    @params.setter
    def params(self, params: ArticulatedParams) -> None:
        """Applied from the next frame on, to the tracks, the start and the learned sizes alike."""
        self._params = params
        self.starts.params = params
        self.dimensions.params = params

    def forget(self) -> None:
        """Drop every track and seed; ids go on counting."""
        self.tracks = []
        self.starts.forget()

    def moving_seeds(self) -> list[Rect]:
        """``VehicleStarts.moving_seeds``."""
        return self.starts.moving_seeds()

    def process(
        self,
        points: np.ndarray,
        ground: Callable[[float, float], float],
        stamp_s: float,
        background: Background = Background.NONE,
        rays: Rays | None = None,
    ) -> list[VehicleReport]:
        """``points`` (N, 3): the foreground (off the ground and the background) in the yard frame;
        ``ground(x, y)``: the ground's height there. ``background``: whether the map is learned
        (``vehicle_start.Background``); until it is the foreground holds the yard too: only
        articulated vehicles start then (two hinged units are no wall, container or parked trailer);
        a rigid one needs the learned background to tell it from a container.
        ``rays``: the frame's sensor rays, which show whether a seed's gap was seen empty."""
        self._rays = self.starts.rays = self.dimensions.rays = rays
        priors = [self._prior(t, stamp_s, ground) for t in self.tracks]
        lost = [self._tractor_lost(t) for t in self.tracks]
        owner = self._claim(points, priors, lost)
        owned = [_own_body(points, owner, i, prior) for i, prior in enumerate(priors)]
        reports = []
        free = points[owner < 0]
        for i, (track, (prior, at_wall)) in enumerate(zip(self.tracks, owned)):
            track.at_wall = at_wall
            reports.append(self._step(track, prior, points[owner == i], free, stamp_s, lost[i]))
        leave = self.params.leave_frames
        self.tracks = [t for t in self.tracks if t.missed < leave and t.cab_gone < leave]
        reports = [r for r in reports if any(t.id == r.id for t in self.tracks)]
        reports += self._start(free, ground, stamp_s, background)
        return reports

    def _prior(self, track: VehicleTrack, stamp_s: float, ground) -> Prior:
        s = track.filter.predict(stamp_s)
        slack = 0.0
        if track.model.trailer is not None and track.trailer_length is not None:
            slack = (
                SETTLED_SLACK_M
                if track.trailer_length.settled
                else max(MAX_TRAILER_LENGTH_M - track.model.trailer.length_m, SETTLED_SLACK_M)
            )
        return Prior(s.x_m, s.y_m, s.yaw_rad, s.hitch_rad, track.model, float(ground(s.x_m, s.y_m)), slack)

    def _claim(self, points: np.ndarray, priors: list[Prior], lost: list[bool]) -> np.ndarray:
        """Index of the track whose predicted boxes (grown by the gate margin) are nearest each point; -1 none.
        A lost tractor (``_tractor_lost``) may be at any of the start hitches around its kingpin."""
        if not priors:
            return np.full(len(points), -1, dtype=np.int64)
        boxes = [
            np.vstack([prior_boxes(prior)] + [prior_boxes(p)[:1] for p in _tractor_around(prior)])
            if gone
            else prior_boxes(prior)
            for prior, gone in zip(priors, lost)
        ]
        track_of_box = np.repeat(np.arange(len(priors)), [len(b) for b in boxes])
        return kernels.claim_points(
            points, np.vstack(boxes), track_of_box, len(priors), float(self.params.gate_margin_m)
        )

    def _step(
        self, track: VehicleTrack, prior: Prior, points: np.ndarray, free: np.ndarray, stamp_s: float, lost: bool
    ) -> VehicleReport:
        """One frame of a track: fit its claimed ``points``, fuse, learn (``free``: the points no track claimed)."""
        track.ground_z_m = prior.ground_z_m
        m = fit(points, prior, self.params) if len(points) else None
        found = self._reacquired(points, prior, m) if m is not None and lost else None
        measured = False
        if found is None and m is not None:
            m = self.dimensions.with_seen_end(track, m, points)
            if _trailer_hidden(m):
                m = without_hitch(m, self.params)
            elif _cab_hidden(m):
                m = trailer_pose_only(m, prior.model, self.params)
            # a fit folded through its cab is no pose at all
            measured = not _folded(m) and track.filter.update(
                m.vector, m.covariance, m.observed, may_restart=bool(np.any(m.unit == 0))
            )
            self.rejected += not measured
            if not (measured or lost) and prior.model.articulated:  # warm-started in the wrong place?
                found = self._better(self._reacquired(points, prior, m), m)
        if found is not None:  # the pose restarts from it (the prediction's sigma points are elsewhere)
            track.filter.restart(found.vector, found.covariance)
            m, measured = found, True
            prior = _at_pose(prior, m)  # what is learned from
        if measured:
            track.missed, track.last = 0, m
            if self.params.learn_dimensions:
                before = (track.model, track.catalogue_name)
                self.dimensions.learn(track, prior, points, m, stamp_s)
                self._follow_model(track, prior, m, *before)
            track = self._recheck_rigid(track, points, free, stamp_s)
        else:
            track.missed += 1
        track.cab_gone = track.cab_gone + 1 if self._cab_seen_through(track) else 0
        return VehicleReport.of(track, measured)

    def _cab_seen_through(self, track: VehicleTrack) -> bool:
        """Whether an articulated track's cab, of which its last fit explained fewer than
        ``SIDE_MIN_POINTS`` points, was crossed by ``CAB_GONE_MIN_RAYS`` rays where the filter has it
        (``unit_crossed``): it is not there; for ``leave_frames`` frames in a row, the vehicle has
        left. (A hidden cab stops the rays that would cross its place; rays ending on the trailer
        beside it do not say that the cab is there.) A car that drove past a container, started
        with it as a Twizy and its trailer before the background was learned, drove off: the
        container was tracked as its trailer, the cab's place empty, for 25 s."""
        if self._rays is None or not _cab_unseen(track):
            return False
        s, model = track.filter.state, track.model
        cab_xy = model.box_centers(s.x_m, s.y_m, s.yaw_rad, s.hitch_rad)[0]
        return unit_crossed(self._rays, cab_xy, s.yaw_rad, model.tractor, track.ground_z_m) >= CAB_GONE_MIN_RAYS

    @staticmethod
    def _better(found: Measurement | None, m: Measurement) -> Measurement | None:
        """``found`` if it explains the frame's points better than its own fit ``m`` by
        ``DIRECTION_COST_RATIO`` (both fitted to all of them; a fit gated out on a straight, its cab's
        few points fitted well, was replaced by one 0.3 m back at three times its cost, and the MAN's
        trailer was learned 0.63 m too long)."""
        return found if found is not None and found.cost < DIRECTION_COST_RATIO * m.cost else None

    def _tractor_lost(self, track: VehicleTrack) -> bool:
        """The last fit explained fewer than ``SIDE_MIN_POINTS`` points by the cab and the hitch's
        standard deviation exceeds ``TRACTOR_LOST_SIGMA_DEG``: the cab has not been seen for a while
        (hidden behind its trailer), and the prediction may have run far off."""
        return _cab_unseen(track) and track.filter.state.hitch_std_rad > np.radians(TRACTOR_LOST_SIGMA_DEG)

    def _reacquired(self, points: np.ndarray, prior: Prior, m: Measurement) -> Measurement | None:
        """The trailer where the prior has it and the tractor at each start hitch around its kingpin,
        the best fit refined, if it costs less than ``DIRECTION_COST_RATIO`` times the prior's own
        fit, both units are supported and it is not folded beyond ``start_max_hitch_deg`` (a Twizy's
        cab at its dock fitted best jack-knifed onto the dock): the cab is back in sight where the prediction did not
        look for it. All are fitted to one sample, half of it from within a tractor's reach of the
        kingpin and off the trailer (their costs are compared). Reversing with the cab hidden from
        its one LiDAR, a MAN's prediction ran 80 deg off while the trailer was tracked, and its fits
        stayed there once the cab showed again. Asked too when the frame's fit was gated out: warm-
        started from a prediction several degrees off, a fit can settle with the cab's front face
        unexplained (seen by `l3` and `l4` at a roundabout's turn-in, an unknown cab then ran 12-55
        deg off for 8 s, the filter restarting from such fits)."""
        model = prior.model
        sample = _around_kingpin(points, prior, self.params.fit_max_points)
        here = fit(sample, prior, self.params)
        coarse = [fit(sample, start, self.params, COARSE_ITERATIONS, START_SCALE_M) for start in _tractor_around(prior)]
        best = min((c for c in coarse if c is not None), key=lambda c: c.cost, default=None)
        if here is None or best is None:
            return None
        found = fit(sample, _at_pose(prior, best), self.params)
        if (
            found is None
            or found.cost >= DIRECTION_COST_RATIO * here.cost
            or not supported(found, model, prior.ground_z_m)
            or not unfolded(found, self.params)
        ):
            return None
        return fit(points, _at_pose(prior, found), self.params)  # from all the points, as every frame's fit

    def _follow_model(self, track: VehicleTrack, prior: Prior, m: Measurement, before: VehicleModel, name: str) -> None:
        """A learned change moved a front or the kingpin against the rear axle by more than
        ``MODEL_FOLLOW_MIN_M``: the frame's points are fitted again with the new model and the
        filter's pose moves by the difference of the two fits, so that the next fit's jump is not
        read as motion (a trailer's front learned 0.46 m further forward read as 4.1 m/s; the fits
        that followed fell outside the gate and the prediction ran 2.9 m away). A retyped vehicle's
        reference point was moved by ``_retype`` itself."""
        if track.catalogue_name != name or _shift_along_m(before, track.model) <= MODEL_FOLLOW_MIN_M:
            return
        again = fit(m.points, replace(_at_pose(prior, m), model=track.model), self.params)
        if again is None:
            return
        delta = again.vector - m.vector
        if any(_trailer_hidden(f) for f in (m, again)):
            delta[3] = 0.0  # a trailer none of whose points are seen is held nowhere: its hitch stays
        track.filter.move_pose(delta)

    def _start(self, points: np.ndarray, ground, stamp_s: float, background: Background) -> list[VehicleReport]:
        """Tracks of the vehicles that start among the unclaimed ``points`` (``VehicleStarts.found``):
        their first reports."""
        reports = []
        for start in self.starts.found(points, ground, background):
            track = self._track(next(self._ids), start.model, start.fit, start.ground_z_m, stamp_s, 0.0, start.points)
            track.rigid_seen = rigid_seen(start.rect, self.params, start.top_seen)
            self._learn_at_start(track, start.points, start.fit)
            self.tracks.append(track)
            reports.append(VehicleReport.of(track, True))
        return reports

    def _learn_at_start(self, track: VehicleTrack, cluster: np.ndarray, m: Measurement) -> None:
        """The start frame's sizes learned before the first report, the pose fitted again with them
        if they changed: an unknown 10.5 m trailer whose rear face the start saw was reported for a
        frame with the 13.68 m of the model it started as, its centre 1.5 m back. Not when it was
        renamed: ``_retype`` moved its reference point with the model (fitted again from the start
        fit's pose too, a MAN seen by one LiDAR that started as a Volvo had its trailer measured
        up to 0.8 m long from then on: its success 97 -> 1 %)."""
        if not self.params.learn_dimensions:
            return
        before, name = track.model, track.catalogue_name
        self.dimensions.learn_sizes(track, m, cluster)
        if track.model == before or track.catalogue_name != name:
            return
        prior = Prior(m.x_m, m.y_m, m.yaw_rad, m.hitch_rad or 0.0, track.model, track.ground_z_m)
        again = fit(cluster, prior, self.params, START_ITERATIONS)
        if again is not None:
            track.filter.restart(again.vector, _start_covariance(again))
            track.last = again

    def _track(
        self,
        track_id: int,
        model: VehicleModel,
        m: Measurement,
        ground_z_m: float,
        stamp_s: float,
        speed_m_s: float,
        points: np.ndarray | None = None,
    ) -> VehicleTrack:
        """A track started from the fit ``m`` of ``points`` (default: the fit's own sample)."""
        # the seed's points are not de-skewed (no motion known yet): the first pose is a rough one
        start_cov = _start_covariance(m)
        filt = KinematicFilter(
            m.vector,
            start_cov,
            stamp_s,
            model.kingpin_behind_axle_m,
            model.trailer_axle_m,
            model.articulated,
            self.params,
            speed_m_s,
        )
        return self.dimensions.new_track(track_id, model, m, filt, ground_z_m, m.points if points is None else points)

    def _recheck_rigid(self, track: VehicleTrack, points: np.ndarray, free: np.ndarray, stamp_s: float) -> VehicleTrack:
        """A rigid track is fitted again as every model every ``RECHECK_FRAMES`` frames while it
        moves: a tractor and trailer driving straight can look like one long box, a hinge shows
        later (it becomes articulated, with its id). Fitted with the unclaimed points connected to
        its own (``VehicleStarts.with_connected``): a MAN that came into one LiDAR's view cab first started as a
        rigid box 7.6 m long, which claimed no more of it, and its trailer's side stayed outside."""
        track.frames += 1
        s = track.filter.state
        if track.model.articulated or track.frames % RECHECK_FRAMES or abs(s.speed_m_s) < RECHECK_MIN_SPEED_M_S:
            return track
        points = self.starts.with_connected(points, free, track.ground_z_m)
        heading = np.array([np.cos(s.yaw_rad), np.sin(s.yaw_rad)]) * np.sign(s.speed_m_s)
        here = np.array([s.x_m, s.y_m])
        probe = Seed(here, here - heading, moving=True)  # the direction of travel, for a tie between the two ends
        rect = min_area_rect(points[:, :2])
        top_seen = not self.starts.at_view_top(points)
        chosen = self.starts.candidate(points, rect, probe, track.ground_z_m, False, top_seen)
        if chosen is None:
            return track
        model, m = chosen
        new = self._track(track.id, model, m, track.ground_z_m, stamp_s, s.speed_m_s, points)
        new.first_xy, new.rigid_seen = track.first_xy, rigid_seen(rect, self.params, top_seen)
        self._learn_at_start(new, points, m)
        self.tracks[self.tracks.index(track)] = new
        return new


def _trailer_hidden(m: Measurement) -> bool:
    """An articulated fit with fewer than ``SIDE_MIN_POINTS`` points on its trailer's faces but the
    front: that face stands right behind the cab's rear face, and explains the cab's points when
    the trailer is out of view."""
    return m.hitch_rad is not None and np.count_nonzero((m.unit == 1) & (m.face != FRONT)) < SIDE_MIN_POINTS


def _cab_hidden(m: Measurement) -> bool:
    """An articulated fit with fewer than ``SIDE_MIN_POINTS`` points on its cab: they measure the
    trailer's pose alone (``trailer_pose_only``), the cab is bridged by the motion. Fits of a cab
    out of a one-sided sensor's view swung the hitch 18-56 deg onto nothing and the filter
    restarted from one (an unknown 10.5 m trailer reported 44 deg off, its hitch sigma 0.6 deg).
    A few cab points consistent with the prediction do hold it: a MAN's cab reversing behind its
    trailer with 2-5 in the fits drifts 2-6 deg now (held within 1.2 deg before; session 43)."""
    return m.hitch_rad is not None and np.count_nonzero(m.unit == 0) < SIDE_MIN_POINTS


def _folded(m: Measurement) -> bool:
    """The trailer's box swung past square to its cab's: through the cab (a fit of a reversing cab
    whose trailer had left the view folded the trailer 133-140 deg onto the cab's points)."""
    return m.hitch_rad is not None and abs(m.hitch_rad) > FOLDED_HITCH_RAD


def _tractor_around(prior: Prior) -> list[Prior]:
    """``prior`` with its trailer where it is and its tractor at each of the start hitches (hypotheses)."""
    model = prior.model
    trailer_yaw = prior.yaw_rad + prior.hitch_rad
    kingpin = model.kingpin_xy(prior.x_m, prior.y_m, prior.yaw_rad)
    out = []
    for hitch in np.radians(START_HITCHES_DEG):
        yaw = trailer_yaw - hitch
        x, y = kingpin + model.kingpin_behind_axle_m * np.array([np.cos(yaw), np.sin(yaw)])
        out.append(
            replace(prior, x_m=float(x), y_m=float(y), yaw_rad=float(yaw), hitch_rad=float(hitch), hypothesis=True)
        )
    return out


def _around_kingpin(points: np.ndarray, prior: Prior, max_points: int) -> np.ndarray:
    """``max_points`` of ``points`` (all if fewer), half of them from those within a tractor's reach
    of the kingpin and outside the trailer's box, where the cab may be (all of those if fewer, more
    if the others are fewer)."""
    if len(points) <= max_points:
        return np.asarray(points, dtype=float)
    model = prior.model
    kingpin = model.kingpin_xy(prior.x_m, prior.y_m, prior.yaw_rad)
    reach = model.tractor.front_m - model.kingpin_behind_axle_m + END_BAND_M
    on_trailer = in_unit_box(points, prior, 1, END_BAND_M)  # its faces' points lie on both sides of them
    near = (np.hypot(*(points[:, :2] - kingpin).T) <= reach) & ~on_trailer
    n_near = int(np.count_nonzero(near))
    k_near = min(n_near, max(max_points // 2, max_points - (len(points) - n_near)))
    return np.asarray(points[kernels.strided_pick(near, k_near, max_points - k_near)], dtype=float)


def _at_pose(prior: Prior, m: Measurement) -> Prior:
    """``prior`` moved to the pose of the fit ``m``."""
    return replace(prior, x_m=m.x_m, y_m=m.y_m, yaw_rad=m.yaw_rad, hitch_rad=m.hitch_rad or 0.0)


def _start_covariance(m: Measurement) -> np.ndarray:
    """A start fit's covariance widened by ``START_SIGMAS`` (the seed's points are not de-skewed)."""
    return m.covariance + np.diag(START_SIGMAS[: len(m.vector)] ** 2)


def _cab_unseen(track: VehicleTrack) -> bool:
    """An articulated track whose last fit explained fewer than ``SIDE_MIN_POINTS`` points by the cab."""
    return track.model.articulated and track.last is not None and _cab_hidden(track.last)


def _own_body(points: np.ndarray, owner: np.ndarray, i: int, prior: Prior) -> tuple[Prior, bool]:
    """``prior`` with the claimed points of track ``i`` (``owner``) that are no part of its trailer's
    body released (-1): those behind a gap (``_beyond_gap``, which also cuts the prior's slack) and a
    wall behind it (``_wall_behind``) among the rest; and whether the wall ran across the trailer's
    body (``END_BAND_M / 2`` ahead of its rear face or more): its rear end is not seen then."""
    if prior.model.trailer is None:
        return prior, False
    mine, q = kernels.owned_to_frame(points, owner, i, *frame_args(*unit_origins(prior.vector, prior.model)[1]))
    prior, beyond = _beyond_gap(q, prior)
    if beyond is not None:
        owner[mine[beyond]] = -1
        mine, q = mine[~beyond], q[~beyond]
    wall = _wall_behind(q, prior.model)
    if wall is None:
        return prior, False
    owner[mine[wall]] = -1
    trailer, on_wall = prior.model.trailer, q[wall]
    across = (on_wall[:, 0] >= trailer.rear_m + END_BAND_M / 2) & (np.abs(on_wall[:, 1]) <= trailer.width_m / 2)
    return prior, bool(across.any())


def _wall_behind(q: np.ndarray, model: VehicleModel) -> np.ndarray | None:
    """Which of a trailer's claimed points (``q``: its frame, xy) are a wall behind it (None: no wall): straight
    faces at its rear (``END_BAND_M`` ahead of it or any way behind) with points ``WALL_BESIDE_M[0]``
    or more out past its sides run on past them; a trailer's body does not. Of those points beside
    its rear, the most on one line (``_wall_normal``) give the wall's direction, which must lie
    ``WALL_MIN_ANGLE_DEG`` or more off the trailer's axis (a dock's shelter beside a trailer's rear
    runs along it); each line in that direction passing its rear with ``WALL_MIN_POINTS`` of the
    points out past its sides, ``WALL_MIN_ACROSS_M`` long, is a face of the wall
    (``_wall_offsets``). The wall's points lie within ``END_BAND_M / 2`` of one, ahead of the
    trailer's front none. A dock's wall 0.2 m behind a Volvo's trailer, seen from the front, was
    explained by turning the trailer 10 deg; a Twizy's trailer pulled out of its dock at 45 deg to
    the wall, the wall's two faces across its box, by 5-9 deg of hitch (the first version took
    walls square to the trailer only). (Tried: faces of points behind the trailer too: a vehicle
    close behind an unknown trailer gave faces across its unseen rear, and its length was lost.)"""
    trailer = model.trailer
    edge = trailer.width_m / 2 + WALL_BESIDE_M[0]
    if kernels.count_beside(q, trailer.rear_m + END_BAND_M, edge) < WALL_MIN_POINTS:  # its rear is behind its front
        return None  # (most frames: counted without the masks)
    ahead = q[:, 0] <= trailer.front_m
    past = ahead & (np.abs(q[:, 1]) >= edge)
    beside = past & (q[:, 0] <= trailer.rear_m + END_BAND_M)
    normal = _wall_normal(q[beside])
    if abs(normal[1]) > np.sin(np.radians(90.0 - WALL_MIN_ANGLE_DEG)):
        return None  # along the trailer: a dock's shelter
    wall = np.zeros(len(q), dtype=bool)
    for offset in _wall_offsets(q[past], normal):
        # it passes the trailer's rear: a line of points beside its middle (a shelter's end) does not
        if min((offset - normal[1] * y) / normal[0] for y in (-edge, edge)) <= trailer.rear_m + END_BAND_M:
            wall |= np.abs(q @ normal - offset) <= END_BAND_M / 2
    return wall & ahead


def _wall_normal(points: np.ndarray) -> np.ndarray:
    """The normal of the direction in which most of ``points`` (xy) lie on one line: a Hough vote
    over ``WALL_ANGLE_STEP_DEG`` steps in ``WALL_LINE_M`` wide bins, refined by the principal axes of
    the points in and beside the winning bin (a step's error turns a 6 m face across three bins)."""
    normals = _line_normals()
    projections = np.ascontiguousarray(points @ normals.T)  # (n, angles)
    best, b = kernels.fullest_bin(projections, WALL_LINE_M)
    bins = np.floor(projections[:, best] / WALL_LINE_M).astype(np.int64)
    line = points[np.abs(bins - bins.min() - b) <= 1]
    _, axes = np.linalg.eigh(np.cov((line - line.mean(axis=0)).T))
    return axes[:, 0]


def _wall_offsets(points: np.ndarray, normal: np.ndarray) -> list[float]:
    """The offsets along ``normal`` of the lines across it (``WALL_LINE_M`` wide bins) that hold
    ``WALL_MIN_POINTS`` of ``points`` (out past the trailer's sides) spanning ``WALL_MIN_ACROSS_M``:
    a wall's faces."""
    bins = np.floor(points @ normal / WALL_LINE_M).astype(np.int64)
    along = points @ np.array([-normal[1], normal[0]])
    order = np.lexsort((along, bins))
    bins, along = bins[order], along[order]
    first = np.flatnonzero(np.r_[True, np.diff(bins) > 0])
    last = np.r_[first[1:], len(bins)] - 1
    face = (last - first + 1 >= WALL_MIN_POINTS) & (along[last] - along[first] >= WALL_MIN_ACROSS_M)
    return [float((b + 0.5) * WALL_LINE_M) for b in bins[first[face]]]


@lru_cache(maxsize=1)
def _line_normals() -> np.ndarray:
    angles = np.radians(np.arange(0.0, 180.0, WALL_ANGLE_STEP_DEG))
    return np.column_stack([np.cos(angles), np.sin(angles)])


def _beyond_gap(q: np.ndarray, prior: Prior) -> tuple[Prior, np.ndarray | None]:
    """(``prior`` with its trailer's slack cut where its claimed points (``q``: the trailer's frame,
    xy) behind the model's rear face stop running on without a gap longer than ``MAX_BODY_GAP_M``,
    which of them lie beyond; None when its length is settled). A trailer is one body: an object the moving trailer has just
    uncovered metres behind it (a fence, a parked car) is not its unseen rear, and it pulled the
    fit's sides (a Volvo driving off from a fence 5-7 m behind it read a 3 degree hitch for 5 s)."""
    if prior.trailer_slack_m <= SETTLED_SLACK_M:
        return prior, None
    behind = prior.model.trailer.rear_m - q[:, 0]
    chain = np.concatenate([[0.0], np.sort(behind[behind > 0.0])])
    gaps = np.flatnonzero(np.diff(chain) > MAX_BODY_GAP_M)
    reach = float(chain[gaps[0]] if len(gaps) else chain[-1])
    slack = min(reach + SETTLED_SLACK_M, prior.trailer_slack_m)
    return replace(prior, trailer_slack_m=slack), behind > slack


def _shift_along_m(before: VehicleModel, after: VehicleModel) -> float:
    """How far a model change moves a unit's faces along the vehicle relative to the tractor's
    reference point (the fronts, the cab's rear and the kingpin; a trailer's length moves only its
    rear face, which pins the reference point only when nothing else does): as far, the next fit
    may move the point."""
    shifts = [abs(after.tractor.front_m - before.tractor.front_m), abs(after.tractor.rear_m - before.tractor.rear_m)]
    if before.trailer is not None and after.trailer is not None:
        shifts.append(abs(after.kingpin_behind_axle_m - before.kingpin_behind_axle_m))
        shifts.append(abs(after.trailer.front_m - before.trailer.front_m))
    return max(shifts)
