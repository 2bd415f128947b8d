"""The articulated estimator's filter: one unscented Kalman filter per vehicle over the
one-trailer, off-axle-hitch kinematics (docs/pipeline.md, Articulated estimator).

State [x, y, ψ1, v, κ, γ]: tractor rear-axle position, tractor yaw, signed speed (reversing is
v < 0, never a turned heading), path curvature (yaw rate ω = v κ, so a standing vehicle keeps its
yaw) and hitch angle γ = ψ2 − ψ1. With the kingpin M behind the rear axle and L2 from the kingpin
to the trailer's axle, the trailer's yaw rate is ψ2' = (v sin(ψ1 − ψ2) − M ω cos(ψ1 − ψ2)) / L2,
so γ' = −(v sin γ + M ω cos γ) / L2 − ω. Reversing (γ = 0 unstable), a driver steers the trailer
from folding: κ relaxes to the curvature that holds γ (``kernels.holding_curvature``) over
``reverse_hold_m`` travelled backwards; forward, κ is a random walk. A rigid vehicle keeps γ = 0
(no noise, not measured).
Measurement: the hinged fit's (x, y, ψ1, γ) with its covariance.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from i2v_loc.geometry import wrap_rad
from i2v_loc.params import ArticulatedParams
from i2v_loc.stages import kernels
from i2v_loc.stages.vehicle_model import VehicleModel

X, Y, YAW, SPEED, CURVATURE, HITCH = range(6)
_ANGLES_X = np.array([YAW, HITCH])
_ANGLES_Z = {4: np.array([2, 3]), 3: np.array([2])}  # of (x, y, yaw, hitch) and (x, y, yaw)
INITIAL_SPEED_SIGMA_M_S = 3.0
INITIAL_CURVATURE_SIGMA_1_M = 0.05
TWO_FIT_MIN_SPEED_M_S = 1.0  # slower, two fits' yaw difference is noise, not a turn
TWO_FIT_SPEED_SIGMA_M_S = 1.0  # two fits 0.1 s apart, a few centimetres each
MAX_START_SPEED_M_S = 25.0  # 90 km/h, a truck's top speed
MAX_CURVATURE_1_M = 0.5  # a turning circle of 2 m: tighter than any road vehicle's
MAX_STEP_S = 0.1  # the kinematics are integrated in midpoint steps no longer than this
_AT_FIRST_PREDICTION = "taken at the first prediction"  # a new vehicle's state to measure its first motion from
_AT_NEXT_FIT = "restarted from the next fit"  # its model changed before its motion was measured


def _midpoint_steps(dt_s: float) -> tuple[float, int]:
    """(step length, number of steps) of ``dt_s`` in midpoint steps no longer than ``MAX_STEP_S``."""
    steps = max(1, int(np.ceil(abs(dt_s) / MAX_STEP_S)))
    return float(dt_s / steps), steps


def propagate(
    state: np.ndarray,
    dt_s: float,
    kingpin_m: float,
    trailer_axle_m: float,
    articulated: bool,
    hold_m: float,
    axle_m: float = 0.0,
) -> np.ndarray:
    """The state (6,) or states (k, 6) ``dt_s`` later (midpoint steps, compiled: ``kernels.propagate_states``)."""
    s = np.array(state, dtype=float)
    out = kernels.propagate_states(
        np.atleast_2d(s), *_midpoint_steps(dt_s), float(kingpin_m), float(trailer_axle_m), bool(articulated),
        float(hold_m), float(axle_m),
    )  # fmt: skip
    return out.reshape(s.shape)


class _Ukf:
    """An unscented Kalman filter with Merwe's scaled sigma points over the one-trailer kinematics,
    computed as filterpy's ``UnscentedKalmanFilter`` computes them (the same sigma points, weights,
    transforms and gain) with each step one compiled call (``kernels.ukf_predict``,
    ``kernels.ukf_update``). (filterpy itself imports scipy.stats: half a second of every start-up.)"""

    def __init__(self, n: int, alpha: float, beta: float, kappa: float, measured: np.ndarray):
        lambda_ = alpha**2 * (n + kappa) - n
        self.wm = np.full(2 * n + 1, 0.5 / (n + lambda_))
        self.wc = self.wm.copy()
        self.wc[0] = lambda_ / (n + lambda_) + (1 - alpha**2 + beta)
        self.wm[0] = lambda_ / (n + lambda_)
        self.spread = lambda_ + n
        self.measured = measured  # the state's columns the measurement holds
        self._z_angles = _ANGLES_Z[len(measured)]
        self._all_rows = np.eye(len(measured))
        self.x, self.P = np.zeros(n), np.eye(n)
        self.sigmas_f = np.zeros((2 * n + 1, n))
        self.mahalanobis = 0.0

    def predict(
        self,
        dt: float,
        q: np.ndarray,
        kingpin_m: float,
        trailer_axle_m: float,
        articulated: bool,
        hold_m: float,
        axle_m: float,
    ) -> None:
        self.x, self.P, self.sigmas_f = kernels.ukf_predict(
            self.x, self.P, self.wm, self.wc, self.spread, q, *_midpoint_steps(dt),
            float(kingpin_m), float(trailer_axle_m), articulated, float(hold_m), float(axle_m), _ANGLES_X,
        )  # fmt: skip

    def update(self, z: np.ndarray, r: np.ndarray, rows: np.ndarray | None = None) -> None:
        """Fuse ``z`` with noise ``r``; with ``rows`` (k, m) only those directions of z (r is k x k)."""
        self.x, self.P, self.mahalanobis = kernels.ukf_update(
            self.x, self.P, self.sigmas_f, self.wm, self.wc, self.measured, z, np.ascontiguousarray(r, dtype=float),
            self._all_rows if rows is None else np.ascontiguousarray(rows, dtype=float), _ANGLES_X, self._z_angles,
        )  # fmt: skip


@dataclass(frozen=True)
class FilterState:
    x_m: float
    y_m: float
    yaw_rad: float
    speed_m_s: float
    curvature_1_m: float
    hitch_rad: float
    covariance: np.ndarray  # (6, 6)
    hitch_rate_rad_s: float
    jackknife: bool
    axle_behind_m: float = 0.0  # the rear axle that does not slip sideways, behind (x, y)

    @property
    def hitch_std_rad(self) -> float:
        return float(np.sqrt(max(self.covariance[HITCH, HITCH], 0.0)))


@dataclass(frozen=True)
class UnitMotion:
    """How one unit of a vehicle moves: its box centre, yaw, the centre's velocity and the yaw rate
    (level frame)."""

    center_xy: np.ndarray
    yaw_rad: float
    velocity_xy: np.ndarray
    rate_rad_s: float


def unit_motions(s: FilterState, model: VehicleModel) -> list[UnitMotion]:
    """Each unit's motion in the state ``s`` (a turning cab's centre moves sideways; the trailer
    turns about its kingpin at the tractor's rate plus the hitch's)."""
    centers = model.box_centers(s.x_m, s.y_m, s.yaw_rad, s.hitch_rad)
    heading = np.array([np.cos(s.yaw_rad), np.sin(s.yaw_rad)])
    axle = np.array([s.x_m, s.y_m]) - s.axle_behind_m * heading
    axle_velocity = s.speed_m_s * heading
    omega = s.speed_m_s * s.curvature_1_m
    motions = [UnitMotion(centers[0], s.yaw_rad, axle_velocity + _turn(omega, centers[0] - axle), omega)]
    if model.trailer is not None:
        kingpin = model.kingpin_xy(s.x_m, s.y_m, s.yaw_rad)
        kingpin_velocity = axle_velocity + _turn(omega, kingpin - axle)
        rate = omega + s.hitch_rate_rad_s
        motions.append(
            UnitMotion(centers[1], s.yaw_rad + s.hitch_rad, kingpin_velocity + _turn(rate, centers[1] - kingpin), rate)
        )
    return motions


def _turn(rate_rad_s: float, arm_xy: np.ndarray) -> np.ndarray:
    """Velocity of a point ``arm_xy`` from a centre turning at ``rate_rad_s``."""
    return rate_rad_s * np.array([-arm_xy[1], arm_xy[0]])


_TINY_NOISE = np.eye(6) * 1e-12  # keeps the covariance positive definite


@lru_cache(maxsize=16)
def _squared_rates(rates: tuple) -> np.ndarray:
    """The squared random-walk rates of the state's columns from (position, yaw in deg/s,
    acceleration, curvature rate, hitch in deg/s or None): the process noise per second. Cached
    per parameter set (``kernels.ukf_predict`` only reads the noise it is given)."""
    position, yaw_deg, accel, curvature, hitch_deg = rates
    hitch = 0.0 if hitch_deg is None else np.radians(hitch_deg)
    return np.array([position, position, np.radians(yaw_deg), accel, curvature, hitch]) ** 2


class KinematicFilter:
    """One vehicle's UKF. ``predict(stamp)`` then ``update(z, R)``; ``state`` after either."""

    def __init__(
        self,
        z: np.ndarray,
        r: np.ndarray,
        stamp_s: float,
        kingpin_m: float,
        trailer_axle_m: float,
        articulated: bool,
        params: ArticulatedParams,
        speed_m_s: float = 0.0,
    ):
        self.params = params
        self.articulated = articulated
        self.kingpin_m, self.trailer_axle_m = kingpin_m, trailer_axle_m
        self.axle_behind_m = 0.0  # the catalogue's rear axle until the tracker learns where it is
        self.stamp_s = stamp_s
        self.ukf = _Ukf(6, 0.3, 2.0, 0.0, np.array([X, Y, YAW, HITCH] if articulated else [X, Y, YAW]))
        x = np.zeros(6)
        x[[X, Y, YAW]] = z[:3]
        x[SPEED] = speed_m_s
        x[HITCH] = z[3] if articulated else 0.0
        p = np.zeros((6, 6))
        p[:3, :3] = r[:3, :3]
        p[SPEED, SPEED] = INITIAL_SPEED_SIGMA_M_S**2
        p[CURVATURE, CURVATURE] = INITIAL_CURVATURE_SIGMA_1_M**2
        p[HITCH, HITCH] = r[3, 3] if articulated else 1e-12
        if articulated:
            p[:3, HITCH] = p[HITCH, :3] = r[:3, 3]
        self.ukf.x, self.ukf.P = x, p
        self.rejected = 0  # measurements outside the innovation gate
        self._in_a_row = 0
        # without a speed, the second fit gives the motion (``_motion_of_two_fits``) from the state
        # before the first prediction (the start's sizes may have moved it since): taken then
        self._first: tuple[np.ndarray, np.ndarray, float] | str | None = (
            _AT_FIRST_PREDICTION if speed_m_s == 0.0 else None
        )

    def restart(self, z: np.ndarray, r: np.ndarray, observed: tuple[np.ndarray, np.ndarray] | None = None) -> None:
        """The pose and hitch restart from the fit ``z`` (covariance ``r``); speed and curvature are
        kept, their variance reset. With ``observed`` (the directions its points measured, fewer
        than all): the fit there, the filter along the rest (``_observed_restart``)."""
        n = len(z)
        idx = [X, Y, YAW, HITCH][:n]
        if observed is not None and 0 < len(observed[0]) < n:
            z, r = self._observed_restart(z, *observed, idx)
        self.ukf.x[idx] = z
        p = np.diag(np.diag(self.ukf.P)).copy()
        p[np.ix_(idx, idx)] = r
        p[SPEED, SPEED] = max(p[SPEED, SPEED], INITIAL_SPEED_SIGMA_M_S**2)
        p[CURVATURE, CURVATURE] = max(p[CURVATURE, CURVATURE], INITIAL_CURVATURE_SIGMA_1_M**2)
        self.ukf.P = p
        self._in_a_row = 0
        if isinstance(self._first, tuple):  # no longer the first fit's state
            self._first = None

    def _observed_restart(
        self, z: np.ndarray, rows: np.ndarray, noise: np.ndarray, idx: list[int]
    ) -> tuple[np.ndarray, np.ndarray]:
        """The pose and its covariance from the fit's information along the directions it measured
        and the filter's along those it did not (the null space of ``rows``). (Restarted whole from a
        fit that saw no cab, the hitch took the fit's weak prior, a 17 deg sigma, and the next fit of
        the trailer alone swung it 25 deg off.)"""
        x, p = self.ukf.x[idx], self.ukf.P[np.ix_(idx, idx)]
        null = np.linalg.svd(rows)[2][len(rows) :].T
        kept = null @ np.linalg.inv(null.T @ p @ null) @ null.T
        measured = rows.T @ np.linalg.inv(noise) @ rows
        cov = np.linalg.inv(measured + kept)
        step = z - x
        step[2:] = wrap_rad(step[2:])  # the angles
        new = x + cov @ measured @ step
        new[2:] = wrap_rad(new[2:])
        return new, (cov + cov.T) / 2

    def _q(self, dt_s: float) -> np.ndarray:
        p = self.params
        rates = (
            p.position_sigma_m_s,
            p.yaw_sigma_deg_s,
            p.accel_sigma_m_s2,
            p.reverse_curvature_rate_sigma_1_m_s if self._reversing else p.curvature_rate_sigma_1_m_s,
            p.hitch_sigma_deg_s if self.articulated else None,
        )
        return np.diag(_squared_rates(rates) * max(dt_s, 1e-3)) + _TINY_NOISE

    @property
    def _reversing(self) -> bool:
        """Backwards by more than the speed's standard deviation (a standing vehicle's speed wavers
        about zero: with the reversing driver's curvature noise a tractor standing before its
        trailer, seen by one LiDAR, drove off at 3 m/s and its fits folded 20 deg off)."""
        return bool(self.ukf.x[SPEED] + math.sqrt(max(self.ukf.P[SPEED, SPEED], 0.0)) < 0.0)

    def predict(self, stamp_s: float) -> FilterState:
        dt = stamp_s - self.stamp_s if np.isfinite(stamp_s) else 0.1
        if self._first is _AT_FIRST_PREDICTION:
            self._first = (self.ukf.x.copy(), self.ukf.P.copy(), self.stamp_s)
        if dt > 0:
            self.ukf.predict(
                dt, self._q(dt), self.kingpin_m, self.trailer_axle_m, self.articulated, self.params.reverse_hold_m,
                self.axle_behind_m,
            )  # fmt: skip
            self.stamp_s = stamp_s
        return self.state

    def update(
        self,
        z: np.ndarray,
        r: np.ndarray,
        observed: tuple[np.ndarray, np.ndarray] | None = None,
        may_restart: bool = True,
    ) -> bool:
        """Fuse one fit, ``z`` with covariance ``r``, or only its ``observed`` directions (rows and
        their noise: what its points measured); False (state unchanged) when it lies outside the
        innovation gate. After ``reset_after_rejections`` rejections in a row the fits are right and
        the prediction is not: the pose and hitch restart from the fit (speed and curvature kept,
        their variance reset). Only fits that ``may_restart`` count (the tracker's: those that see
        the tractor at all; with the cab hidden behind its trailer, fits folded their cab 68 deg onto
        nothing, and after three such fits the filter restarted from one)."""
        z = np.asarray(z, dtype=float)
        if self._first is _AT_NEXT_FIT:
            self.restart(z, r, observed)
            self._first = _AT_FIRST_PREDICTION
            return True
        if isinstance(self._first, tuple):
            self._motion_of_two_fits(z)
        x, p = self.ukf.x.copy(), self.ukf.P.copy()
        if observed is None:
            self.ukf.update(z, r)
        else:
            self.ukf.update(z, observed[1], observed[0])
        if self.ukf.mahalanobis**2 > self.params.innovation_gate:
            self.ukf.x, self.ukf.P = x, p
            self.rejected += 1
            self._in_a_row = self._in_a_row + 1 if may_restart else 0
            if self._in_a_row >= self.params.reset_after_rejections:
                self.restart(z, r, observed)
            return False
        self._in_a_row = 0
        self.ukf.x[YAW], self.ukf.x[HITCH] = wrap_rad(self.ukf.x[YAW]), wrap_rad(self.ukf.x[HITCH])
        return True

    def _motion_of_two_fits(self, z: np.ndarray) -> None:
        """A new vehicle's speed and curvature from its first two fits (their difference over the
        time between them), before the second is fused. Started at speed 0, the filter cannot
        learn the curvature from the yaw (the yaw rate is their product, and each sigma point
        moves one of them): a Twizy first seen by one LiDAR at 3.1 m/s in a roundabout (0.28 1/m)
        had 0.96 m/s and 0.02 1/m after its second fit, and its fits fell outside the gate. The
        first two fits' points are alike not yet moved to the frame's time: their difference is
        the motion. Implausible differences (a jump between two objects) are left to the filter."""
        (x, p, stamp), self._first = self._first, None
        dt = self.stamp_s - stamp
        if dt <= 0:
            return
        turn = wrap_rad(z[YAW] - x[YAW])
        heading = x[YAW] + turn / 2
        speed = float((z[:2] - x[:2]) @ np.array([np.cos(heading), np.sin(heading)])) / dt
        curvature = turn / dt / speed if abs(speed) >= TWO_FIT_MIN_SPEED_M_S else 0.0
        if abs(speed) > MAX_START_SPEED_M_S or abs(curvature) > MAX_CURVATURE_1_M:
            return
        x[SPEED], x[CURVATURE] = speed, curvature
        p[SPEED, SPEED] = TWO_FIT_SPEED_SIGMA_M_S**2
        self.ukf.x, self.ukf.P = x, p  # predicted again from the start, with the motion
        self.stamp_s = stamp
        self.predict(stamp + dt)

    def move_pose(self, delta: np.ndarray) -> None:
        """Move the pose (x, y, yaw[, hitch]) by ``delta`` without touching the motion or the
        covariance (the model changed under the vehicle, the vehicle did not move)."""
        idx = [X, Y, YAW, HITCH][: len(delta)]
        self.ukf.x[idx] += delta
        self.ukf.x[YAW], self.ukf.x[HITCH] = wrap_rad(self.ukf.x[YAW]), wrap_rad(self.ukf.x[HITCH])

    def shift_reference(self, forward_m: float) -> None:
        """Move the reference point ``forward_m`` along the tractor's heading (its model changed).
        A new vehicle's first motion is then measured between two fits of the new model, from the
        next on: the old model's pose, moved, is not the new one's fit (a MAN seen by one LiDAR
        from behind started as a Volvo; the two models' fits of a standing truck lay 0.25 m apart,
        and it drove off at 2.5 m/s, 4.8 m ahead within 3 s)."""
        yaw = self.ukf.x[YAW]
        self.ukf.x[X] += forward_m * np.cos(yaw)
        self.ukf.x[Y] += forward_m * np.sin(yaw)
        if self._first is not None:
            self._first = _AT_NEXT_FIT

    @property
    def speed_m_s(self) -> float:
        return float(self.ukf.x[SPEED])

    @property
    def speed_std_m_s(self) -> float:
        return float(np.sqrt(max(self.ukf.P[SPEED, SPEED], 0.0)))

    @property
    def state(self) -> FilterState:
        x = self.ukf.x.tolist()
        rate = (
            kernels.hitch_rate(
                x[SPEED], x[CURVATURE], x[HITCH], float(self.kingpin_m - self.axle_behind_m), float(self.trailer_axle_m)
            )
            if self.articulated
            else 0.0
        )
        jackknife = self.articulated and (
            abs(x[HITCH]) > math.radians(self.params.jackknife_hitch_deg)
            or abs(rate) > math.radians(self.params.jackknife_rate_deg_s)
        )
        return FilterState(*x, self.ukf.P.copy(), rate, bool(jackknife), self.axle_behind_m)
