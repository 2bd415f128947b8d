"""The one-trailer kinematic UKF: its model against the simulator's, reversing, standstill,
jackknife warning, innovation gate."""

from __future__ import annotations

import numpy as np
import pytest

from i2v_loc.params import Params
from i2v_loc.sim.kinematics import Articulation, step
from i2v_loc.stages.kinematic_filter import CURVATURE, HITCH, SPEED, KinematicFilter, propagate

PARAMS = Params()
VOLVO = PARAMS.vehicles["volvo_fh"]
ART = Articulation.from_vehicle(VOLVO)
R = np.diag([0.03, 0.03, np.radians(0.3), np.radians(0.3)]) ** 2
HOLD_M = PARAMS.articulated.reverse_hold_m
NEVER_HOLDS_M = 1e12  # the kinematics alone (the simulator's driver steers as it likes)


def new_filter(truth: np.ndarray, speed: float = 0.0) -> KinematicFilter:
    z = np.array([truth[0], truth[1], truth[2], truth[3] - truth[2]])
    return KinematicFilter(
        z, R, 0.0, ART.hitch_behind_axle_m, ART.trailer_hitch_to_axle_m, True, PARAMS.articulated, speed
    )


def run(speed: float, steer: float, seconds: float, seed: int = 0):
    """Simulated truth (x, y, ψ1, ψ2) and the filter fed noisy measurements at 10 Hz; per frame
    (truth, filter state)."""
    rng = np.random.default_rng(seed)
    truth = np.array([0.0, 0.0, 0.3, 0.3 + np.radians(10.0)])
    f = new_filter(truth)
    out = []
    for k in range(1, int(seconds * 10) + 1):
        truth = step(truth, speed, steer, ART, 0.1)
        f.predict(k * 0.1)
        z = np.array([truth[0], truth[1], truth[2], truth[3] - truth[2]]) + rng.normal(0, np.sqrt(np.diag(R)))
        f.update(z, R)
        out.append((truth.copy(), f.state))
    return out


def angle_deg(a: float) -> float:
    return float(np.degrees(np.arctan2(np.sin(a), np.cos(a))))


def test_propagation_matches_the_simulator_kinematics():
    truth = np.array([1.0, 2.0, 0.2, 0.5])
    speed, steer = 2.5, 0.25
    state = np.array([1.0, 2.0, 0.2, speed, np.tan(steer) / ART.wheelbase_m, 0.3])
    for _ in range(50):
        truth = step(truth, speed, steer, ART, 0.1)
        state = propagate(state, 0.1, ART.hitch_behind_axle_m, ART.trailer_hitch_to_axle_m, True, NEVER_HOLDS_M)
    assert np.hypot(*(state[:2] - truth[:2])) < 1e-3
    assert abs(angle_deg(state[2] - truth[2])) < 1e-3
    assert abs(angle_deg(state[HITCH] - (truth[3] - truth[2]))) < 1e-2
    assert abs(angle_deg(truth[3] - truth[2]) - np.degrees(0.3)) > 5  # the hitch did change


def rms(values) -> float:
    return float(np.sqrt(np.mean(np.square(values))))


@pytest.mark.parametrize("hitch_deg", [-60.0, -25.0, 0.0, 10.0, 45.0])
def test_at_the_holding_curvature_the_hitch_holds_still_at_any_speed(hitch_deg):
    from i2v_loc.stages import kernels

    hitch = np.radians(hitch_deg)
    kingpin, axle = ART.hitch_behind_axle_m, ART.trailer_hitch_to_axle_m
    curvature = kernels.holding_curvature(hitch, kingpin, axle)
    for speed in (-2.0, -0.3, 1.5):
        assert abs(kernels.hitch_rate(speed, curvature, hitch, kingpin, axle)) < 1e-12
        steer = np.arctan(curvature * ART.wheelbase_m)  # the simulator's own kinematics agree
        truth = step(np.array([0.0, 0.0, 0.4, 0.4 + hitch]), speed, steer, ART, 0.1)
        assert abs(angle_deg(truth[3] - truth[2]) - hitch_deg) < 1e-3
    if hitch_deg:
        assert np.sign(curvature) == -np.sign(hitch)


def reverse_with_cab_hidden(
    params, speed: float, start_hitch: float, target, frames: int, seen_frames: int, seed: int
) -> np.ndarray:
    """A driver reversing at ``speed`` from ``start_hitch``, each frame ``k`` steering towards the
    hitch ``target(k, hitch)`` (the curvature that holds it and a correction towards it), seen
    whole for ``seen_frames`` frames, then with the cab hidden: the filter gets the trailer's yaw
    and the kingpin's position only. Per hidden frame, the filter's hitch error (deg)."""
    rng = np.random.default_rng(seed)
    kingpin, axle = ART.hitch_behind_axle_m, ART.trailer_hitch_to_axle_m
    truth = np.array([0.0, 0.0, 0.3, 0.3 + start_hitch])
    f = KinematicFilter(np.array([0.0, 0.0, 0.3, start_hitch]), R, 0.0, kingpin, axle, True, params, speed)
    errors = []
    for k in range(1, frames + 1):
        hitch = truth[3] - truth[2]
        goal = target(k, hitch)
        curvature = -np.sin(goal) / (axle + kingpin * np.cos(goal)) - 2.0 * (hitch - goal) / axle
        steer = np.clip(np.arctan(curvature * ART.wheelbase_m), -np.radians(35.0), np.radians(35.0))
        truth = step(truth, speed, steer, ART, 0.1)
        f.predict(k * 0.1)
        z = np.array([truth[0], truth[1], truth[2], truth[3] - truth[2]]) + rng.normal(0, np.sqrt(np.diag(R)))
        if k <= seen_frames:
            f.update(z, R)
            continue
        fuse_without_the_cab(f, z, kingpin, truth[2])
        errors.append(angle_deg(f.state.hitch_rad - (truth[3] - truth[2])))
    return np.array(errors)


def fuse_without_the_cab(f: KinematicFilter, z: np.ndarray, kingpin: float, yaw: float) -> None:
    """Fuse of the fit ``z`` what a trailer seen without its cab measures: its yaw and its kingpin's place."""
    rows = np.array([[0, 0, 1, 1], [1, 0, kingpin * np.sin(yaw), 0], [0, 1, -kingpin * np.cos(yaw), 0]], float)
    f.update(z, R, (rows, rows @ R @ rows.T))


def drive_reversing_and_hold(reverse_hold_m: float, seed: int) -> np.ndarray:
    """A driver reversing folds the trailer (the steering at its limit) for 2 s, seen whole, then
    holds the hitch where it is for 8 s while the cab is hidden (``reverse_with_cab_hidden``)."""
    params = PARAMS.articulated.model_copy(update={"reverse_hold_m": reverse_hold_m})
    held = {}

    def target(k: int, hitch: float) -> float:
        if k >= 21:
            return held.setdefault("hitch", hitch)
        return np.radians(-80.0)

    return reverse_with_cab_hidden(params, -1.2, 0.0, target, 100, 20, seed)


@pytest.mark.parametrize("seed", [0, 1])
def test_reversing_with_the_cab_hidden_the_hitch_does_not_run_off(seed):
    # a reversing trailer folds unless its driver steers against it: the curvature the filter
    # learned while folding would fold it on in the prediction; a driver holds it
    errors = np.abs(drive_reversing_and_hold(HOLD_M, seed))
    assert errors.max() < 13.0
    assert (
        np.abs(drive_reversing_and_hold(NEVER_HOLDS_M, seed)).max() > errors.max() + 5.0
    )  # the kinematics alone ran off


def drive_reversing_and_fold(curvature_rate: float, seed: int) -> np.ndarray:
    """A driver reversing at -17 deg, seen whole for 1 s, then with the cab hidden folds the
    trailer on to -45 deg within 3 s and holds it (``reverse_with_cab_hidden``), with
    ``curvature_rate`` the reversing curvature's process noise."""
    params = PARAMS.articulated.model_copy(update={"reverse_curvature_rate_sigma_1_m_s": curvature_rate})
    start, end = np.radians(-17.0), np.radians(-45.0)

    def target(k: int, hitch: float) -> float:
        return start + (end - start) * min(max((k - 20) / 30, 0.0), 1.0)

    return reverse_with_cab_hidden(params, -1.5, start, target, 80, 10, seed)


@pytest.mark.parametrize("seed", [0, 1])
def test_reversing_with_the_cab_hidden_the_filter_follows_a_driver_folding_the_trailer(seed):
    # reversing, a driver steers to set the hitch: the curvature changes three times as fast as
    # forward's process noise allows, and the filter lagged the hitch by up to 11 deg (one LiDAR)
    assert rms(drive_reversing_and_fold(PARAMS.articulated.reverse_curvature_rate_sigma_1_m_s, seed)) < 2.0
    assert rms(drive_reversing_and_fold(PARAMS.articulated.curvature_rate_sigma_1_m_s, seed)) > 2.2


def test_a_standing_vehicle_is_not_reversing_while_its_speed_wavers_about_zero():
    """The reversing curvature noise only once the speed is below zero by more than its standard
    deviation."""
    f = new_filter(np.array([0.0, 0.0, 0.3, 0.3]), speed=-0.05)
    assert f.state.speed_m_s < 0 and not f._reversing
    f = new_filter(np.array([0.0, 0.0, 0.3, 0.3]), speed=-5.0)
    assert f._reversing
    q_still, q_back = new_filter(np.zeros(4), speed=-0.05)._q(0.1), f._q(0.1)
    assert q_back[CURVATURE, CURVATURE] == pytest.approx(9 * q_still[CURVATURE, CURVATURE], rel=1e-6)


def test_reversing_vehicle_keeps_its_heading_and_negative_speed():
    frames = run(speed=-1.5, steer=0.03, seconds=8)[10:]
    yaw_err = [angle_deg(s.yaw_rad - t[2]) for t, s in frames]
    hitch_err = [angle_deg(s.hitch_rad - (t[3] - t[2])) for t, s in frames]
    assert max(np.abs(yaw_err)) < 1.0 and rms(yaw_err) < 0.3  # never turned round
    assert max(np.abs(hitch_err)) < 1.0 and rms(hitch_err) < 0.4
    assert all(s.speed_m_s < -1.0 for _, s in frames)
    assert abs(np.mean([s.speed_m_s for _, s in frames]) + 1.5) < 0.1


def test_standstill_keeps_its_yaw():
    frames = run(speed=0.0, steer=0.0, seconds=10, seed=3)[10:]
    truth = frames[0][0]
    yaw_err = [angle_deg(s.yaw_rad - truth[2]) for _, s in frames]
    assert max(np.abs(yaw_err)) < 0.5 and rms(yaw_err) < 0.2
    speeds = np.array([s.speed_m_s for _, s in frames])
    assert np.abs(speeds).max() < 0.3 and abs(speeds.mean()) < 0.05


def test_turning_vehicle_estimates_curvature_and_hitch():
    frames = run(speed=3.0, steer=0.2, seconds=8, seed=1)
    errors = [angle_deg(s.hitch_rad - (t[3] - t[2])) for t, s in frames[20:]]
    assert np.sqrt(np.mean(np.square(errors))) < 0.3
    assert abs(frames[-1][1].curvature_1_m - np.tan(0.2) / ART.wheelbase_m) < 0.015  # 0.054 1/m
    assert 0.0 < frames[-1][1].hitch_std_rad < np.radians(0.5)


def test_jackknife_warning_from_angle():
    small = new_filter(np.array([0.0, 0.0, 0.0, np.radians(20.0)]))
    large = new_filter(np.array([0.0, 0.0, 0.0, np.radians(70.0)]))
    assert not small.state.jackknife
    assert large.state.jackknife


def test_jackknife_warning_from_rate_when_reversing():
    f = new_filter(np.array([0.0, 0.0, 0.0, np.radians(40.0)]), speed=-3.0)
    assert abs(np.degrees(f.state.hitch_rate_rad_s)) > PARAMS.articulated.jackknife_rate_deg_s
    assert f.state.jackknife
    f.ukf.x[SPEED] = 0.0
    assert not f.state.jackknife


def test_the_first_two_fits_give_a_new_vehicles_speed_and_curvature():
    """First seen in a steady turn at 3 m/s and 0.2 1/m, started without a speed: after its second
    fit the filter has the speed and the curvature their difference shows (the UKF alone cannot
    learn a curvature at speed 0: the yaw rate is their product)."""
    steer = np.arctan(0.2 * ART.wheelbase_m)
    truth = np.zeros(4)
    for _ in range(100):  # 10 s into the turn: its hitch settled
        truth = step(truth, 3.0, steer, ART, 0.1)
    f = new_filter(truth)
    truth = step(truth, 3.0, steer, ART, 0.1)
    f.predict(0.1)
    assert f.update(np.array([truth[0], truth[1], truth[2], truth[3] - truth[2]]), R)
    assert abs(f.state.speed_m_s - 3.0) < 0.1 and abs(f.state.curvature_1_m - 0.2) < 0.02


@pytest.mark.parametrize("speed", [0.0, 2.0])
def test_a_new_vehicles_motion_is_measured_between_fits_of_one_model(speed):
    """Renamed before its second fit (``shift_reference``: the new model's reference point), a new
    vehicle's first motion is measured between the new model's fits, not from the old model's fit
    moved: that lay 0.25 m behind the new one's, and a standing truck drove off at 2.5 m/s."""
    f = new_filter(np.array([-0.35, 0.0, 0.0, 0.0]))  # the old model's fit of a truck at x = 0 (new reference)
    f.shift_reference(0.1)  # the old pose moved to the new reference point: 0.25 m behind the new model's fit
    for k in (1, 2):  # the new model's first two fits
        f.predict(k * 0.1)
        assert f.update(np.array([speed * (k - 1) * 0.1, 0.0, 0.0, 0.0]), R)
    assert abs(f.state.speed_m_s - speed) < 0.1


def test_far_measurement_is_gated_then_taken_after_repeats():
    truth = np.array([0.0, 0.0, 0.0, 0.0])
    f = new_filter(truth)
    f.predict(0.1)
    before = f.ukf.x.copy()
    wrong = np.array([3.0, 0.0, 0.0, 0.0])
    assert not f.update(wrong, R)
    np.testing.assert_array_equal(f.ukf.x, before)
    for _ in range(PARAMS.articulated.reset_after_rejections - 1):
        f.update(wrong, R)
    assert abs(f.state.x_m - 3.0) < 1e-9  # the fits were right: restarted from them
    assert f.ukf.P[CURVATURE, CURVATURE] > 0


def test_gated_fits_that_may_not_restart_never_do():
    """A fit that does not see the tractor (the tracker's ``may_restart``: no point on its cab) is
    gated as any other but never counts towards the restart: with the cab hidden, fits folded
    their cab 68 deg onto nothing, and the filter restarted from one after three."""
    truth = np.array([0.0, 0.0, 0.0, 0.0])
    f = new_filter(truth)
    f.predict(0.1)
    before = f.ukf.x.copy()
    folded = np.array([0.0, 0.0, 0.0, np.radians(70.0)])
    for _ in range(3 * PARAMS.articulated.reset_after_rejections):
        assert not f.update(folded, R, may_restart=False)
    np.testing.assert_array_equal(f.ukf.x, before)
    for _ in range(PARAMS.articulated.reset_after_rejections):
        f.update(folded, R)
    assert abs(f.state.hitch_rad - np.radians(70.0)) < 1e-9  # the ones that may, do


def test_rigid_vehicle_has_no_hitch():
    f = KinematicFilter(np.array([1.0, 2.0, 0.5]), R[:3, :3], 0.0, 0.0, 1.0, False, PARAMS.articulated, 2.0)
    for k in range(1, 11):
        f.predict(k * 0.1)
        x = 1.0 + 2.0 * k * 0.1 * np.cos(0.5)
        y = 2.0 + 2.0 * k * 0.1 * np.sin(0.5)
        assert f.update(np.array([x, y, 0.5]), R[:3, :3])
    assert f.state.hitch_rad == 0.0 and not f.state.jackknife
    assert abs(f.state.speed_m_s - 2.0) < 0.1


@pytest.mark.parametrize("articulated", [True, False])
def test_the_filter_computes_what_filterpys_ukf_computes(articulated):
    """The same sigma points, weights, transforms and gain as filterpy's UnscentedKalmanFilter with
    Merwe's points over the same model: the same states and covariances (to rounding: filterpy
    transforms and correlates the sigma points one by one)."""
    from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter

    from i2v_loc.stages import kinematic_filter as kf

    n_z = 4 if articulated else 3
    rng = np.random.default_rng(7)
    z0, r = np.array([1.0, 2.0, 0.3, 0.1])[:n_z], np.diag([0.01, 0.01, 1e-4, 1e-4][:n_z])
    ours = kf.KinematicFilter(z0, r, 0.0, -0.3, 7.0, articulated, PARAMS.articulated, 1.0)
    points = MerweScaledSigmaPoints(6, alpha=0.3, beta=2.0, kappa=0.0, sqrt_method=lambda p: np.linalg.cholesky(p).T)
    measured, z_angles = ([0, 1, 2, HITCH], [2, 3]) if articulated else ([0, 1, 2], [2])
    theirs = UnscentedKalmanFilter(
        6, n_z, 0.1, lambda x: x[measured], lambda x, dt: propagate(x, dt, -0.3, 7.0, articulated, HOLD_M), points,
        x_mean_fn=lambda s, w: ref_mean(s, w, [2, HITCH]), z_mean_fn=lambda s, w: ref_mean(s, w, z_angles),
        residual_x=lambda a, b: ref_residual(a, b, [2, HITCH]), residual_z=lambda a, b: ref_residual(a, b, z_angles),
    )  # fmt: skip
    theirs.x, theirs.P = ours.ukf.x.copy(), ours.ukf.P.copy()
    for k in range(1, 120):
        dt = 0.1 * k - ours.stamp_s  # the filter's own step (0.1 * k - 0.1 * (k - 1) is not always 0.1)
        theirs.Q = ours._q(dt)
        ours.predict(0.1 * k)
        theirs.predict(dt=dt)
        z = z0 + np.r_[0.1 * k, 0.02 * k, 0.01 * k, 0.0][:n_z] + rng.normal(0, 0.02, n_z)
        ours.ukf.update(z, r)
        theirs.update(z, R=r)
        assert np.allclose(ours.ukf.x, theirs.x, rtol=1e-12, atol=1e-12)
        assert np.allclose(ours.ukf.P, theirs.P, rtol=1e-9, atol=1e-15)
        assert ours.ukf.mahalanobis == pytest.approx(theirs.mahalanobis, rel=1e-12)


# ----------------------------------------------------------------------------- the compiled parts


def ref_wrap(angle):
    return (angle + np.pi) % (2 * np.pi) - np.pi


def ref_mean(sigmas, weights, angles):
    """The weighted mean of the rows, the angle columns on the circle (filterpy's recipe)."""
    mean = weights @ sigmas
    for i in angles:
        mean[i] = np.arctan2(weights @ np.sin(sigmas[:, i]), weights @ np.cos(sigmas[:, i]))
    return mean


def ref_residual(a, b, angles):
    d = np.subtract(a, b)
    d[..., angles] = ref_wrap(d[..., angles])
    return d


def ref_derivative(s, kingpin_m, trailer_axle_m, articulated, hold_m, axle_m=0.0):
    v, kappa, yaw, hitch = s[..., SPEED], s[..., CURVATURE], s[..., 2], s[..., HITCH]
    d = np.zeros_like(s)
    slip = v * kappa * axle_m  # the reference point axle_m ahead of the axle moves sideways
    d[..., 0], d[..., 1], d[..., 2] = (
        v * np.cos(yaw) - slip * np.sin(yaw),
        v * np.sin(yaw) + slip * np.cos(yaw),
        v * kappa,
    )
    if articulated:
        omega = v * kappa
        kingpin_m = kingpin_m - axle_m
        d[..., HITCH] = -(v * np.sin(hitch) + kingpin_m * omega * np.cos(hitch)) / trailer_axle_m - omega
        holding = -np.sin(hitch) / np.maximum(trailer_axle_m + kingpin_m * np.cos(hitch), 0.5)
        d[..., CURVATURE] = (holding - kappa) * np.maximum(-v, 0.0) / hold_m
    return d


def ref_propagate(state, dt_s, kingpin_m, trailer_axle_m, articulated, hold_m, axle_m=0.0):
    """The numpy kinematics ``kernels.propagate_states`` replaced."""
    s = np.array(state, dtype=float)
    steps = max(1, int(np.ceil(abs(dt_s) / 0.1)))
    h = dt_s / steps
    for _ in range(steps):
        mid = s + 0.5 * h * ref_derivative(s, kingpin_m, trailer_axle_m, articulated, hold_m, axle_m)
        s = s + h * ref_derivative(mid, kingpin_m, trailer_axle_m, articulated, hold_m, axle_m)
    s[..., 2], s[..., HITCH] = ref_wrap(s[..., 2]), ref_wrap(s[..., HITCH])
    return s


@pytest.mark.parametrize("articulated", [True, False])
def test_the_compiled_kinematics_and_sigma_means_are_numpys(articulated):
    from i2v_loc.stages import kernels

    rng = np.random.default_rng(11)
    for _ in range(200):
        states = np.column_stack(
            [rng.normal(0, 30, (13, 2)), rng.uniform(-7, 7, 13), rng.normal(0, 3, 13), rng.normal(0, 0.1, 13)]
            + [rng.uniform(-4, 4, 13)]
        )
        dt = float(rng.choice([0.05, 0.1, 0.1000000001, 0.37, 2.0, -0.1]))
        axle = float(rng.choice([0.0, 0.3, -0.25]))
        derivative = kernels._kinematics(states, -0.35, 7.9, articulated, 1.3, axle)
        assert np.array_equal(derivative, ref_derivative(states, -0.35, 7.9, articulated, 1.3, axle))
        want = ref_propagate(states, dt, -0.35, 7.9, articulated, 1.3, axle)
        assert np.array_equal(propagate(states, dt, -0.35, 7.9, articulated, 1.3, axle), want)
        assert np.array_equal(propagate(states[3], dt, -0.35, 7.9, articulated, 1.3, axle), want[3])
        weights = rng.normal(size=13)
        mean = ref_mean(want, weights, [2, HITCH])
        # a weighted sum through BLAS: numpy's and scipy's builds part by 1e-15 on an AVX-512 Xeon
        assert np.allclose(kernels.angle_mean(want, weights, np.array([2, HITCH])), mean, rtol=1e-12, atol=1e-12)
        assert np.array_equal(
            kernels.angle_residuals(want, states[:1], np.array([2, HITCH])), ref_residual(want, states[:1], [2, HITCH])
        )
        z = np.ascontiguousarray(want[:, [0, 1, 2, HITCH]] if articulated else want[:, :3])
        dz = np.subtract(z, z[4])
        dz[:, 2:] = ref_wrap(dz[:, 2:])
        assert np.array_equal(kernels.angle_residuals(z, z[4][None, :], np.arange(2, z.shape[1])), dz)
    # the wrap's edges: exactly +-pi and beyond several turns
    edges = np.array([[0.0, 0.0, np.pi, 0.0, 0.0, -np.pi], [1.0, 0.0, 7 * np.pi, 0.0, 0.0, -1e-300]])
    assert np.array_equal(
        propagate(edges, 0.0, -0.35, 7.9, articulated, 1.3), ref_propagate(edges, 0.0, -0.35, 7.9, articulated, 1.3)
    )


def test_the_sigma_points_factor_is_choleskys_and_survives_a_covariance_rounded_indefinite():
    from i2v_loc.stages import kernels

    rng = np.random.default_rng(3)
    a = rng.normal(size=(6, 6))
    p = a @ a.T + 0.1 * np.eye(6)
    assert np.allclose(kernels.upper_factor(p), np.linalg.cholesky(p).T, rtol=1e-12, atol=1e-14)
    v, _ = np.linalg.qr(a)
    indefinite = (v * np.array([4.0, 1.0, 0.5, 0.1, 1e-3, -1e-9])) @ v.T  # one eigenvalue rounded below 0
    u = kernels.upper_factor(indefinite)
    clipped = (v * np.array([4.0, 1.0, 0.5, 0.1, 1e-3, 1e-12])) @ v.T
    assert np.allclose(u.T @ u, clipped, atol=1e-12)


def test_a_fit_fused_in_its_observed_directions_only():
    """All four directions as rows are the full update; the trailer's yaw (yaw + hitch) alone is the
    full update with a fit that says nothing in the other directions (a huge variance there)."""
    truth = np.array([1.0, 2.0, 0.3, 0.5])  # x, y, tractor yaw, trailer yaw: hitch 0.2
    z = np.array([1.01, 1.99, 0.302, 0.204])
    filters = [new_filter(truth) for _ in range(4)]
    for f in filters:
        f.predict(0.1)
    full, rows, trailer, vague = filters
    assert full.update(z, R) and rows.update(z, R, (np.eye(4), R))
    assert np.allclose(full.ukf.x, rows.ukf.x, atol=1e-12) and np.allclose(full.ukf.P, rows.ukf.P, atol=1e-15)
    u = np.array([0.0, 0.0, 1.0, 1.0]) / np.sqrt(2.0)
    basis = np.linalg.qr(np.column_stack([u, np.eye(4)[:, [0, 1, 2]]]))[0]  # u, then three orthogonal to it
    before = trailer.ukf.x.copy()
    assert trailer.update(z, R, (u[None, :], np.array([[1e-8]])))
    assert vague.update(z, basis @ np.diag([1e-8, 1e8, 1e8, 1e8]) @ basis.T)
    assert np.allclose(trailer.ukf.x, vague.ukf.x, rtol=1e-3, atol=1e-5)
    assert np.allclose(trailer.ukf.P, vague.ukf.P, rtol=1e-3, atol=1e-6)
    assert abs((trailer.ukf.x - before)[[0, 1, 2, HITCH]] @ u) > 0.003  # it moved towards the fit


def test_moving_the_pose_keeps_the_motion_and_the_covariance():
    """The model changed under the vehicle: the pose moves, the speed, curvature and covariance stay."""
    f = new_filter(np.array([5.0, -2.0, 3.1, 3.1 + 0.2]), speed=2.0)
    f.predict(0.1)
    before = f.ukf.x.copy(), f.ukf.P.copy()
    f.move_pose(np.array([-0.4, 0.1, 0.1, -0.05]))
    assert np.allclose(f.ukf.x[:2], before[0][:2] + [-0.4, 0.1], atol=1e-12)
    assert f.ukf.x[2] == pytest.approx(before[0][2] + 0.1 - 2 * np.pi)  # wrapped
    assert before[0][2] + 0.1 > np.pi
    assert f.ukf.x[HITCH] == pytest.approx(before[0][HITCH] - 0.05)
    assert f.ukf.x[SPEED] == before[0][SPEED] and f.ukf.x[CURVATURE] == before[0][CURVATURE]
    assert np.array_equal(f.ukf.P, before[1])


def test_a_restart_from_fits_that_measured_some_directions_keeps_the_filters_others():
    """Fits outside the gate, in a row, that measured the trailer's pose only (x, y and the trailer's
    yaw, yaw + hitch; no cab): the restart takes them along those directions and keeps the filter's
    hitch along the one they left open. (Restarted whole, the hitch took the fits' value there,
    which only their weak prior held: 17 deg sigma, and the next fit swung it 25 deg off.)"""
    f = new_filter(np.zeros(4))
    f.predict(0.1)
    hitch_before = f.state.hitch_rad
    u = np.array([0.0, 0.0, 1.0, 1.0]) / np.sqrt(2.0)
    rows = np.vstack([np.eye(4)[:2], u])
    basis = np.linalg.qr(np.column_stack([u, np.eye(4)[:, [0, 1, 2]]]))[0]
    vague = basis @ np.diag([1e-6, 1e-6, 1e-6, 0.3]) @ basis.T  # the open direction: the weak prior's
    z = np.array([3.0, 0.5, 0.3, -0.3])  # trailer yaw 0: the filter's; cab and hitch 0.3 rad off
    for _ in range(PARAMS.articulated.reset_after_rejections):
        assert not f.update(z, vague, (rows, np.eye(3) * 1e-6))
    s = f.state
    assert abs(s.x_m - 3.0) < 1e-3 and abs(s.y_m - 0.5) < 1e-3  # the fits were right there
    assert abs(s.yaw_rad + s.hitch_rad) < 1e-3  # the trailer's yaw, as measured
    assert abs(s.hitch_rad - hitch_before) < 0.01  # the filter's, not the fits' -0.3
    assert s.hitch_std_rad < np.radians(1.0)


def test_each_units_motion_is_its_box_centres_in_the_kinematics():
    """A turning, bending vehicle: each unit's box centre moves over 1 ms as ``unit_motions`` says
    (the trailer's rate is the tractor's plus the hitch's), along the unit's yaw."""
    from i2v_loc.stages.kinematic_filter import FilterState, unit_motions
    from i2v_loc.stages.vehicle_model import VehicleModel

    model = VehicleModel.from_config("volvo_fh", VOLVO)
    x = np.array([1.0, 2.0, 0.4, 3.0, 0.08, np.radians(25.0)])
    dt, axle = 1e-3, 0.3  # the rear axle that does not slip 0.3 m behind the model's
    later = propagate(x, dt, model.kingpin_behind_axle_m, model.trailer_axle_m, True, NEVER_HOLDS_M, axle)
    hitch_rate = (later[HITCH] - x[HITCH]) / dt
    state = FilterState(*x[:6], np.eye(6), hitch_rate, False, axle)
    motions = unit_motions(state, model)
    now_centers = model.box_centers(x[0], x[1], x[2], x[HITCH])
    later_centers = model.box_centers(later[0], later[1], later[2], later[HITCH])
    for motion, now, then, yaw, rate in zip(
        motions, now_centers, later_centers, (x[2], x[2] + x[HITCH]), (3.0 * 0.08, 3.0 * 0.08 + hitch_rate)
    ):
        assert motion.velocity_xy == pytest.approx((then - now) / dt, abs=2e-3)
        assert motion.rate_rad_s == pytest.approx(rate)
        assert motion.yaw_rad == pytest.approx(yaw)
        assert motion.center_xy == pytest.approx(now)
    assert abs(motions[1].rate_rad_s - motions[0].rate_rad_s) > 0.05  # the hitch did change


def drive_behind_its_trailer(axle_behind_m: float, seed: int, behind_m: float = 0.35) -> np.ndarray:
    """A Volvo in a steady turn at 3 m/s whose rear axle, the point that does not slip sideways,
    lies ``behind_m`` behind the catalogue's (an unknown tractor named after the nearest known
    one): its fits give the pose of a reference point ``behind_m`` ahead of the axle, and the
    filter has the kingpin's offset from that point and ``axle_behind_m``. Seen whole for 10 s,
    then with the cab hidden for 4 s (the trailer's yaw and the kingpin's position only): the
    hidden frames' hitch errors (deg)."""
    rng = np.random.default_rng(seed)
    steer = np.arctan(0.11 * ART.wheelbase_m)
    truth = np.zeros(4)
    for _ in range(100):  # its hitch settled in the turn
        truth = step(truth, 3.0, steer, ART, 0.1)
    kingpin = ART.hitch_behind_axle_m + behind_m

    def fitted(t: np.ndarray) -> np.ndarray:
        ahead = behind_m * np.array([np.cos(t[2]), np.sin(t[2])])
        return np.array([t[0] + ahead[0], t[1] + ahead[1], t[2], t[3] - t[2]]) + rng.normal(0, np.sqrt(np.diag(R)))

    f = KinematicFilter(fitted(truth), R, 0.0, kingpin, ART.trailer_hitch_to_axle_m, True, PARAMS.articulated, 3.0)
    f.axle_behind_m = axle_behind_m
    errors = []
    for k in range(1, 141):
        truth = step(truth, 3.0, steer, ART, 0.1)
        f.predict(k * 0.1)
        z = fitted(truth)
        if k <= 100:
            f.update(z, R)
            continue
        fuse_without_the_cab(f, z, kingpin, z[2])
        errors.append(angle_deg(f.state.hitch_rad - (truth[3] - truth[2])))
    return np.array(errors)


@pytest.mark.parametrize("seed", [0, 1])
def test_with_its_rear_axle_where_it_is_a_hidden_cabs_hitch_holds(seed):
    """The kingpin's motion shows the tractor's heading through the point that does not slip:
    taken at the catalogue's axle, 0.35 m ahead of the true one, the heading runs atan(0.35 m x
    0.11 1/m) = 2.2 deg off while the cab is hidden, and the hitch with it (the unknown 13.6 m
    trailer's tractor in the simulated roundabout, seen by one LiDAR: up to 5 deg). The noise of
    the trailer's fits alone: 0.6 deg."""
    errors = drive_behind_its_trailer(0.35, seed)
    assert abs(errors.mean()) < 0.3 and rms(errors) < 0.8
    assert drive_behind_its_trailer(0.0, seed).mean() < -1.5
