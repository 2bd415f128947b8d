"""The yard around the vehicles: ground (optionally sloped), building wall with dock bays,
containers, poles, parked trailers (static), and a car and pedestrians (moving distractors)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from i2v_loc.geometry import planar_pose, rotate_xy
from i2v_loc.sim import meshes as m

FIELD_CENTER_XY = (0.0, 6.0)
CONTAINER_SIZE_M = (6.06, 2.44, 2.59)


@dataclass
class Distractor:
    kind: str
    dimensions: tuple[float, float, float]
    mesh: m.Mesh  # in its box frame
    path: callable  # t (n,) -> (x (n,), y (n,), yaw_rad (n,)) of the box centre on the ground plane


@dataclass
class Yard:
    static_parts: list[m.Mesh] = field(default_factory=list)
    static_objects: list[dict] = field(default_factory=list)
    distractors: list[Distractor] = field(default_factory=list)

    def static_mesh(self) -> m.Mesh:
        return m.merge(self.static_parts)


class FreeSpace:
    """Where objects may go: away from the vehicles' swept footprint and the sensors."""

    def __init__(self, occupied_xy: np.ndarray, clearance_m: float):
        self.tree = cKDTree(occupied_xy)
        self.clearance_m = clearance_m

    def is_free(self, xy: np.ndarray) -> bool:
        d, _ = self.tree.query(np.atleast_2d(xy))
        return bool(np.all(d > self.clearance_m))

    def add(self, xy: np.ndarray) -> None:
        self.tree = cKDTree(np.vstack([self.tree.data, np.atleast_2d(xy)]))


def footprint_points(center_xy, length_m: float, width_m: float, yaw_rad, step_m: float = 0.5) -> np.ndarray:
    """(M, 2) points filling a rotated rectangle (for clearance checks); with ``center_xy`` (N, 2) and
    ``yaw_rad`` (N,), the points of N such rectangles stacked."""
    xs = np.linspace(-length_m / 2, length_m / 2, max(2, int(length_m / step_m) + 1))
    ys = np.linspace(-width_m / 2, width_m / 2, max(2, int(width_m / step_m) + 1))
    local = np.array(np.meshgrid(xs, ys)).reshape(2, -1).T
    return (
        rotate_xy(local, np.asarray(yaw_rad, float)[..., None]) + np.asarray(center_xy, float)[..., None, :]
    ).reshape(-1, 2)


def dock_wall(rear_center_xy, facing_yaw_rad: float, bays: int = 3, bay_width_m: float = 4.0) -> list[m.Mesh]:
    """A building wall with dock doors; the middle door is centred on ``rear_center_xy`` and the
    wall faces ``facing_yaw_rad`` (the direction from the wall into the yard)."""
    height, door_w, door_h, recess, thickness = 6.0, 3.0, 3.6, 0.4, 0.5
    parts = []
    half = bays * bay_width_m / 2
    edges = (
        [-half] + [(-half + (i + 0.5) * bay_width_m) + s * door_w / 2 for i in range(bays) for s in (-1, 1)] + [half]
    )
    for y0, y1 in zip(edges[0::2], edges[1::2]):  # pillars between the doors
        parts.append(m.box_between(-thickness, 0.0, y0, y1, 0.0, height, "concrete"))
    for i in range(bays):
        yc = -half + (i + 0.5) * bay_width_m
        parts.append(
            m.box_between(-thickness - recess, -recess, yc - door_w / 2, yc + door_w / 2, 0.0, height, "steel")
        )  # door
        parts.append(
            m.box_between(-recess, 0.0, yc - door_w / 2, yc + door_w / 2, door_h, height, "concrete")
        )  # lintel
        for s in (-1, 1):  # rubber bumpers at trailer-floor height
            parts.append(m.box_between(0.0, 0.15, yc + s * 1.1 - 0.15, yc + s * 1.1 + 0.15, 0.9, 1.3, "rubber"))
    # Local frame: x out of the wall, so rotate x onto the facing direction.
    pose = planar_pose(rear_center_xy[0], rear_center_xy[1], facing_yaw_rad)
    shift = np.eye(4)
    shift[:3, 3] = (-0.25, 0.0, 0.0)  # a small gap between the docked trailer and the bumpers
    return [m.transformed(p, pose @ shift) for p in parts]


def build_yard(
    rng: np.random.Generator,
    occupied_xy: np.ndarray,
    sensor_xyz: np.ndarray,
    dock: tuple[np.ndarray, float] | None,
    parked_trailer,
    distractors: bool = True,
    clutter_near: bool = False,
) -> Yard:
    """Static objects and distractors placed clear of ``occupied_xy`` (the vehicles' swept footprint);
    with ``clutter_near`` the containers and parked trailers stand right beside it."""
    yard = Yard()
    yard.static_parts.append(m.box_between(-90, 90, -90, 90, -0.2, 0.0, "asphalt"))  # ground (top face at z = 0)
    sensor_xy = sensor_xyz[:, :2]
    space = FreeSpace(np.vstack([occupied_xy, sensor_xy]), clearance_m=2.0)
    swept = cKDTree(occupied_xy)
    if dock is None:
        # North of the vehicles and behind the sensors (a layout may mount them along this side).
        wall_y = max(float(occupied_xy[:, 1].max()) + 6.0, float(sensor_xy[:, 1].max()) + 2.0, 22.0)
        dock, bays = (np.array([0.0, wall_y]), -math.pi / 2), 5
    else:
        bays = 3
    yard.static_parts += dock_wall(dock[0], dock[1], bays=bays)
    yard.static_objects.append(
        {"kind": "dock_wall", "center": [float(v) for v in dock[0]], "yaw_deg": math.degrees(dock[1])}
    )
    behind = np.asarray(dock[0], float) - 0.5 * np.array([math.cos(dock[1]), math.sin(dock[1])])
    space.add(footprint_points(behind, 1.0, bays * 4.0, dock[1]))  # nothing stands in the wall
    for x, y, z in sensor_xyz:  # the sensors' poles, up to 0.3 m below the sensor
        yard.static_parts.append(m.cylinder((x, y, (z - 0.3) / 2), 0.12, z - 0.3, surface="pole"))

    def place(kind, length, width, tries=200, ring=(18.0, 34.0)):
        if clutter_near and kind != "pole":
            return place_near(length, width)
        for _ in range(tries):
            angle = rng.uniform(0, 2 * np.pi)
            radius = rng.uniform(*ring)
            xy = np.array(FIELD_CENTER_XY) + radius * np.array([math.cos(angle), math.sin(angle) * 0.8])
            yaw = rng.uniform(-np.pi, np.pi)
            pts = footprint_points(xy, length, width, yaw)
            if space.is_free(pts):
                space.add(pts)
                return xy, yaw
        return None

    def place_near(length, width, tries=400):
        """The free spot (of ``tries`` random ones) nearest to the vehicles' swept area."""
        best = None
        for _ in range(tries):
            xy = np.array(FIELD_CENTER_XY) + rng.uniform([-30.0, -20.0], [30.0, 26.0])
            yaw = rng.uniform(-np.pi, np.pi)
            pts = footprint_points(xy, length, width, yaw)
            gap = float(swept.query(pts)[0].min())
            if (best is None or gap < best[0]) and space.is_free(pts):
                best = (gap, xy, yaw, pts)
        if best is None:
            return None
        space.add(best[3])
        return best[1], best[2]

    def add_containers():
        for _ in range(3):
            spot = place("container", CONTAINER_SIZE_M[0], CONTAINER_SIZE_M[1])
            if spot:
                xy, yaw = spot
                size = CONTAINER_SIZE_M
                yard.static_parts.append(m.box((xy[0], xy[1], size[2] / 2), size, yaw, surface="container"))
                yard.static_objects.append(
                    {"kind": "container", "center": [float(xy[0]), float(xy[1])], "yaw_deg": math.degrees(yaw)}
                )

    def add_poles():
        for _ in range(3):
            spot = place("pole", 0.4, 0.4, ring=(8.0, 30.0))
            if spot:
                xy, _ = spot
                yard.static_parts.append(m.cylinder((xy[0], xy[1], 4.0), 0.1, 8.0, surface="pole"))
                yard.static_objects.append({"kind": "pole", "center": [float(xy[0]), float(xy[1])]})

    def add_parked_trailers():
        if parked_trailer is None:
            return
        for _ in range(2):
            spot = place("parked_trailer", parked_trailer.length_m, parked_trailer.width_m, ring=(20.0, 34.0))
            if spot:
                xy, yaw = spot
                center = m.box_center_in_axle_frame(parked_trailer, is_truck=False)
                mesh = m.shifted(m.trailer_mesh(parked_trailer), (-center[0], 0.0, 0.0))
                yard.static_parts.append(m.transformed(mesh, planar_pose(xy[0], xy[1], yaw)))
                yard.static_objects.append(
                    {"kind": "parked_trailer", "center": [float(xy[0]), float(xy[1])], "yaw_deg": math.degrees(yaw)}
                )

    # Packed beside the vehicles, the long trailers go first: they fit fewer gaps.
    for add in (
        (add_parked_trailers, add_containers, add_poles)
        if clutter_near
        else (add_containers, add_poles, add_parked_trailers)
    ):
        add()
    if distractors:
        _add_distractors(yard, rng, space)
    return yard


def _add_distractors(yard: Yard, rng: np.random.Generator, space: FreeSpace) -> None:
    # A car circling at 3 m/s outside the vehicles' area.
    for _ in range(200):
        center = np.array(FIELD_CENTER_XY) + rng.uniform([-30, -22], [30, 30])
        radius = rng.uniform(5.0, 8.0)
        ring = center + radius * np.c_[np.cos(np.linspace(0, 2 * np.pi, 40)), np.sin(np.linspace(0, 2 * np.pi, 40))]
        if space.is_free(ring):
            space.add(ring)
            yard.distractors.append(
                Distractor(
                    "car", (4.5, 1.8, 1.5), m.car_mesh(), _circle_path(center, radius, 3.0, rng.uniform(0, 2 * np.pi))
                )
            )
            break
    # Pedestrians walking back and forth at 1.3 m/s.
    for _ in range(2):
        for _ in range(200):
            a = np.array(FIELD_CENTER_XY) + rng.uniform([-28, -15], [28, 25])
            heading = rng.uniform(-np.pi, np.pi)
            b = a + 12.0 * np.array([math.cos(heading), math.sin(heading)])
            line = a + np.linspace(0, 1, 25)[:, None] * (b - a)
            if space.is_free(line):
                space.add(line)
                yard.distractors.append(
                    Distractor(
                        "pedestrian", (0.3, 0.5, 1.75), m.pedestrian_mesh(), _walk_path(a, b, 1.3, rng.uniform(0, 1))
                    )
                )
                break


def _circle_path(center, radius_m: float, speed_mps: float, phase_rad: float):
    omega = speed_mps / radius_m

    def path(t):
        a = phase_rad + omega * np.asarray(t, float)
        return center[0] + radius_m * np.cos(a), center[1] + radius_m * np.sin(a), a + np.pi / 2

    return path


def _walk_path(a, b, speed_mps: float, phase: float):
    a, b = np.asarray(a, float), np.asarray(b, float)
    length = float(np.linalg.norm(b - a))
    heading = math.atan2(*(b - a)[::-1])

    def path(t):
        s = (np.asarray(t, float) * speed_mps / length + phase) % 2.0  # 0..1 out, 1..2 back
        f = np.where(s < 1.0, s, 2.0 - s)
        xy = a + f[:, None] * (b - a) if np.ndim(f) else a + f * (b - a)
        yaw = np.where(s < 1.0, heading, heading + np.pi)
        return xy[..., 0], xy[..., 1], yaw

    return path
