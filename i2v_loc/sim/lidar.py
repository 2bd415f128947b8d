"""Ray-cast Ouster OS1 model with open3d's RaycastingScene.

The static yard is one scene, cast once per sensor (it does not move). Every moving object has
its own scene in its local frame, built once; for each slice of the sweep (1/8 by default) the
slice's rays are moved into the object's frame at the slice's mid time and cast, and the nearest
hit wins. Rays are culled by each object's bounding sphere first.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import open3d as o3d

from i2v_loc.geometry import extrinsics_matrix
from i2v_loc.recording import beam_directions
from i2v_loc.sim.meshes import Mesh

VERTICAL_FOV_DEG = 45.0


@dataclass
class LidarModel:
    name: str
    model: str
    beams: int
    columns: int
    rate_hz: float
    pose: np.ndarray  # 4x4 sensor -> yard
    min_range_m: float = 0.5
    max_range_m: float = 120.0
    range_noise_m: float = 0.03
    dropout_rate: float = 0.02
    phase_s: float = 0.0  # sweep start after the frame time (true clock)
    clock_offset_s: float = 0.0  # sensor clock minus true clock

    @classmethod
    def from_config(cls, cfg, **kwargs) -> "LidarModel":
        """From an ``i2v_loc.params.SensorConfig``."""
        return cls(name=cfg.name, model=cfg.model, beams=cfg.beams, columns=cfg.columns, rate_hz=cfg.rate_hz,
                   pose=extrinsics_matrix(cfg.extrinsics), min_range_m=cfg.min_range_m, max_range_m=cfg.max_range_m, **kwargs)

    @property
    def beam_altitude_deg(self) -> np.ndarray:
        """Uniform from +22.5 to -22.5 degrees (beam 0 on top, as Ouster orders them)."""
        return np.linspace(VERTICAL_FOV_DEG / 2, -VERTICAL_FOV_DEG / 2, self.beams).astype(np.float32)

    @property
    def beam_azimuth_offset_deg(self) -> np.ndarray:
        return np.zeros(self.beams, dtype=np.float32)

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
            "name": self.name, "model": self.model, "beams": self.beams, "columns": self.columns,
            "rate_hz": self.rate_hz, "beam_altitude_deg": [round(float(a), 4) for a in self.beam_altitude_deg],
            "phase_s": round(self.phase_s, 9), "clock_offset_s": round(self.clock_offset_s, 9),
            "range_noise_m": self.range_noise_m, "dropout_rate": self.dropout_rate,
            "min_range_m": self.min_range_m, "max_range_m": self.max_range_m,
        }


@dataclass
class MovingObject:
    """A rigid moving mesh: ``pose_at(times_s) -> (n, 4, 4)`` local -> yard."""

    key: int
    mesh: Mesh  # in the local frame
    pose_at: Callable[[np.ndarray], np.ndarray]

    def __post_init__(self) -> None:
        v = self.mesh[0]
        self.center_local = (v.min(axis=0) + v.max(axis=0)) / 2
        self.radius_m = float(np.linalg.norm(v - self.center_local, axis=1).max())


def _scene(mesh: Mesh) -> o3d.t.geometry.RaycastingScene:
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(mesh[0].astype(np.float32)), o3d.core.Tensor(mesh[1].astype(np.uint32)))
    return scene


def _cast(scene, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
    rays = np.hstack([origins, directions]).astype(np.float32)
    return scene.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy()


STATIC = -1  # hit id of the static yard; -2 = no hit


class YardCaster:
    def __init__(self, static_mesh: Mesh, objects: list[MovingObject], slices: int = 8):
        self.static_scene = _scene(static_mesh)
        self.objects = objects
        self.object_scenes = [_scene(o.mesh) for o in objects]
        self.slices = slices
        self._static_cache: dict[tuple, np.ndarray] = {}
        self._dir_cache: dict[tuple, np.ndarray] = {}

    @staticmethod
    def _key(lidar: LidarModel) -> tuple:
        return lidar.name, lidar.beams, lidar.columns, lidar.pose.tobytes()

    def _directions(self, lidar: LidarModel) -> np.ndarray:
        key = self._key(lidar)
        if key not in self._dir_cache:
            self._dir_cache[key] = lidar.yard_directions()
        return self._dir_cache[key]

    def static_ranges(self, lidar: LidarModel) -> np.ndarray:
        """Ranges to the static yard (cast once per sensor: neither moves)."""
        key = self._key(lidar)
        if key not in self._static_cache:
            d = self._directions(lidar).reshape(-1, 3)
            origins = np.broadcast_to(lidar.pose[:3, 3], d.shape)
            self._static_cache[key] = _cast(self.static_scene, origins, d).reshape(lidar.beams, lidar.columns)
        return self._static_cache[key]

    def cast_sweep(self, lidar: LidarModel, sweep_start_s: float) -> tuple[np.ndarray, np.ndarray]:
        """True ranges (beams, columns) in metres (inf = no hit) and the id of what each ray hit."""
        ranges = self.static_ranges(lidar).copy()
        hit = np.where(np.isfinite(ranges), STATIC, -2)
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
                t_hit = _cast(scene, np.broadcast_to(local_origin, local_dirs.shape), local_dirs)
                beam, col = np.divmod(selected, c1 - c0)
                col = col + c0
                closer = t_hit < ranges[beam, col]
                ranges[beam[closer], col[closer]] = t_hit[closer]
                hit[beam[closer], col[closer]] = obj.key
        return ranges, hit

    def measure(self, lidar: LidarModel, sweep_start_s: float, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """Measured ranges (noise, dropouts, range limits; NaN = no return) and hit ids (-2 where none)."""
        ranges, hit = self.cast_sweep(lidar, sweep_start_s)
        noisy = ranges + rng.normal(0.0, lidar.range_noise_m, ranges.shape) if lidar.range_noise_m > 0 else ranges
        invalid = ~np.isfinite(noisy) | (noisy < lidar.min_range_m) | (noisy > lidar.max_range_m)
        if lidar.dropout_rate > 0:
            invalid |= rng.random(ranges.shape) < lidar.dropout_rate
        noisy = np.where(invalid, np.nan, noisy)
        hit = np.where(invalid, -2, hit)
        return noisy, hit
