"""The compiled kernels of the hinged fit give what the plain numpy implementation they replaced
gave: kept below as the reference. The nearest faces (kernels.nearest_faces behind hinged_fit.faces,
kernels.fit_faces with fitted dimensions) on random points around, inside, above and under rigid
and articulated models at many hitch angles; the reweighted Gauss-Newton loop (kernels.irls) and
the covariance (kernels.fit_covariance) bit for bit (the tracker follows every last bit of a fit)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from hinged_points import vehicle_points

from i2v_loc.params import Params
from i2v_loc.stages import hinged_fit, kernels
from i2v_loc.stages.hinged_fit import Prior, faces
from i2v_loc.stages.vehicle_model import VehicleModel

PARAMS = Params()
TOP_BAND_M = PARAMS.articulated.fit_top_band_m


# ----------------------------------------------------------------------------- the numpy reference


def ref_face_table(v, model, trailer_slack_m):
    x, y, yaw1 = float(v[0]), float(v[1]), float(v[2])
    c1, s1 = math.cos(yaw1), math.sin(yaw1)
    units = [(model.tractor, x, y, yaw1, 0.0)]
    if model.trailer is not None:
        m = model.kingpin_behind_axle_m
        units.append((model.trailer, x - m * c1, y - m * s1, yaw1 + float(v[3]), trailer_slack_m))
    rows = []
    for u, (box, ox, oy, yaw, slack) in enumerate(units):
        c, s = math.cos(yaw), math.sin(yaw)
        half_w, half_l = box.width_m / 2, box.length_m / 2 + slack / 2
        mid_x = box.center_x_m - slack / 2
        for nx, ny, mx, my, half in (
            (1.0, 0.0, box.front_m, 0.0, half_w),
            (-1.0, 0.0, box.rear_m, 0.0, half_w),
            (0.0, 1.0, mid_x, half_w, half_l),
            (0.0, -1.0, mid_x, -half_w, half_l),
        ):
            big_nx, big_ny = c * nx - s * ny, s * nx + c * ny
            cx, cy = ox + c * mx - s * my, oy + s * mx + c * my
            lever = model.kingpin_behind_axle_m * (-big_nx * s1 + big_ny * c1) if u == 1 else 0.0
            rows.append(
                (
                    big_nx,
                    big_ny,
                    -big_ny,
                    big_nx,
                    big_nx * cx + big_ny * cy,
                    -big_ny * cx + big_nx * cy,
                    half,
                    -ny * mx + nx * my,
                    lever,
                    u,
                )
            )
    return np.array(rows)


def ref_faces(v, xy, z_rel, model, top_band_m, trailer_slack_m=0.0, chassis_gap_m=hinged_fit.CHASSIS_GAP_M):
    """Returns (residual, jacobian, unit, distance, face)."""
    table = ref_face_table(v, model, trailer_slack_m)
    n = len(xy)
    perp = xy @ table[:, 0:2].T - table[:, 4]
    along = xy @ table[:, 2:4].T - table[:, 5]
    excess = np.maximum(np.abs(along) - table[:, 6], 0.0)
    dist2 = perp * perp + excess * excess
    boxes = model.boxes
    roof = np.zeros((n, len(boxes)), dtype=bool)
    for u, box in enumerate(boxes):
        cols = slice(4 * u, 4 * u + 4)
        inside = perp[:, cols].max(axis=1) <= 0.0
        if u == 1 and trailer_slack_m > 0:
            inside = np.maximum(perp[:, [4, 6, 7]].max(axis=1), perp[:, 5] - trailer_slack_m) <= 0.0
        flat = (np.abs(z_rel - box.top_m) <= top_band_m) | (z_rel < box.floor_m - top_band_m)
        roof[:, u] = flat & inside
        dist2[roof[:, u], cols] = 0.0
        dist2[z_rel > box.top_m + top_band_m, cols] = np.inf
    pick = np.argmin(dist2, axis=1)
    rows = np.arange(n)
    face = table[pick]
    unit = face[:, 9].astype(np.int64)
    residual = perp[rows, pick]
    lever = along[rows, pick] + face[:, 7]
    jac = np.zeros((n, len(v)))
    jac[:, 0], jac[:, 1], jac[:, 2] = -face[:, 0], -face[:, 1], lever + face[:, 8]
    if model.articulated:
        jac[:, 3] = np.where(unit == 1, lever, 0.0)
    on_roof = roof[rows, unit]
    if model.articulated:  # the chassis behind the cab: low, within its width, its rear face nearest
        cab = model.tractor
        on_roof |= (
            (pick == 1)
            & (perp[:, 1] > chassis_gap_m)
            & (np.abs(along[:, 1]) <= table[1, 6])
            & (z_rel < cab.floor_m + cab.height_m / 2)
        )
    residual[on_roof] = 0.0
    jac[on_roof] = 0.0
    return residual, jac, unit, np.sqrt(dist2[rows, pick]), np.where(on_roof, -1, pick % 4)


def ref_faces_of(v, xy, z_rel, prior, top_band_m):
    """The reference of ``hinged_fit._faces_of`` with fitted dimensions (the model rebuilt from them)."""
    model = prior.model
    if prior.fits_length:
        model = model.with_boxes(model.tractor, replace(model.trailer, length_m=float(v[4])))
    if prior.fits_kingpin:
        trailer = replace(model.trailer, front_m=float(v[-1]))
        model = replace(model.with_boxes(model.tractor, trailer), kingpin_behind_axle_m=float(v[-2]))
    residual, jac, unit, distance, face = ref_faces(v[:4], xy, z_rel, model, top_band_m, 0.0, prior.chassis_gap_m)
    columns = [jac]
    if prior.fits_length:
        columns.append(-((unit == 1) & (face == hinged_fit.REAR)).astype(float))
    if prior.fits_kingpin:
        trailer = (unit == 1) & (face >= 0)
        for yaw, sign in ((v[2], -1.0), (v[2] + v[3], 1.0)):
            along = jac[:, 0] * np.cos(yaw) + jac[:, 1] * np.sin(yaw)
            columns.append(np.where(trailer, sign * along, 0.0))
    return residual, np.column_stack(columns), unit, distance, face


# ----------------------------------------------------------------------------- cases


def models() -> list[VehicleModel]:
    articulated = [VehicleModel.from_config(name, config) for name, config in PARAMS.vehicles.items()]
    return articulated + [VehicleModel.rigid("bus", 11.6, 2.55, 3.1), VehicleModel.rigid("van", 5.2, 2.0, 2.4, 0.3)]


def random_points(model: VehicleModel, v: np.ndarray, seed: int, n: int = 3000) -> tuple[np.ndarray, np.ndarray]:
    """xy anywhere around and inside the boxes (3 m beyond them); z spread over under the floor,
    the body, the roof band and above every roof, plus points exactly at the band's edges."""
    rng = np.random.default_rng(seed)
    reach = max(abs(b.front_m) + b.length_m for b in model.boxes) + abs(model.kingpin_behind_axle_m) + 3.0
    xy = v[:2] + rng.uniform(-reach, reach, (n, 2))
    top = max(b.top_m for b in model.boxes)
    z = rng.uniform(-0.5, top + 1.0, n)
    edges = [b.top_m + s * TOP_BAND_M for b in model.boxes for s in (-1.0, 1.0)]
    edges += [b.floor_m - TOP_BAND_M for b in model.boxes]
    pick = rng.random(n) < 0.15
    z[pick] = rng.choice(edges, pick.sum())
    on_faces = vehicle_points(model, *v[:3], v[3] if model.articulated else 0.0, noise_m=0.05, seed=seed)[::5]
    return np.vstack([xy, on_faces[:, :2]]), np.r_[z, on_faces[:, 2]]


def assert_same(got, want) -> None:
    """The same nearest distance for every point (whichever face is picked, a wrong pick is
    farther), and the same face, unit, residual and Jacobian row wherever the pick is the same.
    Beyond a box's corner two faces can be equally near: the last bit of the distances (how the
    BLAS under numpy rounds, fused multiply-add or not) decides which one the reference picks."""
    residual, jac, unit, distance, face = want
    for a, b, name in ((got.residual, residual, "residual"), (got.jacobian, jac, "jacobian")):
        assert a.dtype == b.dtype and a.shape == b.shape, name
    assert got.unit.dtype == unit.dtype and got.face.dtype == face.dtype and got.distance.shape == distance.shape
    np.testing.assert_allclose(got.distance, distance, rtol=0.0, atol=1e-9)  # inf where the reference has inf
    same = (got.face == face) & (got.unit == unit)
    assert same.sum() >= 0.99 * len(same)
    np.testing.assert_allclose(got.residual[same], residual[same], rtol=0.0, atol=1e-9)
    np.testing.assert_allclose(got.jacobian[same], jac[same], rtol=0.0, atol=1e-9)


@pytest.mark.parametrize("model", models(), ids=lambda m: m.name)
@pytest.mark.parametrize("hitch_deg", [0.0, 45.0, -45.0, 80.0, -80.0])
@pytest.mark.parametrize("slack_m", [0.0, 1.5])
def test_kernel_faces_are_the_numpy_faces(model, hitch_deg, slack_m):
    seed = int(hitch_deg) + 200 + int(10 * slack_m) + 7 * len(model.name)
    v = np.array([3.0, -2.0, 0.7, np.radians(hitch_deg)])[: 4 if model.articulated else 3]
    xy, z = random_points(model, v, seed)
    got = faces(v, xy, z, model, TOP_BAND_M, slack_m)
    want = ref_faces(v, xy, z, model, TOP_BAND_M, slack_m)
    assert_same(got, want)
    # every branch was exercised: roof / undercarriage points, points above every roof, both units
    assert (got.face == -1).any() and np.isinf(got.distance).any() and (got.face >= 0).any()
    assert set(np.unique(got.unit)) == set(range(len(model.boxes)))


def test_a_point_over_every_roof_takes_the_first_face_like_argmin():
    model = models()[2]
    v = np.array([0.0, 0.0, 0.3, 0.4])
    xy = np.array([[0.0, 0.0], [50.0, 3.0], [-4.0, 1.0]])
    z = np.full(3, 10.0)
    got = faces(v, xy, z, model, TOP_BAND_M)
    assert_same(got, ref_faces(v, xy, z, model, TOP_BAND_M))
    assert np.isinf(got.distance).all() and (got.face == 0).all() and (got.unit == 0).all()


@pytest.mark.parametrize("model", [models()[0], models()[3]], ids=lambda m: m.name)
def test_no_points_give_empty_faces(model):
    v = np.zeros(4 if model.articulated else 3)
    got = faces(v, np.zeros((0, 2)), np.zeros(0), model, TOP_BAND_M, 1.0)
    assert_same(got, ref_faces(v, np.zeros((0, 2)), np.zeros(0), model, TOP_BAND_M, 1.0))
    assert got.jacobian.shape == (0, len(v))


@pytest.mark.parametrize("free_length, free_kingpin", [(True, False), (False, True), (True, True)])
@pytest.mark.parametrize("hitch_deg", [0.0, 45.0, -80.0])
def test_fitted_dimensions_move_the_faces_like_a_rebuilt_model(free_length, free_kingpin, hitch_deg):
    model = models()[2]
    prior = Prior(
        3.0, -2.0, 0.7, np.radians(hitch_deg), model, free_trailer_length=free_length, free_kingpin=free_kingpin
    )
    v = np.r_[prior.vector, [9.1] if free_length else [], [0.4, 1.3] if free_kingpin else []]  # not the model's
    xy, z = random_points(model, v, int(hitch_deg) + 300)
    got = kernel_faces_of(v, xy, z, prior)
    assert_same(got, ref_faces_of(v, xy, z, prior, TOP_BAND_M))
    assert ((got.unit == 1) & (got.face == hinged_fit.REAR)).any() and got.jacobian.shape[1] == len(v)


@pytest.mark.parametrize("hitch_deg", [0.0, 45.0, -80.0])
def test_a_fitted_cab_length_moves_the_cabs_rear_face_like_a_rebuilt_model(hitch_deg):
    """The joint hinge fit's layout: pose, kingpin, trailer front, cab length (not the model's)."""
    model = models()[2]
    prior = Prior(3.0, -2.0, 0.7, np.radians(hitch_deg), model, free_kingpin=True)
    v = np.r_[prior.vector, [0.4, 1.3, model.tractor.length_m - 0.4]]
    xy, z = random_points(model, v, int(hitch_deg) + 400)
    geometry = hinged_fit._geometry(v, model, 0.0)
    got = hinged_fit._Faces(
        *kernels.fit_faces(
            np.ascontiguousarray(xy), np.ascontiguousarray(z), geometry, TOP_BAND_M, 4, False, True, True, v,
            prior.chassis_gap_m,
        )
    )  # fmt: skip
    rebuilt = replace(prior, model=model.with_boxes(replace(model.tractor, length_m=float(v[-1])), model.trailer))
    residual, jac, unit, distance, face = ref_faces_of(v[:-1], xy, z, rebuilt, TOP_BAND_M)
    cab_rear = (unit == 0) & (face == hinged_fit.REAR)
    assert_same(got, (residual, np.column_stack([jac, -cab_rear.astype(float)]), unit, distance, face))
    assert cab_rear.any() and got.jacobian.shape[1] == len(v)


def test_fit_labels_are_the_numpy_masks():
    """A fit's unit and face labels and its count of explained points on the trailer's rear face."""
    rng = np.random.default_rng(9)
    n = 2000
    unit, face = rng.integers(0, 2, n), rng.integers(-1, 4, n)
    distance, residual = rng.exponential(0.2, n), rng.normal(0, 0.2, n)
    units, faces, rear = kernels.fit_labels(unit, face, distance, residual, 0.15, hinged_fit.REAR)
    explained = distance <= 0.15
    assert np.array_equal(units, np.where(explained, unit, -1)) and units.dtype == np.int8
    assert np.array_equal(faces, np.where(np.abs(residual) <= 0.15, face, -1)) and faces.dtype == np.int8
    assert rear == np.count_nonzero(explained & (unit == 1) & (face == hinged_fit.REAR)) > 50


def kernel_faces_of(v, xy, z, prior):
    geometry = hinged_fit._geometry(v, prior.model, 0.0)
    xy, z = np.ascontiguousarray(xy, dtype=float), np.ascontiguousarray(z, dtype=float)
    return hinged_fit._Faces(
        *kernels.fit_faces(
            xy, z, geometry, TOP_BAND_M, 4, prior.fits_length, prior.fits_kingpin, False, v, prior.chassis_gap_m
        )
    )


def ref_fit(points, prior, params, iterations, start_scale_m):
    """The numpy loop ``kernels.irls`` replaced, and the covariance of ``kernels.fit_covariance``:
    (solution, covariance, residual of the last step, the fitted trailer length's standard deviation)."""
    sample = hinged_fit.thin_by_unit(points, params.fit_max_points, prior)
    xy, z_rel = np.ascontiguousarray(sample[:, :2]), sample[:, 2] - prior.ground_z_m
    v0 = np.concatenate([prior.vector, prior.extra])
    scale = params.fit_loss_scale_m
    sigmas = hinged_fit._weak_prior_sigmas(prior)
    prior_weights = (scale / sigmas) ** 2
    prior_info = np.diag(prior_weights)
    v = v0.copy()
    for k in range(iterations):
        c = max(scale, start_scale_m * 0.5**k)
        if prior.extra:
            residual, jacobian, *_ = ref_faces_of(v, xy, z_rel, prior, params.fit_top_band_m)
        else:
            residual, jacobian, *_ = ref_faces(
                v, xy, z_rel, prior.model, params.fit_top_band_m, prior.trailer_slack_m, prior.chassis_gap_m
            )
        w = 1.0 / (1.0 + (residual / c) ** 2)
        jw = jacobian * w[:, None]
        step = np.linalg.solve(jw.T @ jacobian + prior_info, -(jw.T @ residual + prior_weights * (v - v0)))
        v = v + step
        if prior.fits_length:
            v[4] = np.clip(v[4], *hinged_fit.TRAILER_LENGTH_RANGE_M)
        if prior.fits_kingpin:
            v[-2] = np.clip(v[-2], *hinged_fit.KINGPIN_RANGE_M)
        if c == scale and max(abs(step[0]), abs(step[1])) < 1e-3 and max(abs(step[2:4])) < 1e-4:
            break
    w = 1.0 / (1.0 + (residual / scale) ** 2)
    inliers = np.abs(residual) <= params.fit_inlier_m
    sigma2 = max(np.median(residual[inliers] ** 2) / 0.455 if inliers.any() else scale**2, params.fit_noise_floor_m**2)
    info = (jacobian * w[:, None]).T @ jacobian / sigma2 + np.diag(1.0 / sigmas**2)
    position, angle = params.fit_position_floor_m, math.radians(params.fit_angle_floor_deg)
    floor = np.array([position, position, angle, angle][: min(len(sigmas), 4)])
    full = np.linalg.inv(info)
    length_std = math.sqrt(full[4, 4]) if prior.fits_length else None
    return v, full[:4, :4] + np.diag(floor**2), residual, length_std


FIT_CASES = [
    (model, free)
    for model in models()
    for free in ("pose", "slack", "length", "kingpin", "both")
    if model.articulated or free in ("pose", "slack")  # a rigid box fits its pose only
]


def _same(a, b) -> bool:
    """Equal to rounding: numpy's and numba's (scipy's) LAPACK builds take different kernels on some
    processors (to the bit where they were written, 1e-15 apart on an AVX-512 Xeon)."""
    return np.allclose(a, b, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("model, free", FIT_CASES, ids=lambda c: getattr(c, "name", c))
@pytest.mark.parametrize("hitch_deg", [0.0, 35.0, -70.0])
def test_the_compiled_fit_is_the_numpy_fit(model, free, hitch_deg):
    """Whole fits of the pose (and trailer length) agree to rounding. With the kingpin free, 7
    parameters of which two are weakly seen, a rounding difference in the solve flips a point's
    nearest face a step later and the fits part by centimetres: their first step is compared."""
    hitch = np.radians(hitch_deg) if model.articulated else 0.0
    points = vehicle_points(model, 3.0, -2.0, 0.7, hitch, noise_m=0.04, seed=100 + int(hitch_deg) + 17 * len(free))
    rng = np.random.default_rng(len(model.name))
    clutter = np.column_stack([rng.uniform(-15, 15, (60, 2)) + [3.0, -2.0], rng.uniform(0, 4, 60)])
    points = np.vstack([points, clutter])
    # started off the truth, as a prediction is (and as the start's placed models are, by metres)
    prior = Prior(
        3.25,
        -1.8,
        0.7 + np.radians(4.0),
        hitch + np.radians(6.0) if model.articulated else 0.0,
        model,
        trailer_slack_m=1.5 if free == "pose" else 0.0,
        free_trailer_length=free in ("length", "both"),
        free_kingpin=free in ("kingpin", "both"),
    )
    params = PARAMS.articulated
    runs = ((params.fit_iterations, params.fit_start_scale_m), (4, 0.8), (20, 0.8))
    if prior.fits_kingpin:
        runs = ((1, params.fit_start_scale_m), (1, 0.8))
    for iterations, start_scale_m in runs:
        m = hinged_fit.fit(points, prior, params, iterations, start_scale_m)
        v, covariance, residual, length_std = ref_fit(points, prior, params, iterations, start_scale_m)
        assert _same(m.vector, np.r_[v[:2], hinged_fit.wrap_rad(v[2 : len(m.vector)])])
        assert _same(m.covariance, covariance)
        cost = float(np.mean(np.log1p((residual / params.fit_loss_scale_m) ** 2))) * params.fit_loss_scale_m**2 / 2
        assert _same(m.cost, cost)
        if prior.fits_length:
            assert _same(m.trailer_length_m, v[4])
            assert _same(m.trailer_length_std_m, length_std)
        if prior.fits_kingpin:
            assert _same([m.kingpin_m, m.trailer_front_m], v[-2:])


# ----------------------------------------------------------------------------- the tracker's gate


def ref_box_distance(points, prior):
    """The numpy gate the kernel replaced: per unit frame, the distance to its box, the nearer."""
    from i2v_loc.stages.unit_frames import unit_frames

    model = prior.model
    best = np.full(len(points), np.inf)
    for box, slack, q in zip(model.boxes, (0.0, prior.trailer_slack_m), unit_frames(points, prior.vector, model)):
        dx = np.maximum(np.maximum(box.rear_m - slack - q[:, 0], q[:, 0] - box.front_m), 0.0)
        dy = np.maximum(np.abs(q[:, 1]) - box.width_m / 2, 0.0)
        best = np.minimum(best, np.hypot(dx, dy))
    return best


@pytest.mark.parametrize("hitch_deg", [-70.0, -20.0, 0.0, 35.0, 90.0])
@pytest.mark.parametrize("slack_m", [0.0, 3.5])
def test_the_gate_gives_each_point_to_the_nearest_track_within_the_margin(hitch_deg, slack_m):
    """Two overlapping vehicles' priors (an articulated one and a rigid bus beside it): each point
    goes to the track whose boxes are nearer by the numpy distances, within the gate's margin;
    a tie to the first."""
    from i2v_loc.stages.vehicle_tracker import VehicleTracker

    rng = np.random.default_rng(int(hitch_deg * 10 + slack_m * 100) % 2**31)
    man = VehicleModel.from_config("man_tgx", PARAMS.vehicles["man_tgx"])
    priors = [
        Prior(3.0, -2.0, 0.7, math.radians(hitch_deg), man, 0.0, slack_m),
        Prior(6.0, 1.5, 0.9, 0.0, VehicleModel.rigid("rigid", 11.6, 2.55, 3.1), 0.0, 0.0),
    ]
    points = np.column_stack([rng.uniform(-25, 25, (4000, 2)), rng.uniform(0, 4, 4000)]).astype(np.float32)
    tracker = VehicleTracker(PARAMS.articulated, PARAMS.vehicles)
    margin = PARAMS.articulated.gate_margin_m
    got = tracker._claim(points, priors, [False, False])
    distances = np.array([ref_box_distance(points.astype(float), prior) for prior in priors])
    want = np.where(distances.min(axis=0) <= margin, np.argmin(distances, axis=0), -1)
    assert np.array_equal(got, want)
    for track in (-1, 0, 1):  # inside, beside and far from each
        assert np.count_nonzero(got == track) > 30
    assert np.count_nonzero((distances[0] == 0) & (distances[1] == 0)) > 0  # both inside: the first's


def test_the_strided_pick_is_numpys_stride_over_each_part():
    """``strided_pick`` against ``np.linspace(0, n - 1, k).astype(int)`` over the rows of each part
    (the stride ``hinged_fit.thin`` takes), for random masks and counts, 0 and 1 included."""
    rng = np.random.default_rng(0)
    for _ in range(500):
        mask = rng.random(int(rng.integers(1, 3000))) < rng.random()
        parts = np.flatnonzero(mask), np.flatnonzero(~mask)
        counts = [int(rng.integers(0, len(p) + 1)) for p in parts]
        expected = np.concatenate([p[np.linspace(0, len(p) - 1, k).astype(np.int64)] for p, k in zip(parts, counts)])
        np.testing.assert_array_equal(kernels.strided_pick(mask, *counts), expected)


def test_the_unit_masks_and_frames_are_the_numpy_ones():
    """``in_first_box_only`` is the first box's rotated-rectangle test and not the second's,
    ``to_frame`` / ``owned_to_frame`` turn points into a frame as the numpy rotation does, to the
    bit, and ``count_beside`` counts the points up to a place along the axis and out past an edge."""
    rng = np.random.default_rng(5)
    for trial in range(50):
        points = rng.uniform(-8.0, 8.0, (int(rng.integers(0, 400)), 3)).astype(np.float32 if trial % 2 else float)
        boxes = [
            np.array([*rng.uniform(-2, 2, 2), math.cos(a), math.sin(a), *rng.uniform(0.5, 4.0, 2)])
            for a in rng.uniform(-3, 3, 2)
        ]

        def inside(points, box):
            dx, dy = points[:, 0].astype(float) - box[0], points[:, 1].astype(float) - box[1]
            return (np.abs(box[2] * dx + box[3] * dy) <= box[4]) & (np.abs(box[2] * dy - box[3] * dx) <= box[5])

        out = np.empty(len(points), dtype=bool)
        n = kernels.in_first_box_only(points, *boxes, out)
        np.testing.assert_array_equal(out, inside(points, boxes[0]) & ~inside(points, boxes[1]))
        assert n == np.count_nonzero(out)
        origin, yaw = rng.uniform(-3, 3, 2), float(rng.uniform(-3, 3))
        c, s = np.cos(yaw), np.sin(yaw)
        d = points[:, :2] - origin
        want = np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]])
        np.testing.assert_array_equal(kernels.to_frame(points, *origin, c, s), want)
        owner = rng.integers(-1, 3, len(points))
        rows, q = kernels.owned_to_frame(points, owner, 1, *origin, c, s)
        np.testing.assert_array_equal(rows, np.flatnonzero(owner == 1))
        np.testing.assert_array_equal(q, want[rows])
        up_to, edge = rng.uniform(-6.0, 2.0), rng.uniform(0.5, 3.0)
        beside = (want[:, 0] <= up_to) & (np.abs(want[:, 1]) >= edge)
        assert kernels.count_beside(want, up_to, edge) == np.count_nonzero(beside)


def ref_rear_face(q, z_rel, unit, face, heights, front, width, inlier, beside, max_gap, end_band, middle_below, span):
    """The numpy code ``kernels.rear_face`` replaced: (points in the band, the kept points hindmost
    last, whether the rear face is seen, its middle's median x)."""
    tall = (z_rel >= heights[0]) & (z_rel <= heights[1]) & (q[:, 0] <= front)
    side = np.abs(q[:, 1]) - width / 2
    band = tall & (side <= inlier)
    if band.sum() < 5:
        return int(band.sum()), None, False, None
    near = tall & (unit != 0) & (side >= beside[0]) & (side <= beside[1])
    left, right = q[near & (q[:, 1] > 0), 0], q[near & (q[:, 1] < 0), 0]
    order = np.argsort(-q[band][:, 0], kind="stable")
    qb, zb = q[band][order], z_rel[band][order]
    walled = np.zeros(len(qb) - 1, dtype=bool)
    if len(left) and len(right):  # a face running on past both sides: a wall
        walled = (np.abs(qb[1:, 0, None] - left[None, :]).min(axis=1) <= end_band / 2) & (
            np.abs(qb[1:, 0, None] - right[None, :]).min(axis=1) <= end_band / 2
        )
    cut = np.flatnonzero((-np.diff(qb[:, 0]) > max_gap) | walled)
    keep = cut[0] + 1 if len(cut) else len(qb)
    qb, zb = qb[:keep], zb[:keep]
    at_end = qb[:, 0] <= qb[-1, 0] + end_band
    end = qb[at_end]
    middle = end[(np.abs(end[:, 1]) <= width / 4) & (zb[at_end] < middle_below)]
    seen = len(middle) >= 2 and np.ptp(end[:, 1]) >= span
    return int(band.sum()), qb, bool(seen), float(np.median(middle[:, 0])) if seen else None


def test_the_rear_face_kernel_is_the_numpy_one():
    """``kernels.rear_face`` against the numpy code it replaced on random trailers' points: a body
    with gaps, its rear face or none, a wall across its rear running past both sides or one."""
    rng = np.random.default_rng(11)
    width, heights, front = 2.5, (0.6, 4.4), 1.6
    outcomes = set()
    for trial in range(300):
        n = int(rng.integers(3, 300))
        x = rng.uniform(-15.0, 1.5, n)
        if trial % 3 == 1:
            x[x < -6.0] -= 1.5  # a gap in the body
        y = rng.choice([-1.0, 1.0], n) * width / 2 + rng.normal(0.0, 0.05, n)
        face_rows = rng.random(n) < (0.3 if trial % 3 else 0.0)  # points across the rear face
        y[face_rows] = rng.uniform(-width / 2, width / 2, face_rows.sum())
        x[face_rows] = x.min()
        if trial % 7 == 0:
            x[rng.random(n) < 0.1] = x.min() - 3.0  # an object behind it
        if trial % 4 == 0:  # a wall level with the rear, past both sides (or one)
            wall = rng.random(n) < 0.2
            y[wall] = rng.choice([-1.0, 1.0] if trial % 8 else [1.0], wall.sum()) * rng.uniform(1.6, 2.0, wall.sum())
            x[wall] = x.min() + rng.normal(0.0, 0.05, wall.sum())
        q = np.column_stack([np.round(x, 2 if trial % 5 == 0 else 6), y])  # ties too
        z_rel = rng.uniform(0.0, 5.0, n)
        unit = rng.choice(np.array([-1, 0, 1], dtype=np.int8), n, p=[0.1, 0.1, 0.8])
        face = rng.integers(-1, 4, n).astype(np.int8)
        args = (q, z_rel, unit, face, heights, front, width / 2, 0.3, (0.35, 0.8), 1.0, 0.4, 4.0, 0.6 * width)
        n_band, rows, seen, middle = kernels.rear_face(*args)
        want = ref_rear_face(q, z_rel, unit, face, heights, front, width, *args[7:])
        assert n_band == want[0]
        if want[1] is None:
            continue
        np.testing.assert_array_equal(q[rows, 0], want[1][:, 0])  # the same kept points, in order
        assert seen == want[2] and (middle == want[3] if seen else True)
        outcomes.add((seen, len(rows) < n_band))
    assert outcomes == {(False, False), (False, True), (True, False), (True, True)}  # seen or not, cut or not
