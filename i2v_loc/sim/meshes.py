"""Triangle meshes as numpy (vertices float64 (V, 3), triangles int32 (T, 3), the diffuse
reflectivity of each triangle's surface (T,)) built from boxes and cylinders: articulated vehicles,
yard objects, pedestrians. Surfaces are named in ``sensor_model.REFLECTIVITY``."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from i2v_loc.geometry import rotate_xy
from i2v_loc.sim.sensor_model import REFLECTIVITY


class Mesh(NamedTuple):
    vertices: np.ndarray
    triangles: np.ndarray
    reflectivity: np.ndarray


def _surface(n_triangles: int, surface: str) -> np.ndarray:
    return np.full(n_triangles, REFLECTIVITY[surface], dtype=np.float32)


_BOX_TRIANGLES = np.array(
    [
        [0, 2, 1],
        [1, 2, 3],
        [4, 5, 6],
        [5, 7, 6],
        [0, 1, 4],
        [1, 5, 4],
        [2, 6, 3],
        [3, 6, 7],
        [0, 4, 2],
        [2, 4, 6],
        [1, 3, 5],
        [3, 7, 5],
    ],
    dtype=np.int32,
)


def box(center, size, yaw_rad: float = 0.0, surface: str = "paint") -> Mesh:
    """Axis-aligned box (rotated by ``yaw_rad`` about its centre's vertical axis)."""
    corners = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)]) * np.asarray(
        size, float
    )
    corners[:, :2] = rotate_xy(corners[:, :2], yaw_rad)
    return Mesh(corners + np.asarray(center, float), _BOX_TRIANGLES.copy(), _surface(len(_BOX_TRIANGLES), surface))


def box_between(x0, x1, y0, y1, z0, z1, surface: str = "paint") -> Mesh:
    return box(
        ((x0 + x1) / 2, (y0 + y1) / 2, (z0 + z1) / 2), (abs(x1 - x0), abs(y1 - y0), abs(z1 - z0)), surface=surface
    )


def with_surface(mesh: Mesh, surface: str) -> Mesh:
    return mesh._replace(reflectivity=_surface(len(mesh.triangles), surface))


def cylinder(
    center, radius_m: float, length_m: float, axis: str = "z", segments: int = 12, surface: str = "steel"
) -> Mesh:
    """Closed cylinder along ``axis`` ('x', 'y' or 'z')."""
    a = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    ring = np.stack([radius_m * np.cos(a), radius_m * np.sin(a)], axis=1)
    h = length_m / 2
    local = np.vstack([np.c_[ring, np.full(segments, -h)], np.c_[ring, np.full(segments, h)], [[0, 0, -h], [0, 0, h]]])
    i = np.arange(segments)
    j = (i + 1) % segments
    bottom, top = 2 * segments, 2 * segments + 1
    tris = np.vstack(
        [
            np.c_[i, j, i + segments],
            np.c_[j, j + segments, i + segments],
            np.c_[np.full(segments, bottom), j, i],
            np.c_[np.full(segments, top), i + segments, j + segments],
        ]
    ).astype(np.int32)
    order = {"x": [2, 0, 1], "y": [0, 2, 1], "z": [0, 1, 2]}[axis]
    return Mesh(local[:, order] + np.asarray(center, float), tris, _surface(len(tris), surface))


def merge(meshes: list[Mesh]) -> Mesh:
    offsets = np.cumsum([0] + [len(mesh.vertices) for mesh in meshes[:-1]])
    return Mesh(
        np.vstack([mesh.vertices for mesh in meshes]),
        np.vstack([mesh.triangles + offset for mesh, offset in zip(meshes, offsets)]).astype(np.int32),
        np.concatenate([mesh.reflectivity for mesh in meshes]),
    )


def transformed(mesh: Mesh, t: np.ndarray) -> Mesh:
    return mesh._replace(vertices=mesh.vertices @ t[:3, :3].T + t[:3, 3])


def shifted(mesh: Mesh, offset) -> Mesh:
    return mesh._replace(vertices=mesh.vertices + np.asarray(offset, float))


def wheel_radius_m(wheelbase_m: float) -> float:
    return float(np.clip(0.17 * wheelbase_m, 0.25, 0.5))


def wheel_pair(x_m: float, track_half_m: float, radius_m: float, width_m: float) -> list[Mesh]:
    return [
        cylinder((x_m, side * track_half_m, radius_m), radius_m, width_m, axis="y", surface="tyre") for side in (-1, 1)
    ]


def cab(x_back: float, x_front: float, half_w: float, z0: float, z1: float, paint: str) -> list[Mesh]:
    """A painted body whose upper front (windscreen and door windows, up to 1 m deep, below a
    painted roof) is glass."""
    glass_z0 = z0 + 0.55 * (z1 - z0)
    roof_z0 = z1 - min(0.15, 0.1 * (z1 - z0))
    glass_x0 = max(x_back, x_front - min(1.0, 0.4 * (x_front - x_back)))
    return [
        box_between(x_back, x_front, -half_w, half_w, z0, glass_z0, surface=paint),
        box_between(x_back, glass_x0, -half_w, half_w, glass_z0, z1, surface=paint),
        box_between(glass_x0, x_front, -half_w, half_w, glass_z0, roof_z0, surface="glass"),
        box_between(glass_x0, x_front, -half_w, half_w, roof_z0, z1, surface=paint),
    ]


def truck_mesh(truck, paint: str = "paint") -> Mesh:
    """Towing unit in its axle frame (origin: rear-axle centre on the ground, x forward).

    Cab (the GT box, ``paint`` with glass windows) at the front, chassis rails low behind it up to
    the fifth wheel, wheels, and a fifth-wheel plate or a drawbar coupling at the hitch.
    """
    front = truck.wheelbase_m + truck.front_overhang_m
    cab_back = front - truck.length_m
    hitch_x = -truck.hitch_behind_rear_axle_m
    half_w = truck.width_m / 2
    r = wheel_radius_m(truck.wheelbase_m)
    wheel_w = 0.12 * truck.width_m
    parts = cab(cab_back, front, half_w, truck.floor_m, truck.floor_m + truck.height_m, paint)
    parts += wheel_pair(truck.wheelbase_m, half_w - wheel_w / 2 - 0.02, r, wheel_w)
    parts += wheel_pair(0.0, half_w - wheel_w / 2 - 0.02, r, wheel_w)
    rail_top = min(2.0 * r, truck.floor_m + 0.5)
    rails_end = min(hitch_x, 0.0) - 0.6
    if cab_back - rails_end > 0.3:
        # Chassis rails (two, 0.9 m apart) and the fifth-wheel plate on top at the hitch.
        for side in (-1, 1):
            parts.append(
                box_between(
                    rails_end, cab_back, side * 0.45 - 0.08, side * 0.45 + 0.08, rail_top - 0.3, rail_top, "steel"
                )
            )
        parts.append(box_between(hitch_x - 0.5, hitch_x + 0.5, -0.5, 0.5, rail_top, rail_top + 0.15, "steel"))
        # Mudguards over the rear wheels.
        for side in (-1, 1):
            y = side * (half_w - wheel_w / 2 - 0.02)
            parts.append(
                box_between(
                    -r - 0.1,
                    r + 0.1,
                    y - wheel_w / 2 - 0.03,
                    y + wheel_w / 2 + 0.03,
                    2 * r + 0.02,
                    2 * r + 0.08,
                    "rubber",
                )
            )
    if hitch_x < cab_back:
        # Drawbar coupling behind the body.
        parts.append(box_between(hitch_x, cab_back + 0.2, -0.05, 0.05, 0.35, 0.45, "steel"))
    return merge(parts)


def trailer_mesh(trailer, body: str = "trailer_panel") -> Mesh:
    """Towed unit in its axle frame (origin: effective axle centre on the ground, x forward).

    Body (the GT box, panels or tarpaulin) on a raised floor with a gap below, an axle group at the rear, landing legs
    (semitrailer, kingpin under the body) or a drawbar (eye ahead of the body).
    """
    hitch_x = trailer.hitch_to_axle_m
    front = hitch_x + trailer.hitch_to_front_m
    back = front - trailer.length_m
    half_w = trailer.width_m / 2
    floor = trailer.floor_m
    r = float(np.clip(0.7 * floor, 0.25, 0.5))
    wheel_w = 0.12 * trailer.width_m
    parts = [box_between(back, front, -half_w, half_w, floor, floor + trailer.height_m, body)]
    axles = [-1.31, 0.0, 1.31] if trailer.length_m > 9 else ([-0.65, 0.65] if trailer.length_m > 4 else [0.0])
    for dx in axles:
        parts += wheel_pair(dx, half_w - wheel_w / 2 - 0.02, r, wheel_w)
    if trailer.hitch_to_front_m >= 0:
        legs_x = hitch_x - min(2.5, 0.3 * trailer.hitch_to_axle_m)
        for side in (-1, 1):
            parts.append(
                box_between(
                    legs_x - 0.1,
                    legs_x + 0.1,
                    side * (half_w - 0.4) - 0.1,
                    side * (half_w - 0.4) + 0.1,
                    0.0,
                    floor,
                    "steel",
                )
            )
        parts.append(box_between(hitch_x - 0.4, hitch_x + 0.4, -0.4, 0.4, floor - 0.1, floor, "steel"))  # kingpin plate
    else:
        # A-frame drawbar from the eye to the body front.
        parts.append(box_between(hitch_x - 0.05, front + 0.1, -0.05, 0.05, 0.35, 0.45, "steel"))
        parts.append(box_between(front - 0.05, front + 0.15, -half_w * 0.6, half_w * 0.6, 0.35, 0.45, "steel"))
    return merge(parts)


def box_center_in_axle_frame(unit, is_truck: bool) -> np.ndarray:
    """Centre of the unit's GT box (Table 1: length x width x height, bottom at floor) in its axle frame."""
    if is_truck:
        front = unit.wheelbase_m + unit.front_overhang_m
    else:
        front = unit.hitch_to_axle_m + unit.hitch_to_front_m
    return np.array([front - unit.length_m / 2, 0.0, unit.floor_m + unit.height_m / 2])


def pedestrian_mesh(height_m: float = 1.75) -> Mesh:
    """A person in its own box frame (origin at the box centre)."""
    legs = box((0, 0, -height_m / 4), (0.25, 0.35, height_m / 2), surface="clothing")
    torso = box((0, 0, height_m * 0.12), (0.3, 0.5, height_m * 0.26), surface="clothing")
    head = box((0, 0, height_m * 0.37), (0.22, 0.2, height_m * 0.2), surface="clothing")
    return merge([legs, torso, head])


def car_mesh(length_m: float = 4.5, width_m: float = 1.8, height_m: float = 1.5, paint: str = "paint") -> Mesh:
    """A car in its own box frame (origin at the box centre): painted body, glass cabin, painted roof."""
    bottom = -height_m / 2
    body = box_between(-length_m / 2, length_m / 2, -width_m / 2, width_m / 2, bottom + 0.3, bottom + 0.95, paint)
    cabin = box_between(
        -length_m * 0.3,
        length_m * 0.2,
        -width_m / 2 + 0.1,
        width_m / 2 - 0.1,
        bottom + 0.95,
        bottom + height_m - 0.05,
        "glass",
    )
    roof = box_between(
        -length_m * 0.25,
        length_m * 0.15,
        -width_m / 2 + 0.15,
        width_m / 2 - 0.15,
        bottom + height_m - 0.05,
        bottom + height_m,
        paint,
    )
    wheels = []
    for x in (-length_m * 0.32, length_m * 0.32):
        wheels += [shifted(w, (0, 0, bottom)) for w in wheel_pair(x, width_m / 2 - 0.12, 0.32, 0.22)]
    return merge([body, cabin, roof, *wheels])
