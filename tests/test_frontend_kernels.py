"""The compiled front end gives what the plain numpy front end gave (tests/frontend_reference.py):
the same points, the same labels, the same background and ground decisions, on constructed clouds
and on a simulated recording."""

from __future__ import annotations

import itertools

import frontend_reference as ref
import numpy as np
import pytest
from conftest import SAMPLES

from i2v_loc.frame import SensorScan
from i2v_loc.params import BackgroundParams, ConcatenationParams, Extrinsics, RegionParams, SensorConfig, load_params
from i2v_loc.recording import Recording
from i2v_loc.stages import kernels
from i2v_loc.stages.background import BackgroundMap, ProtectedBox
from i2v_loc.stages.concatenation import Concatenation, MotionHint
from i2v_loc.stages.primitives import euclidean_labels, grid_labels, min_area_rect, split_by_label, voxel_centroids
from i2v_loc.stages.region import Region


def blobs(seed, n=4000, spread=30.0, dtype=np.float32):
    """Clusters of points of different sizes and densities, some touching, some far apart."""
    rng = np.random.default_rng(seed)
    centres = rng.uniform(-spread, spread, (12, 3)) * [1, 1, 0.1]
    sizes = rng.uniform(0.2, 4.0, (12, 3))
    which = rng.integers(0, 12, n)
    return (centres[which] + rng.uniform(-0.5, 0.5, (n, 3)) * sizes[which]).astype(dtype)


@pytest.fixture(scope="module")
def recording_frames():
    recording = Recording(SAMPLES / "man_tgx_docking")
    params = load_params(recording.sensors_file)
    return params, list(itertools.islice(recording.frames(), 40))


# ----------------------------------------------------------------------------- primitives


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("voxel_m", [0.1, 0.5, 3.0])  # sparse key range (hash table) to dense (slot per key)
def test_voxel_centroids_are_the_reference_centroids_in_key_order(dtype, voxel_m):
    points = blobs(1, dtype=dtype)
    values = np.random.default_rng(2).normal(size=(len(points), 2))
    got, got_values = voxel_centroids(points, voxel_m, values)
    want, want_values = ref.voxel_centroids(points, voxel_m, values)
    assert got.dtype == dtype and np.array_equal(got, want)
    assert np.array_equal(got_values, want_values)
    assert len(got) < len(points)  # voxels were merged: the test is not trivial


def test_voxel_centroids_of_a_masked_cloud_in_float64_are_those_of_the_selected_points():
    points = blobs(3)
    take = np.random.default_rng(4).random(len(points)) < 0.6
    got, _ = voxel_centroids(points, 0.5, take=take, float64=True)
    want, _ = ref.voxel_centroids(points[take].astype(np.float64), 0.5)
    assert got.dtype == np.float64 and np.array_equal(got, want)


@pytest.mark.parametrize("seed", range(3))
def test_row_mean_is_numpys_mean_over_rows_to_the_bit(seed):
    rng = np.random.default_rng(seed)
    for n in (1, 2, 7, 1000, int(rng.integers(2000, 20000))):
        rows = rng.normal(size=(n, 3)) * rng.uniform(0.1, 100.0) + rng.normal(size=3) * 50.0
        assert np.array_equal(kernels.row_mean(rows), rows.mean(axis=0)), n


@pytest.mark.parametrize("spread", [3.0, 3e5])  # occupancy bits, hash table
@pytest.mark.parametrize("seed", range(3))
def test_voxel_ids_and_lookup_are_the_reference_voxels_of_the_taken_points(spread, seed):
    rng = np.random.default_rng(seed)
    points = blobs(seed, n=3000, spread=spread, dtype=np.float64)
    take = rng.random(len(points)) < 0.7
    ids, voxel_keys, dims, bits, word_rank, table_keys, table_ids = kernels.voxel_ids(points, take, 0.25, 1.0)
    assert (len(bits) > 0) == (spread < 10)  # both groupings are exercised
    if not len(bits):
        voxel_keys = np.sort(voxel_keys)
        kernels.rank_in_key_order(voxel_keys, ids, table_keys, table_ids)
    want_keys, inverse = np.unique(ref.voxel_keys(points[take], 0.25), return_inverse=True)
    assert np.array_equal(voxel_keys, want_keys) and np.all(ids[~take] == -1)
    assert np.array_equal(ids[take], inverse.reshape(-1))
    probes = np.concatenate([want_keys, rng.integers(0, int(np.prod(dims)), 500)])
    want = {int(k): v for v, k in enumerate(want_keys)}
    got = [kernels._lookup(int(k), bits, word_rank, table_keys, table_ids) for k in probes]
    assert got == [want.get(int(k), -1) for k in probes]


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("voxel_m", [0.3, 0.5, 1.5])
def test_grid_labels_are_the_connected_components_of_scipy_numbered_alike(seed, voxel_m):
    points = blobs(seed, spread=12.0)
    got = grid_labels(points, voxel_m)
    want = ref.grid_labels(points, voxel_m)
    assert want.max() >= 2  # several components
    assert np.array_equal(got, want)


def test_grid_labels_of_a_cloud_spanning_a_huge_box_use_the_hash_table_and_agree():
    """Two groups 5 km apart: the grid of their bounding box would not fit in memory."""
    near, far = blobs(5, n=300), blobs(6, n=300) + np.float32([4000.0, -3000.0, 50.0])
    points = np.vstack([near, far])
    origin = points.min(axis=0)
    want_near = ref.grid_labels(near, np.float32(0.2), origin)
    want_far = ref.grid_labels(far, np.float32(0.2), origin) + want_near.max() + 1  # further along x: numbered after
    assert np.array_equal(grid_labels(points, 0.2), np.concatenate([want_near, want_far]))


@pytest.mark.parametrize(
    "labels",
    [
        np.random.default_rng(0).integers(0, 30, 5000),
        np.random.default_rng(1).integers(-5, 3, 200),  # negative labels
        np.random.default_rng(2).integers(0, 10**9, 50),  # sparse labels
        np.array([3, 3, 1, 1, 2, 2, 0]),  # ties in size: lower label first
    ],
)
def test_split_by_label_gives_the_reference_groups_in_the_reference_order(labels):
    got, want = split_by_label(labels), ref.split_by_label(labels)
    assert len(got) == len(want) and all(np.array_equal(g, w) for g, w in zip(got, want))


@pytest.mark.parametrize("seed", range(20))
def test_min_area_rect_matches_the_qhull_reference(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(3, 400))
    yaw = rng.uniform(-np.pi, np.pi)
    local = rng.uniform(-1, 1, (n, 2)) * rng.uniform(0.5, 8.0, 2)
    if seed % 2:  # an L-shaped view of a box edge
        local[: n // 2, 1] = local[: n // 2, 1].max()
    rot = np.array([[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]])
    xy = local @ rot.T + rng.uniform(-50, 50, 2)
    rect = min_area_rect(xy)
    center, length, width, yaw_ref = ref.min_area_rect(xy)
    assert rect.center_xy == pytest.approx(center, abs=1e-9)
    assert (rect.length_m, rect.width_m) == pytest.approx((length, width), abs=1e-9)
    assert rect.yaw_rad == pytest.approx(yaw_ref, abs=1e-12)


def test_min_area_rect_of_a_known_rectangle_and_of_flat_sets():
    corners = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 1.0], [0.0, 1.0], [2.0, 0.5], [1.0, 0.0]])
    rect = min_area_rect(corners)
    assert (rect.length_m, rect.width_m) == pytest.approx((4.0, 1.0))
    assert rect.center_xy == pytest.approx([2.0, 0.5])
    line = min_area_rect(np.array([[0.0, 0.0], [1.0, 1.0], [3.0, 3.0]]))  # collinear: zero width along the line
    assert (line.length_m, line.width_m) == pytest.approx((np.sqrt(18), 0.0))
    assert min_area_rect(np.zeros((0, 2))).area_m2 == 0.0


# ----------------------------------------------------------------------------- merge and interpolation


def test_merge_gives_the_reference_points_lags_and_faults():
    sensors = [
        SensorConfig(name="a", extrinsics=Extrinsics(x_m=10, y_m=-3, z_m=4, yaw_deg=37, pitch_deg=2, roll_deg=-1)),
        SensorConfig(name="b", extrinsics=Extrinsics(x_m=-5, y_m=2, z_m=6, yaw_deg=-120), min_range_m=2.0),
        SensorConfig(name="c", time_offset_s=-0.5),
        SensorConfig(name="d"),
    ]
    stage = Concatenation(ConcatenationParams(voxel_size_m=0, sync_tolerance_s=0.05), sensors)
    rng = np.random.default_rng(0)

    def scan(name, stamp, n):
        points = rng.normal(0, 40, (n, 3)).astype(np.float32)
        points[::97] = np.nan
        return SensorScan(name, stamp, points, rng.uniform(0, 0.1, n).astype(np.float32))

    scans = {"a": scan("a", 2.02, 5000), "b": scan("b", 2.0, 4000), "c": scan("c", 2.6, 300), "x": scan("x", 2, 5)}
    got = stage.merge(scans)
    points, lag, reference, faults, dropped = ref.merge(stage, scans)
    assert faults == {"a": "nan_points", "b": "nan_points", "c": "out_of_sync", "d": "missing", "x": "unknown_sensor"}
    assert (got.stamp_s, got.faults, got.dropped, got.sensors_used) == (reference, faults, dropped, ["a", "b"])
    assert got.points.shape == points.shape and np.allclose(got.points, points, rtol=0, atol=1e-4)
    assert np.array_equal(got.lag_s, lag)


@pytest.mark.parametrize("reference", ["earliest", "latest", "mean"])
def test_sync_window_is_the_reference_window_on_random_stamps(reference):
    rng = np.random.default_rng(5)
    stage = Concatenation(ConcatenationParams(reference=reference, sync_tolerance_s=0.05), [])
    dropped = 0
    for _ in range(3000):
        # up to 6 sweeps: some a period apart, some at the tolerance, some repeated
        stamps = list(1000.0 + rng.choice([0.0, 0.02, 0.05, 0.1], rng.integers(1, 7)) + rng.uniform(0, 0.06, 1))
        got_reference, got_members = stage._synchronise(stamps)
        want_reference, want_members = ref.synchronise(stamps, 0.05, reference)
        assert got_reference == want_reference and np.array_equal(got_members, want_members), stamps
        dropped += int((~got_members).sum())
    assert dropped > 0  # windows that leave sweeps out were exercised


def test_interpolation_moves_the_reference_points():
    rng = np.random.default_rng(1)
    points = rng.uniform(-10, 10, (3000, 3)).astype(np.float32)
    lag = rng.uniform(0, 0.1, len(points)).astype(np.float32)
    motion = [
        MotionHint((1.0, 2.0), 0.3, 4.0, 1.5, (2.0, -1.0), 0.4),
        MotionHint((-3.0, 2.5), -1.2, 3.0, 1.2, (0.5, 1.5)),  # overlaps the first: points move once
        MotionHint((5.0, -4.0), 0.7, 3.0, 1.2, (-3.0, 2.0), 0.3, 0.1),  # 0.1 s old: moved to each capture time
    ]
    got, want = points.copy(), points.copy()
    Concatenation.interpolate(got, lag, motion)
    ref.interpolate(want, lag, motion)
    assert np.array_equal(got, want) and not np.array_equal(got, points)


# ----------------------------------------------------------------------------- background and region on a recording


def merged_frames(params, frames):
    stage = Concatenation(params.concatenation, params.sensors)
    return [stage.merge(f.scans).points for f in frames]


@pytest.mark.parametrize(
    "background",
    [
        BackgroundParams(enabled=True, window_frames=8, min_samples=4, learn_every_frames=1),  # fills, then slides
        BackgroundParams(
            enabled=True, window_frames=10, min_samples=5, learn_every_frames=2, dilation_voxels=2, forget_fraction=0.3
        ),
    ],
)
def test_background_decisions_and_map_are_the_reference_ones_on_a_recording(recording_frames, background):
    params, frames = recording_frames
    clouds = merged_frames(params, frames)
    got_map, want_map = BackgroundMap(background, params.region), ref.BackgroundMap(background, params.region)
    foreground_seen = background_seen = 0
    for k, points in enumerate(clouds):
        # a box driving through the yard, protected from the 10th frame on
        box = [ProtectedBox((-20.0 + 1.5 * k, 5.0), 0.2 + 0.01 * k, 8.0, 1.5)] if k >= 10 else []
        got = got_map.process(points, box)
        in_region, foreground = want_map.process(points, box)
        assert np.array_equal(got.in_region, in_region) and np.array_equal(got.foreground, foreground), k
        foreground_seen += int(foreground.sum())
        background_seen += int((in_region & ~foreground).sum())
    assert foreground_seen > 0 and background_seen > 0
    assert np.array_equal(got_map.counts, want_map.counts)
    assert np.array_equal(got_map.is_background, want_map.is_background)
    assert np.array_equal(got_map.dilated, want_map.dilated)


def test_region_ground_and_kept_points_are_the_reference_ones_on_a_recording(recording_frames):
    params, frames = recording_frames
    region_params = params.region.model_copy(update={"ground_refit_frames": 1})
    got_stage = Region(region_params, seed=7)
    rng = np.random.default_rng(7)  # the reference draws the same hypotheses
    for points in merged_frames(params, frames[:12]):
        roi = ref.BackgroundMap(BackgroundParams(), region_params).process(points)[0]
        candidates = roi & (np.arange(len(points)) % 3 > 0)
        got = got_stage.process(points, roi, candidates)
        normal, offset = ref.fit_ground(got_stage, points[roi], rng)
        assert got.ground.normal == pytest.approx(normal, abs=1e-12) and got.ground.offset == pytest.approx(offset)
        index = np.flatnonzero(candidates)
        above = points[index] @ normal + offset > region_params.ground_distance_threshold_m
        assert np.array_equal(got.index, index[above]) and np.array_equal(got.points, points[index[above]])
        assert (got.roi_points, got.ground_points) == (int(roi.sum()), int((~above).sum()))
        assert 0 < len(got.points) < int(roi.sum())


def test_region_box_is_the_passthrough_box():
    region = Region(RegionParams(x_min_m=-2, x_max_m=2, y_min_m=-1, y_max_m=1, z_min_m=0, z_max_m=1))
    points = np.array([[0, 0, 0.5], [2, 1, 1], [2.01, 0, 0.5], [0, 0, -0.01], [-2, -1, 0]], dtype=np.float32)
    assert region.roi_mask(points).tolist() == [True, True, False, False, True]


@pytest.mark.parametrize("method", ["paper", "default", "articulated"])
def test_no_kernel_is_compiled_while_frames_are_processed(method):
    """Building the pipeline loads every specialisation its frames call: none is compiled in a frame."""
    from numba.core.registry import CPUDispatcher

    from i2v_loc.pipelines import build_pipeline
    from i2v_loc.stages import kernels

    recording = Recording(SAMPLES / "man_tgx_docking")
    pipeline = build_pipeline(load_params(recording.sensors_file), method)
    dispatchers = {name: f for name, f in vars(kernels).items() if isinstance(f, CPUDispatcher)}
    before = {name: set(f.signatures) for name, f in dispatchers.items()}
    for frame in itertools.islice(recording.frames(), 60):  # the map becomes ready, vehicles are found
        pipeline.process(frame)
    assert {name: set(f.signatures) for name, f in dispatchers.items()} == before
    assert not [name for name, sigs in before.items() if not sigs and not name.startswith("_")]  # all loaded


def test_min_area_rect_of_a_dense_blob_with_few_hull_points_matches_qhull():
    """Most points inside the hull (the filter drops them), a few on it, duplicates and collinear ones."""
    rng = np.random.default_rng(11)
    inside = rng.uniform(-1, 1, (20000, 2)) * [6.0, 1.2]
    edge = np.column_stack([np.linspace(-6, 6, 50), np.full(50, 1.2)])  # collinear along the top side
    xy = np.vstack([inside, edge, edge[:5], [[-6.0, -1.2], [6.0, -1.2]]]) @ np.array([[0.8, 0.6], [-0.6, 0.8]])
    rect = min_area_rect(xy)
    center, length, width, yaw = ref.min_area_rect(xy)
    assert (rect.length_m, rect.width_m) == pytest.approx((length, width), abs=1e-9)
    assert rect.center_xy == pytest.approx(center, abs=1e-9) and rect.yaw_rad == pytest.approx(yaw, abs=1e-12)
    assert (length, width) == pytest.approx((12.0, 2.4), abs=1e-3)


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("dims", [2, 3])
@pytest.mark.parametrize("tolerance_m", [0.3, 0.7])
def test_euclidean_labels_are_the_k_d_tree_components_numbered_alike(seed, dims, tolerance_m):
    points = blobs(seed, n=3000, spread=15.0, dtype=np.float64)[:, :dims]
    got = euclidean_labels(points, tolerance_m)
    want = ref.euclidean_labels(points, tolerance_m)
    assert want.max() >= 2 and np.array_equal(got, want)


def test_euclidean_labels_join_points_exactly_at_the_tolerance_and_no_further():
    points = np.array([[0.0, 0.0], [0.5, 0.0], [1.0, 0.0], [1.5000001, 0.0], [0.0, 0.5]])
    assert euclidean_labels(points, 0.5).tolist() == ref.euclidean_labels(points, 0.5).tolist() == [0, 0, 0, 1, 0]


@pytest.mark.parametrize("n", [1, 2, 3, 4, 57, 200, 201])
def test_a_faces_median_is_numpys_median_of_its_points(n):
    """``kernels.face_median`` takes the points of one unit's face within bounds along it and gives
    ``np.median``'s value of their coordinate (repeated values too), and none for a face without points."""
    rng = np.random.default_rng(n)
    for rounded in (False, True):
        q = rng.normal(size=(2 * n, 2)) * 3.0
        q = np.round(q, 1) if rounded else q
        unit = np.repeat(np.array([0, 1], dtype=np.int8), n)
        face = rng.integers(-1, 4, 2 * n).astype(np.int8)
        for (u, f, column), along in itertools.product(
            ((0, 2, 1), (1, 0, 0), (1, 3, 1)), ((-np.inf, np.inf), (-1.0, 2.0))
        ):
            on = (unit == u) & (face == f) & (q[:, 0] >= along[0]) & (q[:, 0] <= along[1])
            got = kernels.face_median(q, column, unit, face, u, f, along)
            assert got[0] == np.count_nonzero(on)
            if got[0]:
                assert got[1] == float(np.median(q[on, column]))
        assert kernels.face_median(q, 0, unit, face, 2, 0, (-np.inf, np.inf)) == (0, pytest.approx(np.nan, nan_ok=True))


def test_ground_hypotheses_are_the_numpy_hypotheses():
    """``kernels.plane_hypotheses`` (behind Region._hypotheses) gives numpy's normals and offsets to
    the bit: degenerate triples (a repeated point) and steep planes dropped."""
    from i2v_loc.stages.region import Region

    def reference(a, b, c, tilt_deg):
        normals = np.cross(b - a, c - a)
        norms = np.linalg.norm(normals, axis=1)
        ok = norms > 1e-9
        normals = normals[ok] / norms[ok, None]
        normals *= np.sign(normals[:, 2:3] + 1e-12)
        admissible = normals[:, 2] >= np.cos(np.radians(tilt_deg))
        normals = normals[admissible]
        return normals, -np.einsum("ij,ij->i", normals, a[ok][admissible])

    rng = np.random.default_rng(4)
    region = Region(RegionParams())
    kept = 0
    for _ in range(200):
        sample = rng.normal(0, 10, (500, 3))
        sample[:, 2] *= rng.choice([0.01, 0.3, 1.0])
        sample[7] = sample[8]  # a degenerate triple when both are drawn
        state = region.rng.bit_generator.state
        normals, offsets = region._hypotheses(sample)
        region.rng.bit_generator.state = state
        idx = region.rng.integers(0, len(sample), size=(region.params.ransac_iterations, 3))
        want = reference(sample[idx[:, 0]], sample[idx[:, 1]], sample[idx[:, 2]], region.params.max_ground_tilt_deg)
        assert np.array_equal(normals, want[0]) and np.array_equal(offsets, want[1])
        kept += len(normals)
    assert 0 < kept < 200 * region.params.ransac_iterations  # some planes kept, some dropped as too steep


def test_the_fullest_bin_is_the_numpy_histograms():
    """``kernels.fullest_bin`` (a wall's Hough vote) finds the bin a histogram of all the directions'
    bins at once finds, ties going to the first direction, then the lowest bin."""
    from i2v_loc.stages.vehicle_tracker import WALL_LINE_M, _line_normals

    normals = _line_normals()
    rng = np.random.default_rng(3)
    for trial in range(500):
        n = int(rng.integers(5, 300))
        points = rng.normal(0.0, 3.0, (n, 2))
        if trial % 3 == 0:
            points = np.round(points, 1)  # on the bins' edges, and ties
        if trial % 5 == 0:
            points[: n // 2, 0] = rng.uniform(-4.0, -3.9, n // 2)  # a wall
        bins = np.floor(points @ normals.T / WALL_LINE_M).astype(np.int64)
        low = bins.min(axis=0)
        span = int((bins.max(axis=0) - low).max()) + 1
        want = divmod(int(np.argmax(np.bincount((bins - low + np.arange(len(normals)) * span).ravel()))), span)
        got = kernels.fullest_bin(np.ascontiguousarray(points @ normals.T), WALL_LINE_M)
        assert tuple(int(v) for v in got) == want
