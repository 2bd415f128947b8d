"""Constructed LiDAR points of hinged vehicles for the articulated estimator's tests: points on the
faces of known boxes that a sensor at a given position sees (facing it, not behind another box),
with range noise."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from i2v_loc.stages.vehicle_model import Box, VehicleModel

FACES = ("front", "rear", "left", "right", "roof")


@dataclass
class WorldBox:
    center_xy: np.ndarray
    yaw_rad: float
    box: Box
    unit: int  # 0 tractor, 1 trailer


def world_boxes(model: VehicleModel, x: float, y: float, yaw: float, hitch: float = 0.0) -> list[WorldBox]:
    tractor_xy, trailer_xy = model.box_centers(x, y, yaw, hitch)
    boxes = [WorldBox(tractor_xy, yaw, model.tractor, 0)]
    if model.trailer is not None:
        boxes.append(WorldBox(trailer_xy, yaw + hitch, model.trailer, 1))
    return boxes


def _face_grid(b: WorldBox, spacing: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points, outward normals and face index of the four walls and the roof of a box."""
    half_l, half_w, box = b.box.length_m / 2, b.box.width_m / 2, b.box
    zs = np.arange(box.floor_m + spacing / 2, box.top_m, spacing)
    us = np.arange(-half_l + spacing / 2, half_l, spacing)
    vs = np.arange(-half_w + spacing / 2, half_w, spacing)
    parts = []
    for face, (fixed, normal) in enumerate(
        (
            ((half_l, None), (1, 0, 0)),
            ((-half_l, None), (-1, 0, 0)),
            ((None, half_w), (0, 1, 0)),
            ((None, -half_w), (0, -1, 0)),
        )
    ):
        if fixed[0] is not None:
            v, z = np.meshgrid(vs, zs)
            local = np.column_stack([np.full(v.size, fixed[0]), v.ravel(), z.ravel()])
        else:
            u, z = np.meshgrid(us, zs)
            local = np.column_stack([u.ravel(), np.full(u.size, fixed[1]), z.ravel()])
        parts.append((local, np.tile(normal, (len(local), 1)), np.full(len(local), face)))
    u, v = np.meshgrid(us, vs)
    roof = np.column_stack([u.ravel(), v.ravel(), np.full(u.size, box.top_m)])
    parts.append((roof, np.tile((0, 0, 1), (len(roof), 1)), np.full(len(roof), 4)))
    local = np.vstack([p[0] for p in parts])
    normals = np.vstack([p[1] for p in parts]).astype(float)
    c, s = np.cos(b.yaw_rad), np.sin(b.yaw_rad)
    rot = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
    world = local @ rot.T + np.r_[b.center_xy, 0.0]
    return world, normals @ rot.T, np.concatenate([p[2] for p in parts])


def _slab_interval(sensor: np.ndarray, direction: np.ndarray, b: WorldBox) -> tuple[np.ndarray, np.ndarray]:
    """Where each ray sensor + t direction enters and leaves box ``b`` (t; enters >= leaves: it misses)."""
    c, s = np.cos(b.yaw_rad), np.sin(b.yaw_rad)
    rot = np.array([[c, s, 0], [-s, c, 0], [0, 0, 1.0]])
    o = rot @ (sensor - np.r_[b.center_xy, 0.0])
    d = direction @ rot.T
    low = np.array([-b.box.length_m / 2, -b.box.width_m / 2, b.box.floor_m])
    high = np.array([b.box.length_m / 2, b.box.width_m / 2, b.box.top_m])
    with np.errstate(divide="ignore", invalid="ignore"):
        t1, t2 = (low - o) / d, (high - o) / d
    return np.nanmax(np.minimum(t1, t2), axis=1), np.nanmin(np.maximum(t1, t2), axis=1)


def _blocked(sensor: np.ndarray, points: np.ndarray, b: WorldBox) -> np.ndarray:
    """Whether the segment sensor -> point passes through the inside of box ``b`` (slab test)."""
    t_near, t_far = _slab_interval(sensor, points - sensor, b)
    return (t_near < t_far) & (t_far > 1e-6) & (t_near < 1.0 - 1e-6) & (t_far - t_near > 1e-6)


def vehicle_points(
    model: VehicleModel,
    x: float,
    y: float,
    yaw: float,
    hitch: float = 0.0,
    sensors=((0.0, -15.0, 4.0),),
    spacing: float = 0.12,
    noise_m: float = 0.02,
    drop: tuple[tuple[int, str], ...] = (),
    others: list[WorldBox] = (),
    seed: int = 0,
) -> np.ndarray:
    """(N, 3) points of the vehicle seen from ``sensors``; ``drop`` removes whole faces ((unit, face name))
    as if occluded; ``others`` are further boxes that occlude (their own points are not returned)."""
    rng = np.random.default_rng(seed)
    boxes = world_boxes(model, x, y, yaw, hitch)
    out = []
    for sensor in np.asarray(sensors, dtype=float):
        for b in boxes:
            pts, normals, face = _face_grid(b, spacing)
            keep = np.einsum("ij,ij->i", normals, sensor - pts) > 0
            for other in list(boxes) + list(others):
                if other is not b:
                    keep &= ~_blocked(sensor, pts, other)
            for unit, name in drop:
                if unit == b.unit:
                    keep &= face != FACES.index(name)
            pts = pts[keep]
            ray = pts - sensor
            ray /= np.linalg.norm(ray, axis=1, keepdims=True)
            out.append(pts + ray * rng.normal(0.0, noise_m, (len(pts), 1)))
    return np.vstack(out) if out else np.zeros((0, 3))


def _entry(sensor: np.ndarray, direction: np.ndarray, b: WorldBox) -> np.ndarray:
    """Where each ray (sensor + t direction) enters box ``b`` (t; inf where it misses)."""
    t_near, t_far = _slab_interval(sensor, direction, b)
    return np.where((t_near < t_far) & (t_near > 0), t_near, np.inf)


def cast_rays(
    boxes: list[WorldBox], sensors, columns: int = 1024, beams: int = 32, ground_reach_m: float = np.inf,
    drop_on_boxes_every: int = 0,
):  # fmt: skip
    """Each sensor's rays as a spinning LiDAR casts them (``columns`` azimuths, ``beams`` elevations
    from -2 to -45 deg), each ending on the nearest box or on flat ground (z = 0): a vehicle's gap
    shows as rays passing through it onto the ground or another vehicle beyond. Ground farther than
    ``ground_reach_m`` (horizontally) returns nothing, nor does every ``drop_on_boxes_every``-th ray
    ending on a box (a dark body far off): those rays are the ``Rays``' ``unreturned``, reaching 120 m."""
    from i2v_loc.stages.visibility import Rays, Unreturned

    azimuth, elevation = np.meshgrid(
        np.linspace(0.0, 2 * np.pi, columns, endpoint=False), np.radians(np.linspace(-2.0, -45.0, beams))
    )
    direction = np.column_stack([np.cos(azimuth.ravel()), np.sin(azimuth.ravel()), np.tan(elevation.ravel())])
    parts, unreturned = [], []
    for sensor in np.asarray(sensors, dtype=float):
        ground = sensor[2] / -direction[:, 2]
        t = np.where(ground <= ground_reach_m, ground, np.inf)
        for b in boxes:
            t = np.minimum(t, _entry(sensor, direction, b))
        returned = np.isfinite(t)
        if drop_on_boxes_every:
            on_box = np.flatnonzero(returned & (t < ground))
            returned[on_box[::drop_on_boxes_every]] = False
        parts.append(sensor + direction[returned] * t[returned, None])
        unreturned.append(direction[~returned] / np.linalg.norm(direction[~returned], axis=1, keepdims=True))
    sensors = np.asarray(sensors, dtype=float).reshape(-1, 3)
    lost = Unreturned(
        [u.astype(np.float32) for u in unreturned],
        np.repeat(np.eye(3)[None], len(sensors), axis=0),
        sensors,
        np.full(len(sensors), 120.0),
    )
    bounds = np.cumsum([0] + [len(p) for p in parts])
    return Rays(np.vstack(parts).astype(np.float32), sensors, bounds, np.eye(3), unreturned=lost)


def unhidden(points: np.ndarray, boxes: list[WorldBox], sensor) -> np.ndarray:
    """The points of a scene (ground, walls) that ``sensor`` sees past ``boxes``: vehicles hide what
    lies behind them."""
    sensor = np.asarray(sensor, dtype=float)
    hidden = np.zeros(len(points), dtype=bool)
    for b in boxes:
        hidden |= _blocked(sensor, points, b)
    return points[~hidden]
