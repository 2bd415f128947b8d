"""Tractor-semitrailer (or car + drawbar trailer) kinematics with an off-axle hitch.

State: truck rear-axle centre (x, y), truck yaw θ, trailer yaw θ2 (radians). Inputs: signed speed v
of the truck's rear axle and front-wheel steering angle δ. With wheelbase L, hitch M behind the rear
axle (negative when ahead of it, as a fifth wheel usually is) and hitch-to-trailer-axle L2:

    ẋ = v cos θ,   ẏ = v sin θ,   θ̇ = v tan δ / L
    θ̇2 = (v sin(θ - θ2) - M θ̇ cos(θ - θ2)) / L2

Derivation of the last line: the hitch H = P - M (cos θ, sin θ) moves with Ḣ = v e(θ) - M θ̇ n(θ);
the trailer axle P2 = H - L2 e(θ2) cannot slip sideways, Ṗ2 · n(θ2) = 0, and
Ṗ2 = Ḣ - L2 θ̇2 n(θ2), so L2 θ̇2 = Ḣ · n(θ2) = v sin(θ - θ2) - M θ̇ cos(θ - θ2).
The hitch angle is φ = θ2 - θ (docs/formats.md), so φ̇ = θ̇2 - θ̇.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from i2v_loc.geometry import wrap_rad


@dataclass(frozen=True)
class Articulation:
    """The kinematic figures of one truck-trailer combination (metres)."""

    wheelbase_m: float
    hitch_behind_axle_m: float  # M
    trailer_hitch_to_axle_m: float  # L2
    max_steer_deg: float = 35.0
    max_steer_rate_deg_s: float = 25.0
    max_accel_mps2: float = 0.6
    max_hitch_deg: float = 60.0

    @classmethod
    def from_vehicle(cls, vehicle) -> Articulation:
        """From an ``i2v_loc.params.VehicleConfig``."""
        return cls(
            wheelbase_m=vehicle.truck.wheelbase_m,
            hitch_behind_axle_m=vehicle.truck.hitch_behind_rear_axle_m,
            trailer_hitch_to_axle_m=vehicle.trailer.hitch_to_axle_m,
        )


def derivatives(state: np.ndarray, speed_mps: float, steer_rad: float, art: Articulation) -> np.ndarray:
    """d/dt of (x, y, θ, θ2)."""
    _, _, yaw, trailer_yaw = state
    yaw_rate = speed_mps * math.tan(steer_rad) / art.wheelbase_m
    rel = yaw - trailer_yaw
    trailer_rate = (
        speed_mps * math.sin(rel) - art.hitch_behind_axle_m * yaw_rate * math.cos(rel)
    ) / art.trailer_hitch_to_axle_m
    return np.array([speed_mps * math.cos(yaw), speed_mps * math.sin(yaw), yaw_rate, trailer_rate])


def step(state: np.ndarray, speed_mps: float, steer_rad: float, art: Articulation, dt_s: float) -> np.ndarray:
    """One RK4 step with the inputs held over the step."""
    k1 = derivatives(state, speed_mps, steer_rad, art)
    k2 = derivatives(state + 0.5 * dt_s * k1, speed_mps, steer_rad, art)
    k3 = derivatives(state + 0.5 * dt_s * k2, speed_mps, steer_rad, art)
    k4 = derivatives(state + dt_s * k3, speed_mps, steer_rad, art)
    return state + dt_s / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)


def hitch_point(state: np.ndarray, art: Articulation) -> np.ndarray:
    x, y, yaw, _ = state
    return np.array([x - art.hitch_behind_axle_m * math.cos(yaw), y - art.hitch_behind_axle_m * math.sin(yaw)])


def trailer_axle_point(state: np.ndarray, art: Articulation) -> np.ndarray:
    hx, hy = hitch_point(state, art)
    yaw2 = state[3]
    return np.array(
        [hx - art.trailer_hitch_to_axle_m * math.cos(yaw2), hy - art.trailer_hitch_to_axle_m * math.sin(yaw2)]
    )


def yaw_rate_for_hitch_rate(hitch_rad: float, speed_mps: float, hitch_rate_rad_s: float, art: Articulation) -> float:
    """Invert φ̇ = -(v sin φ + M θ̇ cos φ) / L2 - θ̇ for the truck yaw rate θ̇."""
    l2, m = art.trailer_hitch_to_axle_m, art.hitch_behind_axle_m
    denominator = 1.0 + m * math.cos(hitch_rad) / l2
    return (-speed_mps * math.sin(hitch_rad) / l2 - hitch_rate_rad_s) / denominator


def steer_for_hitch(
    state: np.ndarray, speed_mps: float, hitch_ref_rad: float, art: Articulation, gain_1pm: float = 1.0
) -> float:
    """Steering that makes the hitch angle approach ``hitch_ref_rad`` (φ̇ = k (φ_ref - φ), k = gain·|v|).

    Used for reversing, where the hitch angle is unstable on its own. Returns the unclipped angle.
    """
    if abs(speed_mps) < 1e-3:
        return 0.0
    hitch = wrap_rad(state[3] - state[2])
    hitch_rate = gain_1pm * abs(speed_mps) * wrap_rad(hitch_ref_rad - hitch)
    yaw_rate = yaw_rate_for_hitch_rate(hitch, speed_mps, hitch_rate, art)
    return math.atan(yaw_rate * art.wheelbase_m / speed_mps)


def steady_turn_steer_rad(radius_m: float, art: Articulation) -> float:
    """Steering angle that puts the rear axle on a circle of signed radius (positive = left)."""
    return math.atan(art.wheelbase_m / radius_m)
