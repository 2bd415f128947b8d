"""Background map: static objects are learned away, moving ones and stopped tracked vehicles stay."""

import numpy as np
import pytest

from i2v_loc.params import BackgroundParams, Params, ParamsError, RegionParams
from i2v_loc.pipelines import build_pipeline
from i2v_loc.stages.background import BackgroundMap, ProtectedBox

REGION = RegionParams(x_min_m=-10, x_max_m=10, y_min_m=-10, y_max_m=10, z_min_m=-1, z_max_m=4)
FAST = dict(window_frames=10, min_samples=5, learn_every_frames=1)


def solid_box(center_xy, size=(2.0, 1.0, 1.5), spacing=0.1, z0=0.5):
    """Points filling a box (every voxel inside is occupied), centred at center_xy, from z0 up
    (0.5 m: above the ground's voxel and its one-voxel dilation)."""
    axes = [np.arange(-s / 2, s / 2 + 1e-9, spacing) for s in size[:2]] + [np.arange(0, size[2] + 1e-9, spacing)]
    pts = np.array(np.meshgrid(*axes, indexing="ij")).reshape(3, -1).T
    return pts + [center_xy[0], center_xy[1], z0]


def ground(spacing=0.2):
    g = np.arange(-9.9, 9.9, spacing)
    xy = np.array(np.meshgrid(g, g)).reshape(2, -1).T
    return np.column_stack([xy, np.zeros(len(xy))])


def run(bg, clouds, protected=()):
    return [bg.process(c.astype(np.float32), protected) for c in clouds]


def test_static_box_disappears_once_learned_and_a_new_object_is_foreground():
    bg = BackgroundMap(BackgroundParams(enabled=True, **FAST), REGION)
    box = solid_box((3.0, -2.0))
    scene = np.vstack([ground(), box])
    results = run(bg, [scene] * 8)
    n_ground = len(ground())
    assert not bg.ready or bg.samples >= 5
    # before min_samples: nothing is background (fall back), every region point is foreground
    assert results[3].foreground.all()
    # after: neither the ground nor the box is left
    assert results[-1].foreground.sum() == 0
    newcomer = solid_box((-4.0, 5.0))
    fg = bg.process(np.vstack([scene, newcomer]).astype(np.float32)).foreground
    assert fg[: n_ground + len(box)].sum() == 0 and fg[n_ground + len(box) :].all()


def test_points_outside_the_region_are_neither_region_nor_foreground():
    bg = BackgroundMap(BackgroundParams(enabled=True, **FAST), REGION)
    pts = np.array([[0.0, 0.0, 1.0], [15.0, 0.0, 1.0], [0.0, -12.0, 1.0], [0.0, 0.0, 6.0], [9.9, 9.9, 3.9]])
    result = bg.process(pts.astype(np.float32))
    assert result.in_region.tolist() == [True, False, False, False, True]
    assert result.foreground.tolist() == [True, False, False, False, True]


def test_moving_box_stays_foreground():
    bg = BackgroundMap(BackgroundParams(enabled=True, **FAST), REGION)
    clouds = [np.vstack([ground(), solid_box((-8.0 + 0.5 * k, 0.0))]) for k in range(30)]
    results = run(bg, clouds)
    n_ground = len(ground())
    for r in results[10:]:
        assert r.foreground[:n_ground].sum() == 0  # the ground is background
        assert r.foreground[n_ground:].all()  # the box, 0.5 m further each frame, is not


def stop_and_stand(protect: bool):
    """A box drives 4 m then stands for three windows; the track's box is protected or not."""
    bg = BackgroundMap(BackgroundParams(enabled=True, **FAST), REGION)
    positions = [(-6.0 + 0.5 * k, 1.0) for k in range(8)] + [(-2.5, 1.0)] * 30
    n_ground = len(ground())
    results = []
    for xy in positions:
        boxes = [ProtectedBox(xy, 0.0, 1.0, 0.5)] if protect else []
        results.append(bg.process(np.vstack([ground(), solid_box(xy)]).astype(np.float32), boxes))
    return [r.foreground[n_ground:].mean() for r in results], [r.foreground[:n_ground].mean() for r in results]


def test_vehicle_that_stops_inside_a_tracked_box_stays_foreground():
    box_fg, ground_fg = stop_and_stand(protect=True)
    assert min(box_fg) == 1.0
    assert ground_fg[-1] < 0.05  # the ground elsewhere was learned meanwhile
    # the same stop without a protected box is absorbed: the protection is what keeps it
    box_fg, _ = stop_and_stand(protect=False)
    assert box_fg[-1] == 0.0


def test_occluded_background_is_kept_until_unseen_for_the_whole_window():
    bg = BackgroundMap(BackgroundParams(enabled=True, **FAST), REGION)
    wall = solid_box((5.0, 0.0), size=(0.4, 6.0, 3.0))
    run(bg, [np.vstack([ground(), wall])] * 10)
    hidden = run(bg, [ground()] * 9)  # the wall hidden for 9 of the 10 samples of the window
    assert bg.process(np.vstack([ground(), wall]).astype(np.float32)).foreground[len(ground()) :].sum() == 0
    run(bg, [ground()] * 12)  # unseen for a whole window: forgotten
    assert bg.process(np.vstack([ground(), wall]).astype(np.float32)).foreground[len(ground()) :].all()
    assert len(hidden) == 9


def test_saved_map_loads_into_an_equal_grid_and_refuses_another(tmp_path):
    params = BackgroundParams(enabled=True, **FAST)
    bg = BackgroundMap(params, REGION)
    scene = np.vstack([ground(), solid_box((3.0, -2.0))]).astype(np.float32)
    run(bg, [scene] * 8)
    bg.save(tmp_path / "map.npz")
    fresh = BackgroundMap(params, REGION)
    fresh.load(tmp_path / "map.npz")
    assert fresh.ready and fresh.process(scene).foreground.sum() == 0
    other = BackgroundMap(params.model_copy(update={"voxel_size_m": 0.25}), REGION)
    with pytest.raises(ValueError, match="another grid"):
        other.load(tmp_path / "map.npz")
    with pytest.raises(ValueError, match="no such"):
        fresh.load(tmp_path / "missing.npz")


def test_too_large_grid_is_a_parameter_error():
    with pytest.raises(ParamsError, match="max_voxels"):
        build_pipeline(Params(background={"voxel_size_m": 0.05}), "default")
    build_pipeline(Params(background={"voxel_size_m": 0.05}), "paper")  # no map, no grid
    pipeline = build_pipeline(Params(), "default")
    with pytest.raises(ParamsError, match="max_voxels"):
        pipeline.update_params({"background": {"max_voxels": 1000}})
    with pytest.raises(ParamsError, match="min_samples"):
        pipeline.update_params({"background": {"min_samples": 50, "window_frames": 10}})


@pytest.mark.parametrize("x_max_m", [1e30, float("inf")])
def test_a_huge_or_infinite_region_is_refused_with_a_value_error(x_max_m):
    """Integer voxel counts overflowed (OverflowError, a server error in the service) for a region
    of 1e30 m; it is a ValueError naming the fix, like any too-large grid."""
    from i2v_loc.params import BackgroundParams, RegionParams
    from i2v_loc.stages.background import check_grid

    region = RegionParams.model_construct(**{**RegionParams().model_dump(), "x_max_m": x_max_m})
    with pytest.raises(ValueError, match="max_voxels"):
        check_grid(BackgroundParams(), region)
    check_grid(BackgroundParams(), RegionParams())  # the default region fits


def test_a_learning_frames_sample_is_counted_in_on_the_next_frame():
    bg = BackgroundMap(BackgroundParams(enabled=True, **{**FAST, "learn_every_frames": 3}), REGION)
    samples = []
    for _ in range(7):
        bg.process(ground().astype(np.float32))
        samples.append(bg.samples)
    assert samples == [0, 1, 1, 1, 2, 2, 2]
    assert bg.counts.max() == 2 and np.count_nonzero(bg.counts) == len(ground())  # every point its own voxel
