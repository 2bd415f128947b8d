"""Compare the simulated sensor with a real labelled scan, object by object.

The real frame is rebuilt as a scene in its sensor's frame: the ground as a height field fitted to
the real cloud, every labelled cuboid as a vehicle or person mesh at its labelled pose (paint from
its ``body_color`` attribute), and the sensor with the real frame's own beam table (per-ring
altitude and azimuth measured from the points). The scene is ray cast with the simulator's return
model; an object's simulated points are the expected number of returns inside its cuboid (the
same rule as the labels' ``num_points``). Rays that in the real frame returned from something
nearer that is neither ground nor a labelled object (a pole, a sign, an unlabelled vehicle) are
blocked in the simulation too: that structure is in the real scene but not in the rebuilt one.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import ndimage
from scipy.spatial.transform import Rotation

from i2v_loc.recording import beam_directions
from i2v_loc.sim import meshes as m
from i2v_loc.sim.lidar import LidarModel, YardCaster
from i2v_loc.sim.sensor_model import COLUMNS, BeamTable, ReturnModel

GROUND_CELL_M = 1.0
CUBOID_MARGIN_M = 0.3  # real points this close to a cuboid belong to its object, not to clutter
BLOCKING_MARGIN_M = 0.5
GROUND_PLANE_BAND_M = 2.0  # the ground may leave the fitted plane by this much (ramps, two carriageways)
PAINTS = {
    "white": "white_paint",
    "gray": "silver_paint",
    "grey": "silver_paint",
    "silver": "silver_paint",
    "red": "red_paint",
    "blue": "blue_paint",
    "black": "dark_paint",
}


class RealismError(ValueError):
    """The real frame or its labels cannot be used (the message says why)."""


@dataclass
class RealFrame:
    xyz: np.ndarray  # (N, 3) sensor frame
    ring: np.ndarray  # (N,) int
    time_ns: np.ndarray | None  # (N,) int64 column time within the sweep, if the file has it


@dataclass
class LabelledObject:
    type: str
    center: np.ndarray
    rotation: np.ndarray  # 3x3 box -> sensor
    size: np.ndarray  # l, w, h
    color: str | None
    real_points: int

    @property
    def range_m(self) -> float:
        return float(np.hypot(*self.center[:2]))

    def contains(self, xyz: np.ndarray, margin_m: float = 0.0) -> np.ndarray:
        local = (xyz - self.center) @ self.rotation
        return np.all(np.abs(local) <= self.size / 2 + margin_m, axis=1)


# --------------------------------------------------------------------------- reading


def read_real_frame(path: str | Path) -> RealFrame:
    """A PCD with per-point ``ring`` (and ``t``, if present) read by pypcd4."""
    from pypcd4 import PointCloud

    path = Path(path)
    if not path.is_file():
        raise RealismError(f"{path}: no such point cloud")
    try:
        pc = PointCloud.from_path(path)
    except Exception as err:  # pypcd4 raises bare exceptions for malformed headers
        raise RealismError(f"{path}: cannot read the PCD ({err})") from None
    fields = set(pc.fields)
    if not {"x", "y", "z", "ring"} <= fields:
        raise RealismError(f"{path}: needs fields x y z ring (a per-point beam index), has {' '.join(pc.fields)}")
    xyz = np.column_stack([pc.numpy(("x",)), pc.numpy(("y",)), pc.numpy(("z",))]).astype(np.float64)
    ring = pc.numpy(("ring",)).ravel().astype(int)
    time_ns = pc.numpy(("t",)).ravel().astype(np.int64) if "t" in fields else None
    finite = np.all(np.isfinite(xyz), axis=1) & (np.linalg.norm(xyz, axis=1) > 0)
    return RealFrame(xyz[finite], ring[finite], None if time_ns is None else time_ns[finite])


def read_labels(path: str | Path, frame: RealFrame) -> list[LabelledObject]:
    """Cuboids of an OpenLABEL file (TUMTraf layout), in the cloud's frame."""
    import json

    path = Path(path)
    try:
        frames = json.loads(path.read_text())["openlabel"]["frames"]
    except (OSError, ValueError, KeyError) as err:
        raise RealismError(f"{path}: not an OpenLABEL file with frames ({err})") from None
    objects = []
    for frame_data in frames.values():
        for obj in frame_data.get("objects", {}).values():
            data = obj.get("object_data", {})
            cuboid = data.get("cuboid")
            if not cuboid:
                continue
            v = np.asarray(cuboid["val"], float)
            attrs = cuboid.get("attributes", {})
            text = {a["name"]: a["val"] for a in attrs.get("text", [])}
            num = {a["name"]: a["val"] for a in attrs.get("num", [])}
            rotation = Rotation.from_quat(v[3:7]).as_matrix()
            labelled = LabelledObject(
                str(data.get("type", "UNKNOWN")).upper(), v[:3], rotation, v[7:10], text.get("body_color"), 0
            )
            labelled.real_points = (
                int(num["num_points"]) if "num_points" in num else int(labelled.contains(frame.xyz).sum())
            )
            objects.append(labelled)
    if not objects:
        raise RealismError(f"{path}: no labelled cuboids")
    return objects


# --------------------------------------------------------------------------- the real sensor


def columns_of(frame: RealFrame) -> tuple[int, np.ndarray]:
    """Columns per sweep (from the azimuth step within rings) and each point's column."""
    az = np.degrees(np.arctan2(frame.xyz[:, 1], frame.xyz[:, 0]))
    order = np.lexsort((az, frame.ring))
    steps = np.diff(az[order])[np.diff(frame.ring[order]) == 0]
    step = float(np.median(steps[(steps > 1e-3) & (steps < 1.0)]))
    columns = min(COLUMNS, key=lambda c: abs(360.0 / c - step))
    if frame.time_ns is not None and frame.time_ns.max() > 0:
        period_ns = 1e8 if frame.time_ns.max() < 1e8 else 5e7 * np.ceil(frame.time_ns.max() / 5e7)
        column = np.rint(frame.time_ns / (period_ns / columns)).astype(int) % columns
    else:  # no timestamps: the column whose nominal azimuth is nearest
        column = np.rint((1.0 - az / 360.0) * columns).astype(int) % columns
    return columns, column


def real_beam_table(frame: RealFrame) -> tuple[BeamTable, np.ndarray]:
    """The frame's beam table (altitude and azimuth offset per ring, from its far points) and each
    point's column."""
    columns, column = columns_of(frame)
    rings = int(frame.ring.max()) + 1
    horizontal = np.hypot(frame.xyz[:, 0], frame.xyz[:, 1])
    altitude = np.degrees(np.arctan2(frame.xyz[:, 2], horizontal))
    az = np.degrees(np.arctan2(frame.xyz[:, 1], frame.xyz[:, 0]))
    offset = (az - 360.0 * (1.0 - column / columns) + 180.0) % 360.0 - 180.0
    far = np.linalg.norm(frame.xyz, axis=1) > 10.0  # the beam origin's offset from the axis fades with range
    alt_table = np.full(rings, np.nan)
    off_table = np.zeros(rings)
    for b in range(rings):  # one median per ring, at most 128
        sel = (frame.ring == b) & far
        sel = sel if sel.sum() >= 10 else frame.ring == b
        if sel.any():
            alt_table[b] = np.median(altitude[sel])
            off_table[b] = _circular_median_deg(offset[sel])
    missing = np.isnan(alt_table)
    if missing.all():
        raise RealismError("no ring has points")
    alt_table[missing] = np.interp(np.nonzero(missing)[0], np.nonzero(~missing)[0], alt_table[~missing])
    table = BeamTable(alt_table.astype(np.float32), off_table.astype(np.float32), columns, "measured on the real frame")
    return table, column


def _circular_median_deg(angles: np.ndarray) -> float:
    mean = np.degrees(np.arctan2(np.sin(np.radians(angles)).mean(), np.cos(np.radians(angles)).mean()))
    return float(mean + np.median((angles - mean + 180.0) % 360.0 - 180.0))


# --------------------------------------------------------------------------- the scene


def on_objects(frame: RealFrame, objects: list[LabelledObject]) -> np.ndarray:
    """(N,) the real points within CUBOID_MARGIN_M of a labelled cuboid."""
    return np.any([o.contains(frame.xyz, CUBOID_MARGIN_M) for o in objects], axis=0)


def ground_height_field(frame: RealFrame, on_object: np.ndarray, extent_m: float) -> m.Mesh:
    """Ground as a height field: per 1 m cell the 10th percentile height of the points that are
    not on labelled objects (``on_object``), cells standing out of their neighbourhood (walls,
    trees) dropped, holes filled from the nearest cell."""
    xyz = frame.xyz[~on_object & (np.abs(frame.xyz[:, 0]) < extent_m) & (np.abs(frame.xyz[:, 1]) < extent_m)]
    n = int(np.ceil(2 * extent_m / GROUND_CELL_M))
    ij = np.clip(((xyz[:, :2] + extent_m) / GROUND_CELL_M).astype(int), 0, n - 1)
    cell = ij[:, 0] * n + ij[:, 1]
    order = np.lexsort((xyz[:, 2], cell))
    cell, z = cell[order], xyz[order, 2]
    first = np.r_[0, np.nonzero(np.diff(cell))[0] + 1]
    counts = np.diff(np.r_[first, len(cell)])
    height = np.full(n * n, np.nan)
    height[cell[first]] = z[first + (counts // 10)]
    height = height.reshape(n, n)
    valid = np.isfinite(height)
    if not valid.any():
        raise RealismError("no ground points to fit")
    lowest_near = ndimage.minimum_filter(np.where(valid, height, np.inf), size=7)
    valid &= height <= lowest_near + 0.5
    valid &= np.abs(height - _robust_plane(height, valid, extent_m)) < GROUND_PLANE_BAND_M
    _, (ii, jj) = ndimage.distance_transform_edt(~valid, return_indices=True)
    height = height[ii, jj]
    return _height_field_mesh(height, extent_m)


def _robust_plane(height: np.ndarray, valid: np.ndarray, extent_m: float) -> np.ndarray:
    """The plane through the cells' heights (iteratively reweighted: structure above it, such as
    the sensor's own gantry, loses its weight), evaluated at every cell."""
    n = height.shape[0]
    centers = -extent_m + (np.arange(n) + 0.5) * GROUND_CELL_M
    gx, gy = np.meshgrid(centers, centers, indexing="ij")
    design = np.column_stack([gx[valid], gy[valid], np.ones(valid.sum())])
    z = height[valid]
    weights = np.ones_like(z)
    for _ in range(10):
        coef, *_ = np.linalg.lstsq(design * weights[:, None], z * weights, rcond=None)
        residual = np.abs(z - design @ coef)
        weights = 1.0 / np.maximum(residual, 0.2)
    return gx * coef[0] + gy * coef[1] + coef[2]


def _height_field_mesh(height: np.ndarray, extent_m: float) -> m.Mesh:
    n = height.shape[0]
    centers = -extent_m + (np.arange(n) + 0.5) * GROUND_CELL_M
    gx, gy = np.meshgrid(centers, centers, indexing="ij")
    vertices = np.column_stack([gx.ravel(), gy.ravel(), height.ravel()])
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, 1:].ravel()
    triangles = np.vstack([np.column_stack([a, b, c]), np.column_stack([b, d, c])]).astype(np.int32)
    return m.Mesh(vertices, triangles, np.full(len(triangles), m.REFLECTIVITY["asphalt"], np.float32))


def object_mesh(obj: LabelledObject) -> m.Mesh:
    """A mesh in the object's box frame (origin at the box centre) for its labelled type."""
    length, width, height = obj.size
    paint = PAINTS.get(str(obj.color).lower(), "paint")
    if obj.type in ("PEDESTRIAN", "PERSON", "BICYCLE", "MOTORCYCLE"):
        return m.pedestrian_mesh(height)
    if obj.type in ("CAR", "VAN"):
        return m.car_mesh(length, width, height, paint)
    if obj.type == "TRAILER":
        floor = min(1.2, 0.3 * height)
        body = m.box_between(
            -length / 2, length / 2, -width / 2, width / 2, -height / 2 + floor, height / 2, "trailer_panel"
        )
        wheels = [
            m.shifted(w, (-length / 2 + 1.5, 0, -height / 2)) for w in m.wheel_pair(0.0, width / 2 - 0.2, 0.5, 0.35)
        ]
        return m.merge([body, *wheels])
    # TRUCK, BUS and the rest: a cab (glass windscreen) over the whole box, on wheels
    bottom = -height / 2
    cab_length = length if obj.type == "BUS" or length < 4 else min(2.5, length)
    parts = m.cab(length / 2 - cab_length, length / 2, width / 2, bottom + 0.5, height / 2, paint)
    if cab_length < length:  # a tractor's chassis behind its cab
        parts.append(
            m.box_between(
                -length / 2,
                length / 2 - cab_length,
                -width / 2 + 0.3,
                width / 2 - 0.3,
                bottom + 0.5,
                bottom + 1.3,
                "steel",
            )
        )
    for x in (-length / 2 + 0.8, length / 2 - 1.0):
        parts += [m.shifted(w, (0, 0, bottom)) for w in m.wheel_pair(x, width / 2 - 0.25, 0.5, 0.35)]
    return m.merge(parts)


def _placed(obj: LabelledObject) -> m.Mesh:
    pose = np.eye(4)
    pose[:3, :3] = obj.rotation
    pose[:3, 3] = obj.center
    return m.transformed(object_mesh(obj), pose)


# --------------------------------------------------------------------------- the comparison


@dataclass
class ObjectResult:
    type: str
    range_m: float
    real_points: int
    sim_points: float
    blocked_by_clutter: float

    @property
    def ratio(self) -> float:
        return self.sim_points / max(self.real_points, 1)


def compare(
    cloud: str | Path, labels: str | Path, returns: ReturnModel | None = None
) -> tuple[list[ObjectResult], BeamTable]:
    frame = read_real_frame(cloud)
    objects = read_labels(labels, frame)
    table, column = real_beam_table(frame)
    returns = returns or ReturnModel()
    extent = max(o.range_m for o in objects) + 20.0
    sensor = LidarModel(name="real", model="real", rate_hz=10, pose=np.eye(4), beam_table=table, returns=None)
    on_object = on_objects(frame, objects)
    ground = YardCaster(ground_height_field(frame, on_object, extent), []).static_hits(sensor)
    hits = YardCaster(m.merge([_placed(o) for o in objects]), []).static_hits(sensor)
    directions = beam_directions(table.altitude_deg, table.azimuth_offset_deg, table.columns)
    points = directions * np.where(np.isfinite(hits.range_m), hits.range_m, 0.0)[..., None]
    expected = returns.return_probability(returns.signal(hits.range_m, hits.reflectivity, hits.cos_incidence))
    real_range = _real_range_image(frame, column, table)
    # The rebuilt ground blocks a ray unless the real ray went past it (then the real ground is lower).
    behind_ground = (ground.range_m < hits.range_m) & ~(real_range > ground.range_m + BLOCKING_MARGIN_M)
    expected = np.where(np.isfinite(hits.range_m) & ~behind_ground, expected, 0.0)
    blocked = _blocked_by_clutter(frame, column, on_object, hits.range_m, table)
    results = []
    for obj in objects:
        inside = obj.contains(points.reshape(-1, 3)).reshape(hits.range_m.shape) & np.isfinite(hits.range_m)
        results.append(
            ObjectResult(
                obj.type,
                obj.range_m,
                obj.real_points,
                float(expected[inside & ~blocked].sum()),
                float(expected[inside & blocked].sum()),
            )
        )
    return results, table


def _real_range_image(frame: RealFrame, column: np.ndarray, table: BeamTable) -> np.ndarray:
    """(beams, columns) range of the real return on each ray (0 where none)."""
    image = np.zeros((table.beams, table.columns))
    valid = frame.ring < table.beams
    np.maximum.at(image, (frame.ring[valid], column[valid]), np.linalg.norm(frame.xyz[valid], axis=1))
    return image


def _blocked_by_clutter(
    frame: RealFrame, column: np.ndarray, on_object: np.ndarray, sim_range: np.ndarray, table: BeamTable
) -> np.ndarray:
    """Rays (beams, columns) whose real return, or a neighbouring column's, came from unlabelled
    structure nearer than what the simulated ray hit."""
    clutter = ~on_object & (frame.ring < table.beams)
    nearest = np.full(sim_range.shape, np.inf)
    r = np.linalg.norm(frame.xyz[clutter], axis=1)
    np.minimum.at(nearest, (frame.ring[clutter], column[clutter]), r)
    nearest = np.minimum(nearest, np.minimum(np.roll(nearest, 1, axis=1), np.roll(nearest, -1, axis=1)))
    # ground returns are clutter too, but the rebuilt ground already blocks what they block
    return nearest < sim_range - BLOCKING_MARGIN_M


def summary(results: list[ObjectResult]) -> dict:
    ratios = np.array([r.ratio for r in results])
    return {
        "median_ratio": float(np.median(ratios)),
        "share_within_half_to_double": float(np.mean((ratios >= 0.5) & (ratios <= 2.0))),
        "objects": [
            {
                "type": r.type,
                "range_m": round(r.range_m, 2),
                "real_points": r.real_points,
                "sim_points": round(r.sim_points, 1),
                "blocked_by_clutter": round(r.blocked_by_clutter, 1),
                "ratio": round(r.ratio, 3),
            }
            for r in sorted(results, key=lambda r: r.range_m)
        ],
    }
