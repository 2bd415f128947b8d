"""One sweep of an OS1-64 on a car's roof (1.8 m), ray-cast (open3d) through constructed scenes on
flat ground: what a vehicle-mounted sensor sees of trucks, buses, walls, trees and signs (no roof
above 1.8 m, one face of most things), with the ground's returns around and under them. The same
scenes seen by a yard's pole (``POLE``: an OS1-32 6 m up) give the service's sweeps."""

from __future__ import annotations

import math
import tempfile
from pathlib import Path

import numpy as np

from i2v_loc.frame import Frame, SensorScan
from i2v_loc.params import Extrinsics, Params, SensorConfig, load_params
from i2v_loc.pipelines import build_pipeline
from i2v_loc.sim import meshes as m
from i2v_loc.sim.kinematics import Articulation, trailer_axle_point
from i2v_loc.sim.lidar import LidarModel, YardCaster
from i2v_loc.sim.sensor_model import BeamTable

SENSOR_HEIGHT_M = 1.8
SENSOR = SensorConfig(
    name="roof", model="OS1-64", columns=2048, max_range_m=120.0, extrinsics=Extrinsics(z_m=SENSOR_HEIGHT_M)
)

POLE = SensorConfig(name="pole", model="OS1-32", columns=1024, max_range_m=120.0, extrinsics=Extrinsics(z_m=6.0))


def _pose(x: float, y: float, yaw: float) -> np.ndarray:
    t = np.eye(4)
    t[:2, :2] = [[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]]
    t[:2, 3] = x, y
    return t


def articulated(name: str, x: float, y: float, yaw: float) -> list[m.Mesh]:
    """A catalogue tractor and its trailer driving straight, the tractor's rear axle at (x, y)."""
    vehicle = Params().vehicles[name]
    axle = trailer_axle_point(np.array([x, y, yaw, yaw]), Articulation.from_vehicle(vehicle))
    return [
        m.transformed(m.truck_mesh(vehicle.truck, "white_paint"), _pose(x, y, yaw)),
        m.transformed(m.trailer_mesh(vehicle.trailer), _pose(*axle, yaw)),
    ]


def parked_trailer(name: str, x: float, y: float, yaw: float) -> list[m.Mesh]:
    """A catalogue vehicle's trailer standing alone (its box's centre at x, y)."""
    trailer = Params().vehicles[name].trailer
    centre = m.box_center_in_axle_frame(trailer, is_truck=False)
    return [m.transformed(m.shifted(m.trailer_mesh(trailer), (-centre[0], 0.0, 0.0)), _pose(x, y, yaw))]


def container(x: float, y: float, yaw: float, length_m: float = 2.99) -> list[m.Mesh]:
    """A 2.44 m wide, 2.6 m tall box set down on the ground (a 10-ft container by default)."""
    return [m.box((x, y, 1.3), (length_m, 2.44, 2.6), yaw, "concrete")]


def bus(x: float, y: float, yaw: float, length_m: float = 12.0, width_m: float = 2.55) -> list[m.Mesh]:
    """A 3.2 m tall body 0.3 m above the ground on two axles (centre at x, y)."""
    wheels = m.wheel_pair(length_m / 2 - 2.5, width_m / 2 - 0.2, 0.5, 0.3)
    wheels += m.wheel_pair(-length_m / 2 + 3.0, width_m / 2 - 0.2, 0.5, 0.3)
    body = m.box_between(-length_m / 2, length_m / 2, -width_m / 2, width_m / 2, 0.3, 3.2, "white_paint")
    return [m.transformed(part, _pose(x, y, yaw)) for part in [body, *wheels]]


def box_truck(
    x: float,
    y: float,
    yaw: float,
    length_m: float = 10.0,
    gap_m: float = 0.1,
    floor_m: float = 1.1,
    box_width_m: float = 2.5,
) -> list[m.Mesh]:
    """A rigid truck (centre at x, y): a cab 2.5 m wide and 2.3 m long from 0.5 to 2.9 m, ``gap_m``
    behind it a cargo box ``box_width_m`` wide from ``floor_m`` to 3.6 m, two axles."""
    front, width_m = length_m / 2, 2.5
    cab = m.box_between(front - 2.3, front, -width_m / 2, width_m / 2, 0.5, 2.9, "white_paint")
    cargo = m.box_between(-front, front - 2.3 - gap_m, -box_width_m / 2, box_width_m / 2, floor_m, 3.6, "white_paint")
    wheels = m.wheel_pair(front - 1.4, width_m / 2 - 0.2, 0.5, 0.3)
    wheels += m.wheel_pair(-front + 2.5, box_width_m / 2 - 0.2, 0.5, 0.3)
    return [m.transformed(part, _pose(x, y, yaw)) for part in [cab, cargo, *wheels]]


def person(x: float, y: float) -> list[m.Mesh]:
    """A 1.7 m tall cylinder 0.6 m across."""
    return [m.cylinder((x, y, 0.85), 0.3, 1.7, surface="concrete")]


def car(x: float, y: float, yaw: float) -> list[m.Mesh]:
    """A 4.5 m long, 1.8 m wide body from 0.3 to 1.5 m (centre at x, y)."""
    return [m.transformed(m.box_between(-2.25, 2.25, -0.9, 0.9, 0.3, 1.5, "white_paint"), _pose(x, y, yaw))]


def wall(x0: float, y0: float, x1: float, y1: float, height_m: float) -> list[m.Mesh]:
    length = math.hypot(x1 - x0, y1 - y0)
    centre = ((x0 + x1) / 2, (y0 + y1) / 2, height_m / 2)
    return [m.box(centre, (length, 0.3, height_m), math.atan2(y1 - y0, x1 - x0), "concrete")]


def tree(x: float, y: float) -> list[m.Mesh]:
    """A trunk and a round crown 2.6 m across from 1.2 to 4.2 m."""
    return [
        m.cylinder((x, y, 0.6), 0.15, 1.2, surface="pole"),
        m.cylinder((x, y, 2.7), 1.3, 3.0, segments=24, surface="concrete"),
    ]


def sign(x: float, y: float, yaw: float) -> list[m.Mesh]:
    """A 2.5 m wide, 1.5 m tall board from 2.2 m on two posts."""
    board = m.box_between(-0.05, 0.05, -1.25, 1.25, 2.2, 3.7, "white_paint")
    posts = [m.box_between(-0.05, 0.05, s - 0.05, s + 0.05, 0.0, 2.2, "steel") for s in (-1.0, 1.0)]
    return [m.transformed(part, _pose(x, y, yaw)) for part in [board, *posts]]


def sweep(
    parts: list[m.Mesh], top_deg: float | None = None, seed: int = 0, sensor: SensorConfig = SENSOR
) -> np.ndarray:
    """The sweep's returns in the sensor's frame (float32, NaN-free). ``top_deg``: 64 beams from
    there 26.8 deg down, evenly (a Velodyne HDL-64E's fan reaches 2 deg up), instead of the OS1-64's
    +-22.5 deg. ``sensor``: the roof's OS1-64 unless given (a yard's pole)."""
    ground = m.box((0.0, 0.0, -0.05), (300.0, 300.0, 0.1), 0.0, "asphalt")
    # a street's buildings, beyond the region: something stands higher in the view than any vehicle
    # (the sweep's highest return is where the view ends, only if the view reaches no higher)
    buildings = [m.box((0.0, sign * 75.0, 10.0), (60.0, 10.0, 20.0), 0.0, "concrete") for sign in (-1, 1)]
    lidar = LidarModel.from_config(sensor)
    if top_deg is not None:
        fan = np.linspace(top_deg, top_deg - 26.8, 64).astype(np.float32)
        lidar.beam_table = BeamTable(fan, np.zeros(64, np.float32), sensor.columns, "even fan")
    ranges, _ = YardCaster(m.merge([ground, *buildings, *parts]), [], 1).measure(
        lidar, 0.0, np.random.default_rng(seed)
    )
    points = (lidar.yard_directions() * ranges[..., None]).reshape(-1, 3)
    return points[np.isfinite(points).all(axis=1)].astype(np.float32)


def params_yaml(sensor: SensorConfig = SENSOR) -> str:
    """``sensor`` (the roof's unless given) for ``detect --params``: its height, the region around it."""
    return (
        f"sensors:\n- name: {sensor.name}\n  model: {sensor.model}\n  columns: {sensor.columns}\n"
        f"  extrinsics: {{z_m: {sensor.extrinsics.z_m}}}\n"
        "region: {x_min_m: -60, x_max_m: 60, y_min_m: -60, y_max_m: 60}\n"
    )


def sensor_params(sensor: SensorConfig = SENSOR) -> Params:
    """The parameters of ``params_yaml`` as the service loads them (the roof's sensor unless given)."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / f"{sensor.name}.yaml"
        path.write_text(params_yaml(sensor))
        return load_params(path)


def pole_params() -> Params:
    """The service's parameters for ``POLE`` alone: frames to come, the map learned."""
    return sensor_params(POLE)


def yard_reports(parts: list[m.Mesh], frames: int, first_seed: int = 0, params: Params | None = None) -> list[list]:
    """The vehicles the service reports in each of ``frames`` sweeps of ``POLE`` from its start (the
    sweeps' noise seeded ``first_seed`` on)."""
    pipeline = build_pipeline(params or pole_params(), "default")
    reports = []
    for k in range(frames):
        scan = SensorScan(POLE.name, 0.1 * k, sweep(parts, None, first_seed + k, POLE), None, from_sensor=True)
        reports.append(pipeline.process(Frame(k, {POLE.name: scan})).to_json()["vehicles"])
    return reports
