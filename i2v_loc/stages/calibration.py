"""Stage 1 (offline): refine each sensor's extrinsics by ICP against the reference sensor (paper 3.1).

Per sensor, ``frames`` sweeps of the scene are accumulated and only the static part is kept
(voxels occupied in most of the frames: moving vehicles and pedestrians drop out). Clouds are put
in the yard frame with the initial guess, voxel-downsampled, and registered with open3d's
generalized ICP (or point-to-plane with normals from a >= 2 m radius: 1 m normals diverge on
sparse 32-beam rings), coarse then fine. Sensors are registered one at a time against the union
of the already calibrated ones, the best-overlapping first, so a sensor that does not see the
reference enough is chained through its neighbours.

Quality figures: the ground fills most of every cloud and matches whatever the error in x, y and
yaw, and two sensors' 32-beam rings never sample the same spots (a correct result leaves 0.1-0.4 m
between neighbours, so open3d's fitness and RMSE at the correspondence distance say little). They
are measured on the structure (points whose target normal is more than STRUCTURE_TILT_DEG from
vertical: walls, containers) that overlaps the target (a neighbour within
``max_correspondence_m``): fitness = share of it with a neighbour within ``fitness_distance_m``,
RMSE = point-to-plane RMSE of those (the target's normals).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from i2v_loc.geometry import extrinsics_matrix, matrix_to_pose
from i2v_loc.params import CalibrationParams, Extrinsics, SensorConfig
from i2v_loc.stages.primitives import voxel_centroids, voxel_keys

STATIC_FRACTION = 0.6  # a voxel occupied in at least this share of the frames is static scene
STATIC_VOXEL_M = 0.3
STRUCTURE_TILT_DEG = 60.0


@dataclass
class SensorCalibration:
    name: str
    extrinsics: Extrinsics
    fitness: float  # share of the overlapping structure points within fitness_distance_m of the target
    inlier_rmse_m: float  # point-to-plane RMSE of those
    target: str  # what it was registered against ("reference" or "l1+l4", ...)


def static_points(sweeps: list[np.ndarray]) -> np.ndarray:
    """Points of the voxels occupied in at least STATIC_FRACTION of the sweeps (sensor frame)."""
    sweeps = [s[np.isfinite(s).all(axis=1)] for s in sweeps if len(s)]
    if not sweeps:
        return np.zeros((0, 3))
    if len(sweeps) == 1:
        return sweeps[0].astype(np.float64)
    cloud = np.vstack(sweeps).astype(np.float64)
    frame_of = np.repeat(np.arange(len(sweeps)), [len(s) for s in sweeps])
    keys = voxel_keys(cloud, STATIC_VOXEL_M)
    pairs = np.unique(np.column_stack([keys, frame_of]), axis=0)  # (voxel, frame) occupied
    voxels, frames_seen = np.unique(pairs[:, 0], return_counts=True)
    static = voxels[frames_seen >= STATIC_FRACTION * len(sweeps)]
    return cloud[np.isin(keys, static)]


class Calibrator:
    def __init__(self, params: CalibrationParams):
        self.params = params

    def calibrate(self, sensors: list[SensorConfig], sweeps: dict[str, list[np.ndarray]]) -> list[SensorCalibration]:
        import open3d as o3d

        o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
        names = [s.name for s in sensors]
        ref = self.params.reference_sensor or names[0]
        if ref not in names:
            raise ValueError(f"reference sensor {ref!r} is not among the sensors {', '.join(names)}")
        guess = {s.name: extrinsics_matrix(s.extrinsics) for s in sensors}
        clouds = {name: self._yard_cloud(static_points(sweeps.get(name, [])), guess[name]) for name in names}
        done = {ref: guess[ref]}
        results = [SensorCalibration(ref, sensors[names.index(ref)].extrinsics, 1.0, 0.0, "reference")]
        target = clouds[ref]
        while len(done) < len(names):
            todo = [n for n in names if n not in done]
            overlaps = {n: self._overlap(clouds[n], target) for n in todo}
            name = max(todo, key=overlaps.get)
            correction, fitness, rmse = self._register(clouds[name], target)
            done[name] = correction @ guess[name]
            clouds[name] = clouds[name].transform(correction)
            target = target + clouds[name]
            x, y, z, roll, pitch, yaw = matrix_to_pose(done[name])
            results.append(
                SensorCalibration(
                    name,
                    Extrinsics(x_m=x, y_m=y, z_m=z, roll_deg=roll, pitch_deg=pitch, yaw_deg=yaw),
                    fitness,
                    rmse,
                    "+".join(n for n in done if n != name),
                )
            )
        return results

    # ----------------------------------------------------------------- internals

    def _yard_cloud(self, points_sensor: np.ndarray, to_yard: np.ndarray):
        import open3d as o3d

        points = points_sensor @ to_yard[:3, :3].T + to_yard[:3, 3]
        points, _ = voxel_centroids(points, self.params.voxel_size_m)
        cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
        cloud.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=self.params.normal_radius_m, max_nn=50))
        return cloud

    def _overlap(self, source, target) -> int:

        if len(source.points) == 0 or len(target.points) == 0:
            return 0
        distances = np.asarray(source.compute_point_cloud_distance(target))
        return int((distances < self.params.max_correspondence_m).sum()) if len(distances) else 0

    def _register(self, source, target) -> tuple[np.ndarray, float, float]:
        import open3d as o3d

        reg = o3d.pipelines.registration
        if len(source.points) < 3 or len(target.points) < 3:
            return np.eye(4), 0.0, float("inf")
        if self.params.method == "gicp":
            estimation = reg.TransformationEstimationForGeneralizedICP()
            run = reg.registration_generalized_icp
        else:
            estimation = reg.TransformationEstimationPointToPlane()
            run = reg.registration_icp
        transform = np.eye(4)
        criteria = reg.ICPConvergenceCriteria(max_iteration=self.params.max_iterations)
        for max_corr in (self.params.max_correspondence_m, self.params.max_correspondence_m / 4):
            result = run(source, target, max_corr, transform, estimation, criteria)
            transform = result.transformation
        return np.asarray(transform), *self.quality(source, target, np.asarray(transform))

    def quality(self, source, target, transform: np.ndarray) -> tuple[float, float]:
        """(fitness, point-to-plane RMSE in m) of the registered source's structure (module docstring)."""
        from scipy.spatial import cKDTree

        points = np.asarray(source.points) @ transform[:3, :3].T + transform[:3, 3]
        target_points, normals = np.asarray(target.points), np.asarray(target.normals)
        if len(points) == 0 or len(target_points) == 0:
            return 0.0, float("inf")
        distance, nearest = cKDTree(target_points).query(points, distance_upper_bound=self.params.max_correspondence_m)
        overlap = np.isfinite(distance)
        nearest = np.where(overlap, nearest, 0)
        overlap &= np.abs(normals[nearest, 2]) < np.cos(np.radians(STRUCTURE_TILT_DEG))
        if not overlap.any():
            return 0.0, float("inf")
        inlier = overlap & (distance < self.params.fitness_distance_m)
        if not inlier.any():
            return 0.0, float("inf")
        residual = np.einsum("ij,ij->i", points[inlier] - target_points[nearest[inlier]], normals[nearest[inlier]])
        return float(inlier.sum() / overlap.sum()), float(np.sqrt(np.mean(residual**2)))
