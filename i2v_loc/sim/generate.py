"""Generate a recording: vehicles driving maneuvers in the yard, seen by ray-cast LiDARs."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from i2v_loc.geometry import planar_poses, pose_matrix, rotate_xy, wrap_deg
from i2v_loc.params import Extrinsics, Params, ParamsError, VehicleConfig, dump_yaml, read_yaml, validate_params
from i2v_loc.recording import SensorScans, meters_to_range_mm, write_recording
from i2v_loc.sim import kinematics as kin
from i2v_loc.sim import maneuvers as mv
from i2v_loc.sim import meshes as m
from i2v_loc.sim.lidar import LidarModel, MovingObject, YardCaster
from i2v_loc.sim.sensor_model import ReturnModel
from i2v_loc.sim.yard import FIELD_CENTER_XY, build_yard, footprint_points

GENERATOR = "i2v-loc sim"
DOCK_Y_M = -1.5
UNKNOWN_PREFIX = "unknown_"


@dataclass
class SimConfig:
    vehicles: list[str]
    scenario: str
    seed: int = 0
    duration_s: float = 30.0
    start_s: float = 0.0  # skip this much of the maneuver (for short clips)
    columns: int | None = None  # override every sensor's columns
    returns: ReturnModel | None = field(default_factory=ReturnModel)  # None: ideal sensors (tests)
    max_phase_s: float = 0.1
    max_clock_offset_s: float = 0.005
    guess_offset_m: float = 0.3
    guess_angle_deg: float = 2.0
    slope_deg: float = 0.0  # ground grade along +x
    distractors: bool = True
    clutter_near: bool = False  # parked trailers and containers right beside the vehicles' swept area
    slices: int = 8
    params: Params = field(default_factory=Params)
    # Simulator-only vehicles (``--vehicles-file``): never written to the recording's parameters,
    # and named ``unknown_<name>`` in the ground truth.
    extra_vehicles: dict[str, VehicleConfig] = field(default_factory=dict)


@dataclass
class PlacedVehicle:
    """One articulated vehicle: its geometry and trajectory in the yard (on the ground plane)."""

    vehicle_id: int
    name: str  # as in the ground truth
    config: VehicleConfig
    trajectory: mv.Trajectory
    truck_center_axle: np.ndarray = field(init=False)
    trailer_center_axle: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        self.truck_center_axle = m.box_center_in_axle_frame(self.config.truck, is_truck=True)
        self.trailer_center_axle = m.box_center_in_axle_frame(self.config.trailer, is_truck=False)

    def unit_poses(self, t_s) -> tuple[np.ndarray, np.ndarray, dict]:
        """(n, 4, 4) truck-box and trailer-box poses on the flat plane, and the samples."""
        s = self.trajectory.sample(t_s)
        art = self.trajectory.art
        truck = _poses(s["x"], s["y"], s["yaw"], self.truck_center_axle)
        hitch_x = s["x"] - art.hitch_behind_axle_m * np.cos(s["yaw"])
        hitch_y = s["y"] - art.hitch_behind_axle_m * np.sin(s["yaw"])
        axle2_x = hitch_x - art.trailer_hitch_to_axle_m * np.cos(s["trailer_yaw"])
        axle2_y = hitch_y - art.trailer_hitch_to_axle_m * np.sin(s["trailer_yaw"])
        trailer = _poses(axle2_x, axle2_y, s["trailer_yaw"], self.trailer_center_axle)
        return truck, trailer, s

    def footprint(self, step_s: float = 0.5) -> np.ndarray:
        t = np.arange(0.0, self.trajectory.time_s[-1], step_s)
        truck, trailer, _ = self.unit_poses(t)
        return np.vstack(
            [
                footprint_points(
                    poses[:, :2, 3], unit.length_m, unit.width_m, np.arctan2(poses[:, 1, 0], poses[:, 0, 0]), 1.0
                )
                for poses, unit in ((truck, self.config.truck), (trailer, self.config.trailer))
            ]
        )


def _poses(x, y, yaw, center_axle) -> np.ndarray:
    """(n, 4, 4) poses of boxes whose centre sits at ``center_axle`` in the axle frame (x, y, yaw)."""
    poses = planar_poses(x, y, yaw, center_axle[2])
    poses[:, :2, 3] += rotate_xy(center_axle[:2], yaw)
    return poses


# --------------------------------------------------------------------------- vehicles


def unknown_name(name: str) -> str:
    return name if name.startswith(UNKNOWN_PREFIX) else UNKNOWN_PREFIX + name


def vehicle_lookup(cfg: SimConfig, name: str) -> tuple[str, VehicleConfig]:
    """Ground-truth name and geometry of a vehicle: a configured vehicle keeps its name; a
    simulator-only one is ``unknown_<name>``, so nothing in the recording names its dimensions."""
    if name in cfg.params.vehicles:
        return name, cfg.params.vehicles[name]
    if name in cfg.extra_vehicles:
        return unknown_name(name), cfg.extra_vehicles[name]
    raise ValueError(f"unknown vehicle {name!r}; known: {', '.join([*cfg.params.vehicles, *cfg.extra_vehicles])}")


def load_vehicles_file(path, known=()) -> dict[str, VehicleConfig]:
    """Simulator-only vehicles from a file in the format of params/vehicles.yaml, validated with the
    parameter model (errors name the file and key). Names of ``known`` vehicles are refused: the
    file defines vehicles the pipeline does not know."""
    data = read_yaml(path)
    if set(data) != {"vehicles"} or not isinstance(data["vehicles"], dict) or not data["vehicles"]:
        raise ParamsError(
            f"{path}: expected one non-empty 'vehicles' mapping as in params/vehicles.yaml, got keys {sorted(data)}"
        )
    vehicles = validate_params({"vehicles": data["vehicles"]}, source=str(path)).vehicles
    clash = sorted(set(vehicles) & set(known))
    if clash:
        raise ParamsError(
            f"{path}: vehicles.{clash[0]} is a configured vehicle; name simulator-only vehicles differently"
        )
    return dict(vehicles)


# --------------------------------------------------------------------------- placement


def _best_rotation(points: np.ndarray) -> float:
    """Rotation (radians) that makes the points' y extent smallest: the field is wide in x."""
    angles = np.radians(np.arange(0.0, 180.0, 5.0))
    extents = [np.ptp(points @ np.array([math.sin(a), math.cos(a)])) for a in angles]
    return float(angles[int(np.argmin(extents))])


def place_vehicles(cfg: SimConfig, tail_s: float) -> list[PlacedVehicle]:
    """Trajectories of every vehicle, moved into the field without overlapping each other."""
    placed: list[PlacedVehicle] = []
    occupied = np.array([[sc.extrinsics.x_m, sc.extrinsics.y_m] for sc in cfg.params.sensors])  # sensor poles
    for i, requested in enumerate(cfg.vehicles):
        name, vcfg = vehicle_lookup(cfg, requested)
        art = kin.Articulation.from_vehicle(vcfg)
        raw = mv.build_trajectory(cfg.scenario, art, cfg.start_s + cfg.duration_s, tail_s)
        if cfg.start_s > 0:
            keep = raw.time_s >= cfg.start_s - 1e-9
            raw = mv.Trajectory(
                art,
                raw.time_s[keep] - cfg.start_s,
                raw.rear_axle_xy[keep],
                raw.yaw_rad[keep],
                raw.trailer_yaw_rad[keep],
                raw.speed_mps[keep],
                raw.steer_rad[keep],
                raw.label_index[keep],
            )
        options = []
        for variant in (raw, raw.mirrored()):
            options.append(_fit(PlacedVehicle(i + 1, name, vcfg, variant), occupied, allow_dock=i == 0))
            if cfg.scenario not in ("docking", "reverse_docking"):
                break  # only docks are worth mirroring to keep them clear of the sensors
        yaw, offset, fp, variant, _ = min(options, key=lambda o: o[4])
        vehicle = PlacedVehicle(i + 1, name, vcfg, variant.moved(yaw, offset))
        placed.append(vehicle)
        occupied = np.vstack([occupied, fp])
    return placed


def _fit(probe: PlacedVehicle, occupied: np.ndarray, allow_dock: bool):
    """Rotation, shift, footprint in the yard and the trajectory of one vehicle placed in the field."""
    pts = probe.footprint()
    dock = _dock_pose(probe) if allow_dock else None
    # A dock goes on the field's long south edge (between l2 and l3, away from the sensors):
    # the docked trailer faces north with its rear at y = DOCK_Y_M. Otherwise fit the field.
    yaw = math.pi / 2 - dock[1] if dock is not None else _best_rotation(pts)
    rotated = rotate_xy(pts, yaw)
    centering = np.array(FIELD_CENTER_XY) - (rotated.min(axis=0) + rotated.max(axis=0)) / 2
    if dock is not None:
        centering[1] = DOCK_Y_M - rotate_xy(dock[0], yaw)[1]
    shift = _free_offset(rotated + centering, occupied, along_x_only=dock is not None)
    return yaw, centering + shift, rotated + centering + shift, probe.trajectory, float(np.hypot(*shift))


def _free_offset(
    points: np.ndarray, occupied: np.ndarray, clearance_m: float = 2.0, along_x_only: bool = False
) -> np.ndarray:
    """The smallest shift that keeps ``points`` ``clearance_m`` away from ``occupied``."""
    tree = cKDTree(occupied)
    dys = [0.0] if along_x_only else np.arange(-30, 31, 1.0)
    grid = np.array([(dx, dy) for dx in np.arange(-40, 41, 1.0) for dy in dys])
    for offset in grid[np.argsort(np.hypot(grid[:, 0], grid[:, 1] * 1.5), kind="stable")]:
        if tree.query(points + offset)[0].min() > clearance_m:
            return offset
    raise ValueError("cannot place the vehicles clear of each other and of the sensors; use fewer vehicles")


# --------------------------------------------------------------------------- sensors


def make_lidars(cfg: SimConfig, rng: np.random.Generator) -> list[LidarModel]:
    lidars = []
    for sensor in cfg.params.sensors:
        if cfg.columns is not None:
            sensor = sensor.model_copy(update={"columns": cfg.columns})
        returns = None if cfg.returns is None else replace(cfg.returns, min_range_m=sensor.min_range_m)
        lidars.append(
            LidarModel.from_config(
                sensor,
                returns=returns,
                phase_s=float(rng.uniform(0.0, cfg.max_phase_s)),
                clock_offset_s=float(rng.uniform(-cfg.max_clock_offset_s, cfg.max_clock_offset_s)),
            )
        )
    return lidars


def with_true_time_offsets(params: Params, lidars: list[LidarModel]) -> Params:
    """The sensors with ``time_offset_s`` undoing each LiDAR's clock offset: a sweep stamped
    ``t + clock_offset_s`` started at ``t`` on the common clock, and the offset is added to stamps."""
    offsets = {lidar.name: -round(lidar.clock_offset_s, 9) for lidar in lidars}
    sensors = [s.model_copy(update={"time_offset_s": offsets[s.name]}) for s in params.sensors]
    return params.model_copy(update={"sensors": sensors})


def guessed_sensors(cfg: SimConfig, rng: np.random.Generator) -> Params:
    """The true sensors with every pose but the reference's perturbed by ± the guess offsets."""
    reference = cfg.params.calibration.reference_sensor
    names = [s.name for s in cfg.params.sensors]
    if reference not in names:
        reference = names[0]
    sensors = []
    for sensor in cfg.params.sensors:
        signs = rng.choice([-1.0, 1.0], size=6)
        if sensor.name == reference:
            sensors.append(sensor)
            continue
        e = sensor.extrinsics
        d, a = cfg.guess_offset_m, cfg.guess_angle_deg
        ext = Extrinsics(
            x_m=e.x_m + signs[0] * d,
            y_m=e.y_m + signs[1] * d,
            z_m=e.z_m + signs[2] * d,
            roll_deg=float(wrap_deg(e.roll_deg + signs[3] * a)),
            pitch_deg=float(np.clip(e.pitch_deg + signs[4] * a, -90, 90)),
            yaw_deg=float(wrap_deg(e.yaw_deg + signs[5] * a)),
        )
        sensors.append(sensor.model_copy(update={"extrinsics": ext}))
    return cfg.params.model_copy(update={"sensors": sensors})


# --------------------------------------------------------------------------- generation


def _dock_pose(vehicle: PlacedVehicle) -> tuple[np.ndarray, float] | None:
    """Where the docking trailer's rear face ends: the last reverse_docking sample."""
    traj = vehicle.trajectory
    idx = np.nonzero(traj.label_index == mv.LABELS.index("reverse_docking"))[0]
    if len(idx) == 0:
        return None
    t = traj.time_s[idx[-1]]
    _, trailer, _ = vehicle.unit_poses([t])
    heading = math.atan2(trailer[0, 1, 0], trailer[0, 0, 0])
    rear = trailer[0, :2, 3] - vehicle.config.trailer.length_m / 2 * np.array([math.cos(heading), math.sin(heading)])
    return rear, heading


@dataclass
class Simulation:
    cfg: SimConfig
    vehicles: list[PlacedVehicle]
    lidars: list[LidarModel]
    caster: YardCaster
    yard: object
    tilt: np.ndarray
    n_frames: int
    rate_hz: float
    surfaces: dict[int, tuple[str, str]]  # vehicle id -> (cab paint, trailer body)


def build_simulation(cfg: SimConfig) -> Simulation:
    if cfg.duration_s <= 0:
        raise ValueError(f"duration must be positive, got {cfg.duration_s} s")
    if cfg.scenario not in mv.SCENARIOS:
        raise ValueError(f"unknown scenario {cfg.scenario!r}; choose one of {', '.join(mv.SCENARIOS)}")
    seeds = np.random.SeedSequence(cfg.seed).spawn(3)
    rng_sensors, rng_yard = np.random.default_rng(seeds[0]), np.random.default_rng(seeds[1])
    rates = {s.rate_hz for s in cfg.params.sensors}
    if len(rates) != 1:
        raise ValueError(f"all sensors must share one rate, got {sorted(rates)} Hz")
    rate_hz = float(rates.pop())
    lidars = make_lidars(cfg, rng_sensors)
    tail_s = cfg.max_phase_s + 1.0 / rate_hz + 0.1
    vehicles = place_vehicles(cfg, tail_s)
    tilt = pose_matrix(0, 0, 0, 0, -cfg.slope_deg, 0)  # ground rising along +x for a positive grade
    occupied = np.vstack([v.footprint() for v in vehicles])
    sensor_xyz = np.array([lidar.pose[:3, 3] for lidar in lidars])
    dock = next((d for d in (_dock_pose(v) for v in vehicles) if d is not None), None)
    semitrailer = next(
        (v.config.trailer for v in vehicles if v.config.trailer.hitch_to_front_m >= 0),
        cfg.params.vehicles["man_tgx"].trailer if "man_tgx" in cfg.params.vehicles else None,
    )
    yard = build_yard(rng_yard, occupied, sensor_xyz, dock, semitrailer, cfg.distractors, cfg.clutter_near)
    objects = []
    rng_paint = np.random.default_rng(np.random.SeedSequence(cfg.seed).spawn(5)[4])
    surfaces = {}
    for v in vehicles:
        paint, body = surfaces[v.vehicle_id] = vehicle_surfaces(rng_paint)
        truck_mesh = m.shifted(m.truck_mesh(v.config.truck, paint), -v.truck_center_axle)
        trailer_mesh = m.shifted(m.trailer_mesh(v.config.trailer, body), -v.trailer_center_axle)
        objects.append(MovingObject(2 * v.vehicle_id, truck_mesh, lambda t, v=v: tilt @ v.unit_poses(t)[0]))
        objects.append(MovingObject(2 * v.vehicle_id + 1, trailer_mesh, lambda t, v=v: tilt @ v.unit_poses(t)[1]))
    for j, d in enumerate(yard.distractors):
        objects.append(MovingObject(1000 + j, d.mesh, lambda t, d=d: tilt @ _distractor_poses(d, t)))
    caster = YardCaster(m.transformed(yard.static_mesh(), tilt), objects, cfg.slices)
    n_frames = max(1, int(round(cfg.duration_s * rate_hz)))
    return Simulation(cfg, vehicles, lidars, caster, yard, tilt, n_frames, rate_hz, surfaces)


CAB_PAINTS = {"white_paint": 0.45, "silver_paint": 0.15, "red_paint": 0.15, "blue_paint": 0.1, "dark_paint": 0.15}
TRAILER_BODIES = {"trailer_panel": 0.5, "tarpaulin": 0.5}


def vehicle_surfaces(rng: np.random.Generator) -> tuple[str, str]:
    """A cab paint and a trailer body drawn from a yard's usual mix (a dark cab returns little)."""
    paint = rng.choice(list(CAB_PAINTS), p=list(CAB_PAINTS.values()))
    body = rng.choice(list(TRAILER_BODIES), p=list(TRAILER_BODIES.values()))
    return str(paint), str(body)


def _distractor_poses(d, t) -> np.ndarray:
    x, y, yaw = d.path(np.atleast_1d(np.asarray(t, float)))
    return planar_poses(x, y, yaw, d.dimensions[2] / 2)


def _yaw_deg(t: np.ndarray) -> float:
    return float(wrap_deg(math.degrees(math.atan2(t[1, 0], t[0, 0]))))


def _rounded(values, digits: int):
    """Rounded floats (nested lists for arrays) without the noise sign of -0.0."""
    values = np.asarray(values, dtype=float)
    if values.ndim == 0:
        return round(float(values), digits) + 0.0
    return [_rounded(v, digits) for v in values]


def _unit_gt(pose: np.ndarray, velocity_xy, unit, by_sensor: dict[str, int]) -> dict:
    return {
        "center": _rounded(pose[:3, 3], 4),
        "dimensions": [unit.length_m, unit.width_m, unit.height_m],
        "yaw_deg": _rounded(_yaw_deg(pose), 4),
        "velocity": _rounded(velocity_xy, 4),
        "points": int(sum(by_sensor.values())),
        "points_by_sensor": {name: int(n) for name, n in by_sensor.items()},
    }


def ground_truth_line(sim: Simulation, frame: int, counts: dict[str, dict[int, int]]) -> dict:
    """The truth at frame ``frame``; ``counts``: per sensor, the returns of each unit (id 2 v, 2 v + 1)."""
    t = frame / sim.rate_hz
    dt = 0.02
    vehicles = []
    for v in sim.vehicles:
        truck, trailer, s = v.unit_poses([t - dt, t, t + dt])
        truck, trailer = sim.tilt @ truck, sim.tilt @ trailer
        t_truck, t_trailer = truck[1], trailer[1]
        truck_gt = _unit_gt(
            t_truck,
            (truck[2, :2, 3] - truck[0, :2, 3]) / (2 * dt),
            v.config.truck,
            {name: c.get(2 * v.vehicle_id, 0) for name, c in counts.items()},
        )
        trailer_gt = _unit_gt(
            t_trailer,
            (trailer[2, :2, 3] - trailer[0, :2, 3]) / (2 * dt),
            v.config.trailer,
            {name: c.get(2 * v.vehicle_id + 1, 0) for name, c in counts.items()},
        )
        vehicles.append(
            {
                "id": v.vehicle_id,
                "vehicle": v.name,
                "maneuver": str(s["label"][1]),
                "hitch_deg": _rounded(wrap_deg(trailer_gt["yaw_deg"] - truck_gt["yaw_deg"]), 4),
                "truck": truck_gt,
                "trailer": trailer_gt,
                "tractor_to_trailer": _rounded(np.linalg.inv(t_trailer) @ t_truck, 6),
            }
        )
    distractors = []
    for d in sim.yard.distractors:
        pose = sim.tilt @ _distractor_poses(d, [t])[0]
        distractors.append(
            {
                "kind": d.kind,
                "center": _rounded(pose[:3, 3], 4),
                "dimensions": list(d.dimensions),
                "yaw_deg": _rounded(_yaw_deg(pose), 4),
            }
        )
    return {"frame": frame, "stamp_s": round(t, 6), "vehicles": vehicles, "distractors": distractors}


def simulate(cfg: SimConfig, progress=None) -> tuple[Simulation, dict[str, SensorScans], list[dict]]:
    """Run the simulation: range images per sensor and one ground-truth line per frame."""
    sim = build_simulation(cfg)
    rng_noise = np.random.default_rng(np.random.SeedSequence(cfg.seed).spawn(3)[2])
    ranges = {lidar.name: np.zeros((sim.n_frames, lidar.beams, lidar.columns), dtype=np.uint16) for lidar in sim.lidars}
    stamps = {lidar.name: np.zeros(sim.n_frames, dtype=np.int64) for lidar in sim.lidars}
    gt = []
    for k in range(sim.n_frames):
        counts: dict[str, dict[int, int]] = {}
        for lidar in sim.lidars:
            sweep_start = k / sim.rate_hz + lidar.phase_s
            measured, hit = sim.caster.measure(lidar, sweep_start, rng_noise)
            ranges[lidar.name][k] = meters_to_range_mm(measured)
            hit = np.where(ranges[lidar.name][k] > 0, hit, -2)
            ids, n = np.unique(hit[hit >= 0], return_counts=True)
            counts[lidar.name] = {int(i): int(c) for i, c in zip(ids, n)}
            stamps[lidar.name][k] = int(round((sweep_start + lidar.clock_offset_s) * 1e9))
        gt.append(ground_truth_line(sim, k, counts))
        if progress is not None:
            progress(1)
    scans = {
        lidar.name: SensorScans(
            ranges[lidar.name],
            stamps[lidar.name],
            lidar.column_time_ns,
            lidar.beam_altitude_deg,
            lidar.beam_azimuth_offset_deg,
        )
        for lidar in sim.lidars
    }
    return sim, scans, gt


def openlabel(gt: list[dict], rate_hz: float) -> dict:
    """The ground truth as ASAM OpenLABEL 1.0 (one TRUCK and one TRAILER object per unit)."""
    from scipy.spatial.transform import Rotation

    objects, frames = {}, {}
    for line in gt:
        frame_objects = {}
        for v in line["vehicles"]:
            for unit, kind in (("truck", "TRUCK"), ("trailer", "TRAILER")):
                uid = str(2 * v["id"] - (1 if unit == "truck" else 0))
                objects.setdefault(
                    uid,
                    {
                        "name": f"{kind}_{v['id']}",
                        "type": kind,
                        "object_data": {"text": [{"name": "vehicle", "val": v["vehicle"]}]},
                    },
                )
                u = v[unit]
                q = Rotation.from_euler("z", u["yaw_deg"], degrees=True).as_quat()  # x, y, z, w
                frame_objects[uid] = {
                    "object_data": {
                        "cuboid": {
                            "name": "shape3D",
                            "val": [*u["center"], *_rounded(q, 8), *u["dimensions"]],
                            "attributes": {
                                "num": [
                                    {"name": "num_points", "val": u["points"]},
                                    {"name": "hitch_deg", "val": v["hitch_deg"]},
                                ],
                                "text": [{"name": "maneuver", "val": v["maneuver"]}],
                            },
                        }
                    }
                }
        frames[str(line["frame"])] = {"frame_properties": {"timestamp": line["stamp_s"]}, "objects": frame_objects}
    return {
        "openlabel": {
            "metadata": {"schema_version": "1.0.0", "annotator": GENERATOR},
            "coordinate_systems": {"yard": {"type": "scene_cs", "parent": "", "children": []}},
            "objects": objects,
            "frames": frames,
            "frame_intervals": [{"frame_start": 0, "frame_end": len(gt) - 1}],
        }
    }


def run(cfg: SimConfig, out: str | Path, progress=None) -> tuple[Simulation, Path]:
    """Simulate and write the recording directory ``out``."""
    sim, scans, gt = simulate(cfg, progress)
    rng_guess = np.random.default_rng(np.random.SeedSequence(cfg.seed).spawn(4)[3])
    sensors = cfg.params
    if cfg.columns is not None:
        sensors = sensors.model_copy(
            update={"sensors": [s.model_copy(update={"columns": cfg.columns}) for s in sensors.sensors]}
        )
    guess = guessed_sensors(
        SimConfig(**{**cfg.__dict__, "params": sensors}), rng_guess
    )  # clocks uncalibrated: offsets 0
    sensors = with_true_time_offsets(sensors, sim.lidars)
    meta = {
        "generator": GENERATOR,
        "seed": cfg.seed,
        "scenario": cfg.scenario,
        "vehicles": [v.name for v in sim.vehicles],
        "rate_hz": sim.rate_hz,
        "duration_s": cfg.duration_s,
        "start_s": cfg.start_s,
        "slope_deg": cfg.slope_deg,
        "sensors": [lidar.meta() for lidar in sim.lidars],
        "static_objects": sim.yard.static_objects,
        "vehicle_surfaces": {str(i): {"cab": cab, "trailer": body} for i, (cab, body) in sim.surfaces.items()},
    }
    path = write_recording(
        out, meta, scans, gt, dump_yaml(sensors, ["sensors"]), dump_yaml(guess, ["sensors"]), openlabel(gt, sim.rate_hz)
    )
    return sim, path
