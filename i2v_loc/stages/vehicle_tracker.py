"""The articulated estimator's vehicle tracks: per vehicle gate -> hinged fit -> kinematic UKF;
unclaimed points seed new vehicles (docs/pipeline.md, Articulated estimator).

A new vehicle starts from a connected component of the right size (length, height) that persists
for ``start_frames`` frames; its model (catalogue vehicle, or one rigid box of the measured size),
its direction (tractor ahead) and hitch come from fitting every hypothesis to its points and
keeping the best explained; the motion decides the direction only when both ends fit alike. A
vehicle leaves after ``leave_frames`` frames without points. The trailer's length and the units'
widths are re-estimated from the points seen in each unit's frame (the catalogue is the prior).
"""

from __future__ import annotations

import bisect
import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from functools import lru_cache
from itertools import count

import numpy as np
from scipy.spatial import cKDTree

from i2v_loc.geometry import box_corners, rotate_xy, wrap_rad
from i2v_loc.params import ArticulatedParams, VehicleConfig
from i2v_loc.stages import kernels
from i2v_loc.stages.faces import (
    END_FACE_WIDTH_M,
    ONE_SIDE_WIDTH_M,
    away_from_sensor,
    end_face,
    face_foot,
    face_line,
    faces_grounded,
    l_shaped,
    low_at_both_ends,
    one_face_sized,
    passes_under,
    rigid_seen,
    roof_shown,
    unit_grounded,
    unit_raised,
    vehicle_face,
)
from i2v_loc.stages.hinged_fit import (
    FRONT,
    LEFT,
    REAR,
    RIGHT,
    TRAILER_LENGTH_RANGE_M,
    Hinge,
    Measurement,
    Prior,
    TurnFrame,
    explained_share,
    fit,
    fit_hinge,
    in_unit_box,
    rear_sigma_m,
    thin,
    with_rear_end,
    without_hitch,
)
from i2v_loc.stages.kinematic_filter import FilterState, KinematicFilter, unit_motions
from i2v_loc.stages.primitives import Rect, min_area_rect, voxel_keys
from i2v_loc.stages.vehicle_model import MAX_VEHICLE_HEIGHT_M, RIGID_MAX_LENGTH_M, Box, VehicleModel
from i2v_loc.stages.visibility import Rays

START_HITCHES_DEG = (-90.0, -60.0, -30.0, 0.0, 30.0, 60.0, 90.0)
COARSE_ITERATIONS = 4  # per start hitch; the best is refined with START_ITERATIONS
START_NUDGE_RAD = np.radians(7.0)  # the refined start fit fitted again this far either way in hitch
START_ITERATIONS = 20
START_SIGMAS = np.array([0.3, 0.3, np.radians(3.0), np.radians(5.0)])  # added to the first fit's covariance
START_SCALE_M = 0.8  # first loss scale of the start fits (a placed model is off by up to metres)
DIRECTION_COST_RATIO = 0.8  # one end's fit must cost this much less than the other's to decide the direction
RIGID_COST_RATIO = 0.7  # an articulated model must cost this much less than one rigid box
START_BEND_TOLERANCE_RAD = np.radians(10.0)  # catalogue models' fits of one vehicle bend alike (within 2 deg)
FOLDED_HITCH_RAD = np.radians(90.0)  # no trailer swings further round its kingpin: its box runs through the cab
TRACTOR_LOST_SIGMA_DEG = 1.0  # tracked, the hitch's is 0.2-0.4 deg; the cab hidden behind its trailer, 1-5 deg
MAX_TRAILER_LENGTH_M = TRAILER_LENGTH_RANGE_M[1]
REAR_FACE_MIN_POINTS = 3
SIDE_MIN_POINTS = 5
SIDE_MAX_SLOPE = np.tan(np.radians(5.0))  # a side's points run along its unit's axis (the fits' yaw: within 2 deg)
LOW_SEED_SLACK_M = 0.5  # a seed shorter than a rigid vehicle and this much lower than every articulated one is none
REFIT_SIZE_CHANGE_M = 0.1  # a rigid start's box refitted on the footprint its fit explains (``_rigid_fits``)
APART_VOXEL_M = 0.3  # a seed taken apart in one sweep (``_start_apart``): lanes 0.6 m apart stay apart
TALL_COLUMN_MIN_POINTS = 2  # points above a vehicle's height that make a column a structure (not one noise point)
RIGID_MIN_WIDTH_M = 1.6  # a rigid vehicle starts once its width is seen (an end face or both sides)
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
GAP_TEST_MAX_HITCH_RAD = np.radians(10.0)  # beyond, a trailer's front corner swings into the gap
WALL_MIN_POINTS = 5
WALL_MIN_ACROSS_M = 0.2
WALL_MIN_ANGLE_DEG = 30.0
WALL_ANGLE_STEP_DEG = 2.0
WALL_LINE_M = 0.1
GAP_FILL_RATIO = 0.5
GAP_MIN_POINTS = 5
GAP_OPEN_RATIO = 0.1  # a moving seed with so few points in its gap is two units, however well one box fits
GAP_OPEN_MIN_POINTS = 10
GAP_SEEN_MIN_RAYS = 1  # a solid side stops every ray: one through a seed's gap shows it empty, not hidden
GAP_SEEN_BEYOND_M = 0.3  # past the gap: a ray ending on a side running through it did not cross it
GAP_SIDES_REACH_M = 2.5  # the body's sides next to the gap: about a cab's length either way
# the gap's box is this far inside the sides: rays grazing a parked trailer's side ran along it within
# 3 cm of its points' extent for a metre and "crossed" its "gap" (a false vehicle for 25 s on the
# generalization suite with a trial start rule); 0.25 m inside kept too few of a MAN's rays through its
# 0.7 m gap (two started 26 frames late)
GAP_SIDE_INSET_M = 0.1
GAP_LOOKED_MIN_POINTS = 8  # on a face across the gap, seen through its opening (one sweep: no motion to wait for)
GAP_FACE_MARGIN_M = 0.15  # the faces bounding the gap: their points' noise and the fit's error along
END_SLAB_M = 1.0  # beyond a rigid body's end: a ray ending there and none crossing, it goes on (``_ends_free``)
SOLID_INSET_M = 0.5  # a unit's box this far inside its faces is crossed by no ray (a sweep's motion blurs them)
SEEN_THROUGH_RATIO = 0.1  # of the rays ending on a unit, at most this many cross it (real ones: under 0.01)
CAB_SLICE_MIN_M = 1.0
LENGTH_CONVERGED_OBSERVATIONS = 5
TURN_MAX_SPEED_STD_M_S = 0.5  # the hinge is measured in a turn from frames de-skewed with a speed known this well
LENGTH_MAX_STD_M = 0.05  # a trailer's length the points pin no better than this is not measured
SETTLED_SLACK_M = 0.5
STILL_END_FRAMES = 20  # moving frames whose reach must agree before it is taken as the unit's end
STILL_END_SPREAD_M = 0.5  # a shadow's edge moves by metres over these frames; the thinned points' hindmost by 0.3 m
STILL_END_MIN_SPEED_M_S = 0.5
END_SEEN_OFFSET_M = 0.3  # past the hindmost point: a side's points are up to a column's spacing apart
END_SEEN_LENGTH_M = 2.0
END_SEEN_MIN_RAYS = 2
END_SEEN_REACH_M = 1.0
END_TRAVEL_M = 0.3  # a moving trailer's end counts once it has gone this far with it (not stayed put)
END_HISTORY = 50  # frames of ends kept to judge that by
ANYWHERE = (-np.inf, np.inf)  # no bound along a unit
# per unit of an articulated vehicle: the end face nothing of the vehicle hides (a cab covers part of
# its trailer's front face at a hitch angle, the trailer part of the cab's rear)
OPEN_ENDS = (FRONT, REAR)
# both sides seen: one frame's width can be a dock shelter's (a Twizy's 1.75 m trailer, 1.99)
WIDTH_MIN_OBSERVATIONS = 3
BRACKETS_SETTLED = 10  # a unit's widths bracketed from one side (``_width_across_end``) before they count
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
FACE_SEEN_SPAN = 0.6  # an end face is seen when its points span this share of the unit's width
END_BAND_M = 0.4
MAX_BODY_GAP_M = 1.0
WALL_BESIDE_M = (0.35, 0.8)  # a face with points this far out past a trailer's side is wider than it
UNIT_SUPPORT = 0.5
VIEW_TOP_TOLERANCE_RAD = np.radians(0.5)  # about one beam's spacing
# the rear axle that does not slip sideways, from pairs of whole fits along one arc (``_learn_axle``)
AXLE_MIN_TURN_RAD = np.radians(8.0)  # a pair's turn: 3 cm of side noise make 0.3 m of axle
AXLE_MAX_SPAN_S = 3.0  # a pair's time apart
AXLE_STEADY_SHARE = 0.15  # of a pair's turn: the heading halfway off the mean (noise 0.3 deg)
AXLE_MIN_SAMPLES = 15  # pairs before their median counts
AXLE_SAMPLES_KEPT = 100
AXLE_MAX_M = 1.0  # from the catalogue's: tractors' wheelbases and overhangs vary less
RECHECK_MIN_SPEED_M_S = 0.5  # a rigid track is fitted again as every model while it moves this fast
RECHECK_FRAMES = 20  # a moving rigid track is fitted as every model every this many frames (the fits cost ~0.1 s)
VACATED_M = 0.5  # a first point this far from all of a seed's points now: its place was left
VACATED_MIN_SHARE = 0.1
VACATED_SEEN_MIN_RAYS = 3  # through a place a seed's first points left: seen empty, not hidden
SEED_FIRST_POINTS = 200
SEED_RETRY_FRAMES = 20  # a seed that was no vehicle is fitted again after this many frames
SHAPE_CHANGE_M = 0.5  # if its extent or centre moved this much
SHAPE_POINTS_CHANGE = 0.3  # or its point count changed by this share
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


@dataclass(frozen=True)
class _Shape:
    """A seed's cluster as far as a start fit could tell (points, extent, centre) and whether rigid
    vehicles could start: the fits cost ~0.1 s, a container's or a wall's seed is not fitted
    again every few frames while it stays as it was."""

    points: int
    length_m: float
    width_m: float
    center_xy: np.ndarray
    rigid_allowed: bool

    def changed(self, now: _Shape) -> bool:
        return (
            now.rigid_allowed != self.rigid_allowed
            or abs(now.points - self.points) > SHAPE_POINTS_CHANGE * self.points
            or abs(now.length_m - self.length_m) > SHAPE_CHANGE_M
            or abs(now.width_m - self.width_m) > SHAPE_CHANGE_M
            or float(np.hypot(*(now.center_xy - self.center_xy))) > SHAPE_CHANGE_M
        )


@dataclass(eq=False)
class Seed:
    center_xy: np.ndarray
    first_xy: np.ndarray
    frames: int = 1
    seen: bool = True
    # best explained by one rigid box: fitted again once it has moved and the map is ready
    rigid: bool = False
    first_fit: np.ndarray | None = None  # xy of its first rigid fit
    failed: _Shape | None = None  # its shape when it was last fitted and was no vehicle
    failed_frame: int = 0  # its frame count then
    moving: bool = False  # known to move (a tracked vehicle's probe), however short its travel
    travelled: bool = False  # it once moved (``moved``): no background, whether it stands now or not
    rect: Rect | None = None  # this frame's footprint
    first_points: np.ndarray = field(default_factory=lambda: np.empty((0, 3)))  # thinned, when first seen
    points: np.ndarray = field(default_factory=lambda: np.empty((0, 3)))  # this frame's

    def retry_due(self, rigid_allowed: bool) -> bool:
        """A rigid seed that may start as one (it moved, the map is ready) at once; any other after
        a while."""
        return (self.rigid and rigid_allowed) or self.frames - self.failed_frame >= SEED_RETRY_FRAMES

    @property
    def travel_m(self) -> float:
        return float(np.hypot(*(self.center_xy - self.first_xy)))

    def moved(self, travel_m: float, rays: Rays | None = None) -> bool:
        """Known to move, or its centre travelled ``travel_m`` and it left a place behind: at least
        ``VACATED_MIN_SHARE`` of its first points are ``VACATED_M`` from all of its points now and,
        when asked with the frame's ``rays``, their place is seen empty (``_seen_empty``). A standing
        container that a passing truck uncovers grows where it was hidden, and its centre travels as
        far (one started as a Twizy, 9 false vehicle-s on held-out seeds); what it showed first stays
        where it was, or is hidden now: a parked trailer's side, seen by one LiDAR past a MAN driving
        by, lost its first points behind the MAN, showed others, and started as a rigid vehicle."""
        if self.moving:
            return True
        if self.travel_m < travel_m or len(self.first_points) == 0 or len(self.points) == 0:
            return False
        distance, _ = cKDTree(self.points[:, :2]).query(self.first_points[:, :2], distance_upper_bound=VACATED_M)
        vacated = np.isinf(distance)
        if float(np.mean(vacated)) < VACATED_MIN_SHARE:
            return False
        return rays is None or _seen_empty(rays, self.first_points[vacated])


def _seen_empty(rays: Rays, points: np.ndarray) -> bool:
    """At least ``VACATED_SEEN_MIN_RAYS`` rays crossed the box around ``points`` (their footprint's
    rectangle, at least ``VACATED_M`` wide, and heights) and ended ``GAP_SEEN_BEYOND_M`` beyond it:
    no surface is there now (hidden, the rays would have ended before it)."""
    rect = min_area_rect(points[:, :2])
    z = (float(points[:, 2].min()), float(points[:, 2].max()))
    half_width = max(rect.width_m, VACATED_M) / 2
    crossed, _, _ = rays.through(
        tuple(rect.center_xy), rect.yaw_rad, rect.length_m / 2, half_width, z, GAP_SEEN_BEYOND_M
    )
    return crossed >= VACATED_SEEN_MIN_RAYS


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
    along a moving unit, its end does not (seen from one side, a trailer's rear face never shows)."""

    prior: float
    window: int
    values: _Window = field(default_factory=_Window)
    bounds: _Window = field(default_factory=_Window)
    median: float | None = None
    lower_bound: float = -np.inf
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
        in most frames, but 0.45 m in some)."""
        return self.counted or len(self.brackets) >= BRACKETS_SETTLED

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
        """The measured value; at least the lower bound until settled (a face seen outweighs points
        that only reach further)."""
        return self.measured if self.settled else max(self.measured, self.lower_bound)


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
class _Track:
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

    def report(self, measured: bool) -> VehicleReport:
        s = self.filter.state
        n0 = int(np.count_nonzero(self.last.unit == 0)) if measured else 0
        n1 = int(np.count_nonzero(self.last.unit == 1)) if measured else 0
        travel = float(np.hypot(s.x_m - self.first_xy[0], s.y_m - self.first_xy[1]))
        return VehicleReport(self.id, self.model, s, n0, n1, measured, travel, self.dimensions_seen())

    def dimensions_seen(self) -> tuple[tuple[bool, bool, bool], ...]:
        """Per unit, which of its length, width and height its points measured: a rigid one's as it
        started (one face shows one of its length and width) and its width once both sides showed;
        an articulated one's lengths and widths once observed (the cab's length also once the hinge's
        fit pins it within ``HINGE_MAX_STD_M``), its heights never (the catalogue's)."""
        width = [w.observed for w in self.widths]
        if self.trailer_length is None:
            return ((self.rigid_seen[0], self.rigid_seen[1] or width[0], self.rigid_seen[2]),)
        return (
            (self.cab_length.median is not None or self._cab_fitted(), width[0], False),
            (self.trailer_length.median is not None, width[1], False),
        )

    def _cab_fitted(self) -> bool:
        return self.hinge is not None and self.hinge.cab_std_m <= HINGE_MAX_STD_M


class VehicleTracker:
    def __init__(self, params: ArticulatedParams, catalogue: dict[str, VehicleConfig]):
        self.params = params
        self.catalogue = {name: VehicleModel.from_config(name, v) for name, v in catalogue.items()}
        self.tracks: list[_Track] = []
        self.seeds: list[Seed] = []
        self._rays: Rays | None = None  # this frame's
        self._ids = count(1)
        self.rejected = 0  # fits outside a filter's innovation gate

    def forget(self) -> None:
        """Drop every track and seed; ids go on counting."""
        self.tracks, self.seeds = [], []

    # ----------------------------------------------------------------- per frame

    def process(
        self,
        points: np.ndarray,
        ground: Callable[[float, float], float],
        stamp_s: float,
        background_ready: bool = True,
        rays: Rays | None = None,
    ) -> list[VehicleReport]:
        """``points`` (N, 3): the foreground (off the ground and the background) in the yard frame;
        ``ground(x, y)``: the ground's height there. Until ``background_ready`` the foreground holds
        the yard too: only articulated vehicles start then (two hinged units are no wall, container
        or parked trailer); a rigid one needs the learned background to tell it from a container.
        ``rays``: the frame's sensor rays, which show whether a seed's gap was seen empty."""
        self._rays = rays
        priors = [self._prior(t, stamp_s, ground) for t in self.tracks]
        lost = [self._tractor_lost(t) for t in self.tracks]
        owner = self._claim(points, priors, lost)
        owned = [_own_body(points, owner, i, prior) for i, prior in enumerate(priors)]
        reports = []
        free = points[owner < 0]
        for i, (track, (prior, at_wall)) in enumerate(zip(self.tracks, owned)):
            track.at_wall = at_wall
            reports.append(self._step(track, prior, points[owner == i], free, stamp_s, lost[i]))
        self.tracks = [t for t in self.tracks if t.missed < self.params.leave_frames]
        reports = [r for r in reports if any(t.id == r.id for t in self.tracks)]
        reports += self._start(free, ground, stamp_s, rigid_allowed=background_ready)
        return reports

    def _prior(self, track: _Track, stamp_s: float, ground) -> Prior:
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
        self, track: _Track, prior: Prior, points: np.ndarray, free: np.ndarray, stamp_s: float, lost: bool
    ) -> VehicleReport:
        """One frame of a track: fit its claimed ``points``, fuse, learn (``free``: the points no track claimed)."""
        track.ground_z_m = prior.ground_z_m
        m = fit(points, prior, self.params) if len(points) else None
        found = self._reacquired(points, prior, m) if m is not None and lost else None
        measured = False
        if found is None and m is not None:
            m = self._with_seen_end(track, m, points)
            if _trailer_hidden(m):
                m = without_hitch(m, self.params)
            # a fit whose cab explains no point says nothing of where the cab is; one folded through
            # its cab is no pose at all
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
                # a face apart behind the trailer (a dock's door) is no rear end of it, as a wall across it
                track.at_wall = track.at_wall or self._face_behind(track, m)
                self._learn_hinge(track, prior, points, m)
                before = (track.model, track.catalogue_name)
                self._learn(track, m, points)
                self._follow_model(track, prior, m, *before)
                _learn_axle(track, m, stamp_s)
            track = self._recheck_rigid(track, points, free, stamp_s)
        else:
            track.missed += 1
        return track.report(measured)

    def _with_seen_end(self, track: _Track, m: Measurement, points: np.ndarray) -> Measurement:
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

    @staticmethod
    def _better(found: Measurement | None, m: Measurement) -> Measurement | None:
        """``found`` if it explains the frame's points better than its own fit ``m`` by
        ``DIRECTION_COST_RATIO`` (both fitted to all of them; a fit gated out on a straight, its cab's
        few points fitted well, was replaced by one 0.3 m back at three times its cost, and the MAN's
        trailer was learned 0.63 m too long)."""
        return found if found is not None and found.cost < DIRECTION_COST_RATIO * m.cost else None

    def _tractor_lost(self, track: _Track) -> bool:
        """The last fit explained fewer than ``SIDE_MIN_POINTS`` points by the cab and the hitch's
        standard deviation exceeds ``TRACTOR_LOST_SIGMA_DEG``: the cab has not been seen for a while
        (hidden behind its trailer), and the prediction may have run far off."""
        return (
            track.model.articulated
            and track.last is not None
            and np.count_nonzero(track.last.unit == 0) < SIDE_MIN_POINTS
            and track.filter.state.hitch_std_rad > np.radians(TRACTOR_LOST_SIGMA_DEG)
        )

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
            or not _supported(found, model, prior.ground_z_m)
            or not self._unfolded(found)
        ):
            return None
        return fit(points, _at_pose(prior, found), self.params)  # from all the points, as every frame's fit

    # ----------------------------------------------------------------- dimensions

    def _learn(self, track: _Track, m: Measurement, points: np.ndarray) -> None:
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
        if track.cab_length is not None:
            self._learn_cab_length(track, m, local[0])
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
        self, track: _Track, m: Measurement, points: np.ndarray, local: np.ndarray, unit: int, side: int
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
        if not model.articulated or self._rays is None or extent.counted or len(extent.brackets) >= BRACKETS_KEPT:
            return None
        if not _face_seen(m, model, unit, face, track.ground_z_m, self.params.fit_top_band_m):
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
        origin, yaw = _unit_origins(m.vector, model)[unit]
        along, across = np.array([np.cos(yaw), np.sin(yaw)]), np.array([-np.sin(yaw), np.cos(yaw)])
        motion = unit_motions(track.filter.state, model)[unit]
        rays = self._rays.crossings(
            origin + end_m * along, across, box.width_m / 2 + 1.0, heights[1], CORNER_BEYOND_M, motion
        )
        beside = -outward * rays[rays[:, 1] >= heights[0], 0]
        beside = beside[beside > -last - CORNER_BRACKET_M]
        if not len(beside) or beside.min() + last > CORNER_BRACKET_M:
            return None
        width = outward * side_m + (beside.min() - last) / 2
        return width if VEHICLE_WIDTH_M[0] <= width <= VEHICLE_WIDTH_M[1] else None

    def _follow_model(self, track: _Track, prior: Prior, m: Measurement, before: VehicleModel, name: str) -> None:
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

    def _sides_faced(self, m: Measurement, model: VehicleModel) -> list[bool]:
        """Per unit, whether both its sides face a sensor of the frame (each is outside one of its
        side planes; all, without rays). One sensor sees one side of a box at most: what lies where
        the other would be is something else (seen by `l3` alone, a dock shelter's wall beyond the
        Twizy's trailer made it 1.95 m wide, 1.75)."""
        if self._rays is None:
            return [True] * len(model.boxes)
        local = unit_frames(self._rays.origins @ self._rays.to_level.T, m.vector, model)
        return [
            bool(np.any(q[:, 1] > box.width_m / 2) and np.any(q[:, 1] < -box.width_m / 2))
            for q, box in zip(local, model.boxes)
        ]

    def _learn_cab_length(self, track: _Track, m: Measurement, q: np.ndarray) -> None:
        """The cab's length: between the middles of its front and rear faces' points, when both are
        seen (``_face_seen``; its front pins it in the fit; an unknown tractor's cab 0.27 m shorter
        than the MAN's put its box centre 0.13 m off). (Five points on each, before: with the chassis
        behind the cab no longer on its rear face, an unknown tractor's cab had them only after 20 s.)"""
        seen = [
            _face_seen(m, track.model, 0, face, track.ground_z_m, self.params.fit_top_band_m) for face in (FRONT, REAR)
        ]
        if not all(seen):
            return
        (_, front), (_, rear) = (kernels.face_median(q, 0, m.unit, m.face, 0, f, ANYWHERE) for f in (FRONT, REAR))
        track.cab_length.add(front - rear)

    def _learn_hinge(self, track: _Track, prior: Prior, points: np.ndarray, own: Measurement) -> None:
        """The kingpin's offset shows only at a hitch angle (straight, it trades with the trailer's
        front: only where the front reaches ahead of the rear axle shows). Turning, frames' fits
        ``own`` are kept (every second turning frame for the first ten, then every fifth:
        ``HINGE_FRAME_STEPS``; the latest ``HINGE_FRAMES``) and each time one is, the hinge is
        fitted to them all at once (``fit_hinge``). (Fitted free in each frame, the kingpin and the
        front traded along a valley: an unknown 6.5 m trailer's kingpin was learned at -0.42 to
        -0.52 m, -0.70, and its cab's yaw ran 4.5 deg off. The first 40 turning frames of a
        roundabout alone put a 13.6 m trailer's hinge 2-3 cm off, and its hitch 0.2 deg.) Only
        once the filter knows the speed within ``TURN_MAX_SPEED_STD_M_S``: the frames are de-skewed
        with it. Straight, a fit with the hinge free measures the reach, when the cab's rear face
        pins the axle: until the first hinge is fitted."""
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
        front_seen = _face_seen(m, model, 1, FRONT, track.ground_z_m, self.params.fit_top_band_m)
        if front_seen and np.sum((m.unit == 0) & (m.face == REAR)) >= REAR_FACE_MIN_POINTS:
            track.reach.add(m.trailer_front_m - m.kingpin_m)

    def _fit_turn(self, track: _Track, prior: Prior, own: Measurement) -> None:
        """``own`` kept as a frame of the turn, and the hinge fitted to the frames kept (``_learn_hinge``)."""
        track.turn.append(TurnFrame.of(own, prior.ground_z_m, track.model))
        cab = track.cab_length
        cab_prior = None if cab.counted else (cab.prior, CAB_LENGTH_SIGMA_M)
        hinge = fit_hinge(list(track.turn), track.model, self.params, cab_prior=cab_prior)
        if hinge.std_m.max() <= HINGE_MAX_STD_M:
            track.hinge = hinge
            # the next fit starts where this one ended (each frame's pose was the model's then)
            track.turn = deque((replace(f, pose=p) for f, p in zip(track.turn, hinge.poses)), maxlen=HINGE_FRAMES)

    def _retype(self, track: _Track, name: str) -> None:
        """The learned sizes match another catalogue vehicle better than the start's: take its
        figures the points do not measure (tractor front, floors, heights, kingpin (learned again from
        its axle), trailer front; the cab's and the trailer's lengths until measured), keep the
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
        widths = _unit_widths(track.widths)  # from the new type's where not measured
        tractor = replace(prior.tractor, width_m=widths[0], length_m=cab.estimate if cab else prior.tractor.length_m)
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
        self, track: _Track, m: Measurement, q: np.ndarray, width_m: float, points: np.ndarray
    ) -> None:
        """The rear face: the hindmost of the trailer body's points (within its width and height band,
        reached from the front without a gap longer than ``MAX_BODY_GAP_M``, ahead of any face that
        runs on past the trailer's sides: a wall). A length when points across the middle of the
        face are seen there (not only the ends of the two sides), else a lower bound (the trailer
        reaches at least that far back)."""
        trailer = track.model.trailer
        n_band, rows, face_seen, middle = self._rear_face(track, m, q, width_m)
        if n_band < 5:
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
        self, track: _Track, m: Measurement, q: np.ndarray, width_m: float
    ) -> tuple[int, np.ndarray, bool, float]:
        """The trailer body's hindmost points of the fit ``m`` (``q``: in the trailer's frame) and its
        rear face (``kernels.rear_face``: the points in the body's band, the rows kept, whether the
        face is seen and its middle)."""
        trailer = track.model.trailer
        return kernels.rear_face(
            q, m.points[:, 2] - track.ground_z_m, m.unit, m.face, _body_band(trailer),
            trailer.front_m + END_BAND_M, width_m / 2, self.params.fit_inlier_m, WALL_BESIDE_M, MAX_BODY_GAP_M,
            END_BAND_M, trailer.top_m - self.params.fit_top_band_m, FACE_SEEN_SPAN * width_m,
        )  # fmt: skip

    def _face_behind(self, track: _Track, m: Measurement) -> bool:
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
        if not len(sides_x) or _reached_back(float(sides_x.max()), sides_x, FACE_APART_GAP_M) < front:
            return False
        return self._seen_empty_behind(track, m, front, trailer.width_m, back)

    def _fitted_length(self, track: _Track, m: Measurement, points: np.ndarray, seen_m: float) -> float | None:
        """The trailer's length fitted to the claimed ``points`` from the frame's fit ``m`` and the length
        its rear face shows in it (``seen_m``), when they pin it within ``LENGTH_MAX_STD_M``. (The length
        the frame's fit shows is the model's own whenever the cab's place along the vehicle is pinned
        weakly: a length learned 0.2 m long from a start frame's points, not de-skewed, stayed so, and
        the fits put the tractor 0.2 m off.)"""
        if seen_m < TRAILER_LENGTH_RANGE_M[0]:  # its front face, seen from ahead
            return None
        free = fit(points, _free_length_at(m, track.model, seen_m, track.ground_z_m), self.params)
        if free is None or free.trailer_length_std_m > LENGTH_MAX_STD_M:
            return None
        return free.trailer_length_m

    def _end_went_along(self, track: _Track, m: Measurement, kind: str, end_m: float) -> bool:
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

    def _side_end(self, track: _Track, m: Measurement, points: np.ndarray, side: np.ndarray, width_m: float) -> float:
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
            & _body_heights(z_rel, trailer)
            & (q[:, 0] < end)
        )
        return _reached_back(end, q[on_side, 0])

    def _seen_end(
        self, track: _Track, m: Measurement, points: np.ndarray, sides: list[np.ndarray], width_m: float
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
        self, track: _Track, m: Measurement, end_m: float, width_m: float, back_to_m: float = -np.inf
    ) -> bool:
        """Whether at least ``END_SEEN_MIN_RAYS`` rays crossed the trailer's body behind ``end_m`` (its
        frame; a slab ``END_SEEN_LENGTH_M`` long from ``END_SEEN_OFFSET_M`` behind it, or shorter,
        back to ``back_to_m``; ``SOLID_INSET_M`` inside its sides, floor and roof), one of them within
        ``END_SEEN_REACH_M`` of the slab's front, and none ended in it: the body ends there. A
        shadow's edge is no end: the trailer hidden behind it stops the rays that would cross (those
        passing further back show only that it ends before them); a return in the slab is a surface
        there (its own rear face, a dock)."""
        if self._rays is None:
            return False
        model, inset = track.model, SOLID_INSET_M
        front = end_m - END_SEEN_OFFSET_M
        length = min(END_SEEN_LENGTH_M, front - back_to_m)
        yaw = m.yaw_rad + m.hitch_rad
        centre = _on_trailer_axis(m, model, front - length / 2)
        floor, top = track.ground_z_m + model.trailer.floor_m, track.ground_z_m + model.trailer.top_m
        crossed, ended, reach = self._rays.through(
            tuple(centre), yaw, length / 2, width_m / 2 - inset, (floor + inset, top - inset), GAP_SEEN_BEYOND_M
        )
        return crossed >= END_SEEN_MIN_RAYS and ended == 0 and reach >= length / 2 - END_SEEN_REACH_M

    def _trailer_axle(self, track: _Track) -> float:
        """L2 scaled with the trailer's length behind the kingpin (the catalogue's proportion)."""
        prior = self.catalogue.get(track.catalogue_name)
        if prior is None or prior.trailer is None or track.model.trailer is None:
            return track.model.trailer_axle_m
        behind = prior.trailer.length_m - prior.trailer.front_m
        return prior.trailer_axle_m * (track.model.trailer.length_m - track.model.trailer.front_m) / behind

    def _type_name(self, track: _Track) -> str:
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

    # ----------------------------------------------------------------- start

    def _start(self, points: np.ndarray, ground, stamp_s: float, rigid_allowed: bool) -> list[VehicleReport]:
        clusters = self._seed_clusters(points, ground)
        for seed in self.seeds:
            seed.seen = False
        ready = []
        for cluster, rect in clusters:
            center = rect.center_xy
            seed = min(self.seeds, key=lambda s: float(np.hypot(*(s.center_xy - center))), default=None)
            if (
                seed is not None
                and not seed.seen
                and np.hypot(*(seed.center_xy - center)) <= self.params.start_max_step_m
            ):
                seed.center_xy, seed.frames, seed.seen = center, seed.frames + 1, True
            else:
                seed = Seed(center, center, first_points=thin(cluster, SEED_FIRST_POINTS))
                self.seeds.append(seed)
            seed.points, seed.rect = cluster, rect
            seed.travelled = seed.travelled or seed.moved(self.params.start_travel_m)
            shape = _Shape(len(cluster), rect.length_m, rect.width_m, center, rigid_allowed)
            if (
                seed.frames >= self.params.start_frames
                and self._may_fit(seed)
                and (seed.failed is None or (seed.retry_due(rigid_allowed) and seed.failed.changed(shape)))
            ):
                ready.append((seed, cluster, rect, shape))
        self.seeds = [s for s in self.seeds if s.seen]
        reports = []
        for seed, cluster, rect, shape in ready:
            center = seed.center_xy
            track = self._new_track(cluster, rect, seed, float(ground(center[0], center[1])), stamp_s, rigid_allowed)
            if track is None:  # no vehicle (yet): fitted again after a while if its shape changed
                seed.failed, seed.failed_frame = shape, seed.frames
                if self._one_sweep():
                    reports += self._start_apart(cluster, ground, stamp_s, rigid_allowed)
                continue
            self.seeds.remove(seed)
            reports.append(self._started(track))
        return reports

    def _started(self, track: _Track) -> VehicleReport:
        """``track`` tracked from this frame on: its first report."""
        self.tracks.append(track)
        return track.report(True)

    def _start_apart(self, cluster: np.ndarray, ground, stamp_s: float, rigid_allowed: bool) -> list[VehicleReport]:
        """The vehicles among a seed that is none, taken apart at ``APART_VOXEL_M`` (one sweep: no
        frame to come in which vehicles side by side drive apart). Its voxels bridge a cab's gap, and
        a street's lanes too: a bus 1.6 m beside a car was one seed 18.7 m by 5.0 m in an Argoverse 2
        sweep, which no model explains."""
        p = self.params
        reports = []
        for rows in seed_group_rows(cluster, ground, APART_VOXEL_M, p.start_min_height_m, p.fit_min_points, 0.0, 0.0):
            if len(rows) == len(cluster):
                return []  # one piece: the seed itself
            part = cluster[rows]
            rect = min_area_rect(part[:, :2])
            if not self._seen_wide(rect):
                continue  # one face split off: a crown beside another, seen as an end, started as one
            seed = Seed(
                rect.center_xy, rect.center_xy, first_points=thin(part, SEED_FIRST_POINTS), points=part, rect=rect
            )
            ground_z_m = float(ground(*rect.center_xy))
            track = self._new_track(part, rect, seed, ground_z_m, stamp_s, rigid_allowed)
            if track is not None:
                reports.append(self._started(track))
        return reports

    def moving_seeds(self) -> list[Rect]:
        """The footprints of the seeds that moved (``Seed.moved``), standing now or not: a trailer that
        drove off while the background was learned, its tractor out of reach, had become background
        along its sides (they stay in place as it moves along them) and was cut out of its points
        for 5 s once it stopped and reversed into a dock."""
        return [s.rect for s in self.seeds if s.travelled and s.rect is not None]

    def _fit_moved(self, seed: Seed, m: Measurement) -> bool:
        """A rigid seed's fitted pose moved ``start_travel_m`` since its first rigid fit (its points'
        centre alone jumps when a passing vehicle hides part of a container)."""
        if not seed.rigid:
            return True
        if seed.first_fit is None:
            seed.first_fit = m.vector[:2].copy()
        return float(np.hypot(*(m.vector[:2] - seed.first_fit))) >= self.params.start_travel_m

    def _may_fit(self, seed: Seed) -> bool:
        """A seed that fitted one rigid box best is fitted again once it moved, before the map is
        ready too: driving straight, a tractor and trailer seen from one side fit one box, and their
        hinge shows as an open gap only in motion (``_two_units``); ``_candidate`` starts it then
        only as articulated."""
        return not seed.rigid or self._one_sweep() or seed.moved(self.params.start_travel_m)

    def _one_sweep(self) -> bool:
        """No frame to come (``start_travel_m`` 0, as ``detect`` sets it): no motion to wait for, and
        no more of a vehicle to wait to see."""
        return self.params.start_travel_m <= 0.0

    def _may_start(self, seed: Seed, rigid_allowed: bool) -> bool:
        """A rigid seed once the background is learned and it moved."""
        return self._may_fit(seed) and (rigid_allowed or not seed.rigid)

    def _seed_clusters(self, points: np.ndarray, ground) -> list[tuple[np.ndarray, Rect]]:
        """Connected components tall enough to be a vehicle, those closer than ``start_join_m`` joined
        (a cab and its trailer are apart by up to about 1.5 m), of a vehicle's length and at least
        ``start_min_width_m`` wide (a wall, or a vehicle seen from one side only, is a plane)."""
        p = self.params
        points = _in_grid_precision(_below_tall_structures(points, ground, p.start_voxel_m))
        out = []
        for rows in seed_group_rows(
            points,
            ground,
            p.start_voxel_m,
            p.start_min_height_m,
            p.fit_min_points,
            p.start_join_m,
            min(p.start_min_length_m, END_FACE_WIDTH_M[0]),
        ):
            cluster = points[rows]
            rect = min_area_rect(cluster[:, :2])
            if self._seen_wide(rect) or one_face_sized(rect, p):
                out.append((cluster, rect))
        return out

    def _seen_wide(self, rect: Rect) -> bool:
        """A footprint of a vehicle's length and at least ``start_min_width_m`` wide."""
        p = self.params
        return p.start_min_length_m <= rect.length_m <= p.start_max_length_m and rect.width_m >= p.start_min_width_m

    def _new_track(
        self, cluster: np.ndarray, rect: Rect, seed: Seed, ground_z_m: float, stamp_s: float, rigid_allowed: bool
    ) -> _Track | None:
        top_seen = not self._at_view_top(cluster)
        chosen = self._candidate(cluster, rect, seed, ground_z_m, rigid_allowed, top_seen)
        if chosen is None:
            return None
        model, m = chosen
        track = self._track(next(self._ids), model, m, ground_z_m, stamp_s, 0.0, cluster)
        track.rigid_seen = rigid_seen(rect, self.params, top_seen)
        self._learn_at_start(track, cluster, m)
        return track

    def _learn_at_start(self, track: _Track, cluster: np.ndarray, m: Measurement) -> None:
        """The start frame's sizes learned before the first report, the pose fitted again with them
        if they changed: an unknown 10.5 m trailer whose rear face the start saw was reported for a
        frame with the 13.68 m of the model it started as, its centre 1.5 m back. Not when it was
        renamed: ``_retype`` moved its reference point with the model (fitted again from the start
        fit's pose too, a MAN seen by one LiDAR that started as a Volvo had its trailer measured
        up to 0.8 m long from then on: its success 97 -> 1 %)."""
        if not self.params.learn_dimensions:
            return
        before, name = track.model, track.catalogue_name
        self._learn(track, m, cluster)
        if track.model == before or track.catalogue_name != name:
            return
        prior = Prior(m.x_m, m.y_m, m.yaw_rad, m.hitch_rad or 0.0, track.model, track.ground_z_m)
        again = fit(cluster, prior, self.params, START_ITERATIONS)
        if again is not None:
            track.filter.restart(again.vector, _start_covariance(again))
            track.last = again

    def _candidate(
        self, cluster: np.ndarray, rect: Rect, seed: Seed, ground_z_m: float, rigid_allowed: bool, top_seen: bool
    ) -> tuple[VehicleModel, Measurement] | None:
        """The best-explaining model and its fit, if it passes the start's checks (``rect``: the
        cluster's minimum-area rectangle; ``top_seen``: no point at a sensor's view top). A seed
        longer than any rigid vehicle is articulated: the catalogue models are tried cheapest first
        (an unknown tractor's cab puts a model's gap on the real trailer's front), but while one
        that costs alike or less only lacks points (not supported, nor ``_refuted``), none the
        other way round starts unless its own gap shows (``_waits_for``): seen by one LiDAR ahead
        of its cab, a MAN's right fit waited for its trailer's side to show, and a Volvo the wrong
        way round, at 16 times its cost, started instead."""
        if one_face_sized(rect, self.params):
            return self._one_face(cluster, rect, seed, ground_z_m, rigid_allowed, top_seen)
        may_be_rigid = rect.length_m <= RIGID_MAX_LENGTH_M
        if rect.length_m < self.params.rigid_min_length_m and not self._tall_enough(cluster, ground_z_m, top_seen):
            return None  # a car or a person: no fit needed (the start's fits cost 40-80 ms)
        hypotheses = self._hypotheses(cluster, rect, ground_z_m, may_be_rigid, top_seen)
        if not hypotheses:
            return None
        choices = self._articulated_choices(hypotheses)
        if may_be_rigid:
            two = self._two_units(hypotheses, cluster, seed, ground_z_m, top_seen)
            choices = [two] if two is not None else self._choose(hypotheses, seed, ground_z_m, top_seen)
            choices += self._rigid_after(choices, hypotheses)
        bent = _bent_flags([m for _, m in choices])
        supported = [_supported(m, model, ground_z_m, top_seen) for model, m in choices]
        waiting = [  # fits that only lack points yet: more of the vehicle may show in the frames to come
            m
            for (model, m), b, s in zip(choices, bent, supported)
            if not (b or s or self._refuted(cluster, m, model, ground_z_m))
        ]
        for (model, m), b, s in zip(choices, bent, supported):
            if not self._allowed_to_start(seed, model, m, rigid_allowed):
                return None
            if b or not s or (_waits_for(m, waiting) and not self._gap_shown(cluster, m, model, ground_z_m)):
                continue
            filled = _gap_filled(cluster, m, model, ground_z_m)
            if (
                self._explains(m, model)
                and not filled
                # without rays a hole and a gap look alike: the points alone decide
                and (self._rays is None or self._hinge_shown(seed, m, model, ground_z_m))
                and not self._seen_through(m, self._as_far_as_seen(m, model, cluster, ground_z_m), ground_z_m)
                and self._stands_on_wheels(cluster, m, model, ground_z_m, top_seen)
                and not self._cab_grounded(cluster, m, model, ground_z_m)
                and self._ends_free(m, model, ground_z_m)
            ):
                return model, m
        return None

    def _ends_free(self, m: Measurement, model: VehicleModel, ground_z_m: float) -> bool:
        """Whether nothing stands against a rigid fit's ends: at each end whose face does not show
        (``_face_seen``), no ray ended in the slab ``END_SLAB_M`` beyond it (within the box's width
        and height, ``SOLID_INSET_M`` inside) unless rays also crossed it. A body going on there, or
        a unit hinged to it, makes the box a part of a longer vehicle: seen by `l3` and `l4`, a
        reversing MAN's trailer alone, its cab hidden at -40 deg in that slab, started as a 13.85 m
        rigid box for 6 s. An end the view does not reach (no ray in the slab: a truck seen from its
        side and end hides its far end) is not refuted in one sweep; with frames to come the start
        waits for rays to cross the slab's upper half (rays pass under a semitrailer's floor, its
        body going on above them): a MAN seen from ahead, its trailer's side past its cab, started
        as an 11.2 m rigid box for 4 s (paper `l3`). Articulated fits and frames without rays: True."""
        if self._rays is None or model.articulated:
            return True
        box = model.tractor
        axis = np.array([np.cos(m.yaw_rad), np.sin(m.yaw_rad)])
        centre, _ = model.box_centers(m.x_m, m.y_m, m.yaw_rad, 0.0)
        floor, top = ground_z_m + box.floor_m, ground_z_m + box.top_m - SOLID_INSET_M
        for face, sign in ((FRONT, 1.0), (REAR, -1.0)):
            if _face_seen(m, model, 0, face, ground_z_m, self.params.fit_top_band_m):
                continue
            beyond = tuple(centre + sign * (box.length_m + END_SLAB_M) / 2 * axis)
            slab = (beyond, m.yaw_rad, END_SLAB_M / 2, box.width_m / 2 - SOLID_INSET_M)
            through, ended, _ = self._rays.through(*slab, (floor + SOLID_INSET_M, top), GAP_SEEN_BEYOND_M)
            if ended and through < GAP_SEEN_MIN_RAYS:
                return False
            if not self._one_sweep():
                above, _, _ = self._rays.through(*slab, ((floor + top) / 2, top), GAP_SEEN_BEYOND_M)
                if above < GAP_SEEN_MIN_RAYS:
                    return False
        return True

    def _refuted(self, cluster: np.ndarray, m: Measurement, model: VehicleModel, ground_z_m: float) -> bool:
        """Whether the points rule a start's fit out, however many more show: its gap filled or a
        unit seen through."""
        return _gap_filled(cluster, m, model, ground_z_m) or self._seen_through(
            m, self._as_far_as_seen(m, model, cluster, ground_z_m), ground_z_m
        )

    def _as_far_as_seen(
        self, m: Measurement, model: VehicleModel, cluster: np.ndarray, ground_z_m: float
    ) -> VehicleModel:
        """``model`` with its trailer as long as the start's points reach (``_trailer_reach``) when the
        fit ``m`` saw no rear face: where it ends is not known (the track starts no longer either,
        ``_start_length``), and rays crossing the catalogue's longer box beyond do not refute the
        body: seen from one side, an unknown 10.5 m trailer's right fit as the MAN (13.68 m) was
        seen through there, and the start waited 11 s (held-out +1500 `l3`)."""
        if model.trailer is None or m.rear_points >= REAR_FACE_MIN_POINTS:
            return model
        return _with_trailer_length(model, self._trailer_reach(m, model, cluster, ground_z_m))

    def _gap_shown(self, cluster: np.ndarray, m: Measurement, model: VehicleModel, ground_z_m: float) -> bool:
        """Whether the points show the fit's gap open (``_gap_open``) or rays crossed it
        (``_gap_seen_empty``): the hinge is where the fit puts it."""
        return model.articulated and (
            _gap_open(cluster, m, model, ground_z_m) or self._gap_seen_empty(m, model, ground_z_m)
        )

    def _one_face(
        self, cluster: np.ndarray, rect: Rect, seed: Seed, ground_z_m: float, rigid_allowed: bool, top_seen: bool
    ) -> tuple[VehicleModel, Measurement] | None:
        """A seed that is one upright face (no roof, one side or one end: a vehicle-mounted sensor sees
        a truck so) is a rigid vehicle when the face is a vehicle's (``faces.vehicle_face``) and stands on
        wheels: rays cross under it (``faces.passes_under``; a wall stands on the ground). Its body lies behind
        the face, away from the sensor: as long as the shortest rigid vehicle behind an end, as
        wide as ``ONE_SIDE_WIDTH_M`` behind a side, until more of it shows. Never without rays. With
        frames to come an end alone waits for a side to show: a semitrailer's rear face is one too,
        its tractor hidden ahead of it (seen from behind by paper `l2`, a Volvo pulling away started
        as a 5.5 m rigid box for 2 s)."""
        if end_face(rect) and not self._one_sweep():
            return None
        if self._rays is None or not (
            vehicle_face(cluster, rect, ground_z_m) and self._tall_enough(cluster, ground_z_m, top_seen)
        ):
            return None
        face, along, away = face_line(self._rays, cluster, rect)
        if not passes_under(self._rays, cluster, face, along, rect.length_m / 2, ground_z_m):
            return None
        model, prior = self._behind_face(cluster, rect, face, along, away, seed, ground_z_m)
        m = fit(thin(cluster, self.params.fit_max_points), prior, self.params, START_ITERATIONS, START_SCALE_M)
        if m is None:
            return None
        if not self._allowed_to_start(seed, model, m, rigid_allowed):
            return None
        if not self._explains(m, model) or self._seen_through(m, model, ground_z_m):
            return None
        if not (end_face(rect) or low_at_both_ends(cluster, m, model.tractor, ground_z_m)):
            return None  # a side standing on legs at one end: a semitrailer's
        if not self._one_sweep() and not seed.moved(self.params.start_travel_m, self._rays):
            return None  # a face's points come and go as things pass before it: where it was must be seen empty
        return model, m

    def _allowed_to_start(self, seed: Seed, model: VehicleModel, m: Measurement, rigid_allowed: bool) -> bool:
        """Whether the seed, now fitted ``m`` with ``model``, may start: a rigid one once it (and its
        first rigid fit, remembered here) moved and the map is ready (``_may_start``)."""
        seed.rigid = not model.articulated
        fit_moved = self._fit_moved(seed, m)
        return fit_moved and self._may_start(seed, rigid_allowed)

    def _explains(self, m: Measurement, model: VehicleModel) -> bool:
        """The fit explains ``start_min_explained`` of its points (``hinged_fit.explained_share``)."""
        return explained_share(m, model) >= self.params.start_min_explained

    def _stands_on_wheels(
        self, cluster: np.ndarray, m: Measurement, model: VehicleModel, ground_z_m: float, top_seen: bool
    ) -> bool:
        """Whether a start's fit stands on wheels where that is asked (``faces.unit_raised``): a rigid box
        unless its roof shows (``faces.roof_shown``: one sweep of a 13 m wall with a short one across it
        is a box of a coach's size, its top two lines; from a pole 7.5 m up, rays pass under a van
        in a few columns only; in a yard a rigid start also needs its seed to have moved), an articulated one's trailer when
        the sensors' view ends below its top and its points do not reach the heights ``_supported``
        asks anyway (the heights that tell a trailer from a wall are not seen then: a round crown
        beside a wall, seen with beams reaching 2 deg up, had started as a Volvo). Never without
        rays."""
        if self._rays is None:
            return True
        if not model.articulated:
            if np.ptp(cluster[:, 2]) < UNIT_SUPPORT * model.tractor.height_m:
                return False  # a plate of points at one height (a canopy, a gantry's deck) is no body
            raised = roof_shown(cluster, m, model, ground_z_m) or unit_raised(
                self._rays, cluster, m, model, 0, ground_z_m
            )
            body = low_at_both_ends(cluster, m, model.tractor, ground_z_m)
            return raised and body and not faces_grounded(self._rays, cluster, m, model, 0, ground_z_m)
        heights_shown = top_seen or _supported(m, model, ground_z_m)
        return heights_shown or unit_raised(self._rays, cluster, m, model, 1, ground_z_m)

    def _cab_grounded(self, cluster: np.ndarray, m: Measurement, model: VehicleModel, ground_z_m: float) -> bool:
        """Whether an articulated fit's cab has a face reaching down to the ground
        (``faces.unit_grounded``): a box set down before a parked trailer's front, a 10-ft
        container, had started as its tractor in one sweep. Never without rays."""
        return (
            model.articulated and self._rays is not None and unit_grounded(self._rays, cluster, m, model, 0, ground_z_m)
        )

    def _behind_face(
        self,
        cluster: np.ndarray,
        rect: Rect,
        face: np.ndarray,
        along: np.ndarray,
        away: np.ndarray,
        seed: Seed,
        ground_z_m: float,
    ) -> tuple[VehicleModel, Prior]:
        """The rigid model of a one-face seed and its placement behind the face (``faces.face_line``),
        along its travel if it moved (else facing the sensor from its end; along the face's line
        from its side)."""
        floor = face_foot(cluster, face, along, ground_z_m)
        spread = (cluster[:, :2] - face) @ along
        face = face + along * float(np.ptp(spread) / 2 + spread.min())  # the face's middle
        height = float(cluster[:, 2].max() - ground_z_m) - floor
        if end_face(rect):
            model = VehicleModel.rigid("rigid", self.params.rigid_min_length_m, rect.length_m, height, floor)
            axis, behind_m = -away, model.tractor.length_m / 2
        else:
            model = VehicleModel.rigid("rigid", rect.length_m, ONE_SIDE_WIDTH_M, height, floor)
            axis, behind_m = along, ONE_SIDE_WIDTH_M / 2
        travel = seed.center_xy - seed.first_xy
        if np.hypot(*travel) > 0.3 and axis @ travel < 0:
            axis = -axis
        centre = face + away * behind_m
        return model, Prior(*centre, float(np.arctan2(axis[1], axis[0])), 0.0, model, ground_z_m)

    def _seen_through(self, m: Measurement, model: VehicleModel, ground_z_m: float) -> bool:
        """Whether some unit of the fit is no solid body: more than ``SEEN_THROUGH_RATIO`` as many
        rays crossed its box (``SOLID_INSET_M`` inside its faces) and ended beyond as ended on it
        (within ``SOLID_INSET_M`` of its box). A parked trailer with a pole beside it had started
        as a tractor bent at 34 degrees: the rays crossed the "cab" between pole and trailer."""
        if self._rays is None:
            return False
        inset = SOLID_INSET_M
        hitch = m.hitch_rad or 0.0
        for centre, yaw, box in zip(
            model.box_centers(m.x_m, m.y_m, m.yaw_rad, hitch), (m.yaw_rad, m.yaw_rad + hitch), model.boxes
        ):
            centre = tuple(centre)
            half_l, half_w, floor, top = (
                box.length_m / 2,
                box.width_m / 2,
                ground_z_m + box.floor_m,
                ground_z_m + box.top_m,
            )
            through, _, _ = self._rays.through(
                centre, yaw, half_l - inset, half_w - inset, (floor + inset, top - inset), GAP_SEEN_BEYOND_M
            )
            _, ended, _ = self._rays.through(
                centre, yaw, half_l + inset, half_w + inset, (floor - inset, top + inset), GAP_SEEN_BEYOND_M
            )
            if through > SEEN_THROUGH_RATIO * ended:
                return True
        return False

    def _hinge_shown(self, seed: Seed, m: Measurement, model: VehicleModel, ground_z_m: float) -> bool:
        """Whether a straight articulated fit is two units: it moves (its seed moved
        ``start_travel_m``, or it is a tracked vehicle's probe), or its gap was seen empty, or, in one
        sweep, into (``_gap_looked_into``); a standing straight one may be a parked trailer with a
        hole in its side (a pole's shadow). A rigid fit, or a bent one, needs neither. (Tried: the
        motion of the fit's middle between cab front and trailer rear instead of the seed's centre;
        a first fit of the seed merged with a dock wall put it elsewhere, and a 16 m vehicle
        started 20 frames later on held-out seeds.)"""
        if model.trailer is None or abs(m.hitch_rad) > GAP_TEST_MAX_HITCH_RAD:
            return True
        return (
            seed.moved(self.params.start_travel_m)
            or self._gap_seen_empty(m, model, ground_z_m)
            or (self._one_sweep() and _gap_looked_into(seed.points, m, model, ground_z_m))
        )

    def _tall_enough(self, cluster: np.ndarray, ground_z_m: float, top_seen: bool) -> bool:
        """As tall as some catalogue vehicle's higher unit, less ``LOW_SEED_SLACK_M`` (a Twizy is
        car-sized, but its box trailer stands 2.85 m high), or its top not seen (``_at_view_top``)."""
        tops = [max(box.top_m for box in model.boxes) for model in self.catalogue.values() if model.articulated]
        return not top_seen or not tops or float(cluster[:, 2].max()) - ground_z_m >= min(tops) - LOW_SEED_SLACK_M

    def _at_view_top(self, points: np.ndarray) -> bool:
        """Whether some of ``points`` lie at the top of a sensor's view (within ``VIEW_TOP_TOLERANCE_RAD``
        of the elevation of its sweep's highest return): what stands higher there is not seen, and
        their height is a lower bound. Never without rays."""
        return self._rays is not None and self._rays.at_view_top(points, VIEW_TOP_TOLERANCE_RAD)

    def _two_units(
        self, hypotheses, cluster: np.ndarray, seed: Seed, ground_z_m: float, top_seen: bool
    ) -> tuple[VehicleModel, Measurement] | None:
        """The cheapest supported articulated fit (either direction) if it shows an open gap between
        cab and trailer and its hinge is shown (``_hinge_shown``: moving, or the gap seen empty):
        driving straight and seen from one side, a tractor and an unknown trailer fit one box of
        their measured size better than any catalogue model, and started rigid; the model the wrong
        way round, its cab on a few trailer points, may cost less."""
        fits = sorted((h for h in hypotheses if h[0].articulated and self._unfolded(h[2])), key=lambda h: h[2].cost)
        model, _, m = next((h for h in fits if _supported(h[2], h[0], ground_z_m, top_seen)), (None, None, None))
        if model is None or not _gap_open(cluster, m, model, ground_z_m):
            return None
        return (model, m) if self._hinge_shown(seed, m, model, ground_z_m) else None

    def _gap_seen_empty(self, m: Measurement, model: VehicleModel, ground_z_m: float) -> bool:
        """At least ``GAP_SEEN_MIN_RAYS`` rays crossed the middle of the model's gap (``_gap_counts``'
        box, across between the sides the fit's points show next to it, ``_sides_at_gap``, less
        ``GAP_SIDE_INSET_M`` each) and ended
        ``GAP_SEEN_BEYOND_M`` beyond it: the gap is empty, not hidden (a standing seed's hole may be a
        pole's shadow on a trailer's side)."""
        if self._rays is None:
            return False
        start, length = _gap_middle(model)
        sides = _sides_at_gap(m, model, start, length)
        if sides is None:
            return False
        half_width = (sides[1] - sides[0]) / 2 - GAP_SIDE_INSET_M
        if half_width <= 0.0:
            return False
        centre = np.array([m.x_m, m.y_m]) + rotate_xy((start + length / 2, (sides[0] + sides[1]) / 2), m.yaw_rad)
        low, high = _gap_band(model)
        seen, _, _ = self._rays.through(
            tuple(centre), m.yaw_rad, length / 2, half_width, (ground_z_m + low, ground_z_m + high), GAP_SEEN_BEYOND_M
        )
        return seen >= GAP_SEEN_MIN_RAYS

    def _articulated_choices(self, hypotheses) -> list[tuple[VehicleModel, Measurement]]:
        """Each catalogue model's cheapest fit, cheapest first, none folded beyond the start limit."""
        best: dict[str, tuple[VehicleModel, Measurement]] = {}
        for model, _, m in hypotheses:
            if model.articulated and (model.name not in best or m.cost < best[model.name][1].cost):
                best[model.name] = (model, m)
        return sorted((c for c in best.values() if self._unfolded(c[1])), key=lambda c: c[1].cost)

    def _unfolded(self, m: Measurement) -> bool:
        return abs(m.hitch_rad) <= np.radians(self.params.start_max_hitch_deg)

    def _track(
        self,
        track_id: int,
        model: VehicleModel,
        m: Measurement,
        ground_z_m: float,
        stamp_s: float,
        speed_m_s: float,
        points: np.ndarray | None = None,
    ) -> _Track:
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
        window = self.params.dimension_window
        widths = [_Extent(box.width_m, window, min_values=WIDTH_MIN_OBSERVATIONS) for box in model.boxes]
        cab = _Extent(model.tractor.length_m, window) if model.articulated else None
        length = reach = None
        hinge_prior = (0.0, 0.0)
        if model.trailer is not None:
            length = self._start_length(model, m, m.points if points is None else points, ground_z_m)
            if length.prior != model.trailer.length_m:  # the catalogue's, longer than the points reach
                model = _with_trailer_length(model, length.prior)
            hinge_prior, reach = _hinge_priors(model, window)
        return _Track(
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
        )

    def _start_length(self, model: VehicleModel, m: Measurement, points: np.ndarray, ground_z_m: float) -> _Extent:
        """The trailer's length as the start fit ``m`` of ``points`` shows it (``model`` carries it):
        measured where it saw the rear face; else the trailer reaches at least as far as its points
        do (``_trailer_reach``), and the catalogue's longer length stands until the end shows (a MAN
        entering the region, its rear beyond it, was named ``unknown`` with the 11.1 m its points
        reached, for 8 s)."""
        window, length_m = self.params.dimension_window, model.trailer.length_m
        seen_end = m.rear_points >= REAR_FACE_MIN_POINTS  # the start fit saw where the trailer ends
        listed = self.catalogue.get(model.name)
        if not seen_end and m.trailer_length_m is not None and listed is not None:
            reach = self._trailer_reach(m, model, points, ground_z_m)
            length = _Extent(max(reach, listed.trailer.length_m), window)
            length.add_bound(reach)
            return length
        length = _Extent(length_m, window)
        if seen_end:
            length.add(length_m)
        return length

    def _trailer_reach(self, m: Measurement, model: VehicleModel, points: np.ndarray, ground_z_m: float) -> float:
        """How far behind the trailer's front the start's ``points`` on its body (within its width
        and height band, reached from the front without a gap longer than ``MAX_BODY_GAP_M``) reach
        at the fit ``m``, at most the fitted length: with no rear face, the fitted length is held by
        nothing beyond them (a standing MAN's start kept 14.81 m, its points reaching 13.6, the true
        13.68, and it was named ``unknown`` for 2.6 s). All the start's points, not the fit's thinned
        sample: its hindmost lies up to 1.2 m short (``_side_end``)."""
        trailer = model.trailer
        q = trailer_frame(points, m.vector, model)
        on_body = (
            (np.abs(q[:, 1]) <= trailer.width_m / 2 + self.params.fit_inlier_m)
            & _body_heights(points[:, 2] - ground_z_m, trailer)
            & (q[:, 0] <= trailer.front_m)
        )
        if not on_body.any():
            return trailer.length_m
        hindmost = _reached_back(float(q[on_body, 0].max()), q[on_body, 0])
        return float(min(trailer.front_m - hindmost, trailer.length_m))

    def _recheck_rigid(self, track: _Track, points: np.ndarray, free: np.ndarray, stamp_s: float) -> _Track:
        """A rigid track is fitted again as every model every ``RECHECK_FRAMES`` frames while it
        moves: a tractor and trailer driving straight can look like one long box, a hinge shows
        later (it becomes articulated, with its id). Fitted with the unclaimed points connected to
        its own (``_with_connected``): a MAN that came into one LiDAR's view cab first started as a
        rigid box 7.6 m long, which claimed no more of it, and its trailer's side stayed outside."""
        track.frames += 1
        s = track.filter.state
        if track.model.articulated or track.frames % RECHECK_FRAMES or abs(s.speed_m_s) < RECHECK_MIN_SPEED_M_S:
            return track
        points = self._with_connected(points, free, track.ground_z_m)
        heading = np.array([np.cos(s.yaw_rad), np.sin(s.yaw_rad)]) * np.sign(s.speed_m_s)
        here = np.array([s.x_m, s.y_m])
        probe = Seed(here, here - heading, moving=True)  # the direction of travel, for a tie between the two ends
        rect = min_area_rect(points[:, :2])
        top_seen = not self._at_view_top(points)
        chosen = self._candidate(points, rect, probe, track.ground_z_m, False, top_seen)
        if chosen is None:
            return track
        model, m = chosen
        new = self._track(track.id, model, m, track.ground_z_m, stamp_s, s.speed_m_s, points)
        new.first_xy, new.rigid_seen = track.first_xy, rigid_seen(rect, self.params, top_seen)
        self._learn_at_start(new, points, m)
        self.tracks[self.tracks.index(track)] = new
        return new

    def _with_connected(self, points: np.ndarray, free: np.ndarray, ground_z_m: float) -> np.ndarray:
        """``points`` and the ``free`` points in the start's clusters (``seed_group_rows``) that hold some of them."""
        if len(free) == 0 or len(points) == 0:
            return points
        p = self.params
        both = _in_grid_precision(np.vstack([points, free]))
        groups = seed_group_rows(
            both, lambda x, y: ground_z_m, p.start_voxel_m, p.start_min_height_m, 1, p.start_join_m, 0.0
        )
        holding = [rows for rows in groups if (rows < len(points)).any()]  # rows below len(points) are its own
        return both[np.concatenate(holding)] if holding else points

    def _hypotheses(
        self, cluster: np.ndarray, rect: Rect, ground_z_m: float, may_be_rigid: bool, top_seen: bool
    ) -> list[tuple[VehicleModel, float, Measurement]]:
        """(model, direction sign, fit) of every catalogue vehicle in both directions (best start hitch
        each) and, if ``may_be_rigid``, of one rigid box of the cluster's measured size, placed on
        its footprint and, in one sweep, on the footprint its points hug when that differs
        (``faces.l_shaped``). All are fitted to the same thinned points (their costs are compared)."""
        sample = thin(cluster, self.params.fit_max_points)
        out = []
        # with frames to come, an L-shaped hull is more often a vehicle partly hidden than seen from
        # a car: a reversing trailer's visible end, fitted a rigid box on its L, started as one
        # (25 false vehicle-s on held-out paper +500); it waits for more of it to show
        footprints = [rect, *l_shaped(cluster, rect)] if self._one_sweep() else [rect]
        for footprint in footprints:
            for model in self.catalogue.values():
                out += self._catalogue_fits(sample, cluster, footprint, model, ground_z_m, top_seen)
            height = float(cluster[:, 2].max() - ground_z_m)
            # a wall, a hedge or a building is no rigid vehicle, nor anything longer than a coach
            if may_be_rigid and RIGID_MIN_WIDTH_M <= footprint.width_m and height <= MAX_VEHICLE_HEIGHT_M:
                out += self._rigid_fits(sample, footprint, height, ground_z_m)
        return out

    def _catalogue_fits(
        self,
        sample: np.ndarray,
        cluster: np.ndarray,
        rect: Rect,
        model: VehicleModel,
        ground_z_m: float,
        top_seen: bool,
    ) -> list[tuple[VehicleModel, float, Measurement]]:
        """``model`` placed on the footprint ``rect`` in both directions: per direction the best of the
        start hitches, refined with the trailer's length fitted too. Each direction in turn, if its fit
        costs more than the other's as it stands, is placed again on the other's body (the rectangle
        around its boxes) and kept if it costs less there; a direction bettered first so gives the
        other a place on its new body (decided from the first fits alone, generalization `l1`+`l3`
        kept 8.4 false vehicle-s). A MAN seen by paper `l2` 25 m away, its group's rectangle 2 m
        off its axis, converged 3 m aside the right way round at four times the cost of the wrong
        way round (its cab on the trailer's rear), started driving backwards and was 14 m off for
        12 s."""
        out = {
            sign: self._direction_fit(sample, cluster, rect, model, sign, ground_z_m, top_seen) for sign in (1.0, -1.0)
        }
        for sign in (1.0, -1.0):
            mine, other = out[sign], out[-sign]
            if mine is None or other is None or other[2].cost >= mine[2].cost:
                continue
            body = _body_footprint(other[2], other[0], rect.yaw_rad)
            again = self._direction_fit(sample, cluster, body, model, sign, ground_z_m, top_seen)
            if again is not None and again[2].cost < mine[2].cost:
                out[sign] = again
        return [fitted for fitted in out.values() if fitted is not None]

    def _direction_fit(
        self,
        sample: np.ndarray,
        cluster: np.ndarray,
        rect: Rect,
        model: VehicleModel,
        sign: float,
        ground_z_m: float,
        top_seen: bool,
    ) -> tuple[VehicleModel, float, Measurement] | None:
        """``model`` placed on ``rect`` one way round (``_catalogue_fits``) at each start hitch, its
        footprint centred on the rectangle, and its cab on the rectangle's end (``_placed``), behind
        the side the nearest sensor sees: the cheapest of each placement refined, the cheaper
        of the two kept (``_refined``). (The cheapest coarse fit of all, refined: a Twizy standing
        at its dock, its group widened by the dock, came out 38 deg off from its cab placed on the
        group's end, where centred it had been right, and started 8 frames late.) In one sweep
        (``detect``) centred only, not moved from the sensor, not nudged: a start there is final,
        and on real KITTI sweeps the wider search fitted a MAN folded 46 deg to a row of parked
        cars that passed every check (two false vehicles in 32 sweeps, none before)."""
        one_sweep = self._one_sweep()
        away = None if one_sweep or self._rays is None else away_from_sensor(self._rays, rect)
        longer = _as_long_as(model, rect.length_m)
        refined = []
        for at_front in (False,) if one_sweep else (False, True):
            starts = [(model, h) for h in START_HITCHES_DEG]
            if longer is not model and not at_front:  # a longer trailer centred would put the cab on its front
                starts.append((longer, 0.0))
            coarse = [
                fit(
                    sample,
                    _placed(placed, rect, sign, np.radians(h), ground_z_m, at_front, away),
                    self.params,
                    COARSE_ITERATIONS,
                    START_SCALE_M,
                )
                for placed, h in starts
            ]
            coarse = [m for m in coarse if m is not None]
            if coarse:
                best = min(coarse, key=lambda m: m.cost)
                refined.append(self._refined(sample, best, model, ground_z_m, nudge=not one_sweep))
        if not refined:
            return None
        m = min(refined, key=lambda m: m.cost)
        if not _supported(m, _with_trailer_length(model, m.trailer_length_m), ground_z_m, top_seen):
            # once more on a sample that keeps its tractor's points (thin_by_unit): the even sample
            # of a reversing MAN whose cab hid behind its trailer kept 3 of its 60 cab points, and
            # the fit at the right hitch was not supported for 80 frames
            again = fit(cluster, _sized_start(m, model, ground_z_m), self.params, START_ITERATIONS, START_SCALE_M)
            m = m if again is None else again
        return _with_trailer_length(model, m.trailer_length_m), sign, m

    def _refined(
        self, sample: np.ndarray, coarse: Measurement, model: VehicleModel, ground_z_m: float, nudge: bool = True
    ) -> Measurement:
        """The coarse fit refined with the trailer's length fitted too, then again from its hitch
        ``START_NUDGE_RAD`` either way, the cheaper kept each time: the start hitches lie 30 deg
        apart, and a refined fit can settle in the valley of the cab's points with the trailer a few
        degrees off its side (an unknown 13.6 m trailer entering `l3`'s view, 10 deg off at 1.8 times
        the cost of the fit 5 deg away; the held-out 16 m lane change seen by `l1` started the wrong
        way round, 19 false vehicle-s)."""
        m = fit(sample, _sized_start(coarse, model, ground_z_m), self.params, START_ITERATIONS, START_SCALE_M)
        for step in (-START_NUDGE_RAD, START_NUDGE_RAD) if nudge else ():
            turned = replace(m, hitch_rad=m.hitch_rad + step)
            again = fit(sample, _sized_start(turned, model, ground_z_m), self.params, START_ITERATIONS, START_SCALE_M)
            if again is not None and again.cost < m.cost:
                m = again
        return m

    def _rigid_fits(
        self, sample: np.ndarray, rect: Rect, height_m: float, ground_z_m: float
    ) -> list[tuple[VehicleModel, float, Measurement]]:
        """One rigid box of the footprint's size in both directions, fitted again on the footprint of
        the points its fit explains when that is another, if it explains them better (a bollard
        beside a nuScenes truck turned its group's rectangle 10 deg and widened it by 0.3 m: the
        box reached past the truck's corner, and rays crossed it there)."""
        out = []
        for sign in (1.0, -1.0):
            fitted = self._rigid_fit(sample, rect, rect.yaw_rad + (0.0 if sign > 0 else np.pi), height_m, ground_z_m)
            if fitted is None:
                continue
            own = _explained_footprint(fitted[1], self.params.fit_min_points)
            if own is not None and not _same_size(own, rect):
                again = self._rigid_fit(sample, own, fitted[1].yaw_rad, height_m, ground_z_m)
                fitted = again if again is not None and again[1].cost <= fitted[1].cost else fitted
            out.append((fitted[0], sign, fitted[1]))
        return out

    def _rigid_fit(
        self, sample: np.ndarray, rect: Rect, heading_rad: float, height_m: float, ground_z_m: float
    ) -> tuple[VehicleModel, Measurement] | None:
        """A rigid box of ``rect``'s size fitted from its centre, along its axis the way ``heading_rad`` points."""
        rigid = VehicleModel.rigid("rigid", rect.length_m, rect.width_m, height_m)
        yaw = rect.yaw_rad + (0.0 if np.cos(rect.yaw_rad - heading_rad) >= 0.0 else np.pi)
        prior = Prior(*rect.center_xy, yaw, 0.0, rigid, ground_z_m)
        m = fit(sample, prior, self.params, START_ITERATIONS, START_SCALE_M)
        return None if m is None else (rigid, m)

    def _choose(
        self, hypotheses, seed: Seed, ground_z_m: float, top_seen: bool
    ) -> list[tuple[VehicleModel, Measurement]]:
        """The best-explaining model, in the order its two directions are to be checked: the cheaper
        fit alone, or, when both cost alike, the direction of travel first and then the other (the
        start's checks decide then: a Volvo beside a dock's wall, its cheaper direction's gap
        filled by the wall, waited 44 frames for its other direction to come out cheaper). In one
        sweep (``start_travel_m`` 0: no next frame to wait for), where a rigid box explains the
        points (``start_min_explained``), an articulated fit they do not support is no contender:
        the side and end of a 9 m bus lie on the faces of a 16.5 m MAN as well as on its own box's.
        With frames to come, an unsupported cheapest fit waits for more of the vehicle to show (so
        asked in every start, a reversing trailer whose tractor hid behind it started as a rigid
        vehicle: 25 false vehicle-s on held-out paper +500; its unit hidden there is not seen
        through, either, nor the MAN's beyond the bus)."""
        articulated = [h for h in hypotheses if h[0].articulated]
        rigid = [h for h in hypotheses if not h[0].articulated]
        if self._one_sweep() and any(self._explains(h[2], h[0]) for h in rigid):
            articulated = [h for h in articulated if _supported(h[2], h[0], ground_z_m, top_seen)]
        best_art = min(articulated, key=lambda h: h[2].cost, default=None)
        best_rigid = min(rigid, key=lambda h: h[2].cost, default=None)
        if best_art is not None and (best_rigid is None or best_art[2].cost < RIGID_COST_RATIO * best_rigid[2].cost):
            if abs(best_art[2].hitch_rad) > np.radians(self.params.start_max_hitch_deg):
                return []  # it looks jack-knifed: a parked trailer beside a container, more likely
            # the other way round may be folded further (a container's end started as a car-sized
            # cab folded 170 deg onto its trailer, its unfolded way not supported)
            pool = [h for h in articulated if h[0].name == best_art[0].name and self._unfolded(h[2])]
        else:
            pool = [h for h in rigid if h[0].tractor.length_m >= self.params.rigid_min_length_m]
        pool.sort(key=lambda h: h[2].cost)
        if len(pool) < 2 or pool[0][2].cost <= DIRECTION_COST_RATIO * pool[1][2].cost:
            return [(h[0], h[2]) for h in pool[:1]]
        pair = pool[:2]
        travel = seed.center_xy - seed.first_xy
        if np.hypot(*travel) > 0.3:
            heading = [np.array([np.cos(h[2].yaw_rad), np.sin(h[2].yaw_rad)]) @ travel for h in pair]
            pair = pair[::-1] if heading[1] > heading[0] else pair
        return [(h[0], h[2]) for h in pair]

    def _rigid_after(self, choices, hypotheses) -> list[tuple[VehicleModel, Measurement]]:
        """In one sweep, after articulated ``choices``, the cheapest rigid box of the ``hypotheses``
        long enough that explains the points: tried if the start's checks refute the two units, as
        no frame to come will show more (a nuScenes rigid truck was fitted best as a Volvo with a
        3.7 m trailer, seen through, and nothing was reported)."""
        if not (self._one_sweep() and choices and choices[0][0].articulated):
            return []
        rigid = [
            h for h in hypotheses if not h[0].articulated and h[0].tractor.length_m >= self.params.rigid_min_length_m
        ]
        best = min(rigid, key=lambda h: h[2].cost, default=None)
        return [(best[0], best[2])] if best is not None and self._explains(best[2], best[0]) else []


def _explained_footprint(m: Measurement, min_points: int) -> Rect | None:
    """The smallest rectangle around the points the fit ``m`` explains, if there are ``min_points``."""
    explained = m.points[m.explained, :2]
    return min_area_rect(explained) if len(explained) >= min_points else None


def _body_footprint(m: Measurement, model: VehicleModel, along_rad: float) -> Rect:
    """The smallest rectangle around the fit's unit boxes, its yaw the way of ``along_rad`` (the
    directions placed on it are those placed on the rectangle of that yaw)."""
    hitch = m.hitch_rad or 0.0
    centres = model.box_centers(m.x_m, m.y_m, m.yaw_rad, hitch)
    corners = [
        box_corners(centre, box.length_m, box.width_m, m.yaw_rad + hitch * u)
        for u, (centre, box) in enumerate(zip(centres, model.boxes))
    ]
    body = min_area_rect(np.vstack(corners))
    return body if np.cos(body.yaw_rad - along_rad) >= 0.0 else replace(body, yaw_rad=body.yaw_rad + np.pi)


def _same_size(a: Rect, b: Rect) -> bool:
    return abs(a.length_m - b.length_m) <= REFIT_SIZE_CHANGE_M and abs(a.width_m - b.width_m) <= REFIT_SIZE_CHANGE_M


def _bent_against(m: Measurement, best: Measurement) -> bool:
    """Whether the fit ``m`` bends more than ``START_BEND_TOLERANCE_RAD`` further than ``best``, the
    cheapest catalogue model's: a straighter fit explaining the points better shows a straighter
    body (parked 16 m trailers, fitted best by a MAN straight, its gap filled or its cab's box seen
    through, started as Volvos bent 32-34 deg on them at eight times the cost: 14 s of false
    vehicle). Not the other way: a cheapest fit bent 12 deg and seen through was a misfit of an
    unknown 13.6 m trailer, a MAN's straight fit the right one."""
    return abs(m.hitch_rad or 0.0) - abs(best.hitch_rad or 0.0) > START_BEND_TOLERANCE_RAD


def _bent_flags(fits: list[Measurement]) -> list[bool]:
    """Which of the start's ``fits`` bend further than the cheapest of them (``_bent_against``),
    whatever order they are tried in: the direction of travel first put a reversing MAN's wrong way
    round first, straight, its "cab" on the trailer's rear, and the right way, bent 28 deg with its
    cab hidden and 0.8 times the cost, no longer waited for (paper `l3`: 11.4 false vehicle-s)."""
    cheapest = min(fits, key=lambda m: m.cost, default=None)
    return [_bent_against(m, cheapest) for m in fits]


def _waits_for(m: Measurement, waiting: list[Measurement]) -> bool:
    """Whether the fit ``m`` waits for one of the ``waiting`` fits that only lack points yet (not
    supported, nor ``_refuted``): one the other way round that ``m`` does not undercut by
    ``DIRECTION_COST_RATIO``. Which of two directions that cost alike starts is then left to
    the points to come (``_candidate`` lets a fit whose gap shows start), not to the order they
    were tried in (the direction of travel first: a reversing MAN seen by paper `l3`, its cab
    hidden, started the wrong way round, its "cab" on the trailer's rear, at 0.92 times the cost
    of the right way)."""
    return any(not _same_way(m, w) and m.cost > DIRECTION_COST_RATIO * w.cost for w in waiting)


def _same_way(a: Measurement, b: Measurement) -> bool:
    """Whether two fits' mean axes (between tractor and trailer) point the same way."""
    axis = [m.yaw_rad + (m.hitch_rad or 0.0) / 2 for m in (a, b)]
    return bool(np.cos(axis[0] - axis[1]) > 0.0)


def _trailer_hidden(m: Measurement) -> bool:
    """An articulated fit with fewer than ``SIDE_MIN_POINTS`` points on its trailer's faces but the
    front: that face stands right behind the cab's rear face, and explains the cab's points when
    the trailer is out of view."""
    return m.hitch_rad is not None and np.count_nonzero((m.unit == 1) & (m.face != FRONT)) < SIDE_MIN_POINTS


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


def _hinge(track: _Track) -> tuple[float, float]:
    """The kingpin's offset behind the rear axle and the trailer's front ahead of the kingpin:
    fitted in a turn, else the catalogue's kingpin with the front where the reach seen straight puts
    it, else the catalogue's."""
    if track.hinge is not None:
        return track.hinge.kingpin_m, track.hinge.trailer_front_m
    kingpin, front = track.hinge_prior
    return kingpin, (track.reach.estimate + kingpin if track.reach.values else front)


def _cab_length(track: _Track) -> float:
    """The cab's length: measured between its faces once counted, else the hinge's (fitted with it),
    else the catalogue's (or at least the lower bound the faces gave)."""
    if not track.cab_length.counted and track.hinge is not None and track.hinge.cab_length_m is not None:
        return track.hinge.cab_length_m
    return track.cab_length.estimate


def _changed(obj, **values):
    """``dataclasses.replace(obj, **values)``, or ``obj`` itself when it holds those values already
    (the learned sizes of a settled vehicle rarely change: a frozen copy costs more than the check)."""
    if all(getattr(obj, name) == value for name, value in values.items()):
        return obj
    return replace(obj, **values)


def _body_band(trailer: Box) -> tuple[float, float]:
    """The heights above the ground within ``END_BAND_M`` of the trailer body's floor to roof."""
    return trailer.floor_m - END_BAND_M, trailer.top_m + END_BAND_M


def _reached_back(start_m: float, along: np.ndarray, gap_m: float = MAX_BODY_GAP_M) -> float:
    """The hindmost of the positions ``along`` a unit (its frame's x) reached from ``start_m`` backwards
    without a gap longer than ``gap_m``; ``start_m`` if none is."""
    behind = np.sort(along[along <= start_m])[::-1]
    gaps = np.flatnonzero(-np.diff(np.r_[start_m, behind]) > gap_m)
    reached = behind[: gaps[0]] if len(gaps) else behind
    return float(reached[-1]) if len(reached) else start_m


def _body_heights(z_rel: np.ndarray, trailer: Box) -> np.ndarray:
    """Which heights above the ground (``z_rel``) lie in the trailer body's band (``_body_band``)."""
    low, high = _body_band(trailer)
    return (z_rel >= low) & (z_rel <= high)


def _start_covariance(m: Measurement) -> np.ndarray:
    """A start fit's covariance widened by ``START_SIGMAS`` (the seed's points are not de-skewed)."""
    return m.covariance + np.diag(START_SIGMAS[: len(m.vector)] ** 2)


def _sized_start(m: Measurement, model: VehicleModel, ground_z_m: float) -> Prior:
    """A start fit's refinement from ``m``: ``model`` with the trailer's length ``m`` fitted, the
    length fitted again."""
    return _free_length_at(m, model, m.trailer_length_m, ground_z_m, hypothesis=True)


def _free_length_at(
    m: Measurement, model: VehicleModel, length_m: float, ground_z_m: float, hypothesis: bool = False
) -> Prior:
    """At the pose of the fit ``m``: ``model`` with its trailer ``length_m`` long, the length free."""
    sized = _with_trailer_length(model, length_m)
    return Prior(
        m.x_m, m.y_m, m.yaw_rad, m.hitch_rad, sized, ground_z_m, free_trailer_length=True, hypothesis=hypothesis
    )


def _on_trailer_axis(m: Measurement, model: VehicleModel, x_m: float) -> np.ndarray:
    """The yard xy of the point ``x_m`` along the trailer's axis from the kingpin, at the fit ``m``."""
    yaw = m.yaw_rad + m.hitch_rad
    return model.kingpin_xy(m.x_m, m.y_m, m.yaw_rad) + x_m * np.array([np.cos(yaw), np.sin(yaw)])


def _own_body(points: np.ndarray, owner: np.ndarray, i: int, prior: Prior) -> tuple[Prior, bool]:
    """``prior`` with the claimed points of track ``i`` (``owner``) that are no part of its trailer's
    body released (-1): those behind a gap (``_beyond_gap``, which also cuts the prior's slack) and a
    wall behind it (``_wall_behind``) among the rest; and whether the wall ran across the trailer's
    body (``END_BAND_M / 2`` ahead of its rear face or more): its rear end is not seen then."""
    if prior.model.trailer is None:
        return prior, False
    mine, q = kernels.owned_to_frame(points, owner, i, *_frame_args(*_unit_origins(prior.vector, prior.model)[1]))
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


def _face_seen(m: Measurement, model: VehicleModel, unit: int, face: int, ground_z_m: float, top_band_m: float) -> bool:
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
    roof_below = ground_z_m + model.boxes[unit].top_m - top_band_m
    on = (m.unit == unit) & (m.face == face) & (m.points[:, 2] < roof_below)
    if np.count_nonzero(on) < 2:
        return False
    across = unit_frames(m.points[on], m.vector, model)[unit][:, 1]
    width = model.boxes[unit].width_m
    return np.count_nonzero(np.abs(across) <= width / 4) >= 2 and float(np.ptp(across)) >= FACE_SEEN_SPAN * width


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


def _supported(m: Measurement, model: VehicleModel, ground_z_m: float, top_seen: bool = True) -> bool:
    """Each unit's explained points span at least ``UNIT_SUPPORT`` of its length, reach
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
            or np.ptp(q[mine, 0]) < UNIT_SUPPORT * box.length_m
            or (top_seen and z_rel[mine].max() < box.floor_m + UNIT_SUPPORT * box.height_m)
            or np.mean(z_rel[mine] < box.floor_m) > UNIT_SUPPORT
        ):
            return False
    return True


def _gap_filled(cluster: np.ndarray, m: Measurement, model: VehicleModel, ground_z_m: float) -> bool:
    """A straight articulated vehicle seen from the side shows a gap between the cab's rear and the
    trailer's front above the chassis; a wall or a parked trailer's side runs on through it. The
    middle half of the gap, between the trailer's floor and the lower roof, holds more than
    ``GAP_FILL_RATIO`` times the points per metre of a slice of the cab just ahead of it (of at least
    ``GAP_MIN_POINTS``)."""
    counts = _gap_counts(cluster, m, model, ground_z_m)
    return counts is not None and counts[1] >= GAP_MIN_POINTS and counts[0] > GAP_FILL_RATIO * counts[1] * counts[2]


def _gap_open(cluster: np.ndarray, m: Measurement, model: VehicleModel, ground_z_m: float) -> bool:
    """The gap's middle (``_gap_filled``) holds at most ``GAP_OPEN_RATIO`` times the points per metre
    of the cab's slice, of at least ``GAP_OPEN_MIN_POINTS``: two units, not one long box."""
    counts = _gap_counts(cluster, m, model, ground_z_m)
    return (
        counts is not None and counts[1] >= GAP_OPEN_MIN_POINTS and counts[0] <= GAP_OPEN_RATIO * counts[1] * counts[2]
    )


def _gap_looked_into(cluster: np.ndarray, m: Measurement, model: VehicleModel, ground_z_m: float) -> bool:
    """At least ``GAP_LOOKED_MIN_POINTS`` of the points between the cab's rear and the trailer's front
    (``GAP_FACE_MARGIN_M`` either way), at the gap's heights, lie ``GAP_SIDE_INSET_M`` inside the sides the
    fit shows there (``_sides_at_gap``): a face across the body, the cab's rear or the trailer's
    front, seen through the gap's opening. Seen at a slant from a car, a straight MAN's 0.7 m gap
    lets no ray through (it needs one within 15 deg of square to it), but shows the face behind
    it; a parked trailer's side with a pole's shadow on it shows none."""
    trailer_front = model.trailer.front_m - model.kingpin_behind_axle_m
    start, length = _gap_middle(model)
    sides = _sides_at_gap(m, model, start, length)
    if sides is None:
        return False
    (q,) = unit_frames(cluster, m.vector, model.with_boxes(model.tractor, None))
    z_rel = cluster[:, 2] - ground_z_m
    low, high = _gap_band(model)
    inside = (
        (q[:, 0] >= trailer_front - GAP_FACE_MARGIN_M)
        & (q[:, 0] <= model.tractor.rear_m + GAP_FACE_MARGIN_M)
        & (q[:, 1] >= sides[0] + GAP_SIDE_INSET_M)
        & (q[:, 1] <= sides[1] - GAP_SIDE_INSET_M)
        & (z_rel >= low)
        & (z_rel <= high)
    )
    return int(np.count_nonzero(inside)) >= GAP_LOOKED_MIN_POINTS


def _gap_counts(
    cluster: np.ndarray, m: Measurement, model: VehicleModel, ground_z_m: float
) -> tuple[int, int, float] | None:
    """Points in the middle half of the model's gap between cab and trailer, in a slice of the cab
    just ahead of it (as long, at least ``CAB_SLICE_MIN_M``: a gap of a metre leaves a slice of half
    a metre, a handful of points) between the trailer's floor and the lower roof, within the cab's
    width and ``END_BAND_M`` beyond its sides, and the gap's length over the slice's; None unless
    articulated and nearly straight."""
    if model.trailer is None or abs(m.hitch_rad) > GAP_TEST_MAX_HITCH_RAD:
        return None
    start, length = _gap_middle(model)
    if length <= 0.0:
        return None
    cab_rear = model.tractor.rear_m
    slice_m = max(length, CAB_SLICE_MIN_M)
    (q,) = unit_frames(cluster, m.vector, model.with_boxes(model.tractor, None))
    z_rel = cluster[:, 2] - ground_z_m
    low, high = _gap_band(model)
    # the cab's sides count with their surface: a parked trailer's side running on through the
    # "gap" lay just outside the model's cab width and left the gap empty (held-out seeds)
    band = (np.abs(q[:, 1]) <= model.tractor.width_m / 2 + END_BAND_M) & (z_rel >= low) & (z_rel <= high)
    in_gap = int(np.sum(band & (q[:, 0] >= start) & (q[:, 0] <= start + length)))
    in_cab = int(np.sum(band & (q[:, 0] >= cab_rear) & (q[:, 0] <= cab_rear + slice_m)))
    return in_gap, in_cab, length / slice_m


def _sides_at_gap(m: Measurement, model: VehicleModel, start_m: float, length_m: float) -> tuple[float, float] | None:
    """The extent across (tractor frame, within the cab's width) of the fit's explained points within
    ``GAP_SIDES_REACH_M`` ahead of and behind the gap's middle: the body's sides there. Rays running
    along a parked trailer's side 0.1 m outside it, inside the wider box of the MAN cab fitted to its
    front, had shown the "gap" behind that cab empty (a false vehicle for 20 s, generalization suite)."""
    (q,) = unit_frames(m.points, m.vector, model.with_boxes(model.tractor, None))
    half = model.tractor.width_m / 2
    near = (
        (m.unit >= 0) & (q[:, 0] >= start_m - GAP_SIDES_REACH_M) & (q[:, 0] <= start_m + length_m + GAP_SIDES_REACH_M)
    )
    if not near.any():
        return None
    return max(float(q[near, 1].min()), -half), min(float(q[near, 1].max()), half)


def _gap_middle(model: VehicleModel) -> tuple[float, float]:
    """Where the middle half of the gap between the trailer's front and the cab's rear begins along
    the tractor's frame at hitch 0, and its length (not positive: no gap)."""
    trailer_front = model.trailer.front_m - model.kingpin_behind_axle_m
    length = (model.tractor.rear_m - trailer_front) / 2
    return trailer_front + length / 2, length


def _gap_band(model: VehicleModel) -> tuple[float, float]:
    """The heights above the ground of the gap test: above the trailer's floor, below the lower roof."""
    return model.trailer.floor_m + END_BAND_M, min(model.tractor.top_m, model.trailer.top_m) - END_BAND_M


def _below_tall_structures(points: np.ndarray, ground, cell_m: float) -> np.ndarray:
    """``points`` without the ``cell_m`` columns that reach higher than any vehicle: a dock wall, a
    building or a tree's crown (before the background map is learned, a trailer standing at a dock
    is one component with the wall)."""
    if len(points) == 0:
        return points
    above = points[:, 2] - ground_heights(ground, points[:, :2]) > MAX_VEHICLE_HEIGHT_M
    if np.count_nonzero(above) < TALL_COLUMN_MIN_POINTS:
        return points
    columns = voxel_keys(np.floor(points[:, :2] / cell_m), 1.0)  # the cells of a grid through the origin
    _, index = np.unique(columns, return_inverse=True)
    tall = np.bincount(index, weights=above) >= TALL_COLUMN_MIN_POINTS
    return points[~tall[index]]


def ground_heights(ground, xy: np.ndarray) -> np.ndarray:
    """The ground's height under each of ``xy`` (N, 2): it is a plane, so three samples give it."""
    z0 = ground(0.0, 0.0)
    return z0 + (ground(1.0, 0.0) - z0) * xy[:, 0] + (ground(0.0, 1.0) - z0) * xy[:, 1]


def seed_group_rows(
    points: np.ndarray,
    ground,
    voxel_m: float,
    min_height_m: float,
    min_points: int,
    join_m: float,
    min_diagonal_m: float,
) -> list[np.ndarray]:
    """The rows of ``points`` in each start cluster (``kernels.seed_groups``): connected ``voxel_m``
    components of ``min_points`` points reaching ``min_height_m`` above the ground under their
    centre, joined where points of two come closer than ``join_m`` (a cab and its trailer are apart
    by up to about 1.5 m), whose footprint's diagonal reaches ``min_diagonal_m`` (no rectangle
    around a shorter one is that long)."""
    if len(points) == 0:
        return []
    points = _in_grid_precision(points)
    dtype = points.dtype.type
    z0 = ground(0.0, 0.0)
    rows, bounds = kernels.seed_groups(
        points, dtype(voxel_m), dtype(1.0), z0, ground(1.0, 0.0) - z0, ground(0.0, 1.0) - z0,
        float(min_height_m), int(min_points), float(join_m), float(min_diagonal_m),
    )  # fmt: skip
    return [rows[a:b] for a, b in zip(bounds[:-1].tolist(), bounds[1:].tolist())]


def _in_grid_precision(points: np.ndarray) -> np.ndarray:
    """``points`` contiguous, float32 if they are, else float64: the start's grid in their precision."""
    return np.ascontiguousarray(points, dtype=np.float32 if points.dtype == np.float32 else np.float64)


def _as_long_as(model: VehicleModel, length_m: float) -> VehicleModel:
    """The model with the longer trailer that makes it, straight, ``length_m`` long overall (up to
    the longest trailer); never shorter: a cluster shorter than the model may be a part of it."""
    if model.trailer is None:
        return model
    tractor_c, trailer_c = model.box_centers(0.0, 0.0, 0.0, 0.0)
    overall = tractor_c[0] + model.tractor.length_m / 2 - (trailer_c[0] - model.trailer.length_m / 2)
    if length_m <= overall:
        return model
    trailer_m = min(model.trailer.length_m + length_m - overall, MAX_TRAILER_LENGTH_M)
    return _with_trailer_length(model, trailer_m)


def _with_trailer_length(model: VehicleModel, length_m: float | None) -> VehicleModel:
    if length_m is None:
        return model
    return model.with_boxes(model.tractor, replace(model.trailer, length_m=length_m))


def _placed(
    model: VehicleModel,
    rect: Rect,
    sign: float,
    hitch_rad: float,
    ground_z_m: float,
    at_front: bool = False,
    away: np.ndarray | None = None,
) -> Prior:
    """A prior for ``model`` bent ``hitch_rad`` on the footprint ``rect``, its mean axis along the
    rectangle (``sign``: which end the tractor is at): its footprint's centre on the rectangle's,
    or (``at_front``) its cab's front on the rectangle's end, as only part of a vehicle may be in
    view (a 13.6 m trailer's first 3-6 m behind its cab, centred: fitted 22-125 deg off). With
    ``away`` (across the rectangle, from the sensor), moved back as far as its outline beside the
    rectangle reaches past the rectangle's side toward the sensor: the points are the faces the
    sensor sees, the body lies behind them (centred on a bent vehicle's near sides, half the
    hypotheses lay between the sensor and those faces: a mirror image that fits them as well)."""
    axis = rect.yaw_rad + (0.0 if sign > 0 else np.pi)
    yaw = axis - hitch_rad / 2 if model.articulated else axis
    tractor_c, trailer_c = model.box_centers(0.0, 0.0, yaw, hitch_rad)
    front = tractor_c + (model.tractor.length_m / 2) * np.array([np.cos(yaw), np.sin(yaw)])
    if trailer_c is None:
        centre = tractor_c
    else:
        back = trailer_c - (model.trailer.length_m / 2) * np.array([np.cos(yaw + hitch_rad), np.sin(yaw + hitch_rad)])
        centre = (front + back) / 2
    x, y = rect.center_xy - centre
    if at_front:
        direction = np.array([np.cos(axis), np.sin(axis)])
        x, y = np.array([x, y]) + direction * (rect.length_m / 2 - float((front - centre) @ direction))
    if away is not None:
        x, y = np.array([x, y]) + away * _in_front_of_seen_side(model, rect, x, y, yaw, hitch_rad, away)
    return Prior(
        float(x), float(y), float(yaw), float(hitch_rad), model, ground_z_m, 0.0, model.articulated, hypothesis=True
    )


def _in_front_of_seen_side(
    model: VehicleModel, rect: Rect, x: float, y: float, yaw: float, hitch_rad: float, away: np.ndarray
) -> float:
    """How far the outline of ``model`` at the pose (x, y, yaw, hitch), where it lies beside the
    footprint ``rect`` (within its length), reaches past the rectangle's side toward the sensor
    (``away`` points from the sensor, across the rectangle): the boxes' sides clipped to the
    rectangle's length, their nearest ends to the sensor."""
    boxes = model.boxes
    corners = (
        box_corners(
            np.array(model.box_centers(x, y, yaw, hitch_rad)[: len(boxes)]),
            np.array([box.length_m for box in boxes]),
            np.array([box.width_m for box in boxes]),
            yaw + hitch_rad * np.arange(len(boxes)),
        ).reshape(-1, 4, 2)
        - rect.center_xy
    )
    ends = np.roll(corners, -1, axis=1)
    along = np.array([np.cos(rect.yaw_rad), np.sin(rect.yaw_rad)])
    a0, a1 = corners @ along, ends @ along
    half = rect.length_m / 2
    with np.errstate(divide="ignore", invalid="ignore"):  # a side across the rectangle's axis: a1 == a0
        t_low, t_high = (-half - a0) / (a1 - a0), (half - a0) / (a1 - a0)
    across, inside = np.abs(a1 - a0) < 1e-12, np.abs(a0) <= half
    t_in = np.where(across, np.where(inside, 0.0, np.inf), np.minimum(t_low, t_high))
    t_out = np.where(across, np.where(inside, 1.0, -np.inf), np.maximum(t_low, t_high))
    t_in, t_out = np.maximum(t_in, 0.0), np.minimum(t_out, 1.0)
    beside = t_in <= t_out
    if not beside.any():
        return 0.0
    w0, w1 = corners @ away, ends @ away
    nearest = np.minimum(w0 + t_in * (w1 - w0), w0 + t_out * (w1 - w0))[beside].min()
    return max(-rect.width_m / 2 - float(nearest), 0.0)


def _unit_origins(v: np.ndarray, model: VehicleModel) -> list[tuple[np.ndarray, float]]:
    """Origin xy and yaw of each unit's frame (tractor: rear axle; trailer: kingpin) for pose ``v``."""
    frames = [(v[:2], v[2])]
    if model.trailer is not None:
        frames.append((model.kingpin_xy(v[0], v[1], v[2]), v[2] + v[3]))
    return frames


def unit_frames(points: np.ndarray, v: np.ndarray, model: VehicleModel) -> list[np.ndarray]:
    """(N, 2) coordinates of the points in each unit's frame (tractor: rear axle; trailer: kingpin)."""
    return [_in_frame(points, origin, yaw) for origin, yaw in _unit_origins(v, model)]


def trailer_frame(points: np.ndarray, v: np.ndarray, model: VehicleModel) -> np.ndarray:
    """``unit_frames``' trailer frame alone."""
    return _in_frame(points, *_unit_origins(v, model)[1])


def _in_frame(points: np.ndarray, origin: np.ndarray, yaw: float) -> np.ndarray:
    return kernels.to_frame(np.ascontiguousarray(points), *_frame_args(origin, yaw))


def _frame_args(origin: np.ndarray, yaw: float) -> tuple[float, float, float, float]:
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
                _unit_origins(prior.vector, model), model.boxes, (0.0, prior.trailer_slack_m)
            )
        ],
        dtype=float,
    )


def _learn_axle(track: _Track, m: Measurement, stamp_s: float) -> None:
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
