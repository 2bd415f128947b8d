"""Region stage: passthrough bounds and RANSAC ground plane with the tilt limit."""

import numpy as np
import pytest

from i2v_loc.params import Params, ParamsError, RegionParams, apply_patch
from i2v_loc.stages.region import Region, ground_below_origin_m


def plane_of(tilt_deg, n=4000, seed=0):
    rng = np.random.default_rng(seed)
    xy = rng.uniform(-15, 15, (n, 2))
    z = np.tan(np.radians(tilt_deg)) * xy[:, 0] + rng.normal(0, 0.02, n)
    return np.column_stack([xy, z]).astype(np.float32)


def box_on_ground(n=500, seed=1):
    rng = np.random.default_rng(seed)
    return np.column_stack([rng.uniform(2, 4, n), rng.uniform(2, 4, n), rng.uniform(0.5, 2.0, n)]).astype(np.float32)


def wide_region(**kw):
    return RegionParams(x_min_m=-50, x_max_m=50, y_min_m=-50, y_max_m=50, z_min_m=-20, z_max_m=20, **kw)


def test_finds_a_tilted_plane_within_the_limit_and_removes_it():
    ground = plane_of(5.0)
    cloud = np.vstack([ground, box_on_ground()])
    result = Region(wide_region(max_ground_tilt_deg=10.0)).process(cloud)
    assert result.ground_found
    assert result.ground.tilt_deg == pytest.approx(5.0, abs=0.3)
    # the refined normal is the plane's: (-sin 5, 0, cos 5)
    assert result.ground.normal == pytest.approx([-np.sin(np.radians(5)), 0, np.cos(np.radians(5))], abs=0.01)
    assert result.ground_points >= 0.98 * len(ground)
    # the object standing on the plane survives (its points are all well above the plane at x<=4)
    assert len(result.points) >= 490


def test_rejects_a_plane_tilted_beyond_the_limit_and_passes_the_cloud_through():
    cloud = plane_of(20.0)
    result = Region(wide_region(max_ground_tilt_deg=10.0)).process(cloud)
    assert not result.ground_found
    assert len(result.points) == len(cloud)


def test_passthrough_bounds_are_inclusive_boxes():
    pts = np.array([[0, 0, 1], [41, 0, 1], [0, -26, 1], [0, 0, 6], [39.9, 39.9, 4.9]], dtype=np.float32)
    mask = Region(RegionParams()).roi_mask(pts)
    assert mask.tolist() == [True, False, False, False, True]


def test_horizontal_ground_at_height_is_removed_with_the_threshold():
    rng = np.random.default_rng(3)
    ground = np.column_stack([rng.uniform(-20, 20, (3000, 2)), rng.normal(0.3, 0.03, 3000)]).astype(np.float32)
    low_object = np.column_stack([rng.uniform(0, 1, (100, 2)), np.full(100, 0.3 + 0.4)]).astype(np.float32)
    result = Region(RegionParams(ground_distance_threshold_m=0.15)).process(np.vstack([ground, low_object]))
    assert result.ground.height_at(0, 0) == pytest.approx(0.3, abs=0.02)
    assert len(result.points) == pytest.approx(100, abs=5)


def test_bounds_must_be_ordered():
    with pytest.raises(ParamsError, match="x_min_m"):
        apply_patch(Params(), {"region": {"x_min_m": 10, "x_max_m": 5}})


def test_the_ground_is_fitted_until_found_then_refitted_every_n_frames_over_two_frames():
    """The sample on one frame, RANSAC on it on the next; a refit that finds no ground starts over."""
    region = Region(RegionParams(ground_refit_frames=3))
    sampled, fitted = [], []
    region._sample = lambda points, in_region: sampled.append(frame) or frame
    region._fit = lambda sample: fitted.append((frame, sample)) or (None if frame in (0, 1, 9) else "plane")
    planes = []
    for frame in range(15):  # noqa: B007 (the lambdas read it)
        planes.append(region.ground(np.zeros((0, 3)), None))
    # 0, 1: none found, fitted on the frame itself; 2 found; 5 sampled, 6 fitted on it; 9's fit of
    # 8's sample finds none: 10 fits its own; 13 sampled, 14 fitted
    assert sampled == [0, 1, 2, 5, 8, 10, 13]
    assert fitted == [(0, 0), (1, 1), (2, 2), (6, 5), (9, 8), (10, 10), (14, 13)]
    assert planes[:2] == [None, None] and planes[9] is None and planes[10] == planes[14] == "plane"


def _street(ground_z_m: float, seed: int = 4) -> np.ndarray:
    """A sweep's cloud in its sensor's frame: the ground ``ground_z_m`` below it and, on both sides,
    building fronts 8 m up whose 0.5 m voxels outnumber the ground's nine to one."""
    rng = np.random.default_rng(seed)
    ground = np.column_stack([rng.uniform(-30, 30, (3000, 2)), rng.normal(ground_z_m, 0.02, 3000)])
    fronts = []
    for y in (-9.0, 9.0):
        x, z = np.meshgrid(np.arange(-30, 30, 0.1), np.arange(ground_z_m, ground_z_m + 8.0, 0.1))
        fronts.append(np.column_stack([x.ravel(), np.full(x.size, y) + rng.normal(0, 0.5, x.size), z.ravel()]))
    return np.vstack([ground, *fronts]).astype(np.float32)


def test_the_ground_below_a_sweeps_origin_is_found_among_walls_that_outnumber_it():
    cloud = _street(-1.9)
    region = Region(RegionParams(z_min_m=-20, z_max_m=20))
    assert region.ground(cloud, region.roi_mask(cloud)) is None  # a hundred triples miss it
    assert ground_below_origin_m(cloud, RegionParams()) == pytest.approx(1.9, abs=0.05)  # the fronts' feet lift it
    assert ground_below_origin_m(plane_of(20.0), RegionParams()) is None  # no ground at all


def test_the_ground_below_a_sweeps_origin_is_the_one_near_it():
    """A sensor on a viaduct 3.7 m above its road: farther out, the land 3.1 m below the road
    outnumbers it; the ground under the sensor is the road's."""
    rng = np.random.default_rng(5)
    road = np.column_stack([rng.uniform(-40, 40, 3000), rng.uniform(-6, 6, 3000), rng.normal(-3.7, 0.02, 3000)])
    land = np.column_stack([rng.uniform(-100, 100, (20000, 2)), rng.normal(-6.8, 0.02, 20000)])
    land = land[np.abs(land[:, 1]) > 8.0]  # under the viaduct's deck: hidden
    cloud = np.vstack([road, land]).astype(np.float32)
    wide = RegionParams(x_min_m=-100, x_max_m=100, y_min_m=-100, y_max_m=100)
    assert ground_below_origin_m(cloud, wide) == pytest.approx(3.7, abs=0.03)
