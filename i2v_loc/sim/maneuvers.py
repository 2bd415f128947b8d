"""Maneuvers as sequences of phases, integrated into a dense, labelled trajectory.

A phase drives forward or backward until its goal (distance, truck heading, trailer heading,
time) is reached. Speed and steering are rate limited, so speed never jumps. Reversing steers with
a cascaded controller: the trailer-heading error sets a hitch-angle reference and
``kinematics.steer_for_hitch`` tracks it (reversing an articulated vehicle open loop is unstable).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from i2v_loc.geometry import rotate_xy
from i2v_loc.sim import kinematics as kin

LABELS = (
    "straight",
    "single_turn",
    "long_curve",
    "u_turn",
    "lane_change",
    "roundabout",
    "reverse_docking",
    "standstill",
)
SCENARIOS = LABELS + ("docking",)
DT_S = 0.005


@dataclass
class Phase:
    """One step of a maneuver. Exactly one goal applies, checked in this order:
    ``trailer_heading_deg`` (reverse into a bay, then ``distance_m`` straight), ``heading_deg``
    (turn the truck to this heading), ``distance_m``, ``duration_s``. Headings are relative to the
    trajectory's start heading."""

    label: str
    speed_mps: float = 0.0
    distance_m: float | None = None
    heading_deg: float | None = None
    radius_m: float = 10.0
    trailer_heading_deg: float | None = None
    duration_s: float | None = None
    stop: bool = False  # brake to standstill at the end of the phase
    record: bool = True  # False for a warm-up before t = 0


@dataclass
class Trajectory:
    """Dense samples (every ``DT_S``) of one articulated vehicle; angles unwrapped, radians."""

    art: kin.Articulation
    time_s: np.ndarray
    rear_axle_xy: np.ndarray  # (N, 2)
    yaw_rad: np.ndarray
    trailer_yaw_rad: np.ndarray
    speed_mps: np.ndarray
    steer_rad: np.ndarray
    label_index: np.ndarray
    labels: tuple[str, ...] = LABELS

    def sample(self, t_s) -> dict[str, np.ndarray]:
        """Linear interpolation at times ``t_s`` (clamped to the ends); labels from the nearest sample."""
        t = np.atleast_1d(np.asarray(t_s, dtype=float))
        out = {
            "x": np.interp(t, self.time_s, self.rear_axle_xy[:, 0]),
            "y": np.interp(t, self.time_s, self.rear_axle_xy[:, 1]),
            "yaw": np.interp(t, self.time_s, self.yaw_rad),
            "trailer_yaw": np.interp(t, self.time_s, self.trailer_yaw_rad),
            "speed": np.interp(t, self.time_s, self.speed_mps),
        }
        nearest = np.clip(np.rint((t - self.time_s[0]) / DT_S).astype(int), 0, len(self.time_s) - 1)
        out["label"] = np.array([self.labels[i] for i in self.label_index[nearest]])
        return out

    def mirrored(self) -> Trajectory:
        """The mirror image about the x axis (left turns become right turns; still a valid motion)."""
        xy = self.rear_axle_xy * [1.0, -1.0]
        return Trajectory(
            self.art,
            self.time_s,
            xy,
            -self.yaw_rad,
            -self.trailer_yaw_rad,
            self.speed_mps,
            -self.steer_rad,
            self.label_index,
            self.labels,
        )

    def moved(self, yaw_rad: float, offset_xy) -> Trajectory:
        """The same motion rotated about the origin by ``yaw_rad`` and then shifted."""
        xy = rotate_xy(self.rear_axle_xy, yaw_rad) + np.asarray(offset_xy, dtype=float)
        return Trajectory(
            self.art,
            self.time_s,
            xy,
            self.yaw_rad + yaw_rad,
            self.trailer_yaw_rad + yaw_rad,
            self.speed_mps,
            self.steer_rad,
            self.label_index,
            self.labels,
        )


@dataclass
class _Progress:
    start_state: np.ndarray
    distance_m: float = 0.0
    elapsed_s: float = 0.0
    aligned_at_m: float | None = None  # reverse docking: distance when the trailer got aligned
    unwinding: bool = False


@dataclass
class Integrator:
    art: kin.Articulation
    state: np.ndarray = field(default_factory=lambda: np.zeros(4))
    speed_mps: float = 0.0
    steer_rad: float = 0.0

    def run(self, phases: list[Phase], duration_s: float, tail_s: float = 0.5) -> Trajectory:
        """Integrate the phases; pad with standstill (or cut) so recorded time covers ``duration_s + tail_s``."""
        rows: list[tuple] = []
        t = 0.0
        record_start = None
        for phase in phases:
            if phase.record and record_start is None:
                record_start = t
            if record_start is not None and t - record_start > duration_s + tail_s:
                break
            t = self._run_phase(
                phase, t, rows, stop_time=None if record_start is None else record_start + duration_s + tail_s
            )
        if record_start is None:
            record_start = t
        standstill = LABELS.index("standstill")
        while t - record_start <= duration_s + tail_s:
            self._advance(0.0, 0.0)
            t += DT_S
            rows.append((t, *self.state, self.speed_mps, self.steer_rad, standstill))
        data = np.array(rows)
        keep = data[:, 0] >= record_start - 1e-9
        data = data[keep]
        return Trajectory(
            art=self.art,
            time_s=data[:, 0] - record_start,
            rear_axle_xy=data[:, 1:3],
            yaw_rad=data[:, 3],
            trailer_yaw_rad=data[:, 4],
            speed_mps=data[:, 5],
            steer_rad=data[:, 6],
            label_index=data[:, 7].astype(int),
        )

    def _advance(self, speed_target: float, steer_target: float) -> None:
        art = self.art
        dv = art.max_accel_mps2 * DT_S
        self.speed_mps += float(np.clip(speed_target - self.speed_mps, -dv, dv))
        max_steer = math.radians(art.max_steer_deg)
        steer_target = float(np.clip(steer_target, -max_steer, max_steer))
        ds = math.radians(art.max_steer_rate_deg_s) * DT_S
        self.steer_rad += float(np.clip(steer_target - self.steer_rad, -ds, ds))
        self.state = kin.step(self.state, self.speed_mps, self.steer_rad, art, DT_S)

    def _run_phase(self, phase: Phase, t: float, rows: list, stop_time: float | None) -> float:
        label = LABELS.index(phase.label)
        progress = _Progress(start_state=self.state.copy())
        max_steps = int(300.0 / DT_S)
        for _ in range(max_steps):
            if stop_time is not None and t >= stop_time:
                break
            speed_target, steer_target, done = self._control(phase, progress)
            if done and (not phase.stop or abs(self.speed_mps) < 1e-3):
                break
            if done:
                speed_target = 0.0
            before = self.state.copy()
            self._advance(speed_target, steer_target)
            progress.distance_m += float(np.hypot(*(self.state[:2] - before[:2])))
            progress.elapsed_s += DT_S
            t += DT_S
            rows.append((t, *self.state, self.speed_mps, self.steer_rad, label))
        else:
            raise RuntimeError(f"maneuver phase {phase} did not reach its goal within {max_steps * DT_S:.0f} s")
        return t

    def _braking_speed(self, phase: Phase, remaining_m: float) -> float:
        speed = abs(phase.speed_mps)
        if phase.stop:
            speed = min(speed, math.sqrt(2.0 * 0.8 * self.art.max_accel_mps2 * max(remaining_m, 0.0)) + 0.05)
        return math.copysign(speed, phase.speed_mps) if phase.speed_mps else 0.0

    def _control(self, phase: Phase, p: _Progress) -> tuple[float, float, bool]:
        """Speed target, steering target and whether the phase goal is reached."""
        art = self.art
        if phase.trailer_heading_deg is not None:
            return self._reverse_into_bay(phase, p)
        if phase.heading_deg is not None:
            remaining = math.radians(phase.heading_deg) - self.state[2]
            turn_sign = math.copysign(1.0, remaining * (1 if phase.speed_mps >= 0 else -1))
            steer_full = kin.steady_turn_steer_rad(turn_sign * phase.radius_m, art)
            # Heading still gained while the steering winds back to zero at the rate limit.
            unwind_s = abs(self.steer_rad) / math.radians(art.max_steer_rate_deg_s)
            unwind_gain = abs(self.speed_mps * math.tan(self.steer_rad) / art.wheelbase_m) * unwind_s / 2.0
            if abs(remaining) <= unwind_gain + 1e-4 or math.copysign(1.0, remaining) != math.copysign(
                1.0, math.radians(phase.heading_deg) - p.start_state[2]
            ):
                p.unwinding = True
            if p.unwinding:
                return self._braking_speed(phase, 0.0), 0.0, abs(self.steer_rad) < 1e-3
            return self._braking_speed(phase, abs(remaining) * phase.radius_m), steer_full, False
        if phase.distance_m is not None:
            remaining = phase.distance_m - p.distance_m
            return self._braking_speed(phase, remaining), 0.0, remaining <= 0.0
        if phase.duration_s is not None:
            return phase.speed_mps, 0.0, p.elapsed_s >= phase.duration_s
        raise ValueError(f"phase {phase.label} has no goal")

    def _reverse_into_bay(self, phase: Phase, p: _Progress) -> tuple[float, float, bool]:
        art = self.art
        error = math.radians(phase.trailer_heading_deg) - self.state[3]
        max_hitch = math.radians(reverse_hitch_limit_deg(art))
        hitch_ref = float(np.clip(3.0 * error, -max_hitch, max_hitch))
        if p.aligned_at_m is None and abs(error) < math.radians(1.5):
            p.aligned_at_m = p.distance_m
        straight_m = phase.distance_m or 0.0
        if p.aligned_at_m is None:
            remaining = straight_m + abs(error) * art.trailer_hitch_to_axle_m
        else:
            remaining = straight_m - (p.distance_m - p.aligned_at_m)
        speed = self._braking_speed(phase, remaining)
        if abs(speed) < 0.05 and abs(self.speed_mps) < 0.05:
            speed = math.copysign(0.05, phase.speed_mps)  # creep: the hitch controller needs motion
        steer = kin.steer_for_hitch(self.state, self.speed_mps if abs(self.speed_mps) > 0.05 else speed, hitch_ref, art)
        return speed, steer, remaining <= 0.0


def reverse_hitch_limit_deg(art: kin.Articulation, steer_share: float = 0.6) -> float:
    """Largest hitch angle held while reversing whose steady-state steering uses at most
    ``steer_share`` of the steering range (margin for the controller; beyond it the trailer jackknifes)."""
    hitch = np.radians(np.arange(5.0, min(art.max_hitch_deg, 40.0) + 0.1, 0.5))
    l2, m = art.trailer_hitch_to_axle_m, art.hitch_behind_axle_m
    steady_steer = np.degrees(np.arctan(art.wheelbase_m * np.sin(hitch) / (l2 + m * np.cos(hitch))))
    ok = hitch[steady_steer <= steer_share * art.max_steer_deg]
    return float(np.degrees(ok[-1])) if len(ok) else 5.0


# --------------------------------------------------------------------------- scenarios


def turn_radius_m(art: kin.Articulation) -> float:
    """A comfortable turning radius of the truck's rear axle for this combination."""
    return float(np.clip(0.8 * (art.wheelbase_m + art.trailer_hitch_to_axle_m), 4.0, 10.0))


def scenario_phases(scenario: str, art: kin.Articulation, duration_s: float) -> list[Phase]:
    """The phases of a named scenario; the vehicle starts at the origin heading +x."""
    if scenario not in SCENARIOS:
        raise ValueError(f"unknown scenario {scenario!r}; choose one of {', '.join(SCENARIOS)}")
    r = turn_radius_m(art)
    if scenario == "straight":
        speed = float(np.clip(30.0 / max(duration_s - 4.0, 1.0), 1.0, 2.5))
        return [Phase("straight", speed, distance_m=30.0, stop=True)]
    if scenario == "single_turn":
        return [
            Phase("straight", 2.0, distance_m=8.0),
            Phase("single_turn", 1.5, heading_deg=90.0, radius_m=r),
            Phase("straight", 1.5, distance_m=10.0, stop=True),
        ]
    if scenario == "long_curve":
        return [
            Phase("straight", 2.0, distance_m=4.0),
            Phase("long_curve", 2.0, heading_deg=-60.0, radius_m=2.5 * r),
            Phase("straight", 2.0, distance_m=6.0, stop=True),
        ]
    if scenario == "u_turn":
        return [
            Phase("straight", 2.0, distance_m=5.0),
            Phase("u_turn", 2.0, heading_deg=180.0, radius_m=r),
            Phase("straight", 2.0, distance_m=6.0, stop=True),
        ]
    if scenario == "lane_change":
        return [
            Phase("straight", 2.0, distance_m=8.0),
            Phase("lane_change", 2.0, heading_deg=25.0, radius_m=1.5 * r),
            Phase("lane_change", 2.0, heading_deg=0.0, radius_m=1.5 * r),
            Phase("straight", 2.0, distance_m=10.0, stop=True),
        ]
    if scenario == "roundabout":
        radius = max(0.85 * r, 1.2 * art.trailer_hitch_to_axle_m)  # the trailer must fit inside the circle
        loop_s = 2 * math.pi * radius / 3.0
        loops = max(1, int((duration_s - 8.0) // loop_s))  # loop again while time allows
        return [
            Phase("straight", 2.0, distance_m=4.0),
            Phase("roundabout", 3.0, heading_deg=360.0 * loops, radius_m=radius),
            Phase("straight", 2.0, distance_m=6.0, stop=True),
        ]
    if scenario == "reverse_docking":
        return [
            Phase("straight", 1.5, distance_m=5.0, stop=True),
            Phase("standstill", duration_s=1.0),
            Phase("reverse_docking", -1.2, trailer_heading_deg=-80.0, distance_m=3.0, stop=True),
        ]
    if scenario == "standstill":
        # Parked at an angle: a recorded standstill after an unrecorded turn.
        return [
            Phase("single_turn", 1.5, heading_deg=30.0, radius_m=r, record=False),
            Phase("standstill", 1.5, distance_m=1.0, stop=True, record=False),
            Phase("standstill", duration_s=duration_s + 1.0),
        ]
    # docking: approach, turn, reverse into the bay, wait, pull out.
    return [
        Phase("straight", 2.0, distance_m=4.0),
        Phase("single_turn", 1.5, heading_deg=35.0, radius_m=r),
        Phase("straight", 1.5, distance_m=2.0, stop=True),
        Phase("standstill", duration_s=0.5),
        Phase("reverse_docking", -1.5, trailer_heading_deg=-35.0, distance_m=2.0, stop=True),
        Phase("standstill", duration_s=2.0),
        Phase("straight", 1.5, distance_m=5.0, stop=True),
    ]


def build_trajectory(scenario: str, art: kin.Articulation, duration_s: float, tail_s: float = 0.5) -> Trajectory:
    """Integrated trajectory of a scenario in its own frame (start at the origin heading +x)."""
    return Integrator(art).run(scenario_phases(scenario, art, duration_s), duration_s, tail_s)
