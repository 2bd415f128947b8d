"""Ray-cast Ouster OS1 model with open3d's RaycastingScene.

The static yard is one scene, cast once per sensor (it does not move). Every moving object has
its own scene in its local frame, built once; for each slice of the sweep (1/8 by default) the
slice's rays are moved into the object's frame at the slice's mid time and cast, and the nearest
hit wins. Rays are culled by each object's bounding sphere first.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import open3d as o3d

from i2v_loc.geometry import extrinsics_matrix
from i2v_loc.recording import beam_directions
from i2v_loc.sim.meshes import Mesh
from i2v_loc.sim.sensor_model import BeamTable, ReturnModel, SensorModelError, metadata_beam_table, model_beam_table


@dataclass
class LidarModel:
    name: str
    model: str
    rate_hz: float
    pose: np.ndarray  # 4x4 sensor -> yard
    beam_table: BeamTable
    returns: ReturnModel | None = field(default_factory=ReturnModel)  # None: every ray returns, exactly
    max_range_m: float = 120.0
    phase_s: float = 0.0  # sweep start after the frame time (true clock)
    clock_offset_s: float = 0.0  # sensor clock minus true clock

    @classmethod
    def from_config(cls, cfg, **kwargs) -> LidarModel:
        """From an ``i2v_loc.params.SensorConfig``: its metadata file's beam table, else its model's."""
        if cfg.metadata:
            table = metadata_beam_table(cfg.metadata)
            if (table.beams, table.columns) != (cfg.beams, cfg.columns):
                raise SensorModelError(
                    f"sensor {cfg.name}: {cfg.metadata} describes {table.beams} beams x {table.columns} columns, "
                    f"the sensor entry says {cfg.model} x {cfg.columns}"
                )
        else:
            table = model_beam_table(cfg.model, cfg.columns, cfg.beam_config)
        kwargs.setdefault("returns", ReturnModel(min_range_m=cfg.min_range_m))
        return cls(
            name=cfg.name,
            model=cfg.model,
            rate_hz=cfg.rate_hz,
            pose=extrinsics_matrix(cfg.extrinsics),
            beam_table=table,
            max_range_m=cfg.max_range_m,
            **kwargs,
        )

    @property
    def beams(self) -> int:
        return self.beam_table.beams

    @property
    def columns(self) -> int:
        return self.beam_table.columns

    @property
    def beam_altitude_deg(self) -> np.ndarray:
        return self.beam_table.altitude_deg

    @property
    def beam_azimuth_offset_deg(self) -> np.ndarray:
        return self.beam_table.azimuth_offset_deg

    @property
    def column_time_s(self) -> np.ndarray:
        return np.arange(self.columns) / (self.columns * self.rate_hz)

    @property
    def column_time_ns(self) -> np.ndarray:
        return np.arange(self.columns, dtype=np.int64) * int(round(1e9 / self.rate_hz)) // self.columns

    def yard_directions(self) -> np.ndarray:
        """(beams, columns, 3) unit rays in the yard frame."""
        d = beam_directions(self.beam_altitude_deg, self.beam_azimuth_offset_deg, self.columns)
        return d @ self.pose[:3, :3].T

    def meta(self) -> dict:
        return {
            "name": self.name,
            "model": self.model,
            "beams": self.beams,
            "columns": self.columns,
            "rate_hz": self.rate_hz,
            "beam_table": self.beam_table.source,
            "beam_altitude_deg": [round(float(a), 4) for a in self.beam_altitude_deg],
            "beam_azimuth_offset_deg": [round(float(a), 4) for a in self.beam_azimuth_offset_deg],
            "phase_s": round(self.phase_s, 9),
            "clock_offset_s": round(self.clock_offset_s, 9),
            "return_model": self.returns.meta() if self.returns else "ideal (every ray returns, no noise)",
            "max_range_m": self.max_range_m,
        }


@dataclass
class MovingObject:
    """A rigid moving mesh: ``pose_at(times_s) -> (n, 4, 4)`` local -> yard."""

    key: int
    mesh: Mesh  # in the local frame
    pose_at: Callable[[np.ndarray], np.ndarray]

    def __post_init__(self) -> None:
        v = self.mesh.vertices
        self.center_local = (v.min(axis=0) + v.max(axis=0)) / 2
        self.radius_m = float(np.linalg.norm(v - self.center_local, axis=1).max())


def _scene(mesh: Mesh) -> o3d.t.geometry.RaycastingScene:
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor(mesh.vertices.astype(np.float32)), o3d.core.Tensor(mesh.triangles.astype(np.uint32))
    )
    return scene


@dataclass
class Hits:
    """What each ray hit: range (inf = nothing), hit id, the surface's reflectivity and the cosine
    of the incidence angle. Arrays of one shape: (rays,) or (beams, columns)."""

    range_m: np.ndarray
    hit_id: np.ndarray
    reflectivity: np.ndarray
    cos_incidence: np.ndarray

    def reshaped(self, shape) -> Hits:
        return Hits(*(a.reshape(shape) for a in (self.range_m, self.hit_id, self.reflectivity, self.cos_incidence)))

    def take_closer(self, other: Hits, index) -> None:
        """Where ``other`` (hits of the rays at ``index``) is closer, it wins."""
        closer = other.range_m < self.range_m[index]
        target = tuple(i[closer] for i in index)
        for mine, theirs in (
            (self.range_m, other.range_m),
            (self.hit_id, other.hit_id),
            (self.reflectivity, other.reflectivity),
            (self.cos_incidence, other.cos_incidence),
        ):
            mine[target] = theirs[closer]


def _cast(scene, mesh: Mesh, hit_id: int, origins: np.ndarray, directions: np.ndarray) -> Hits:
    rays = np.hstack([origins, directions]).astype(np.float32)
    result = scene.cast_rays(o3d.core.Tensor(rays))
    t_hit = result["t_hit"].numpy()
    hit = np.isfinite(t_hit)
    primitive = np.where(hit, result["primitive_ids"].numpy(), 0).astype(np.int64)
    cos = np.abs(np.einsum("ij,ij->i", result["primitive_normals"].numpy(), directions.astype(np.float32)))
    return Hits(
        t_hit,
        np.where(hit, hit_id, NO_HIT),
        np.where(hit, mesh.reflectivity[primitive], 0.0).astype(np.float32),
        np.where(hit, cos, 0.0).astype(np.float32),
    )


STATIC = -1  # hit id of the static yard
NO_HIT = -2


class YardCaster:
    def __init__(self, static_mesh: Mesh, objects: list[MovingObject], slices: int = 8):
        self.static_mesh = static_mesh
        self.static_scene = _scene(static_mesh)
        self.objects = objects
        self.object_scenes = [_scene(o.mesh) for o in objects]
        self.slices = slices
        self._static_cache: dict[tuple, Hits] = {}
        self._dir_cache: dict[tuple, np.ndarray] = {}

    @staticmethod
    def _key(lidar: LidarModel) -> tuple:
        return lidar.name, lidar.beams, lidar.columns, lidar.pose.tobytes(), lidar.beam_altitude_deg.tobytes()

    def _directions(self, lidar: LidarModel) -> np.ndarray:
        key = self._key(lidar)
        if key not in self._dir_cache:
            self._dir_cache[key] = lidar.yard_directions()
        return self._dir_cache[key]

    def static_hits(self, lidar: LidarModel) -> Hits:
        """Hits on the static yard (cast once per sensor: neither moves)."""
        key = self._key(lidar)
        if key not in self._static_cache:
            d = self._directions(lidar).reshape(-1, 3)
            origins = np.broadcast_to(lidar.pose[:3, 3], d.shape)
            hits = _cast(self.static_scene, self.static_mesh, STATIC, origins, d)
            self._static_cache[key] = hits.reshaped((lidar.beams, lidar.columns))
        return self._static_cache[key]

    def cast_sweep(self, lidar: LidarModel, sweep_start_s: float) -> Hits:
        """True hits (beams, columns) of one sweep, moving objects at each slice's mid time."""
        static = self.static_hits(lidar)
        hits = Hits(
            static.range_m.copy(), static.hit_id.copy(), static.reflectivity.copy(), static.cos_incidence.copy()
        )
        directions = self._directions(lidar)
        origin = lidar.pose[:3, 3]
        bounds = np.linspace(0, lidar.columns, self.slices + 1).astype(int)
        mid_times = sweep_start_s + (bounds[:-1] + bounds[1:]) / 2 / (lidar.columns * lidar.rate_hz)
        for obj, scene in zip(self.objects, self.object_scenes):
            poses = obj.pose_at(mid_times)
            for s in range(self.slices):
                c0, c1 = bounds[s], bounds[s + 1]
                pose = poses[s]
                center = pose[:3, :3] @ obj.center_local + pose[:3, 3]
                to_center = center - origin
                distance = float(np.linalg.norm(to_center))
                d = directions[:, c0:c1].reshape(-1, 3)
                if distance > obj.radius_m:
                    cos_limit = np.sqrt(1.0 - (obj.radius_m / distance) ** 2)
                    selected = np.nonzero(d @ (to_center / distance) >= cos_limit)[0]
                    if len(selected) == 0:
                        continue
                else:
                    selected = np.arange(len(d))
                rot = pose[:3, :3]
                local_origin = rot.T @ (origin - pose[:3, 3])
                local_dirs = d[selected] @ rot
                obj_hits = _cast(scene, obj.mesh, obj.key, np.broadcast_to(local_origin, local_dirs.shape), local_dirs)
                beam, col = np.divmod(selected, c1 - c0)
                hits.take_closer(obj_hits, (beam, col + c0))
        return hits

    def measure(
        self, lidar: LidarModel, sweep_start_s: float, rng: np.random.Generator
    ) -> tuple[np.ndarray, np.ndarray]:
        """Measured ranges (NaN = no return) by the sensor's return model, and hit ids (-2 where none)."""
        hits = self.cast_sweep(lidar, sweep_start_s)
        if lidar.returns is None:
            valid = np.isfinite(hits.range_m) & (hits.range_m <= lidar.max_range_m)
            measured = np.where(valid, hits.range_m, np.nan)
        else:
            measured = lidar.returns.measure(
                hits.range_m, hits.reflectivity, hits.cos_incidence, rng, lidar.max_range_m
            )
        return measured, np.where(np.isfinite(measured), hits.hit_id, NO_HIT)
