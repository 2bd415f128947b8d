"""The articulated estimator's start of a vehicle (docs/pipeline.md, Start): seeds, the connected
components of the points no track claimed, that persist for ``start_frames`` frames; every
catalogue model (both ways round, at several start hitches and placements) and one rigid box of
the measured size fitted to them; the best explained kept if the points and the sensors' rays
allow it (supported, its gap shown or not filled, not seen through, standing on wheels). The
tracker (``vehicle_tracker``) tracks what starts here.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field, replace
from enum import Enum

import numpy as np
from scipy.spatial import cKDTree

from i2v_loc.geometry import box_corners, rotate_xy
from i2v_loc.params import ArticulatedParams
from i2v_loc.stages import kernels
from i2v_loc.stages.faces import (
    END_FACE_WIDTH_M,
    FACE_BAND_M,
    FACE_MAX_DEPTH_M,
    ONE_SIDE_WIDTH_M,
    away_from_sensor,
    closed_below_at_an_end,
    end_face,
    face_foot,
    face_line,
    faces_grounded,
    l_shaped,
    low_at_both_ends,
    one_face_sized,
    passes_under,
    roof_shown,
    unit_grounded,
    unit_raised,
    vehicle_face,
)
from i2v_loc.stages.hinged_fit import (
    FRONT,
    REAR,
    Measurement,
    Prior,
    explained_share,
    fit,
    in_unit_box,
    thin,
)
from i2v_loc.stages.primitives import Rect, min_area_rect, unit_axes, voxel_keys
from i2v_loc.stages.unit_frames import (
    END_BAND_M,
    MAX_TRAILER_LENGTH_M,
    REAR_FACE_MIN_POINTS,
    UNIT_SUPPORT,
    face_seen,
    free_length_at,
    supported,
    trailer_frame,
    trailer_reach,
    unfolded,
    unit_frames,
    with_trailer_length,
)
from i2v_loc.stages.vehicle_model import MAX_VEHICLE_HEIGHT_M, RIGID_MAX_LENGTH_M, Box, VehicleModel
from i2v_loc.stages.visibility import Rays

START_HITCHES_DEG = (-90.0, -60.0, -30.0, 0.0, 30.0, 60.0, 90.0)
COARSE_ITERATIONS = 4  # per start hitch; the best is refined with START_ITERATIONS
START_NUDGE_RAD = np.radians(7.0)  # the refined start fit fitted again this far either way in hitch
START_ITERATIONS = 20
START_SCALE_M = 0.8  # first loss scale of the start fits (a placed model is off by up to metres)
DIRECTION_COST_RATIO = 0.8  # one end's fit must cost this much less than the other's to decide the direction
RIGID_COST_RATIO = 0.7  # an articulated model must cost this much less than one rigid box
START_BEND_TOLERANCE_RAD = np.radians(10.0)  # catalogue models' fits of one vehicle bend alike (within 2 deg)
LOW_SEED_SLACK_M = 0.5  # a seed shorter than a rigid vehicle and this much lower than every articulated one is none
REFIT_SIZE_CHANGE_M = 0.1  # a rigid start's box refitted on the footprint its fit explains (``_rigid_fits``)
APART_VOXEL_M = 0.3  # a seed taken apart in one sweep (``_start_apart``): lanes 0.6 m apart stay apart
TALL_COLUMN_MIN_POINTS = 2  # points above a vehicle's height that make a column a structure (not one noise point)
RIGID_MIN_WIDTH_M = 1.6  # a rigid vehicle starts once its width is seen (an end face or both sides)
GAP_TEST_MAX_HITCH_RAD = np.radians(10.0)  # beyond, a trailer's front corner swings into the gap
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
GAP_LOOKED_MIN_POINTS = 8  # on a face across the gap, seen through its opening
GAP_FACE_MARGIN_M = 0.15  # the faces bounding the gap: their points' noise and the fit's error along
END_SLAB_M = 1.0  # beyond a rigid body's end: a ray ending there and none crossing, it goes on (``_ends_free``)
SOLID_INSET_M = 0.5  # a unit's box this far inside its faces is crossed by no ray (a sweep's motion blurs them)
CAB_TOP_LOW_M = 0.3  # a cab model's top this far above its points' may be refuted by the rays
CAB_TOP_ABOVE_M = 0.1  # the rays asked from this far above its highest point (their noise)
CAB_TOP_MIN_RAYS = 3
CAB_TOP_MIN_POINTS = 20
CAB_TOP_INSET_M = 0.1  # inside the cab box's sides and ends: rays grazing a face
SEEN_THROUGH_RATIO = 0.1  # of the rays ending on a unit, at most this many cross it (real ones: under 0.01)
CAB_SLICE_MIN_M = 1.0
CAB_AROUND_M = 2.0  # a cab's surroundings whose points it must explain at the start (``_cab_explains_around``)
GAP_CORRIDOR_M = 1.5  # the trailer's box run on along its axis: the gap, and a trailer's front ahead of its model's
# a semitrailer's rear face is open between its under-run guard (at most 0.7 m up) and its floor
REAR_OPEN_BAND_M = (0.75, 0.15)  # from this high to this far below the trailer's floor
REAR_OPEN_MIN_COLUMNS = 4
REAR_CLOSED_SHARE = 0.6  # of its columns holding points in that band: a body reaching down, no trailer's rear
VIEW_TOP_TOLERANCE_RAD = np.radians(0.5)  # about one beam's spacing
VACATED_M = 0.5  # a first point this far from all of a seed's points now: its place was left
VACATED_MIN_SHARE = 0.1
VACATED_SEEN_MIN_RAYS = 3  # through a place a seed's first points left: seen empty, not hidden
SEED_FIRST_POINTS = 200
HIDDEN_STEP_M = 0.25  # places along a unit asked whether they are hidden (``_hidden_length``)
HIDDEN_CONE_RAD = np.radians(1.0)  # returns this near a ray are on it: an OS1-32's beams are 1.4 deg apart
HIDDEN_BEFORE_M = 0.3  # a return this far before a place hides it; as near a unit's box, it is the unit's own
FOOTPRINT_MAX_WIDTH_M = 8.0  # no vehicle's is wider (a MAN folded 60 deg: 16.0 x 6.1 m)
CARVE_MARGIN_M = 0.5  # a seed's last footprint grown by a frame's travel at yard speeds (``_seeds_in``)
START_MOVED_M = 0.5  # a seed of few points starting after the map was learned moved this far (or start_travel_m)
SHAPE_MIN_UNIT_POINTS = 10  # explained in each unit of a vehicle starting by its shape alone (map not learned)
STANDING_MIN_POINTS = 100  # fewer, a seed waits for motion once the map is learned (``_stood_in``)
SEED_RETRY_FRAMES = 20  # a seed that was no vehicle is fitted again after this many frames
SHAPE_CHANGE_M = 0.5  # if its extent or centre moved this much
SHAPE_POINTS_CHANGE = 0.3  # or its point count changed by this share


class Background(Enum):
    """What the points a start is given hold besides vehicles."""

    NONE = "none"  # no map learned (turned off, or one sweep): what stands is not told from vehicles anyway
    LEARNING = "learning"  # the yard too, while the map is learned: only articulated seeds start
    READY = "ready"  # the foreground: a rigid seed, or one of few points, starts once it moved

    @property
    def rigid_allowed(self) -> bool:
        """A rigid seed may start (once it moved): no wall or container is in the points, or none can be told."""
        return self is not Background.LEARNING


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
    left_seen: bool = False  # it once moved and the rays crossed the place it left (``moved`` with rays)
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
        if self.travel_m < travel_m:
            return False
        vacated = self._vacated()
        if not _left(vacated):
            return False
        return rays is None or _seen_empty(rays, self.first_points[vacated])

    def away(self) -> bool:
        """It once left a place the rays saw empty (``left_seen``), or it once moved (``travelled``)
        and its first place is still left: a vehicle coming head-on hides the place it left behind
        its own front. A parked trailer's seed, its side hidden behind a MAN driving by, moved while
        it grew along its other side; once the MAN passed it showed its first points again, and
        started as a vehicle (13 false vehicle-s on held-out seeds) while its place still counted as
        left. (Its first place left alone, a MAN driving on past one LiDAR covered its first points
        with its trailer's side again, and started 20 frames late.)"""
        return self.moving or self.left_seen or (self.travelled and _left(self._vacated()))

    def _vacated(self) -> np.ndarray:
        """Which first points lie ``VACATED_M`` from all of its points now."""
        if len(self.first_points) == 0 or len(self.points) == 0:
            return np.zeros(0, bool)
        distance, _ = cKDTree(self.points[:, :2]).query(self.first_points[:, :2], distance_upper_bound=VACATED_M)
        return np.isinf(distance)


def _left(vacated: np.ndarray) -> bool:
    """Whether at least ``VACATED_MIN_SHARE`` of a seed's first points are vacated."""
    return len(vacated) > 0 and float(np.mean(vacated)) >= VACATED_MIN_SHARE


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


def unit_seen_through(rays: Rays, centre_xy: np.ndarray, yaw_rad: float, box: Box, ground_z_m: float) -> bool:
    """Whether a unit's box (centre, yaw) is no solid body: more than ``SEEN_THROUGH_RATIO`` as many
    rays crossed it (``unit_crossed``) as ended on it (within ``SOLID_INSET_M`` of its box)."""
    inset, floor, top = SOLID_INSET_M, ground_z_m + box.floor_m, ground_z_m + box.top_m
    _, ended, _ = rays.through(
        tuple(centre_xy), yaw_rad, box.length_m / 2 + inset, box.width_m / 2 + inset, (floor - inset, top + inset),
        GAP_SEEN_BEYOND_M,
    )  # fmt: skip
    return unit_crossed(rays, centre_xy, yaw_rad, box, ground_z_m) > SEEN_THROUGH_RATIO * ended


def unit_crossed(rays: Rays, centre_xy: np.ndarray, yaw_rad: float, box: Box, ground_z_m: float) -> int:
    """The rays that crossed a unit's box ``SOLID_INSET_M`` inside its faces and ended beyond it: a
    body there stops them all."""
    inset, floor, top = SOLID_INSET_M, ground_z_m + box.floor_m, ground_z_m + box.top_m
    through, _, _ = rays.through(
        tuple(centre_xy), yaw_rad, box.length_m / 2 - inset, box.width_m / 2 - inset, (floor + inset, top - inset),
        GAP_SEEN_BEYOND_M,
    )  # fmt: skip
    return through


@dataclass(frozen=True)
class Start:
    """A vehicle to track from this frame on: its seed's points and footprint, the model that
    explains them and its fit, the ground under it, and whether its top was seen."""

    points: np.ndarray
    rect: Rect
    model: VehicleModel
    fit: Measurement
    ground_z_m: float
    top_seen: bool


class VehicleStarts:
    """The seeds (connected components of the points no track claimed that persist) and the
    vehicles found among them: every model's hypotheses fitted, the best checked against the
    points and the sensors' rays (``candidate``)."""

    def __init__(self, params: ArticulatedParams, catalogue: dict[str, VehicleModel]):
        self.params = params
        self.catalogue = catalogue
        self.seeds: list[Seed] = []
        self.rays: Rays | None = None  # this frame's

    def found(self, points: np.ndarray, ground, background: Background) -> list[Start]:
        """The vehicles that start this frame among ``points`` (those no track claimed)."""
        rigid_allowed = background.rigid_allowed
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
            if not seed.left_seen:  # it left a place the rays saw empty only in a frame in which it moved
                moved = seed.moved(self.params.start_travel_m)
                seed.travelled = seed.travelled or moved
                seed.left_seen = moved and seed.moved(self.params.start_travel_m, self.rays)
            shape = _Shape(len(cluster), rect.length_m, rect.width_m, center, rigid_allowed)
            if (
                seed.frames >= self.params.start_frames
                and self._may_fit(seed)
                and not self._stood_in(seed, background)
                and (seed.failed is None or (seed.retry_due(rigid_allowed) and seed.failed.changed(shape)))
            ):
                ready.append((seed, cluster, rect, shape))
        self.seeds = [s for s in self.seeds if s.seen]
        starts = []
        for seed, cluster, rect, shape in ready:
            center = seed.center_xy
            start = self._start(cluster, rect, seed, float(ground(center[0], center[1])), rigid_allowed)
            if start is None:  # no vehicle (yet): fitted again after a while if its shape changed
                seed.failed, seed.failed_frame = shape, seed.frames
                starts += self._start_apart(cluster, ground, rigid_allowed, seed)
                continue
            self.seeds.remove(seed)
            starts.append(start)
        return starts

    def forget(self) -> None:
        self.seeds = []

    def _start_apart(self, cluster: np.ndarray, ground, rigid_allowed: bool, seed: Seed) -> list[Start]:
        """The vehicles among a seed that is none, taken apart: in one sweep at ``APART_VOXEL_M``, its
        parts not joined (no frame to come in which vehicles side by side drive apart: its voxels
        bridge a cab's gap, and a street's lanes too; a bus 1.6 m beside a car was one seed 18.7 m by
        5.0 m in an Argoverse 2 sweep, which no model explains); with frames to come, its parts
        joined at half ``start_join_m`` only, each a seed that moved as it did. An unknown 13.6 m
        tractor-trailer in a lane change was one seed 17 x 11 m with an object 1.5 m beside it from
        the first frame, no model explained it, and it started once it had moved 10 frames later."""
        p = self.params
        voxel, join = (APART_VOXEL_M, 0.0) if self._one_sweep() else (p.start_voxel_m, p.start_join_m / 2)
        travel = seed.center_xy - seed.first_xy
        starts = []
        for rows in seed_group_rows(cluster, ground, voxel, p.start_min_height_m, p.fit_min_points, join, 0.0):
            if len(rows) == len(cluster):
                return []  # one piece: the seed itself
            part = cluster[rows]
            rect = min_area_rect(part[:, :2])
            if not self._seen_wide(rect):
                continue  # one face split off: a crown beside another, seen as an end, started as one
            c = rect.center_xy
            part_seed = Seed(c, c - travel, points=part, rect=rect, travelled=seed.travelled, left_seen=seed.left_seen)
            start = self._start(part, rect, part_seed, float(ground(*c)), rigid_allowed)
            if start is not None:
                starts.append(start)
        return starts

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
        hinge shows as an open gap only in motion (``_two_units``); ``candidate`` starts it then
        only as articulated. Once it left a place seen empty (``Seed.left_seen``), wherever it is
        now: a MAN that drove 5 m ahead, its cab hidden, and reversed past its first place into
        its dock was not fitted again while its trailer stood near where it was first seen, its
        cab in view from then on (held-out paper +3500: started 20 frames late)."""
        return not seed.rigid or self._one_sweep() or seed.left_seen or seed.moved(self.params.start_travel_m)

    def _one_sweep(self) -> bool:
        """No frame to come (``start_travel_m`` 0, as ``detect`` sets it): no motion to wait for, and
        no more of a vehicle to wait to see."""
        return self.params.start_travel_m <= 0.0

    def _may_start(self, seed: Seed, rigid_allowed: bool) -> bool:
        """A rigid seed once the background is learned and it moved."""
        return self._may_fit(seed) and (rigid_allowed or not seed.rigid)

    def _stood_in(self, seed: Seed, background: Background) -> bool:
        """Whether a seed waits for motion: once the background is learned, a seed of fewer than
        ``STANDING_MIN_POINTS`` points is fitted only after it moved ``START_MOVED_M`` and left a
        place seen empty (``Seed.moved``). The few points of a container or a parked trailer that
        the map did not learn, or that a passing vehicle uncovered, stand (seen by one LiDAR, the
        rest of a container started as a Twizy of 26 points, 6 false vehicle-s on held-out seeds);
        a vehicle standing shows more (asked of every seed, a Volvo standing in `l2`'s view, seen
        whole only once the map was learned, never started, nor a Twizy driving by `l3`, whose
        sparse first points the rays could not show left; it still starts 4 s late)."""
        return (
            background is Background.READY
            and not self._one_sweep()
            and len(seed.points) < STANDING_MIN_POINTS
            and not seed.moved(min(START_MOVED_M, self.params.start_travel_m), self.rays)
        )

    def _seed_clusters(self, points: np.ndarray, ground) -> list[tuple[np.ndarray, Rect]]:
        """Connected components tall enough to be a vehicle, those closer than ``start_join_m`` joined
        (a cab and its trailer are apart by up to about 1.5 m), of a vehicle's length and at least
        ``start_min_width_m`` wide (a wall, or a vehicle seen from one side only, is a plane). One
        larger than any vehicle is taken apart into the seeds it holds (``_seeds_in``), or, holding
        none, cut at its gaps (``_cut_at_gaps``)."""
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
            beyond = _beyond_any_vehicle(rect, p)
            parts = self._seeds_in(cluster, rect) if beyond else []
            if parts:
                out += [(cluster[r], own) for r in parts if self._seen_wide(own := min_area_rect(cluster[r, :2]))]
            elif self._seed_sized(rect):
                out.append((cluster, rect))
            elif beyond:
                out += [(cluster[r], own) for r, own in _cut_at_gaps(cluster, rect, p) if self._seed_sized(own)]
        return out

    def _seed_sized(self, rect: Rect) -> bool:
        """A footprint seen wide (``_seen_wide``) or of one end face's size (``one_face_sized``)."""
        return self._seen_wide(rect) or one_face_sized(rect, self.params)

    def _seeds_in(self, cluster: np.ndarray, rect: Rect) -> list[np.ndarray]:
        """The rows of a cluster (footprint ``rect``) in the last footprint of each seed of a
        vehicle's size (``_seen_wide``), ``CARVE_MARGIN_M`` around it, that holds ``fit_min_points``
        of them (a point in several: the nearest centre's). A cluster larger than any vehicle
        (``_beyond_any_vehicle``) is taken apart into them: seeds persist through merges. Before
        the background is learned, a MAN standing beside a parked trailer was one 24 x 12 m cluster
        with it in some frames and apart in others; its seed, lost with every merged frame, started
        4 frames late; one whose points came within a voxel of a 20-ft container's, 25.8 m together,
        3 frames late. (Taken apart whenever it held two seeds, a Volvo coming into `l2`'s view, its
        cab a seed of one face and its trailer another, lost its cab's points: it started 3 frames
        later, its trailer learned 0.65 m too long, hitch RMSE 0.45 -> 1.63 deg.)"""
        reach = rect.length_m / 2 + CARVE_MARGIN_M
        rects = [
            s.rect
            for s in self.seeds
            if s.rect is not None
            and self._seen_wide(s.rect)
            and np.hypot(*(s.rect.center_xy - rect.center_xy)) <= reach + s.rect.length_m / 2
        ]
        if not rects:
            return []
        xy = cluster[:, :2]
        distance = np.array([np.hypot(*(xy - r.center_xy).T) for r in rects])
        distance[~np.array([r.holds(xy, CARVE_MARGIN_M) for r in rects])] = np.inf
        nearest = np.where(np.isfinite(distance.min(axis=0)), np.argmin(distance, axis=0), -1)
        parts = [np.flatnonzero(nearest == k) for k in range(len(rects))]
        return [rows for rows in parts if len(rows) >= self.params.fit_min_points]

    def _seen_wide(self, rect: Rect) -> bool:
        """A footprint of a vehicle's length and at least ``start_min_width_m`` wide."""
        p = self.params
        return p.start_min_length_m <= rect.length_m <= p.start_max_length_m and rect.width_m >= p.start_min_width_m

    def _start(
        self, cluster: np.ndarray, rect: Rect, seed: Seed, ground_z_m: float, rigid_allowed: bool
    ) -> Start | None:
        top_seen = not self.at_view_top(cluster)
        chosen = self.candidate(cluster, rect, seed, ground_z_m, rigid_allowed, top_seen)
        return None if chosen is None else Start(cluster, rect, *chosen, ground_z_m, top_seen)

    def candidate(
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
        backed = [self._spanned(m, model, ground_z_m, top_seen) for model, m in choices]
        waiting = [  # fits that only lack points yet: more of the vehicle may show in the frames to come
            m
            for (model, m), b, s in zip(choices, bent, backed)
            if not (b or s or self._refuted(cluster, m, model, ground_z_m))
        ]
        for (model, m), b, s in zip(choices, bent, backed):
            if not self._allowed_to_start(seed, model, m, rigid_allowed):
                return None
            if b or not s or (_waits_for(m, waiting) and not self._gap_shown(cluster, m, model, ground_z_m)):
                continue
            filled = _gap_filled(cluster, m, model, ground_z_m)
            if (
                self._explains(m, model)
                and _cab_explains_around(cluster, m, model, ground_z_m, self.params)
                and _shape_shown(m, model, rigid_allowed)
                and not _rear_closed(cluster, m, model, ground_z_m)
                and not filled
                # without rays a hole and a gap look alike: the points alone decide
                and (self.rays is None or self._hinge_shown(seed, m, model, ground_z_m))
                and not self._seen_through(m, self._as_far_as_seen(m, model, cluster, ground_z_m), ground_z_m)
                and self._stands_on_wheels(cluster, m, model, ground_z_m, top_seen)
                and not self._cab_grounded(cluster, m, model, ground_z_m)
                and not self._cab_topped_low(cluster, m, model, ground_z_m)
                and self._ends_free(m, model, ground_z_m)
            ):
                return model, m
        return None

    def _ends_free(self, m: Measurement, model: VehicleModel, ground_z_m: float) -> bool:
        """Whether nothing stands against a rigid fit's ends: at each end whose face does not show
        (``face_seen``), no ray ended in the slab ``END_SLAB_M`` beyond it (within the box's width
        and height, ``SOLID_INSET_M`` inside) unless rays also crossed it. A body going on there, or
        a unit hinged to it, makes the box a part of a longer vehicle: seen by `l3` and `l4`, a
        reversing MAN's trailer alone, its cab hidden at -40 deg in that slab, started as a 13.85 m
        rigid box for 6 s. An end the view does not reach (no ray in the slab: a truck seen from its
        side and end hides its far end) is not refuted in one sweep; with frames to come the start
        waits for rays to cross the slab's upper half (rays pass under a semitrailer's floor, its
        body going on above them): a MAN seen from ahead, its trailer's side past its cab, started
        as an 11.2 m rigid box for 4 s (paper `l3`). Articulated fits and frames without rays: True."""
        if self.rays is None or model.articulated:
            return True
        box = model.tractor
        axis = np.array([np.cos(m.yaw_rad), np.sin(m.yaw_rad)])
        centre, _ = model.box_centers(m.x_m, m.y_m, m.yaw_rad, 0.0)
        floor, top = ground_z_m + box.floor_m, ground_z_m + box.top_m - SOLID_INSET_M
        for face, sign in ((FRONT, 1.0), (REAR, -1.0)):
            if face_seen(m, model, 0, face, ground_z_m, self.params.fit_top_band_m):
                continue
            beyond = tuple(centre + sign * (box.length_m + END_SLAB_M) / 2 * axis)
            slab = (beyond, m.yaw_rad, END_SLAB_M / 2, box.width_m / 2 - SOLID_INSET_M)
            through, ended, _ = self.rays.through(*slab, (floor + SOLID_INSET_M, top), GAP_SEEN_BEYOND_M)
            if ended and through < GAP_SEEN_MIN_RAYS:
                return False
            if not self._one_sweep():
                above, _, _ = self.rays.through(*slab, ((floor + top) / 2, top), GAP_SEEN_BEYOND_M)
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
        """``model`` with its trailer as long as the start's points reach (``unit_frames.trailer_reach``) when the
        fit ``m`` saw no rear face: where it ends is not known (the track starts no longer either,
        ``_start_length``), and rays crossing the catalogue's longer box beyond do not refute the
        body: seen from one side, an unknown 10.5 m trailer's right fit as the MAN (13.68 m) was
        seen through there, and the start waited 11 s (held-out +1500 `l3`)."""
        if model.trailer is None or m.rear_points >= REAR_FACE_MIN_POINTS:
            return model
        return with_trailer_length(model, trailer_reach(m, model, cluster, ground_z_m, self.params.fit_inlier_m))

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
        if self.rays is None or not (
            vehicle_face(cluster, rect, ground_z_m) and self._tall_enough(cluster, ground_z_m, top_seen)
        ):
            return None
        face, along, away = face_line(self.rays, cluster, rect)
        if not passes_under(self.rays, cluster, face, along, rect.length_m / 2, ground_z_m):
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
        if not self._one_sweep() and not seed.moved(self.params.start_travel_m, self.rays):
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
        the sensors' view ends below its top and its points do not reach the heights ``supported``
        asks anyway (the heights that tell a trailer from a wall are not seen then: a round crown
        beside a wall, seen with beams reaching 2 deg up, had started as a Volvo). Never without
        rays."""
        if self.rays is None:
            return True
        if not model.articulated:
            if np.ptp(cluster[:, 2]) < UNIT_SUPPORT * model.tractor.height_m:
                return False  # a plate of points at one height (a canopy, a gantry's deck) is no body
            raised = roof_shown(cluster, m, model, ground_z_m) or unit_raised(
                self.rays, cluster, m, model, 0, ground_z_m
            )
            body = low_at_both_ends(cluster, m, model.tractor, ground_z_m) and closed_below_at_an_end(
                self.rays, m, model.tractor, ground_z_m
            )
            return raised and body and not faces_grounded(self.rays, cluster, m, model, 0, ground_z_m)
        heights_shown = top_seen or supported(m, model, ground_z_m)
        return heights_shown or unit_raised(self.rays, cluster, m, model, 1, ground_z_m)

    def _cab_grounded(self, cluster: np.ndarray, m: Measurement, model: VehicleModel, ground_z_m: float) -> bool:
        """Whether an articulated fit's cab has a face reaching down to the ground
        (``faces.unit_grounded``): a box set down before a parked trailer's front, a 10-ft
        container, had started as its tractor in one sweep. Never without rays."""
        return (
            model.articulated and self.rays is not None and unit_grounded(self.rays, cluster, m, model, 0, ground_z_m)
        )

    def _cab_topped_low(self, cluster: np.ndarray, m: Measurement, model: VehicleModel, ground_z_m: float) -> bool:
        """Whether an articulated fit's cab box is empty above the highest of its points: rays crossed
        it between ``CAB_TOP_ABOVE_M`` over them and its model's top, which lies ``CAB_TOP_LOW_M`` or
        more higher, and fewer than ``SEEN_THROUGH_RATIO`` as many ended there. A 10-ft container (2.6 m
        high) 0.5-1.5 m before a parked trailer's front had started as a MAN's cab (3.3 m) with the
        trailer, from the service's start (13 of 60 yard scenes). Never without rays."""
        if self.rays is None or not model.articulated:
            return False
        box = model.tractor
        at = Prior(m.x_m, m.y_m, m.yaw_rad, m.hitch_rad, model, ground_z_m)
        z_rel = cluster[in_unit_box(cluster, at, 0, 0.0), 2] - ground_z_m
        if len(z_rel) < CAB_TOP_MIN_POINTS or box.top_m - float(z_rel.max()) < CAB_TOP_LOW_M:
            return False
        (centre, _) = model.box_centers(m.x_m, m.y_m, m.yaw_rad, m.hitch_rad or 0.0)
        band = (ground_z_m + float(z_rel.max()) + CAB_TOP_ABOVE_M, ground_z_m + box.top_m)
        through, ended, _ = self.rays.through(
            tuple(centre), m.yaw_rad, box.length_m / 2 - CAB_TOP_INSET_M, box.width_m / 2 - CAB_TOP_INSET_M, band, 0.0
        )
        return through >= CAB_TOP_MIN_RAYS and ended < SEEN_THROUGH_RATIO * through

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
        """Whether some unit of the fit is no solid body (``unit_seen_through``). A parked trailer with
        a pole beside it had started as a tractor bent at 34 degrees: the rays crossed the "cab"
        between pole and trailer."""
        if self.rays is None:
            return False
        hitch = m.hitch_rad or 0.0
        return any(
            unit_seen_through(self.rays, centre, yaw, box, ground_z_m)
            for centre, yaw, box in zip(
                model.box_centers(m.x_m, m.y_m, m.yaw_rad, hitch), (m.yaw_rad, m.yaw_rad + hitch), model.boxes
            )
        )

    def _hinge_shown(self, seed: Seed, m: Measurement, model: VehicleModel, ground_z_m: float) -> bool:
        """Whether a straight articulated fit is two units: it moves (its seed moved
        ``start_travel_m``, now or once and is still away: ``Seed.away``, or it is a tracked
        vehicle's probe; a vehicle seen head-on grows towards its rear as it comes, and its seed's
        centre wavers about that travel), or its gap was seen empty or into (``_gap_looked_into``);
        a standing straight one may be a parked trailer with a hole in its side (a pole's shadow).
        Standing in view from the service's start, a MAN whose gap no ray crossed waited to move
        (2 s, 22 frames, in 4 of 7 paper draws) though its cab's rear showed through the gap. A
        rigid fit, or a bent one, needs neither. (Tried: the
        motion of the fit's middle between cab front and trailer rear instead of the seed's centre;
        a first fit of the seed merged with a dock wall put it elsewhere, and a 16 m vehicle
        started 20 frames later on held-out seeds.)"""
        if model.trailer is None or abs(m.hitch_rad) > GAP_TEST_MAX_HITCH_RAD:
            return True
        return (
            seed.away()
            or seed.moved(self.params.start_travel_m)
            or self._gap_seen_empty(m, model, ground_z_m)
            or _gap_looked_into(seed.points, m, model, ground_z_m)
        )

    def _tall_enough(self, cluster: np.ndarray, ground_z_m: float, top_seen: bool) -> bool:
        """As tall as some catalogue vehicle's higher unit, less ``LOW_SEED_SLACK_M`` (a Twizy is
        car-sized, but its box trailer stands 2.85 m high), or its top not seen (``at_view_top``)."""
        tops = [max(box.top_m for box in model.boxes) for model in self.catalogue.values() if model.articulated]
        return not top_seen or not tops or float(cluster[:, 2].max()) - ground_z_m >= min(tops) - LOW_SEED_SLACK_M

    def at_view_top(self, points: np.ndarray) -> bool:
        """Whether some of ``points`` lie at the top of a sensor's view (within ``VIEW_TOP_TOLERANCE_RAD``
        of the elevation of its sweep's highest return): what stands higher there is not seen, and
        their height is a lower bound. Never without rays."""
        return self.rays is not None and self.rays.at_view_top(points, VIEW_TOP_TOLERANCE_RAD)

    def _two_units(
        self, hypotheses, cluster: np.ndarray, seed: Seed, ground_z_m: float, top_seen: bool
    ) -> tuple[VehicleModel, Measurement] | None:
        """The cheapest supported articulated fit (either direction) if it shows an open gap between
        cab and trailer and its hinge is shown (``_hinge_shown``: moving, or the gap seen empty):
        driving straight and seen from one side, a tractor and an unknown trailer fit one box of
        their measured size better than any catalogue model, and started rigid; the model the wrong
        way round, its cab on a few trailer points, may cost less."""
        fits = sorted(
            (h for h in hypotheses if h[0].articulated and unfolded(h[2], self.params)), key=lambda h: h[2].cost
        )
        model, _, m = next((h for h in fits if self._spanned(h[2], h[0], ground_z_m, top_seen)), (None, None, None))
        if model is None or not _gap_open(cluster, m, model, ground_z_m):
            return None
        return (model, m) if self._hinge_shown(seed, m, model, ground_z_m) else None

    def _spanning(self, articulated, ground_z_m: float, top_seen: bool) -> list:
        """The ``articulated`` hypotheses less those whose points support their fitted trailer but
        not the catalogue's (``_spanned``), unless none is left: a trailer that ends short of the
        model's is another model's, or an unknown one. The unknown 6.5 m reverse docking seen by
        held-out generalization +2500 `l2`, fitted cheapest as a MAN whose trailer shrank to 6.5 m,
        waited 40 frames for its rear face while the Volvo's fit spanned its own trailer."""
        kept = [
            h
            for h in articulated
            if not (
                self._shrunk(h[2], h[0])
                and supported(h[2], h[0], ground_z_m, top_seen)
                and not self._spanned(h[2], h[0], ground_z_m, top_seen)
            )
        ]
        return kept or articulated

    def _shrunk(self, m: Measurement, model: VehicleModel) -> bool:
        """Whether the fit's trailer is shorter than the catalogue's and the fit saw no rear face."""
        listed = self.catalogue.get(model.name)
        return (
            model.trailer is not None
            and listed is not None
            and model.trailer.length_m < listed.trailer.length_m
            and m.rear_points < REAR_FACE_MIN_POINTS
        )

    def _spanned(self, m: Measurement, model: VehicleModel, ground_z_m: float, top_seen: bool) -> bool:
        """Whether a start's fit is ``supported``, its trailer as long as the catalogue's at least
        where the fit saw no rear face: a trailer shortened to the few metres in view spans them.
        A MAN entering paper +2000 `l4`'s view cab first, 35 points of its trailer seen, was fitted
        best as itself (not supported yet) and, at 7 times the cost, as a Volvo whose trailer
        shrank to 2 m: that one started, and the MAN was named a Volvo for 2.4 s."""
        if self._shrunk(m, model):
            model = with_trailer_length(model, self.catalogue[model.name].trailer.length_m)
        return supported(m, model, ground_z_m, top_seen, functools.partial(self._hidden_length, m, model, ground_z_m))

    def _hidden_length(
        self, m: Measurement, model: VehicleModel, ground_z_m: float, unit: int, first_m: float, last_m: float
    ) -> float:
        """How much of a tractor's length outside its points' span (``first_m`` to ``last_m``, its
        frame) the rays show hidden behind something else (``Rays.hidden_along_side``, at half its
        height, every ``HIDDEN_STEP_M``): a reversing MAN's cab half behind its trailer at a
        40 deg hitch showed 1.3 m of its 2.77 m to held-out paper +500's sensors for 20 frames,
        and started only once it showed half. A place no ray came near is not hidden (the sky, or
        out of view: a vehicle coming into view shows no more than it shows). Not a trailer's:
        its span is what pins the hitch, and a trailer hidden behind its cab may lie anywhere in
        the cab's shadow (asked of both units, a Volvo standing folded 49 deg in view of one pole,
        1.6 m of its trailer seen, started at 30 deg and stayed there). Never without rays."""
        if self.rays is None or unit != 0 or not model.articulated:
            return 0.0
        box = model.tractor
        along = np.arange(box.rear_m + HIDDEN_STEP_M / 2, box.front_m, HIDDEN_STEP_M)
        along = along[(along < first_m) | (along > last_m)]
        if not len(along):
            return 0.0
        centre = model.box_centers(m.x_m, m.y_m, m.yaw_rad, m.hitch_rad or 0.0)[0]
        hidden = self.rays.hidden_along_side(
            tuple(centre),
            m.yaw_rad,
            box.length_m / 2,
            box.width_m / 2,
            along - box.center_x_m,
            ground_z_m + box.floor_m + box.height_m / 2,
            HIDDEN_CONE_RAD,
            HIDDEN_BEFORE_M,
        )
        return HIDDEN_STEP_M * float(np.count_nonzero(hidden))

    def _gap_seen_empty(self, m: Measurement, model: VehicleModel, ground_z_m: float) -> bool:
        """At least ``GAP_SEEN_MIN_RAYS`` rays crossed the middle of the model's gap (``_gap_counts``'
        box, across between the sides the fit's points show next to it, ``_sides_at_gap``, less
        ``GAP_SIDE_INSET_M`` each) and ended
        ``GAP_SEEN_BEYOND_M`` beyond it: the gap is empty, not hidden (a standing seed's hole may be a
        pole's shadow on a trailer's side)."""
        if self.rays is None:
            return False
        start, length = _gap_middle(model)
        sides = _sides_at_gap(m, model, start, length)
        if sides is None:
            return False
        half_width = (sides[1] - sides[0]) / 2 - GAP_SIDE_INSET_M
        if half_width <= 0.0:
            return False
        centre = np.array([m.x_m, m.y_m]) + rotate_xy((start + length / 2, (sides[0] + sides[1]) / 2), m.yaw_rad)
        low, high = gap_band(model)
        seen, _, _ = self.rays.through(
            tuple(centre), m.yaw_rad, length / 2, half_width, (ground_z_m + low, ground_z_m + high), GAP_SEEN_BEYOND_M
        )
        return seen >= GAP_SEEN_MIN_RAYS

    def _articulated_choices(self, hypotheses) -> list[tuple[VehicleModel, Measurement]]:
        """Each catalogue model's cheapest fit, cheapest first, none folded beyond the start limit."""
        best: dict[str, tuple[VehicleModel, Measurement]] = {}
        for model, _, m in hypotheses:
            if model.articulated and (model.name not in best or m.cost < best[model.name][1].cost):
                best[model.name] = (model, m)
        return sorted((c for c in best.values() if unfolded(c[1], self.params)), key=lambda c: c[1].cost)

    def with_connected(self, points: np.ndarray, free: np.ndarray, ground_z_m: float) -> np.ndarray:
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
        away = None if one_sweep or self.rays is None else away_from_sensor(self.rays, rect)
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
        if not supported(m, with_trailer_length(model, m.trailer_length_m), ground_z_m, top_seen):
            # once more on a sample that keeps its tractor's points (thin_by_unit): the even sample
            # of a reversing MAN whose cab hid behind its trailer kept 3 of its 60 cab points, and
            # the fit at the right hitch was not supported for 80 frames
            again = fit(cluster, _sized_start(m, model, ground_z_m), self.params, START_ITERATIONS, START_SCALE_M)
            m = m if again is None else again
        return with_trailer_length(model, m.trailer_length_m), sign, m

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
        through, either, nor the MAN's beyond the bus). Models whose trailer shrank short of their
        own give way first (``_spanning``)."""
        articulated = self._spanning([h for h in hypotheses if h[0].articulated], ground_z_m, top_seen)
        rigid = [h for h in hypotheses if not h[0].articulated]
        if self._one_sweep() and any(self._explains(h[2], h[0]) for h in rigid):
            articulated = [h for h in articulated if supported(h[2], h[0], ground_z_m, top_seen)]
        best_art = min(articulated, key=lambda h: h[2].cost, default=None)
        best_rigid = min(rigid, key=lambda h: h[2].cost, default=None)
        if best_art is not None and (best_rigid is None or best_art[2].cost < RIGID_COST_RATIO * best_rigid[2].cost):
            if abs(best_art[2].hitch_rad) > np.radians(self.params.start_max_hitch_deg):
                return []  # it looks jack-knifed: a parked trailer beside a container, more likely
            # the other way round may be folded further (a container's end started as a car-sized
            # cab folded 170 deg onto its trailer, its unfolded way not supported)
            pool = [h for h in articulated if h[0].name == best_art[0].name and unfolded(h[2], self.params)]
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


def _beyond_any_vehicle(rect: Rect, params: ArticulatedParams) -> bool:
    """Whether a footprint is longer than ``start_max_length_m`` or wider than ``FOOTPRINT_MAX_WIDTH_M``."""
    return rect.length_m > params.start_max_length_m or rect.width_m > FOOTPRINT_MAX_WIDTH_M


def _cut_at_gaps(
    cluster: np.ndarray, rect: Rect, params: ArticulatedParams, depth: int = 3
) -> list[tuple[np.ndarray, Rect]]:
    """The parts (rows, footprint) of a cluster longer than any vehicle cut at a gap along its
    length of at least ``start_voxel_m``: the widest that leaves both parts of a vehicle's length
    (``start_min_length_m`` to ``start_max_length_m``), else the widest, its parts cut again. A Volvo standing with a
    trailer parked 1.85 m behind its own was one 26 m cluster; the widest gap alone may be the one
    between a cab and its trailer."""
    along = (cluster[:, :2] - rect.center_xy) @ unit_axes(rect.yaw_rad)[0]
    order = np.argsort(along)
    ends = along[order]
    gaps = np.diff(ends)
    cuts = np.flatnonzero(gaps >= params.start_voxel_m)
    if depth == 0 or not len(cuts):
        return [(np.arange(len(cluster)), rect)]
    low, high = params.start_min_length_m, params.start_max_length_m
    lengths = np.array([ends[cuts] - ends[0], ends[-1] - ends[cuts + 1]])
    sized = np.all((lengths >= low) & (lengths <= high), axis=0)
    k = cuts[sized][np.argmax(gaps[cuts[sized]])] if sized.any() else cuts[np.argmax(gaps[cuts])]
    parts = []
    for rows in (order[: k + 1], order[k + 1 :]):
        own = min_area_rect(cluster[rows, :2])
        if _beyond_any_vehicle(own, params):
            parts += [
                (rows[piece], footprint) for piece, footprint in _cut_at_gaps(cluster[rows], own, params, depth - 1)
            ]
        else:
            parts.append((rows, own))
    return parts


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
    unknown 13.6 m trailer, a MAN's straight fit the right one. Nor when ``best`` costs alike (not
    under ``DIRECTION_COST_RATIO`` times ``m``'s): a cab without points bends as it may, and seen by
    one LiDAR from behind, a MAN's trailer alone started the wrong way round, straight, its "cab" on
    the trailer's rear face, the right way bent 27 deg at 1.14 times the cost (19 false vehicle-s)."""
    bends_further = abs(m.hitch_rad or 0.0) - abs(best.hitch_rad or 0.0) > START_BEND_TOLERANCE_RAD
    return bends_further and best.cost <= DIRECTION_COST_RATIO * m.cost


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
    the points to come (``candidate`` lets a fit whose gap shows start), not to the order they
    were tried in (the direction of travel first: a reversing MAN seen by paper `l3`, its cab
    hidden, started the wrong way round, its "cab" on the trailer's rear, at 0.92 times the cost
    of the right way)."""
    return any(not _same_way(m, w) and m.cost > DIRECTION_COST_RATIO * w.cost for w in waiting)


def _same_way(a: Measurement, b: Measurement) -> bool:
    """Whether two fits' mean axes (between tractor and trailer) point the same way."""
    axis = [m.yaw_rad + (m.hitch_rad or 0.0) / 2 for m in (a, b)]
    return bool(np.cos(axis[0] - axis[1]) > 0.0)


def _sized_start(m: Measurement, model: VehicleModel, ground_z_m: float) -> Prior:
    """A start fit's refinement from ``m``: ``model`` with the trailer's length ``m`` fitted, the
    length fitted again."""
    return free_length_at(m, model, m.trailer_length_m, ground_z_m, hypothesis=True)


def _shape_shown(m: Measurement, model: VehicleModel, rigid_allowed: bool) -> bool:
    """Whether a fit may start by its shape: once rigid vehicles may start too (the map learned, or
    none kept) motion or the map tell a vehicle; while the map is learned its shape alone does, and
    each unit must hold ``SHAPE_MIN_UNIT_POINTS`` explained points (a container's 21 points, 3 of
    them a "cab", had started as a Twizy bent 19 deg and was tracked for 26 s on held-out seeds)."""
    return rigid_allowed or all(np.count_nonzero(m.unit == u) >= SHAPE_MIN_UNIT_POINTS for u in range(len(model.boxes)))


def _rear_closed(cluster: np.ndarray, m: Measurement, model: VehicleModel, ground_z_m: float) -> bool:
    """Whether an articulated fit's trailer rear face, where its points show it (at least
    ``REAR_OPEN_MIN_COLUMNS`` ``FACE_BAND_M`` columns across), holds points in ``REAR_CLOSED_SHARE``
    of them between ``REAR_OPEN_BAND_M`` (above the ground; below the trailer's floor): a cab's
    front, its bumper and grille reaching down, not a trailer's rear, open below its floor but for
    its wheels at the corners. Seen by one LiDAR from ahead, an unknown 16 m vehicle started as a
    Volvo the wrong way round, its "cab" on 16 points of the trailer's rear and its trailer ending
    on the real cab's front (19 false vehicle-s on held-out seeds)."""
    if model.trailer is None:
        return False
    box = model.trailer
    low, high = REAR_OPEN_BAND_M[0], box.floor_m - REAR_OPEN_BAND_M[1]
    if low >= high:
        return False  # a trailer this low (a Twizy's) leaves no band to ask
    q = trailer_frame(cluster, m.vector, model)
    on = (np.abs(q[:, 0] - box.rear_m) <= FACE_MAX_DEPTH_M) & (np.abs(q[:, 1]) <= box.width_m / 2)
    if not on.any():
        return False
    columns = np.floor((q[on, 1] + box.width_m / 2) / FACE_BAND_M)
    z_rel = cluster[on, 2] - ground_z_m
    shown, closed = np.unique(columns), np.unique(columns[(z_rel >= low) & (z_rel <= high)])
    return len(shown) >= REAR_OPEN_MIN_COLUMNS and len(closed) >= REAR_CLOSED_SHARE * len(shown)


def _cab_explains_around(
    cluster: np.ndarray, m: Measurement, model: VehicleModel, ground_z_m: float, params: ArticulatedParams
) -> bool:
    """Whether an articulated start's cab explains the seed's points around it: of those within
    ``CAB_AROUND_M`` of its box, off the trailer's box and the corridor ``GAP_CORRIDOR_M`` ahead of
    it, ``start_min_explained`` lie within ``fit_inlier_m`` of the cab's box. A vehicle's cab is all
    of the vehicle there; a car driving past a container before the background was learned started
    with it as a Twizy (the container its 7.7 m trailer), the car's body running on 2 m past the
    cab's box at 110 deg to it: 0.64 of the points around the cab in it, 0.99-1.00 for the paper
    suite's and generalization +2500's vehicles with two LiDARs. Rigid fits: True."""
    if model.trailer is None:
        return True
    at = Prior(m.x_m, m.y_m, m.yaw_rad, m.hitch_rad, model, ground_z_m)
    around = in_unit_box(cluster, at, 0, CAB_AROUND_M) & ~in_unit_box(
        cluster, at, 1, params.fit_inlier_m, GAP_CORRIDOR_M
    )
    on_cab = around & in_unit_box(cluster, at, 0, params.fit_inlier_m)
    return np.count_nonzero(on_cab) >= params.start_min_explained * np.count_nonzero(around)


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
    low, high = gap_band(model)
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
    low, high = gap_band(model)
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


def gap_band(model: VehicleModel) -> tuple[float, float]:
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
    return with_trailer_length(model, trailer_m)


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
