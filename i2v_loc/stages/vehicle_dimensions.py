"""The sizes of an articulated estimator's tracked vehicle, learned from its points (docs/pipeline.md,
Articulated estimator): the units' widths and lengths, the hinge (kingpin and trailer front), the
tractor's rear axle, and the catalogue vehicle they match (the catalogue is the prior).

The tracker (``vehicle_tracker``) hands ``DimensionLearner`` each frame's rays and each measured fit
of a track; what is learned lives on the track (``VehicleTrack``).
"""

from __future__ import annotations

import bisect
import math
from collections import deque
from dataclasses import dataclass, field, replace

import numpy as np

from i2v_loc.geometry import wrap_rad
from i2v_loc.params import ArticulatedParams
from i2v_loc.stages import kernels
from i2v_loc.stages.faces import END_FACE_WIDTH_M
from i2v_loc.stages.hinged_fit import (
    CAB_LENGTH_RANGE_M,
    FRONT,
    LEFT,
    REAR,
    RIGHT,
    TRAILER_LENGTH_RANGE_M,
    Hinge,
    Measurement,
    Prior,
    TurnFrame,
    fit,
    fit_hinge,
    in_unit_box,
    rear_sigma_m,
    with_rear_end,
)
from i2v_loc.stages.kinematic_filter import KinematicFilter, unit_motions
from i2v_loc.stages.primitives import unit_axes
from i2v_loc.stages.unit_frames import (
    END_BAND_M,
    FACE_SEEN_SPAN,
    MAX_BODY_GAP_M,
    MAX_TRAILER_LENGTH_M,
    REAR_FACE_MIN_POINTS,
    body_band,
    body_heights,
    face_seen,
    free_length_at,
    reached_back,
    trailer_frame,
    trailer_reach,
    unit_frames,
    unit_origins,
    with_trailer_length,
)
from i2v_loc.stages.vehicle_model import MAX_VEHICLE_HEIGHT_M, Box, VehicleModel
from i2v_loc.stages.vehicle_start import (
    GAP_SEEN_BEYOND_M,
    GAP_TEST_MAX_HITCH_RAD,
    RIGID_MIN_WIDTH_M,
    SOLID_INSET_M,
    gap_band,
)
from i2v_loc.stages.visibility import Rays

SIDE_MIN_POINTS = 5
SIDE_MAX_SLOPE = np.tan(np.radians(5.0))  # a side's points run along its unit's axis (the fits' yaw: within 2 deg)
# the kingpin's offset shows only at a hitch angle; from this one the joint fit's own standard
# deviation decides when its frames pin it (at 20 deg a lane change never turned enough, and an
# unknown 13.6 m trailer kept the catalogue's hinge: its cab's yaw 1.5 deg off at a 15 deg hitch)
KINGPIN_MIN_HITCH_RAD = np.radians(8.0)
# every this many turning frames one is kept for the joint hinge fit: the first HINGE_FRAMES / 2, then the rest
HINGE_FRAME_STEPS = (2, 5)
HINGE_FRAMES = 20  # the latest kept frames fitted
HINGE_MAX_STD_M = 0.05  # a joint fit pinning the kingpin or the front no better than this measures nothing
# the spread of tractors' cab lengths (2.3-2.8 m): the prior of a cab's length the joint hinge fit
# learns with the kingpin until both its faces were seen in one frame
CAB_LENGTH_SIGMA_M = 0.3
REACH_SETTLED = 50  # straight frames' reaches of the trailer's front ahead of the rear axle: learned
REACH_MAX_HITCH_RAD = np.radians(5.0)  # nearly straight: the trailer's front reach ahead of the rear axle shows
LENGTH_CONVERGED_OBSERVATIONS = 5
TURN_MAX_SPEED_STD_M_S = 0.5  # the hinge is measured in a turn from frames de-skewed with a speed known this well
LENGTH_MAX_STD_M = 0.05  # a trailer's length the points pin no better than this is not measured
STILL_END_FRAMES = 20  # moving frames whose reach must agree before it is taken as the unit's end
STILL_END_SPREAD_M = 0.5  # a shadow's edge moves by metres over these frames; the thinned points' hindmost by 0.3 m
STILL_END_MIN_SPEED_M_S = 0.5
END_SEEN_OFFSET_M = 0.3  # past the hindmost point: a side's points are up to a column's spacing apart
END_SEEN_LENGTH_M = 2.0
END_SEEN_MIN_RAYS = 2
END_SEEN_REACH_M = 1.0
CAB_END_BRACKET_M = 0.2  # a cab's side's last point to the first ray behind it: a column's spacing or so
CAB_ENDS_KEPT = 20  # cab lengths from a side's end, then no more: each costs a pass over the frame's rays
UNRETURNED_MIN_RAYS = 10  # a dark body far off drops a few returns: no handful of those shows it empty
UNRETURNED_PER_RETURN = 4  # and a body returns most of the rays that reach it
FACE_SHELL_M = 0.3  # around a body's faces: its returns (a sweep's motion and noise spread them)
END_TRAVEL_M = 0.3  # a moving trailer's end counts once it has gone this far with it (not stayed put)
END_HISTORY = 50  # frames of ends kept to judge that by
ANYWHERE = (-np.inf, np.inf)  # no bound along a unit
# per unit of an articulated vehicle: the end face nothing of the vehicle hides (a cab covers part of
# its trailer's front face at a hitch angle, the trailer part of the cab's rear)
OPEN_ENDS = (FRONT, REAR)
# both sides seen: one frame's width can be a dock shelter's (a Twizy's 1.75 m trailer, 1.99)
WIDTH_MIN_OBSERVATIONS = 3
# an articulated vehicle's cab top: the TOP_RANK-th highest of its claimed points within TOP_GROW_M of
# the cab's box and TOP_APART_M outside the trailer's, once TOP_MIN_POINTS stand there (``_learn_cab_top``)
TOP_RANK = 3
TOP_GROW_M = 0.1
TOP_END_INSET_M = 0.5  # inside the cab's ends: a wall or another vehicle may stand right before it
TOP_APART_M = 1.0  # a trailer's front not learned yet lies up to half a metre off its model's
TOP_MIN_POINTS = 10
TOP_MARGIN_M = 0.1  # above the prior's top: a roof's noise and clutter reach higher than its box
TOP_QUANTILE = 0.75  # of the frames' tops (a frame's is a lower bound; the median of a cab's flipped frame to frame)
BRACKETS_SETTLED = 10  # a unit's widths bracketed from one side (``_width_across_end``) before they count
BRACKETS_AGREED = 5  # or this many, their middle half within BRACKETS_AGREE_M, their median as far from the prior
BRACKETS_AGREE_M = 0.1
BRACKETS_KEPT = 20  # then no more: each costs a pass over the frame's rays (about 2 ms for four OS1-32)
CORNER_BRACKET_M = 0.15  # a side's spacing of voxel centroids and columns seen at 20-30 deg, at 20 m
# a ray ending this far past an end face's plane passed it (its points: within 0.05 m), though it
# ends on the ground soon after: past the lower corner of a cab, a ray ending 0.4 m on was the first 0.06 m out
CORNER_BEYOND_M = 0.15
SIDE_NEAR_END_M = 2.0
END_ALONG_SIGMA_M = 0.15  # a side's end before the rays that pass behind it: its points' spacing
FACE_APART_MIN_SLAB_M = 0.25  # of body between a trailer's side's end and a rear face, asked of the rays
FACE_APART_GAP_M = 0.5  # along a side in the fit's thinned points, a gap: the side ends there
FACE_APART_CLEAR_M = 0.15  # the slab ends this short of the face (its points' range noise)
VEHICLE_WIDTH_M = (RIGID_MIN_WIDTH_M, END_FACE_WIDTH_M[1])  # a bracket outside: a fit that went astray
WALL_BESIDE_M = (0.35, 0.8)  # a face with points this far out past a trailer's side is wider than it
# the rear axle that does not slip sideways, from pairs of whole fits along one arc (``_learn_axle``)
AXLE_MIN_TURN_RAD = np.radians(8.0)  # a pair's turn: 3 cm of side noise make 0.3 m of axle
AXLE_MAX_SPAN_S = 3.0  # a pair's time apart
AXLE_STEADY_SHARE = 0.15  # of a pair's turn: the heading halfway off the mean (noise 0.3 deg)
AXLE_MIN_SAMPLES = 15  # pairs before their median counts
AXLE_SAMPLES_KEPT = 100
AXLE_MAX_M = 1.0  # from the catalogue's: tractors' wheelbases and overhangs vary less


class _Window(deque):
    """The observations in arrival order, and sorted."""

    def __init__(self, *args) -> None:
        super().__init__(*args)
        self.ordered: list[float] = sorted(self)


@dataclass
class _Extent:
    """Per-frame observations of one dimension; the estimate is their median (the prior before any).
    Per-frame lower bounds (the unit reaches at least that far) count through their median too: a
    dock's bumpers right behind a trailer reach on from it for some frames, then fall behind. A reach
    that stays put while the unit moves (``add_reach``) is where it ends: the edge of a shadow moves
    along a moving unit, its end does not (seen from one side, a trailer's rear face never shows).
    Per-frame upper bounds (``add_upper_bound``: rays passed where the unit would reach) cap the
    estimate through their median until it is settled."""

    prior: float
    window: int
    values: _Window = field(default_factory=_Window)
    bounds: _Window = field(default_factory=_Window)
    median: float | None = None
    lower_bound: float = -np.inf
    uppers: _Window = field(default_factory=_Window)  # per-frame upper bounds (rays passed where it would reach)
    upper_bound: float = np.inf
    brackets: _Window = field(default_factory=_Window)  # a unit's width from one side (``_width_across_end``)
    bracket_median: float | None = None
    reaches: deque = field(default_factory=lambda: deque(maxlen=STILL_END_FRAMES))
    min_values: int = 1  # observations before their median counts

    def add(self, value: float) -> None:
        self.median = _windowed_median(self.values, value, self.window)

    def add_bracket(self, value: float) -> None:
        self.bracket_median = _windowed_median(self.brackets, value, self.window)

    def add_bound(self, value: float) -> None:
        self.lower_bound = _windowed_median(self.bounds, value, self.window)

    def add_upper_bound(self, value: float) -> None:
        """A frame's upper bound: the unit reaches at most this far (rays passed beyond)."""
        self.upper_bound = _windowed_median(self.uppers, value, self.window)

    def add_reach(self, value: float) -> None:
        """How far the unit's points reach in a frame in which it moved."""
        self.reaches.append(value)

    @property
    def still_end(self) -> float | None:
        """The median reach of the last ``STILL_END_FRAMES`` moving frames if they spread at most
        ``STILL_END_SPREAD_M``."""
        if len(self.reaches) < STILL_END_FRAMES or np.ptp(self.reaches) > STILL_END_SPREAD_M:
            return None
        return float(np.median(self.reaches))

    @property
    def settled(self) -> bool:
        return len(self.values) >= LENGTH_CONVERGED_OBSERVATIONS

    @property
    def counted(self) -> bool:
        """Measured in ``min_values`` frames."""
        return len(self.values) >= self.min_values

    @property
    def observed(self) -> bool:
        """Measured, or bracketed in ``BRACKETS_SETTLED`` frames (one is a fraction of a voxel off
        in most frames, but 0.45 m in some), or sooner where they refute the prior
        (``_brackets_refute_prior``)."""
        return self.counted or len(self.brackets) >= BRACKETS_SETTLED or self._brackets_refute_prior()

    def _brackets_refute_prior(self) -> bool:
        """``BRACKETS_AGREED`` brackets or more, their middle half within ``BRACKETS_AGREE_M``, their
        median further than that from the prior: an unknown tractor taken for the MAN (2.77 m) but
        2.55 m wide, seen from one side on a sloped dock, had 6 brackets within 0.05 m of 2.50 in
        its first 12 frames, then no end face for 20 s; it kept 2.77 and both units sat 0.11 m off
        their axes (held-out generalization +1300 without its miscalibrated `l2`: truck position
        RMSE 0.100 -> 0.044 m). A catalogue vehicle's brackets agree with its prior: it waits for
        the tenth."""
        ordered, n = self.brackets.ordered, len(self.brackets)
        return (
            n >= BRACKETS_AGREED
            and ordered[-1 - n // 4] - ordered[n // 4] <= BRACKETS_AGREE_M
            and abs(self.bracket_median - self.prior) > BRACKETS_AGREE_M
        )

    @property
    def measured(self) -> float:
        """The median once counted, else that of the brackets once settled, else the end the
        moving unit's points kept reaching, else the prior."""
        if self.counted:
            return self.median
        if self.observed:
            return self.bracket_median
        end = self.still_end
        return self.prior if end is None else end

    @property
    def estimate(self) -> float:
        """The measured value; until settled at least the lower bound (a face seen outweighs points
        that only reach further) and, below it, at most the upper bound."""
        return self.measured if self.settled else max(min(self.measured, self.upper_bound), self.lower_bound)


def _unit_widths(extents: list[_Extent]) -> list[float]:
    """Each unit's width; one not yet observed, its vehicle's other one's, less the difference of
    their priors. (Seen from one side, the cab's axis and the trailer's lie half their widths in
    from the sides: an unknown trailer measured 2.55 m wide, its cab left at the catalogue's 2.77,
    had its axis 0.11 m off the cab's, and the hinge bent the cab 2.6 deg.)"""
    widths = [extent.estimate for extent in extents]
    observed = [extent.observed for extent in extents]
    if len(extents) == 2 and observed[0] != observed[1]:
        seen, unseen = (0, 1) if observed[0] else (1, 0)
        # to the bit the prior's when the seen one is its own
        widths[unseen] = extents[unseen].prior + (widths[seen] - extents[seen].prior)
    return widths


def _hinge_priors(model: VehicleModel, window: int) -> tuple[tuple[float, float], _Extent]:
    """``model``'s kingpin offset behind the rear axle and trailer front ahead of the kingpin, and
    that front's reach ahead of the rear axle, to be learned."""
    kingpin, front = model.kingpin_behind_axle_m, model.trailer.front_m
    return (kingpin, front), _Extent(front - kingpin, window)


def _windowed_median(window: _Window, value: float, size: int) -> float:
    """``value`` appended to ``window`` (the oldest dropped beyond ``size``), the median of what is in
    it: ``np.median``'s value, from a sorted copy kept beside it (np.median sorted all of it every
    frame, for each dimension of each vehicle)."""
    ordered = window.ordered
    window.append(value)
    bisect.insort(ordered, value)
    while len(window) > size:
        del ordered[bisect.bisect_left(ordered, window.popleft())]
    half = len(ordered) // 2
    return float(ordered[half]) if len(ordered) % 2 else (float(ordered[half - 1]) + float(ordered[half])) / 2


def _axle_extent() -> _Extent:
    """The pairs' axle offsets from the catalogue's (0 before any): their median once
    ``AXLE_MIN_SAMPLES``, over the last ``AXLE_SAMPLES_KEPT``."""
    return _Extent(0.0, AXLE_SAMPLES_KEPT, min_values=AXLE_MIN_SAMPLES)


@dataclass(eq=False)
class VehicleTrack:
    """One tracked vehicle: its filter and last fit, and what its points showed of its sizes."""

    id: int
    model: VehicleModel
    filter: KinematicFilter
    catalogue_name: str
    trailer_length: _Extent | None
    widths: list[_Extent]
    cab_length: _Extent | None  # an articulated tractor's, from its front and rear faces
    missed: int = 0
    last: Measurement | None = None
    first_xy: np.ndarray = field(default_factory=lambda: np.zeros(2))
    ground_z_m: float = 0.0  # under the vehicle, this frame
    hinge_prior: tuple[float, float] = (0.0, 0.0)  # the catalogue's kingpin offset and trailer front
    reach: _Extent | None = None  # the trailer's front face ahead of the rear axle (seen straight)
    turn: deque = field(default_factory=lambda: deque(maxlen=HINGE_FRAMES))  # TurnFrame kept for the hinge
    turning_frames: int = 0
    hinge: Hinge | None = None  # fitted to the turn's frames
    frames: int = 0  # measured frames
    # (stamp, x, y, yaw) of its whole fits within a pair's span at up to 20 Hz
    axle_fits: deque = field(default_factory=lambda: deque(maxlen=int(AXLE_MAX_SPAN_S * 20)))
    axle: _Extent = field(default_factory=_axle_extent)  # its pairs' offsets (``_learn_axle``)
    # this frame: a wall ran across its trailer's body, or a face stood apart behind it (its rear end is not seen)
    at_wall: bool = False
    ends: dict[str, deque] = field(
        default_factory=dict
    )  # per kind of end, those seen moving: deque of (yard xy, x, kingpin xy)
    rigid_seen: tuple[bool, bool, bool] = (True, True, True)  # a rigid one's sizes came from its points
    cab_gone: int = 0  # frames in a row its unseen cab's place was seen through (``_cab_seen_through``)
    cab_top: _Extent | None = None  # an articulated one's cab's top above the ground

    def dimensions_seen(self) -> tuple[tuple[bool, bool, bool], ...]:
        """Per unit, which of its length, width and height its points measured: a rigid one's as it
        started (one face shows one of its length and width) and its width once both sides showed;
        an articulated one's lengths and widths once observed (the cab's length also once the hinge's
        fit pins it within ``HINGE_MAX_STD_M``), its cab's height once its points reached
        ``TOP_MARGIN_M`` above the catalogue's (``_learn_cab_top``), its trailer's height never."""
        width = [w.observed for w in self.widths]
        if self.trailer_length is None:
            return ((self.rigid_seen[0], self.rigid_seen[1] or width[0], self.rigid_seen[2]),)
        return (
            (self.cab_length.median is not None or self._cab_fitted(), width[0], _top_raised(self.cab_top)),
            (self.trailer_length.median is not None, width[1], False),
        )

    def _cab_fitted(self) -> bool:
        return self.hinge is not None and self.hinge.cab_std_m <= HINGE_MAX_STD_M


class DimensionLearner:
    """Learns each track's sizes from its fits (``learn``) against the catalogue's (``catalogue``:
    the tracker's models by name); ``rays``: the frame's sensor rays (None: unknown)."""

    def __init__(self, params: ArticulatedParams, catalogue: dict[str, VehicleModel]):
        self.params = params
        self.catalogue = catalogue
        self.rays: Rays | None = None  # this frame's

    def new_track(
        self,
        track_id: int,
        model: VehicleModel,
        m: Measurement,
        filt: KinematicFilter,
        ground_z_m: float,
        points: np.ndarray,
    ) -> VehicleTrack:
        """A track of the start fit ``m`` of ``points`` (``filt``: its filter), its sizes' priors
        the catalogue's but for the trailer's length the start shows (``_start_length``)."""
        window = self.params.dimension_window
        widths = [_Extent(box.width_m, window, min_values=WIDTH_MIN_OBSERVATIONS) for box in model.boxes]
        cab = _Extent(model.tractor.length_m, window) if model.articulated else None
        length = reach = None
        hinge_prior = (0.0, 0.0)
        if model.trailer is not None:
            length = self._start_length(model, m, points, ground_z_m)
            if length.prior != model.trailer.length_m:  # the catalogue's, longer than the points reach
                model = with_trailer_length(model, length.prior)
            hinge_prior, reach = _hinge_priors(model, window)
        return VehicleTrack(
            track_id,
            model,
            filt,
            model.name,
            length,
            widths,
            cab,
            0,
            m,
            np.array(m.vector[:2]),
            ground_z_m,
            hinge_prior,
            reach,
            cab_top=_Extent(model.tractor.top_m, window) if model.articulated else None,
        )

    def with_seen_end(self, track: VehicleTrack, m: Measurement, points: np.ndarray) -> Measurement:
        """The fit ``m`` with the trailer's rear end where its side ends before rays that passed
        behind it (``_seen_end``), once its length is settled, when the fit alone places its rear
        face no better than ``END_ALONG_SIGMA_M``. A trailer's side shows not where along it the
        trailer is: with its cab hidden or out of view, the filter ran it on at the speed it had
        (a 16 m trailer that stopped in front of one LiDAR drove 4 m on in 3 s and was lost). (Asked
        also wherever a side's points ended elsewhere than the fit's rear face, that trailer's
        length, learned 0.35 m long, pulled it against its cab's points every frame.)"""
        model = track.model
        if (
            not model.articulated
            or track.trailer_length is None
            or not track.trailer_length.settled
            or rear_sigma_m(m, model, self.params) <= END_ALONG_SIGMA_M
        ):
            return m
        local = trailer_frame(m.points, m.vector, model)
        sides = [local[(m.unit == 1) & (m.face == face)] for face in (LEFT, RIGHT)]
        sides = [side for side in sides if len(side)]
        end = self._seen_end(track, m, points, sides, model.trailer.width_m)
        if end is None:
            return m
        return with_rear_end(m, model, end - model.trailer.rear_m, END_ALONG_SIGMA_M, self.params)

    def learn(self, track: VehicleTrack, prior: Prior, points: np.ndarray, m: Measurement, stamp_s: float) -> None:
        """What the measured fit ``m`` of the track's claimed ``points`` (``prior``: what it was fitted
        from) shows of its sizes, its hinge and its rear axle."""
        # a face apart behind the trailer (a dock's door) is no rear end of it, as a wall across it
        track.at_wall = track.at_wall or self._face_behind(track, m)
        self._learn_hinge(track, prior, points, m)
        self.learn_sizes(track, m, points)
        _learn_axle(track, m, stamp_s)

    def learn_sizes(self, track: VehicleTrack, m: Measurement, points: np.ndarray) -> None:
        """The sizes the fit ``m`` of the vehicle's claimed ``points`` shows."""
        model = track.model
        local = unit_frames(m.points, m.vector, model)
        faced = self._sides_faced(m, model)
        for u, box in enumerate(model.boxes):
            (n_left, left), (n_right, right) = (
                kernels.face_median(local[u], 1, m.unit, m.face, u, f, (box.rear_m, box.front_m)) for f in (LEFT, RIGHT)
            )
            # both sides seen along the body (the trailer's box reaches a slack on behind its rear, where
            # a dock shelter's wall beside a Twizy made its trailer 1.89 m wide, 1.75), each by a sensor
            # it faces: the width between them
            if min(n_left, n_right) >= SIDE_MIN_POINTS and faced[u] and _sides_along(local[u], m, u, box):
                track.widths[u].add(left - right)
            elif max(n_left, n_right) >= SIDE_MIN_POINTS > min(n_left, n_right) and not track.at_wall:
                width = self._width_across_end(track, m, points, local[u], u, LEFT if n_left > n_right else RIGHT)
                if width is not None:
                    track.widths[u].add_bracket(width)
        widths = _unit_widths(track.widths)
        tractor = {"width_m": widths[0]}
        if model.trailer is not None:
            tractor["height_m"] = self._learn_cab_top(track, m, points)
        if track.cab_length is not None:
            self._learn_cab_length(track, m, local[0], points)
            tractor["length_m"] = _cab_length(track)
        learned = {"tractor": _changed(model.tractor, **tractor)}
        if model.trailer is not None:
            trailer = {"width_m": widths[1]}
            if track.trailer_length is not None:
                if not track.at_wall:  # its rear end went with the wall, or lies beyond it
                    self._learn_trailer_length(track, m, local[1], widths[1], points)
                kingpin, front = _hinge(track)
                trailer.update(length_m=track.trailer_length.estimate, front_m=front)
                learned["kingpin_behind_axle_m"] = track.filter.kingpin_m = kingpin
            learned["trailer"] = _changed(model.trailer, **trailer)
        track.model = _changed(model, **learned)
        name = self._type_name(track)
        if name in self.catalogue and name != track.catalogue_name:
            self._retype(track, name)
        track.model = _changed(track.model, name=name, trailer_axle_m=self._trailer_axle(track))
        track.filter.trailer_axle_m = track.model.trailer_axle_m

    def _width_across_end(
        self, track: VehicleTrack, m: Measurement, points: np.ndarray, local: np.ndarray, unit: int, side: int
    ) -> float | None:
        """The unit's width from its one ``side`` seen, next to the end (a yaw 0.5 deg off moves a
        13.6 m trailer's rear 0.06 m across against its side's middle), to the far corner of an end
        face nothing of the vehicle hides (``OPEN_ENDS``): a sensor that sees a side and an end face
        of a box sees the whole face. The corner lies between the face's farthest point (the second
        farthest of all the claimed ``points`` near it: the fit's, ``local`` in the unit's frame,
        are thinned) and the nearest ray that passed beside the face, carried with the unit from its
        capture time: their middle, when they bracket it within ``CORNER_BRACKET_M``. In the body's
        lower half: rays pass through a cab's windscreen. (One sensor never sees both sides: an
        unknown trailer 2.55 m wide kept the catalogue's 2.77, its side fitted 0.11 m off its axis
        bent the hitch 1.5 deg; the farthest points alone, seen at a grazing angle, fell 0.1-0.4 m
        short of the corner.)"""
        model, face = track.model, OPEN_ENDS[unit]
        box, extent = model.boxes[unit], track.widths[unit]
        if not model.articulated or self.rays is None or extent.counted or len(extent.brackets) >= BRACKETS_KEPT:
            return None
        if not face_seen(m, model, unit, face, track.ground_z_m, self.params.fit_top_band_m):
            return None
        _, end_m = kernels.face_median(local, 0, m.unit, m.face, unit, face, ANYWHERE)
        near_end = (end_m - SIDE_NEAR_END_M, end_m + SIDE_NEAR_END_M)
        n_side, side_m = kernels.face_median(local, 1, m.unit, m.face, unit, side, near_end)
        if n_side < SIDE_MIN_POINTS:
            return None
        heights = (track.ground_z_m + box.floor_m, track.ground_z_m + box.floor_m + box.height_m / 2)
        q = unit_frames(points, m.vector, model)[unit]
        outward = 1.0 if side == LEFT else -1.0  # the seen side positive: the far corner is negative
        on_face = (
            (points[:, 2] >= heights[0]) & (points[:, 2] <= heights[1]) & (np.abs(q[:, 0] - end_m) <= END_BAND_M / 2)
        )
        if np.count_nonzero(on_face) < 2:
            return None
        last = np.partition(outward * q[on_face, 1], 1)[1]
        origin, along, across = _unit_axes(m, model, unit)
        motion = unit_motions(track.filter.state, model)[unit]
        rays = self.rays.crossings(
            origin + end_m * along, across, box.width_m / 2 + 1.0, heights[1], CORNER_BEYOND_M, motion
        )
        beside = -outward * rays[rays[:, 1] >= heights[0], 0]
        beside = beside[beside > -last - CORNER_BRACKET_M]
        if not len(beside) or beside.min() + last > CORNER_BRACKET_M:
            return None
        width = outward * side_m + (beside.min() - last) / 2
        return width if VEHICLE_WIDTH_M[0] <= width <= VEHICLE_WIDTH_M[1] else None

    def _learn_cab_top(self, track: VehicleTrack, m: Measurement, points: np.ndarray) -> float:
        """The cab's height: up to where its claimed ``points`` reach (the ``TOP_RANK``-th highest
        within ``TOP_GROW_M`` of its sides and ``TOP_END_INSET_M`` inside its ends at the fit ``m``,
        ``TOP_APART_M`` outside the trailer's box, below ``MAX_VEHICLE_HEIGHT_M``; their
        ``TOP_QUANTILE`` over the frames that had ``TOP_MIN_POINTS`` there) once ``TOP_MARGIN_M``
        above the catalogue's, never below it: beams that pass over a far cab's roof see it lower
        than it is, points above a box's top are the body's. An unknown tractor's cab 3.5 m high,
        its model 3.0 m (the Volvo's), seen from one side by generalization +2500 `l2`: the points
        above its model's roof were no face's, and the fit turned the cab up to 3 deg onto what was
        left in a docking's turn (at most 1.4 deg fitted 3.5 m high). A trailer keeps the
        catalogue's height: the door behind a docked one rises above its roof inside its box
        (docs/pipeline.md, Heights)."""
        at = Prior(m.x_m, m.y_m, m.yaw_rad, m.hitch_rad, track.model)
        z_rel = points[:, 2] - track.ground_z_m
        on_cab = in_unit_box(points, at, 0, TOP_GROW_M, -TOP_END_INSET_M) & (z_rel <= MAX_VEHICLE_HEIGHT_M)
        mine = z_rel[on_cab & ~in_unit_box(points, at, 1, TOP_APART_M)]
        if len(mine) >= TOP_MIN_POINTS:
            track.cab_top.add(float(np.partition(mine, -TOP_RANK)[-TOP_RANK]))
        return _height(track.cab_top, track.model.tractor)

    def _sides_faced(self, m: Measurement, model: VehicleModel) -> list[bool]:
        """Per unit, whether both its sides face a sensor of the frame (each is outside one of its
        side planes; all, without rays). One sensor sees one side of a box at most: what lies where
        the other would be is something else (seen by `l3` alone, a dock shelter's wall beyond the
        Twizy's trailer made it 1.95 m wide, 1.75)."""
        if self.rays is None:
            return [True] * len(model.boxes)
        local = unit_frames(self.rays.origins @ self.rays.to_level.T, m.vector, model)
        return [
            bool(np.any(q[:, 1] > box.width_m / 2) and np.any(q[:, 1] < -box.width_m / 2))
            for q, box in zip(local, model.boxes)
        ]

    def _learn_cab_length(self, track: VehicleTrack, m: Measurement, q: np.ndarray, points: np.ndarray) -> None:
        """The cab's length: from the middle of its front face's points to the middle of its rear
        face's, when both are seen (``face_seen``; its front pins it in the fit; an unknown
        tractor's cab 0.27 m shorter than the MAN's put its box centre 0.13 m off). With its rear
        face unseen, at most from its front face to where the rays show the gap behind a side
        (``_cab_side_end``): an upper bound (``_Extent.add_upper_bound``). (Five points on each
        face, before: with the chassis behind the cab no longer on its rear face, an unknown
        tractor's cab had them only after 20 s.) Never shorter or longer than any cab
        (``CAB_LENGTH_RANGE_M``): a Volvo's cab leaving two LiDARs' view had a ray cross its side's
        plane 0.09 m behind its front, and that one bound made it 0.09 m long (1.2 m off)."""
        model, band = track.model, self.params.fit_top_band_m
        if not face_seen(m, model, 0, FRONT, track.ground_z_m, band):
            return
        _, front = kernels.face_median(q, 0, m.unit, m.face, 0, FRONT, ANYWHERE)
        if face_seen(m, model, 0, REAR, track.ground_z_m, band):
            _, rear = kernels.face_median(q, 0, m.unit, m.face, 0, REAR, ANYWHERE)
            if CAB_LENGTH_RANGE_M[0] <= front - rear <= CAB_LENGTH_RANGE_M[1]:
                track.cab_length.add(front - rear)
        elif len(track.cab_length.uppers) < CAB_ENDS_KEPT:
            end = self._cab_side_end(track, m, q, points)
            if end is not None and front - end >= CAB_LENGTH_RANGE_M[0]:
                track.cab_length.add_upper_bound(front - end)

    def _cab_side_end(self, track: VehicleTrack, m: Measurement, q: np.ndarray, points: np.ndarray) -> float | None:
        """Where (its frame, x) the cab has ended, its rear face unseen: the foremost ray that
        crossed the plane of a side the fit's ``q`` show along the cab, behind the side's hindmost
        point and within ``CAB_END_BRACKET_M`` of it (``Rays.crossings``, each ray carried with the
        cab from its capture time; ``END_SEEN_MIN_RAYS`` of them; those ahead of the point count
        at it). The side's hindmost point: of the claimed ``points`` on its plane at the gap's
        heights (above the trailer's floor, below the lower roof), reached from the side's fitted
        hindmost without a gap of ``END_SEEN_OFFSET_M`` (a column's spacing). No ray crosses where
        a trailer's side runs on in line behind the cab. Nearly straight only (a trailer's front
        corner swings into the gap at a hitch angle), and in frames de-skewed with a speed known
        within ``TURN_MAX_SPEED_STD_M_S``. A straight unknown tractor's cab is seen from its sides
        and its front, its rear face hidden by its trailer's: the generalization suite's 6.5 m
        trailer's cab (2.3 m) kept the catalogue Volvo's 2.55 m for 9 s, until its turn fitted the
        hinge, its box centre 0.12 m back. (The side's hindmost point taken for the cab's end put
        the Volvo's and the Twizy's 0.08-0.09 m short; the middle between it and the ray, the
        MAN's 0.09 m long: its hindmost side point lay 0.08 m past its rear; used as a lower
        bound, it did that too. Each moved the known cabs' kingpins and hitches in their turns.)"""
        model = track.model
        if (
            self.rays is None
            or abs(m.hitch_rad) > GAP_TEST_MAX_HITCH_RAD
            or track.filter.speed_std_m_s > TURN_MAX_SPEED_STD_M_S
        ):
            return None
        cab, (low, high) = model.tractor, gap_band(model)
        claimed = unit_frames(points, m.vector, model)[0]
        z_rel = points[:, 2] - track.ground_z_m
        at_gap = (z_rel >= low) & (z_rel <= high)
        origin, along, across = _unit_axes(m, model, 0)
        motion = unit_motions(track.filter.state, model)[0]
        for face, sign in ((LEFT, 1.0), (RIGHT, -1.0)):
            fitted = q[(m.unit == 0) & (m.face == face), 0]
            if len(fitted) < SIDE_MIN_POINTS:
                continue
            side_y = sign * cab.width_m / 2
            on_side = at_gap & (np.abs(claimed[:, 1] - side_y) <= self.params.fit_inlier_m)
            end = reached_back(float(fitted.min()), claimed[on_side, 0], END_SEEN_OFFSET_M)
            rays = self.rays.crossings(
                origin + end * along + side_y * across, along, CAB_END_BRACKET_M,
                track.ground_z_m + high, GAP_SEEN_BEYOND_M, motion,
            )  # fmt: skip
            behind = end + rays[rays[:, 1] >= track.ground_z_m + low, 0]
            if len(behind) >= END_SEEN_MIN_RAYS:  # those ahead of the end: carried a little too far
                return min(float(behind.max()), end)
        return None

    def _learn_hinge(self, track: VehicleTrack, prior: Prior, points: np.ndarray, own: Measurement) -> None:
        """The kingpin's offset shows only at a hitch angle (straight, it trades with the trailer's
        front: only where the front reaches ahead of the rear axle shows). Turning, frames' fits
        ``own`` are kept (every second turning frame for the first ten, then every fifth:
        ``HINGE_FRAME_STEPS``; the latest ``HINGE_FRAMES``) and each time one is, the hinge is
        fitted to them all at once (``fit_hinge``). (Fitted free in each frame, the kingpin and the
        front traded along a valley: an unknown 6.5 m trailer's kingpin was learned at -0.42 to
        -0.52 m, -0.70, and its cab's yaw ran 4.5 deg off. The first 40 turning frames of a
        roundabout alone put a 13.6 m trailer's hinge 2-3 cm off, and its hitch 0.2 deg.) Only
        once the filter knows the speed within ``TURN_MAX_SPEED_STD_M_S``: the frames are de-skewed
        with it. Straight, a fit with the hinge free measures the reach, when the cab's front face
        (the model's anchor: a learned cab length moves its rear) or its rear face pins the axle:
        until the first hinge is fitted. (Its rear face alone, with one or two points on it, a 6.5 m
        trailer's unknown cab waited five frames with its box 0.51 m ahead of its front face.)"""
        if track.reach is None:
            return
        turning = abs(prior.hitch_rad) >= KINGPIN_MIN_HITCH_RAD and track.filter.speed_std_m_s <= TURN_MAX_SPEED_STD_M_S
        if turning:
            track.turning_frames += 1
            step = HINGE_FRAME_STEPS[track.turning_frames > HINGE_FRAMES // 2 * HINGE_FRAME_STEPS[0]]
            if track.turning_frames % step == 0:
                self._fit_turn(track, prior, own)
            return
        if (
            abs(prior.hitch_rad) > REACH_MAX_HITCH_RAD
            or track.hinge is not None
            or len(track.reach.values) >= REACH_SETTLED
            or track.at_wall  # with the hinge free, a face behind the trailer pulled its box back, front too
        ):
            return
        m = fit(points, replace(prior, free_kingpin=True), self.params)
        if m is None:
            return
        model = _changed(track.model, kingpin_behind_axle_m=m.kingpin_m)
        band = self.params.fit_top_band_m
        axle_pinned = (
            face_seen(m, model, 0, FRONT, track.ground_z_m, band)
            or np.sum((m.unit == 0) & (m.face == REAR)) >= REAR_FACE_MIN_POINTS
        )
        if axle_pinned and face_seen(m, model, 1, FRONT, track.ground_z_m, band):
            track.reach.add(m.trailer_front_m - m.kingpin_m)

    def _fit_turn(self, track: VehicleTrack, prior: Prior, own: Measurement) -> None:
        """``own`` kept as a frame of the turn, and the hinge fitted to the frames kept (``_learn_hinge``)."""
        track.turn.append(TurnFrame.of(own, prior.ground_z_m, track.model, self.params.fit_top_band_m))
        cab = track.cab_length
        cab_prior = None if cab.counted else (cab.prior, CAB_LENGTH_SIGMA_M)
        hinge = fit_hinge(list(track.turn), track.model, self.params, cab_prior=cab_prior)
        if hinge.std_m.max() <= HINGE_MAX_STD_M:
            track.hinge = hinge
            # the next fit starts where this one ended (each frame's pose was the model's then)
            track.turn = deque((replace(f, pose=p) for f, p in zip(track.turn, hinge.poses)), maxlen=HINGE_FRAMES)

    def _retype(self, track: VehicleTrack, name: str) -> None:
        """The learned sizes match another catalogue vehicle better than the start's: take its
        figures the points do not measure (tractor front, floors, heights (the cab's until measured),
        kingpin (learned again from its axle), trailer front; the cab's and the trailer's lengths until measured), keep the
        measured widths and lengths. (An unknown 6.5 m trailer started as the MAN, renamed a Volvo
        where its moving points kept ending, fell back to the MAN's 13.68 m whenever they spread, and
        was renamed back and forth for 7 s, its centre 3.6 m off.)"""
        prior = self.catalogue[name]
        model = track.model
        cab = track.cab_length
        if cab is not None and cab.median is None:  # not measured yet: the new type's
            cab.prior = prior.tractor.length_m
        length = track.trailer_length
        if length is not None and not length.counted:
            length.prior = prior.trailer.length_m
        for extent, box in zip(track.widths, prior.boxes):
            extent.prior = box.width_m
        track.cab_top.prior = prior.tractor.top_m
        widths = _unit_widths(track.widths)  # from the new type's where not measured
        tractor = replace(
            prior.tractor,
            width_m=widths[0],
            length_m=cab.estimate if cab else prior.tractor.length_m,
            height_m=_height(track.cab_top, prior.tractor),
        )
        trailer = replace(prior.trailer, width_m=widths[1], length_m=model.trailer.length_m)
        track.model = replace(prior.with_boxes(tractor, trailer), trailer_axle_m=model.trailer_axle_m)
        track.catalogue_name = name
        # learned again from the old axle
        track.hinge_prior, track.reach = _hinge_priors(prior, self.params.dimension_window)
        track.turn.clear()
        track.turning_frames, track.hinge = 0, None
        track.filter.kingpin_m = prior.kingpin_behind_axle_m
        track.filter.shift_reference(model.tractor.front_m - prior.tractor.front_m)  # the cab stays where it is
        track.axle_fits.clear()  # of the old reference point; the new type's axle until learned again
        track.axle = _axle_extent()
        track.filter.axle_behind_m = 0.0

    def _learn_trailer_length(
        self, track: VehicleTrack, m: Measurement, q: np.ndarray, width_m: float, points: np.ndarray
    ) -> None:
        """The rear face: the hindmost of the trailer body's points (within its width and height band,
        reached from the front without a gap longer than ``MAX_BODY_GAP_M``, ahead of any face that
        runs on past the trailer's sides: a wall). A length when points across the middle of the
        face are seen there (not only the ends of the two sides), else a lower bound (the trailer
        reaches at least that far back). Never into a building (``_structure_behind``)."""
        trailer = track.model.trailer
        n_band, rows, face_seen, middle = self._rear_face(track, m, q, width_m)
        if n_band < 5:
            return
        claimed = trailer_frame(points, m.vector, track.model)
        building = self._structure_behind(track, claimed, points[:, 2] - track.ground_z_m, width_m)
        if not (q[rows, 0] > building).all():  # the hindmost points were a building's
            rows, face_seen = rows[q[rows, 0] > building], face_seen and middle > building
            if not len(rows):
                return
        rear = float(q[rows[-1], 0])
        if face_seen:
            length = self._fitted_length(track, m, points, trailer.front_m - middle)
            if length is not None:
                track.trailer_length.add(length)
        elif not track.trailer_length.settled:
            on_side = [rows[(m.unit[rows] == 1) & (m.face[rows] == face)] for face in (LEFT, RIGHT)]
            end = self._seen_end(track, m, points, [q[side] for side in on_side if len(side)], width_m)
            if end is not None and self._end_went_along(track, m, "seen", end):
                track.trailer_length.add(trailer.front_m - end)
        if self._end_went_along(track, m, "bound", rear):
            track.trailer_length.add_bound(min(trailer.front_m - rear - END_BAND_M, MAX_TRAILER_LENGTH_M))
        reach = min(trailer.front_m - rear, MAX_TRAILER_LENGTH_M)
        # shorter than any trailer: its front face alone, seen from ahead (a Volvo's stayed put 0.04-1.4 m
        # deep for 10 s, and it was named ``unknown``, 0.04 m long)
        if abs(track.filter.speed_m_s) >= STILL_END_MIN_SPEED_M_S and reach >= TRAILER_LENGTH_RANGE_M[0]:
            track.trailer_length.add_reach(reach)

    def _rear_face(
        self, track: VehicleTrack, m: Measurement, q: np.ndarray, width_m: float
    ) -> tuple[int, np.ndarray, bool, float]:
        """The trailer body's hindmost points of the fit ``m`` (``q``: in the trailer's frame) and its
        rear face (``kernels.rear_face``: the points in the body's band, the rows kept, whether the
        face is seen and its middle)."""
        trailer = track.model.trailer
        return kernels.rear_face(
            q, m.points[:, 2] - track.ground_z_m, m.unit, m.face, body_band(trailer),
            trailer.front_m + END_BAND_M, width_m / 2, self.params.fit_inlier_m, WALL_BESIDE_M, MAX_BODY_GAP_M,
            END_BAND_M, trailer.top_m - self.params.fit_top_band_m, FACE_SEEN_SPAN * width_m,
        )  # fmt: skip

    def _face_behind(self, track: VehicleTrack, m: Measurement) -> bool:
        """Whether the rear face the fit ``m`` shows stands apart behind the trailer's body (a
        dock's door, not the trailer's rear): its sides (the fit's points on them, reached from the
        foremost without a gap longer than ``FACE_APART_GAP_M``) end so far ahead of it that a slab
        ``FACE_APART_MIN_SLAB_M`` long fits between, ``FACE_APART_CLEAR_M`` ahead of the face, and
        rays crossed that slab (``_seen_empty_behind``). Ahead of its own rear face the body is
        solid; a face behind it (a dock's door 0.6 m behind a Volvo standing at it, seen by one
        LiDAR from the side) leaves a gap the rays cross. That door had been learned as the rear
        face: the trailer 0.6 m too long, and pulling out, the door held the fitted rear face while
        the cab drove on (0.98 m behind). Sides reaching the face ask no rays (a pass over the
        frame's rays costs about 2 ms)."""
        trailer = track.model.trailer
        if trailer is None or track.trailer_length is None:
            return False
        q = trailer_frame(m.points, m.vector, track.model)
        n_band, rows, face_seen, face_m = self._rear_face(track, m, q, trailer.width_m)
        if n_band < 5 or not face_seen:
            return False
        sides_x = q[rows[(m.unit[rows] == 1) & ((m.face[rows] == LEFT) | (m.face[rows] == RIGHT))], 0]
        back = face_m + FACE_APART_CLEAR_M
        front = back + FACE_APART_MIN_SLAB_M + END_SEEN_OFFSET_M  # the slab's front, as a side's end
        if not len(sides_x) or reached_back(float(sides_x.max()), sides_x, FACE_APART_GAP_M) < front:
            return False
        return self._seen_empty_behind(track, m, front, trailer.width_m, back)

    def _fitted_length(self, track: VehicleTrack, m: Measurement, points: np.ndarray, seen_m: float) -> float | None:
        """The trailer's length fitted to the claimed ``points`` from the frame's fit ``m`` and the length
        its rear face shows in it (``seen_m``), when they pin it within ``LENGTH_MAX_STD_M``. (The length
        the frame's fit shows is the model's own whenever the cab's place along the vehicle is pinned
        weakly: a length learned 0.2 m long from a start frame's points, not de-skewed, stayed so, and
        the fits put the tractor 0.2 m off.) Where the frame shows the trailer's front face too, the
        front is fitted with it (the kingpin free): the length lies between the two faces. Else it
        is measured from the model's front, and a front learned short made the length short, which
        held the front short in the turn's joint fit (an unknown 10.5 m trailer's U-turn: 10.34 m,
        its front 0.15 m short 8 s in, the truth only after 20 s; its hitch 0.41 deg, now 0.17)."""
        if seen_m < TRAILER_LENGTH_RANGE_M[0]:  # its front face, seen from ahead
            return None
        prior = free_length_at(m, track.model, seen_m, track.ground_z_m)
        if face_seen(m, track.model, 1, FRONT, track.ground_z_m, self.params.fit_top_band_m):
            prior = replace(prior, free_kingpin=True)
        free = fit(points, prior, self.params)
        if free is None or free.trailer_length_std_m > LENGTH_MAX_STD_M:
            return None
        return free.trailer_length_m

    def _end_went_along(self, track: VehicleTrack, m: Measurement, kind: str, end_m: float) -> bool:
        """Whether an end of the trailer's points (``end_m``, its frame; ``kind``: which) is the
        trailer's: standing, it is; moving, once it went along with the trailer (its place in the
        trailer's frame kept better than its place in the yard) since the last end of its kind seen
        ``END_TRAVEL_M`` of travel before. A dock shelter's walls beside a Twizy pulling out stayed
        put in the yard and ran on 1-3 m past its trailer's rear (3.0-3.7 m long, 2.5)."""
        if abs(track.filter.speed_m_s) < STILL_END_MIN_SPEED_M_S:
            track.ends.pop(kind, None)
            return True
        kingpin, place = (_on_trailer_axis(m, track.model, x_m) for x_m in (0.0, end_m))
        seen = track.ends.setdefault(kind, deque(maxlen=END_HISTORY))
        before = next((e for e in reversed(seen) if np.hypot(*(kingpin - e[2])) >= END_TRAVEL_M), None)
        seen.append((place, end_m, kingpin))
        return before is not None and abs(end_m - before[1]) < np.hypot(*(place - before[0]))

    def _side_end(
        self, track: VehicleTrack, m: Measurement, points: np.ndarray, side: np.ndarray, width_m: float
    ) -> float:
        """The hindmost of the claimed ``points`` on the trailer's side whose fitted points are ``side``
        (its frame, xy), reached from the fitted ones' hindmost without a gap longer than
        ``MAX_BODY_GAP_M``: the fit's thinned sample keeps one point in many, and its hindmost lay
        0.1-1.2 m short of a MAN's trailer's end (all its side's points: 0.0-0.2 m)."""
        trailer = track.model.trailer
        end = float(side[:, 0].min())
        q = trailer_frame(points, m.vector, track.model)
        z_rel = points[:, 2] - track.ground_z_m
        on_side = (
            (np.abs(q[:, 1] - np.sign(side[0, 1]) * width_m / 2) <= self.params.fit_inlier_m)
            & body_heights(z_rel, trailer)
            & (q[:, 0] < end)
            & (q[:, 0] > self._structure_behind(track, q, z_rel, width_m))
        )
        return reached_back(end, q[on_side, 0])

    def _structure_behind(self, track: VehicleTrack, q: np.ndarray, z_rel: np.ndarray, width_m: float) -> float:
        """Where (the trailer's frame, x) the foremost of the claimed points (``q``: in the trailer's
        frame, ``z_rel``: their heights above the ground) higher than any vehicle lies within the
        trailer's width (``fit_inlier_m`` out past its sides) behind its rear face: a building's
        wall, which the trailer's body does not run into (-inf: none). A Volvo pulling out of its
        dock, the building's 6 m wall in line with its side 1-2 m behind
        its rear, had the side run on into the wall and its trailer learned 8.28 m long (6.30),
        named ``unknown`` throughout. Behind the rear only: a tree's crown above a trailer is no end
        of it, nor a dock's lintel above a docked Twizy's rear (counted from 0.4 m ahead of the
        rear, it cut the trailer's rear face off, and the trailer was learned 1.86 m wide, 1.75)."""
        tall = (
            (z_rel > MAX_VEHICLE_HEIGHT_M)
            & (np.abs(q[:, 1]) <= width_m / 2 + self.params.fit_inlier_m)
            & (q[:, 0] <= track.model.trailer.rear_m)
        )
        return float(q[tall, 0].max()) if tall.any() else -np.inf

    def _seen_end(
        self, track: VehicleTrack, m: Measurement, points: np.ndarray, sides: list[np.ndarray], width_m: float
    ) -> float | None:
        """Where the trailer ends, though its rear face is not seen (from one side it never is): at
        the first of its sides (``sides``: each seen side's fitted points, the trailer's frame) whose
        hindmost fitted point has no body behind it in the rays (``_seen_empty_behind``), that
        side's hindmost claimed point (``_side_end``). A dock's shelter right beside one side
        reaches on past the end; the other side's end is taken then. (The claimed points' end
        asked of the rays instead: a MAN's side ending 0.7 m short in a neighbour's shadow passed.)"""
        for side in sorted(sides, key=lambda points_xy: -float(points_xy[:, 0].min())):
            if self._seen_empty_behind(track, m, float(side[:, 0].min()), width_m):
                return self._side_end(track, m, points, side, width_m)
        return None

    def _seen_empty_behind(
        self, track: VehicleTrack, m: Measurement, end_m: float, width_m: float, back_to_m: float = -np.inf
    ) -> bool:
        """Whether at least ``END_SEEN_MIN_RAYS`` rays crossed the trailer's body behind ``end_m`` (its
        frame; a slab ``END_SEEN_LENGTH_M`` long from ``END_SEEN_OFFSET_M`` behind it, or shorter,
        back to ``back_to_m``), one of them within ``END_SEEN_REACH_M`` of the slab's front, and none
        ended in it: the body ends there. A shadow's edge is no end: the trailer hidden behind it
        stops the rays that would cross (those passing further back show only that it ends before
        them); a return in the slab is a surface there (its own rear face, a dock)."""
        front = end_m - END_SEEN_OFFSET_M
        length = min(END_SEEN_LENGTH_M, front - back_to_m)
        crossed, ended, reach = self._rays_behind(track.model, m, track.ground_z_m, front, length, width_m)
        return crossed >= END_SEEN_MIN_RAYS and ended == 0 and reach >= length / 2 - END_SEEN_REACH_M

    def _listed_seen_through(
        self, model: VehicleModel, m: Measurement, ground_z_m: float, reach_m: float, listed_m: float
    ) -> bool:
        """Whether the start's rays crossed the catalogue's trailer (``listed_m`` long) behind where
        its points reach (``reach_m`` behind its front; ``model``: the start's, with the catalogue's
        front) at least ``END_SEEN_MIN_RAYS`` times, one of them ``END_SEEN_REACH_M`` or more ahead
        of its rear, and none ended there: its body is not there. Any rays count, not only those
        right behind the points (``_seen_empty_behind``: where the trailer ends): the catalogue's
        body would stop them all. Seen from one side by paper `l1`, a Volvo (its points reaching
        6.9 m behind the trailer's front) started as a MAN (13.68 m) whose trailer's hind 6.5 m
        four rays crossed, and was reported as one for 3 frames. Rays that returned nothing count
        too (``_unreturned_behind``); not for where a trailer ends (``_seen_empty_behind``), which
        takes its side's hindmost point though the slab's rays show only that the body ends within
        ``END_SEEN_OFFSET_M`` behind it: counted there, a Volvo hidden beside a MAN had its trailer
        learned 6.03 m (6.30) for 5 s."""
        front = model.trailer.front_m - reach_m - END_SEEN_OFFSET_M
        length = listed_m - reach_m - END_SEEN_OFFSET_M
        if self.rays is None or length <= END_SEEN_REACH_M:
            return False
        slab = (model, m, ground_z_m, front, length, model.trailer.width_m)
        crossed, ended, ahead = self._rays_behind(*slab)
        unreturned, unreturned_ahead = self._unreturned_behind(*slab)
        crossed, ahead = crossed + unreturned, max(ahead, unreturned_ahead)
        return crossed >= END_SEEN_MIN_RAYS and ended == 0 and ahead >= END_SEEN_REACH_M - length / 2

    def _rays_behind(
        self, model: VehicleModel, m: Measurement, ground_z_m: float, front_m: float, length_m: float, width_m: float
    ) -> tuple[int, int, float]:
        """``Rays.through`` the trailer's body (``SOLID_INSET_M`` inside its sides, floor and roof) in
        the slab ``length_m`` long behind ``front_m`` (its frame, x) at the fit ``m``: how many rays
        crossed it, how many ended in it, how far ahead of its middle the crossing ones reach."""
        if self.rays is None:
            return 0, 0, -np.inf
        slab = _slab(model, m, ground_z_m, front_m, length_m, width_m, SOLID_INSET_M)
        return self.rays.through(*slab, GAP_SEEN_BEYOND_M)

    def _unreturned_behind(
        self, model: VehicleModel, m: Measurement, ground_z_m: float, front_m: float, length_m: float, width_m: float
    ) -> tuple[int, float]:
        """The rays that returned nothing through the slab of ``_rays_behind`` and how far ahead of its
        middle they reach, where at least ``UNRETURNED_MIN_RAYS`` crossed and they outnumber the
        returns on the body's faces (``FACE_SHELL_M`` around them) ``UNRETURNED_PER_RETURN`` times: a
        body there returns most rays that reach it (else none: 0, -inf). Seen from one side, an
        unknown 10.5 m trailer started as a MAN's (13.68 m) whose hind 3 m no return crossed: the
        beams at its heights ended on no ground within the sensor's reach, and 29 of them crossed it."""
        if self.rays is None:
            return 0, -np.inf
        slab = _slab(model, m, ground_z_m, front_m, length_m, width_m, SOLID_INSET_M)
        unreturned, reach = self.rays.unreturned_through(*slab)
        if unreturned < UNRETURNED_MIN_RAYS:
            return 0, -np.inf
        shell = _slab(model, m, ground_z_m, front_m, length_m, width_m, -FACE_SHELL_M)
        on_faces = self.rays.through(*shell, GAP_SEEN_BEYOND_M)[1]
        return (unreturned, reach) if unreturned >= UNRETURNED_PER_RETURN * on_faces else (0, -np.inf)

    def _trailer_axle(self, track: VehicleTrack) -> float:
        """L2 scaled with the trailer's length behind the kingpin (the catalogue's proportion)."""
        prior = self.catalogue.get(track.catalogue_name)
        if prior is None or prior.trailer is None or track.model.trailer is None:
            return track.model.trailer_axle_m
        behind = prior.trailer.length_m - prior.trailer.front_m
        return prior.trailer_axle_m * (track.model.trailer.length_m - track.model.trailer.front_m) / behind

    def _type_name(self, track: VehicleTrack) -> str:
        """The catalogue vehicle whose sizes all lie within ``type_max_error_m`` of the measured
        ones, else ``unknown``. The trailer's length is the measured one (the start's before any),
        not a lower bound: a bound says how long at least, not what it is (a Twizy pulling out of
        its dock, the door jamb in line with its trailer's side, was named ``unknown``); once a
        bound counts in as many frames as a length needs, it says where the trailer does not end:
        a MAN entering the view cab first, its trailer in part, started as a Volvo and stayed one
        for 5.5 s while its body reached up to 13.1 m."""
        model = track.model
        if model.trailer is None:
            return "rigid"
        extent = track.trailer_length
        length = extent.estimate if len(extent.bounds) >= LENGTH_CONVERGED_OBSERVATIONS else extent.measured
        best, best_err = "unknown", self.params.type_max_error_m
        for name, c in self.catalogue.items():
            if c.trailer is None:
                continue
            err = max(
                abs(c.trailer.length_m - length),
                abs(c.trailer.width_m - model.trailer.width_m),
                abs(c.tractor.width_m - model.tractor.width_m),
            )
            if err <= best_err:
                best, best_err = name, err
        return best

    def _start_length(self, model: VehicleModel, m: Measurement, points: np.ndarray, ground_z_m: float) -> _Extent:
        """The trailer's length as the start fit ``m`` of ``points`` shows it (``model`` carries it):
        measured where it saw the rear face; else the trailer reaches at least as far as its points
        do (``unit_frames.trailer_reach``), and the catalogue's longer length stands until the end shows (a MAN
        entering the region, its rear beyond it, was named ``unknown`` with the 11.1 m its points
        reached, for 8 s), unless rays crossed it beyond them (``_listed_seen_through``)."""
        window, length_m = self.params.dimension_window, model.trailer.length_m
        seen_end = m.rear_points >= REAR_FACE_MIN_POINTS  # the start fit saw where the trailer ends
        listed = self.catalogue.get(model.name)
        if not seen_end and m.trailer_length_m is not None and listed is not None:
            reach = trailer_reach(m, model, points, ground_z_m, self.params.fit_inlier_m)
            refuted = self._listed_seen_through(model, m, ground_z_m, reach, listed.trailer.length_m)
            length = _Extent(reach if refuted else max(reach, listed.trailer.length_m), window)
            length.add_bound(reach)
            return length
        length = _Extent(length_m, window)
        if seen_end:
            length.add(length_m)
        return length


def _slab(
    model: VehicleModel, m: Measurement, ground_z_m: float, front_m: float, length_m: float, width_m: float,
    inset_m: float,
) -> tuple:  # fmt: skip
    """The trailer's body (``width_m`` wide) in the slab ``length_m`` long behind ``front_m`` (its
    frame, x) at the fit ``m``, ``inset_m`` inside its sides, floor and roof (outside: negative), as
    ``Rays.through`` takes a box: centre, yaw, half length, half width, bottom and top."""
    centre = tuple(_on_trailer_axis(m, model, front_m - length_m / 2))
    floor, top = ground_z_m + model.trailer.floor_m, ground_z_m + model.trailer.top_m
    return centre, m.yaw_rad + m.hitch_rad, length_m / 2, width_m / 2 - inset_m, (floor + inset_m, top - inset_m)


def _hinge(track: VehicleTrack) -> tuple[float, float]:
    """The kingpin's offset behind the rear axle and the trailer's front ahead of the kingpin:
    fitted in a turn, else the catalogue's kingpin with the front where the reach seen straight puts
    it, else the catalogue's."""
    if track.hinge is not None:
        return track.hinge.kingpin_m, track.hinge.trailer_front_m
    kingpin, front = track.hinge_prior
    return kingpin, (track.reach.estimate + kingpin if track.reach.values else front)


def _cab_length(track: VehicleTrack) -> float:
    """The cab's length: measured between its faces once counted, else the hinge's (fitted with it),
    else the catalogue's (or at least the lower bound the faces gave)."""
    if not track.cab_length.counted and track.hinge is not None and track.hinge.cab_length_m is not None:
        return track.hinge.cab_length_m
    return track.cab_length.estimate


def _height(top: _Extent, box: Box) -> float:
    """The height of ``box`` whose top its points reach up to ``top``: the prior's unless they
    reach ``TOP_MARGIN_M`` above it."""
    return (_top_reached(top) if _top_raised(top) else top.prior) - box.floor_m


def _top_reached(top: _Extent) -> float:
    """The ``TOP_QUANTILE`` of the frames' tops: each is as high as the body reaches at least (a
    frame's beams may pass over the roof or stop short of it), a few are higher (clutter)."""
    ordered = top.values.ordered
    return ordered[min(int(TOP_QUANTILE * len(ordered)), len(ordered) - 1)]


def _top_raised(top: _Extent | None) -> bool:
    return top is not None and bool(top.values) and _top_reached(top) > top.prior + TOP_MARGIN_M


def _changed(obj, **values):
    """``dataclasses.replace(obj, **values)``, or ``obj`` itself when it holds those values already
    (the learned sizes of a settled vehicle rarely change: a frozen copy costs more than the check)."""
    if all(getattr(obj, name) == value for name, value in values.items()):
        return obj
    return replace(obj, **values)


def _unit_axes(m: Measurement, model: VehicleModel, unit: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A unit's origin at the fit ``m`` and its unit vectors along it and across it (to its left)."""
    origin, yaw = unit_origins(m.vector, model)[unit]
    along, across = unit_axes(yaw)
    return origin, along, across


def _on_trailer_axis(m: Measurement, model: VehicleModel, x_m: float) -> np.ndarray:
    """The yard xy of the point ``x_m`` along the trailer's axis from the kingpin, at the fit ``m``."""
    yaw = m.yaw_rad + m.hitch_rad
    return model.kingpin_xy(m.x_m, m.y_m, m.yaw_rad) + x_m * np.array([np.cos(yaw), np.sin(yaw)])


def _sides_along(q: np.ndarray, m: Measurement, unit: int, box: Box) -> bool:
    """Whether the points of the unit's left and right faces (``q``: the unit's frame) within its
    length run along its axis, within ``SIDE_MAX_SLOPE``: a docked Twizy's trailer, a dock's wall
    crossing its middle at 37 deg, had the wall's points beside its front counted as its left side
    (1.98 m wide for 1.75, its hitch 3-4 deg off for 2 s)."""
    within = (m.unit == unit) & (q[:, 0] >= box.rear_m) & (q[:, 0] <= box.front_m)
    for face in (LEFT, RIGHT):
        x, y = q[within & (m.face == face), :2].T
        x = x - x.mean()
        if abs(float(x @ (y - y.mean()))) > SIDE_MAX_SLOPE * float(x @ x):
            return False
    return True


def _learn_axle(track: VehicleTrack, m: Measurement, stamp_s: float) -> None:
    """Where the tractor's rear axle, the point that does not slip sideways, lies behind the
    model's reference point (the catalogue's axle): over an arc, a point ``a`` ahead of the axle
    moves sideways of the axle's chord by ``a`` times the chord of its heading, 2 sin(turn / 2).
    Each whole fit (all four pose directions measured) is paired with the latest fit a turn of
    ``AXLE_MIN_TURN_RAD`` before it, when the fit halfway between heads halfway (one arc: a turn
    winding up or down bends the chord, a known MAN's ending gave 0.5-1.7 m); the median of the
    pairs', once ``AXLE_MIN_SAMPLES``, goes to the filter. (An unknown 13.6 m trailer's tractor,
    its axle 0.35 m behind the MAN's it was named after, its cab hidden behind its trailer in a
    roundabout: its heading from the kingpin's motion ran 2.2 deg off, the hitch up to 5.)"""
    if not track.model.articulated or (m.observed is not None and len(m.observed[0]) < len(m.vector)):
        return
    x, y, yaw = m.vector[:3]
    fits = list(track.axle_fits)
    for k in range(len(fits) - 1, -1, -1):
        stamp, x0, y0, yaw0 = fits[k]
        if stamp_s - stamp > AXLE_MAX_SPAN_S:
            break
        turn = wrap_rad(yaw - yaw0)
        if abs(turn) < AXLE_MIN_TURN_RAD:
            continue
        mean = yaw0 + turn / 2
        middle = min(fits[k:], key=lambda f: abs(f[0] - (stamp + stamp_s) / 2))
        if abs(wrap_rad(middle[3] - mean)) <= AXLE_STEADY_SHARE * abs(turn):
            sideways = (y - y0) * math.cos(mean) - (x - x0) * math.sin(mean)
            track.axle.add(sideways / (2 * math.sin(turn / 2)))
        break
    track.axle_fits.append((stamp_s, x, y, yaw))
    if track.axle.counted:
        track.filter.axle_behind_m = float(np.clip(track.axle.median, -AXLE_MAX_M, AXLE_MAX_M))
