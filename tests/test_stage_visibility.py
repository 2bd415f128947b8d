"""Rays through a box: counted against geometry worked out by hand."""

import numpy as np
import pytest

from i2v_loc.stages.level_frame import _rotation_onto_up
from i2v_loc.stages.visibility import Rays

SENSOR = np.array([[0.0, -10.0, 3.0]])
BOX = dict(center_xy=(0.0, 0.0), yaw_rad=0.0, half_length_m=0.5, half_width_m=1.0, z_range_m=(0.5, 2.5), beyond_m=0.3)


def row(y, z, xs=np.linspace(-3, 3, 61)):
    """Returns along x at (y, z): rays from the sensor fan out across the box."""
    return np.column_stack([xs, np.full(len(xs), y), np.full(len(xs), z)]).astype(np.float32)


def rays(points, origins=SENSOR, bounds=None, to_level=np.eye(3), unreturned=None):
    bounds = np.array([0, len(points)]) if bounds is None else np.asarray(bounds)
    return Rays(points, np.asarray(origins, dtype=float), bounds, to_level, unreturned=unreturned)


def sampled_through(points, origin, box=BOX, samples=4000):
    """The count by brute force: points along each segment, the segment counted when one lies in
    the box and the last such lies ``beyond_m`` or more before the return."""
    t = np.linspace(0.0, 1.0, samples)
    (cx, cy), c, s = box["center_xy"], np.cos(box["yaw_rad"]), np.sin(box["yaw_rad"])
    count = 0
    for p in points.astype(float):
        q = origin + t[:, None] * (p - origin)
        x, y = c * (q[:, 0] - cx) + s * (q[:, 1] - cy), -s * (q[:, 0] - cx) + c * (q[:, 1] - cy)
        z_low, z_high = box["z_range_m"]
        inside = (np.abs(x) <= box["half_length_m"]) & (np.abs(y) <= box["half_width_m"])
        inside &= (q[:, 2] >= z_low) & (q[:, 2] <= z_high)
        if inside.any():
            count += (1.0 - t[np.flatnonzero(inside)[-1]]) * np.linalg.norm(p - origin) >= box["beyond_m"]
    return count


def test_rays_that_cross_the_box_and_end_beyond_it_are_counted():
    # returns 15 m from the sensor at y = 5: a ray meets the box's near face (y = -1) at 9/15 of its
    # x, so the 17 with |x| <= 0.8 enter it (through the far face or a side) and end metres beyond
    points = row(5.0, 1.0)
    assert rays(points).through(**BOX)[0] == 17 == sampled_through(points, SENSOR[0])


def test_the_crossing_rays_reach_along_the_box_is_the_most_forward_inside_it():
    # returns at y = 5 for x <= 0.2 only: a ray meets the near face (y = -1) at 9/15 of its x and
    # leaves by the far face (y = 1) at 11/15; the ray to x = 0.2 is inside it up to x = 0.2 * 11/15
    xs = np.linspace(-3, 0.2, 33)
    through, _, front = rays(row(5.0, 1.0, xs)).through(**BOX)
    assert through == int(np.sum(np.abs(xs * 9 / 15) <= 0.5 + 1e-9))
    assert front == pytest.approx(0.2 * 11 / 15, abs=1e-5)
    assert rays(row(0.0, 1.0)).through(**BOX)[2] == -np.inf  # no ray crossed


def test_rays_ending_in_the_box_on_its_far_side_or_short_of_it_are_not():
    assert rays(row(0.0, 1.0)).through(**BOX)[:2] == (
        0,
        11,
    )  # a surface inside: the 11 returns with |x| <= 0.5 end in it
    assert rays(row(-3.0, 1.0)).through(**BOX)[0] == 0  # something in front hid the box
    assert rays(row(5.0, 5.5)).through(**BOX)[0] == 0  # passing above it
    # a side 0.1 m beyond the far face: only rays leaving by a side face early enough count
    side = row(1.1, 1.0)
    assert rays(side).through(**BOX)[0] == sampled_through(side, SENSOR[0]) == 2


def test_random_rays_are_counted_as_by_sampling_the_segments():
    rng = np.random.default_rng(4)
    origin = np.array([3.0, -12.0, 4.0])
    points = np.column_stack([rng.uniform(-4, 4, 400), rng.uniform(-3, 6, 400), rng.uniform(0, 3, 400)])
    box = {**BOX, "yaw_rad": 0.4}
    got, ended, _ = rays(points.astype(np.float32), [origin]).through(**box)
    assert got == sampled_through(points.astype(np.float32), origin, box) and got > 20
    c, s = np.cos(0.4), np.sin(0.4)
    along, across = c * points[:, 0] + s * points[:, 1], -s * points[:, 0] + c * points[:, 1]
    inside = (np.abs(along) <= 0.5) & (np.abs(across) <= 1.0) & (points[:, 2] >= 0.5) & (points[:, 2] <= 2.5)
    assert ended == np.count_nonzero(inside) > 0


def test_a_sweep_whose_sensor_position_is_not_known_tells_nothing():
    points = np.vstack([row(5.0, 1.0), row(0.0, 1.0)])
    unknown = rays(points, [[np.nan] * 3, SENSOR[0]], [0, 61, 122])
    assert unknown.through(**BOX)[:2] == (
        0,
        11,
    )  # the first sweep's 17 crossings are not known; the second's 11 end inside


def test_each_sweep_has_its_own_origin():
    """Two sensors, each sweep its rows: the second's rays pass beside the box; swapped, the first
    sweep's rays come from the side and one of them grazes it."""
    beside = np.array([[0.0, -10.0, 3.0], [10.0, -10.0, 3.0]])
    first, second = row(5.0, 1.0), row(5.0, 1.0) + np.float32(10.0) * np.array([1, 0, 0], dtype=np.float32)
    points = np.vstack([first, second])
    assert rays(points, beside, [0, 61, 122]).through(**BOX)[0] == 17
    swapped = sampled_through(first, beside[1]) + sampled_through(second, beside[0])
    assert rays(points, beside[::-1], [0, 61, 122]).through(**BOX)[0] == swapped == 1


@pytest.mark.parametrize("yaw_deg", [0.0, 30.0, 90.0])
def test_a_turned_box_in_a_tilted_level_frame_counts_as_the_same_box_in_the_yard(yaw_deg):
    """The same rays and box, all turned about z and the yard tilted: the box is asked in the level
    frame, the rays are given in the yard's."""
    turn = np.radians(yaw_deg)
    rz = np.array([[np.cos(turn), -np.sin(turn), 0.0], [np.sin(turn), np.cos(turn), 0.0], [0.0, 0.0, 1.0]])
    to_level = _rotation_onto_up(np.array([0.05, -0.03, 1.0]) / np.linalg.norm([0.05, -0.03, 1.0]))
    to_yard = to_level.T
    points = (row(5.0, 1.0).astype(float) @ rz.T @ to_yard.T).astype(np.float32)
    origins = SENSOR @ rz.T @ to_yard.T
    box = {**BOX, "yaw_rad": turn}
    assert rays(points, origins, to_level=to_level).through(**box)[0] == 17


def test_the_level_frames_read_only_rotation_compiles_no_kernel_in_a_frame():
    """On level ground the level frame's rotation is a read-only array: asking the rays with it
    uses the specialisation the warm-up compiled (a read-only array is another numba type; the
    first frame that asked compiled one)."""
    from i2v_loc.stages import kernels
    from i2v_loc.stages.level_frame import LEVEL

    kernels.warm_up()
    before = set(kernels.rays_through_box.signatures)
    assert not LEVEL.flags.writeable
    rays(row(0.0, 1.5, np.linspace(-3, 3, 5)), to_level=LEVEL).through(**BOX)
    assert set(kernels.rays_through_box.signatures) == before


def test_the_top_of_a_sensors_view_is_its_sweeps_highest_return():
    """Sensor 3 m up; its highest return lies 1 m above it 10 m away (5.71 deg up). A point 20 m away
    2 m above it (5.71 deg) is at the top of the view; one 1.5 m above it (4.29 deg) is not, nor is
    any point of a sweep whose sensor is not known. The points are asked in the level frame: a
    level frame tilted 1 deg along x turns them back first."""
    sweep = np.array([[0.0, 10.0, 4.0], [0.0, 10.0, 2.0], [5.0, 5.0, 0.0]], dtype=np.float32)
    at_top, below = np.array([[20.0, 0.0, 5.0]]), np.array([[20.0, 0.0, 4.5]])
    seen = rays(sweep, origins=[[0.0, 0.0, 3.0]])
    assert seen.top_elevations == pytest.approx([np.arctan2(1.0, 10.0)])
    assert seen.at_view_top(at_top, np.radians(0.1)) and not seen.at_view_top(below, np.radians(0.5))
    unknown = rays(sweep, origins=[[np.nan, np.nan, np.nan]])
    assert not unknown.at_view_top(at_top, np.radians(0.5))
    tilt = _rotation_onto_up(np.array([np.sin(np.radians(1.0)), 0.0, np.cos(np.radians(1.0))]))
    tilted = rays(sweep, origins=[[0.0, 0.0, 3.0]], to_level=tilt)
    assert tilted.at_view_top(at_top @ tilt.T, np.radians(0.1))
    assert not tilted.at_view_top(below @ tilt.T, np.radians(0.5))


def test_rays_are_carried_with_a_moving_unit_from_their_capture_time():
    """A ray captured 0.1 s before the reference time, while a unit moved sideways at 2 m/s and turned
    at 1 rad/s about its centre (2, 0): in the unit's place at the reference time, each end of the
    ray is carried by the unit's velocity there (first order). The sensor at (0, 0): (0, 2) + 1 x
    (-2, 0) = (0, 0) m/s, it stays; the return at (10, 0): (0, 2) + 1 x (8, 0) = (0, 10) m/s, 1 m
    along y. The ray from (0, 0) to (10, 1) crosses x = 5 at y = 0.5."""
    from i2v_loc.stages.kinematic_filter import UnitMotion

    origin, end = np.array([[0.0, 0.0, 2.0]]), np.array([[10.0, 0.0, 2.0]], dtype=np.float32)
    still = Rays(end, origin, np.array([0, 1]), np.eye(3))
    moved = Rays(end, origin, np.array([0, 1]), np.eye(3), np.array([0.1]))
    motion = UnitMotion(np.array([2.0, 0.0]), 0.0, np.array([0.0, 2.0]), 1.0)
    args = (np.array([5.0, 0.0]), np.array([0.0, 1.0]), 3.0, 5.0, 0.3)
    assert moved.crossings(*args, motion)[:, 0] == pytest.approx([0.5], abs=1e-6)
    assert still.crossings(*args, motion)[:, 0] == pytest.approx([0.0])  # no lags known: as captured
    assert moved.crossings(*args)[:, 0] == pytest.approx([0.0])  # no motion: as captured


def test_rays_that_returned_nothing_cross_every_box_on_their_way_out_to_the_sensors_reach():
    """Unreturned rays from the sensor (at y -10, 3 m up) reach 20 m: those aimed at the box cross
    it wherever it stands within their reach (none ends in it), those aimed beside it do not, and a
    sensor turned 90 deg turns its rays with it. Returns alone never count them."""
    from i2v_loc.stages.visibility import Unreturned

    at_box = np.array([0.0, 10.0, -1.5]) / np.linalg.norm([0.0, 10.0, -1.5])  # down into the box's middle
    beside = np.array([0.6, 1.0, -0.15]) / np.linalg.norm([0.6, 1.0, -0.15])  # passes 6 m off to its side
    lost = Unreturned([np.array([at_box, at_box, beside], np.float32)], np.eye(3)[None], SENSOR, [20.0])
    box = {k: v for k, v in BOX.items() if k != "beyond_m"}
    seen = rays(row(1.5, 0.0), unreturned=lost)
    assert seen.unreturned_through(**box) == (2, pytest.approx(0.0, abs=1e-9))
    assert rays(row(1.5, 0.0)).unreturned_through(**box) == (0, -np.inf)
    turned = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # the sensor's x is the yard's y
    along_x = np.array([[10.0, 0.0, -1.5]]) / np.linalg.norm([10.0, 0.0, -1.5])
    lost = Unreturned([along_x.astype(np.float32)], turned[None], SENSOR, [20.0])
    assert rays(row(1.5, 0.0), unreturned=lost).unreturned_through(**box)[0] == 1
    assert seen.through(**BOX)[0] == sampled_through(row(1.5, 0.0), SENSOR[0])


# A unit's box 4 m long (x from -2 to 2) and 2 m wide; its side y = -1 faces SENSOR, 9 m from it.
UNIT = dict(center_xy=(0.0, 0.0), yaw_rad=0.0, half_length_m=2.0, half_width_m=1.0)
ALONG = np.arange(-1.75, 2.0, 0.5)  # the places asked, 1 m up
HIDE = dict(height_m=1.0, cone_rad=np.radians(1.0), before_m=0.3)


def grid(xs, y, zs):
    x, z = np.meshgrid(xs, zs)
    return np.column_stack([x.ravel(), np.full(x.size, y), z.ravel()]).astype(np.float32)


def side_behind_wall(wall_y=-5.0):
    """The unit's near side returns where x > 0; a wall at ``wall_y`` stands before it where x <= 0
    (a ray to (x, -1, 1) meets y = -5 at x 5/9, 1.89 m up: the wall's returns cover those rays)."""
    wall = grid(np.arange(-3.0, 0.001, 0.02), wall_y, np.arange(1.0, 2.6, 0.04))
    side = grid(np.arange(0.02, 2.0, 0.04), -1.0, np.arange(0.5, 1.6, 0.04))
    return np.vstack([wall, side])


def test_places_behind_something_else_are_hidden_those_showing_their_own_side_not():
    hidden = rays(side_behind_wall()).hidden_along_side(**UNIT, along_m=ALONG, **HIDE)
    assert hidden.tolist() == (ALONG < 0).tolist()  # the four places behind the wall


def test_no_return_near_a_ray_hides_nothing_nor_a_wall_at_the_units_own_face():
    side = side_behind_wall()
    open_sky = side[side[:, 1] == -1.0]  # the wall gone: nothing returned towards x < 0
    assert not rays(open_sky).hidden_along_side(**UNIT, along_m=ALONG, **HIDE).any()
    near = side_behind_wall(wall_y=-1.2)  # within before_m of the box: its own face's returns
    assert not rays(near).hidden_along_side(**UNIT, along_m=ALONG, **HIDE).any()


def test_a_place_one_sensor_sees_is_not_hidden_whatever_another_saw():
    first = side_behind_wall()
    other_side = grid(np.arange(-2.0, 2.0, 0.04), 1.0, np.arange(0.5, 1.6, 0.04))  # its y = 1 side, all of it
    both = rays(
        np.vstack([first, other_side]),
        origins=[SENSOR[0], [0.0, 10.0, 3.0]],
        bounds=[0, len(first), len(first) + len(other_side)],
    )
    assert not both.hidden_along_side(**UNIT, along_m=ALONG, **HIDE).any()
    unknown = rays(np.vstack([first, other_side]), origins=[SENSOR[0], [np.nan] * 3], bounds=both.bounds)
    assert unknown.hidden_along_side(**UNIT, along_m=ALONG, **HIDE).tolist() == (ALONG < 0).tolist()
