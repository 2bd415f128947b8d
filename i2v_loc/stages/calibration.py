"""Stage 1 (offline): refine each sensor's extrinsics against the reference sensor (paper 3.1).

The scene is sampled in ``windows`` short windows spread over the recording, each three sweeps
``window_gap_frames`` apart. A window keeps what stood still in it (voxels occupied in all three
sweeps): the ground, walls and poles, and a vehicle that stands or moves slowly. The long-term
scene recurs in every window; a vehicle that stands or passes slowly in view constrains the
sensors like one more wall, where they see it at the same time. Sensors are registered one at a
time against the union of the already calibrated ones, the best-overlapping first, so a sensor
that does not see the reference enough is chained through its neighbours.

The registration is one plane-to-plane (GICP) Gauss-Newton over all windows at once (Cauchy
weights; correspondences only within a window; each point's surface covariance from a >= 2 m
radius: 1 m normals diverge on sparse 32-beam rings), coarse then fine. On the structure, a
correspondence joins two points of the same side of a surface: their normals, each turned towards
the sensor that saw it, agree within 60 degrees. Two sensors see other faces of an object (one a parked trailer's side,
the other its end); near its corners a point of one face lay within reach of the other face, and
those matches pulled sensors along a row of three 12-16 cm off (0.2-0.6 cm without them). The ground (target normal within STRUCTURE_TILT_DEG
of vertical) moves only z, roll and pitch, and the structure only x, y and yaw. Why: the ground
fills most of every cloud, and a few millimetres of disagreement between two sensors' grounds
(ring sampling, range noise) pushed the horizontal directions, which the ground does not
constrain, along the few walls a sensor saw. Measured before (2026-11-26, open3d GICP of the
accumulated static scene): sensors that saw the ground and one wall or pole slid 20-72 cm.

Quality figures: the ground matches whatever the error in x, y and yaw, and two sensors' 32-beam
rings never sample the same spots (a correct result leaves 0.1-0.4 m between neighbours, so the
distance to the nearest neighbour says little). They are measured on the structure (points whose
target normal is more than STRUCTURE_TILT_DEG from vertical) that overlaps the target (a
neighbour within ``max_correspondence_m``): fitness = share of it within ``fitness_distance_m`` of
the target's surface (point to plane), RMSE = point-to-plane RMSE of those. Measured on three
recordings (the others at their true extrinsics): 0.33-0.91 at the truth, 0.07-0.23 at 25 cm off.
Fitness cannot see a sensor whose overlap leaves a direction unconstrained (it fits well whatever
its position along it), so each result also gives the information of its weakest horizontal
direction in points (``constraint_points``): measured 5-31 on four sensors that ended 10-42 cm
off (with their weak directions held at the guess, a variant since dropped), 376 and more on all
that ended within 2 cm; below ``min_constraint_points`` it is a warning.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from i2v_loc.geometry import extrinsics_matrix, matrix_to_pose, transform_points
from i2v_loc.params import CalibrationParams, Extrinsics, SensorConfig
from i2v_loc.stages.primitives import voxel_centroids, voxel_keys

STILL_VOXEL_M = 0.2  # a voxel occupied in every sweep of a window stood still in it
STRUCTURE_TILT_DEG = 60.0
GROUND_DOF = [0, 1, 5]  # roll, pitch, z of the step (rotation vector, translation)
STRUCTURE_DOF = [2, 3, 4]  # yaw, x, y
CONVERGED = 1e-7  # largest change of the 4x4 step that ends a stage
LEVER_M = 10.0  # a rotation's information is compared with a translation's as the motion at this distance
LEVER_SCALE = np.array([LEVER_M] * 3 + [1.0] * 3)  # of a step (rotation vector, translation)
SINGULAR = 1e-12  # a direction with no information at all (no structure in view) keeps its value
PLANE_FLATNESS = 1e-3  # GICP's: a surface's covariance along its normal, relative to along it
DETERMINED_POINTS = 1.0  # a direction with less information than one structure point's is not determined
SAME_SIDE_COS = 0.5  # a correspondence's two normals (each towards its sensor) agree this well: one side of a surface


@dataclass
class SensorCalibration:
    name: str
    extrinsics: Extrinsics
    fitness: float  # share of the overlapping structure points within fitness_distance_m of the target
    inlier_rmse_m: float  # point-to-plane RMSE of those
    target: str  # what it was registered against ("reference" or "l1+l4", ...)
    constraint_points: float = float("inf")  # weakest horizontal direction's information, in points (module docstring)
    guess_fitness: float = 1.0  # the fitness at the guess, against the same target

    def accepted(self, min_fitness: float) -> bool:
        """Fit at least ``min_fitness``; or better than at the guess, with every horizontal
        direction determined (``DETERMINED_POINTS``). A sensor seeing little structure calibrated
        to 0.4 cm at a fitness of 0.26 (0.18 at the guess) and was kept at its guess, 52 cm off:
        its points bent a Volvo's trailer 2 deg and widened it by 0.3 m. One seeing the ground,
        a pole and a vehicle slid 1.75 m along a direction with no information, its fitness 0.27
        (0.19 at the guess)."""
        determined = self.constraint_points >= DETERMINED_POINTS
        return self.fitness >= min_fitness or (self.fitness > self.guess_fitness and determined)


@dataclass
class WindowCloud:
    """One window's points in the yard frame, each with the local surface covariance of the sensor
    that saw it (GICP's: the surface's spread, flattened to PLANE_FLATNESS along its normal) and
    that normal turned towards the sensor (the side of the surface it saw)."""

    points: np.ndarray
    covariances: np.ndarray  # (n, 3, 3)
    normals: np.ndarray

    @functools.cached_property
    def tree(self):
        """The search tree, built when first matched against (a sensor's own clouds never are)."""
        from scipy.spatial import cKDTree

        return cKDTree(self.points if len(self.points) else np.zeros((1, 3)))

    def moved(self, transform: np.ndarray) -> WindowCloud:
        rotation = transform[:3, :3]
        return WindowCloud(
            transform_points(transform, self.points),
            rotation @ self.covariances @ rotation.T,
            self.normals @ rotation.T,
        )

    def joined(self, other: WindowCloud) -> WindowCloud:
        return WindowCloud(
            np.vstack([self.points, other.points]),
            np.concatenate([self.covariances, other.covariances]),
            np.vstack([self.normals, other.normals]),
        )

    def match(self, points: np.ndarray, max_distance_m: float):
        """(source rows, target rows) of the points with a point of this cloud within reach."""
        distance, nearest = self.tree.query(points, distance_upper_bound=max_distance_m)
        rows = np.flatnonzero(np.isfinite(distance))
        return rows, nearest[rows]


def is_structure(normals: np.ndarray) -> np.ndarray:
    """Whether each normal is more than STRUCTURE_TILT_DEG from vertical (a wall, a vehicle's side)."""
    return np.abs(normals[:, 2]) < np.cos(np.radians(STRUCTURE_TILT_DEG))


def still_points(sweeps: list[np.ndarray]) -> np.ndarray:
    """The middle sweep's points in voxels occupied in every sweep of the window (sensor frame)."""
    sweeps = [s[np.isfinite(s).all(axis=1)].astype(np.float64) for s in sweeps]
    if not sweeps or any(len(s) == 0 for s in sweeps):
        return np.zeros((0, 3))
    keys = voxel_keys(np.vstack(sweeps), STILL_VOXEL_M)
    bounds = np.cumsum([0] + [len(s) for s in sweeps])
    per_sweep = [keys[a:b] for a, b in zip(bounds[:-1], bounds[1:])]
    middle = len(sweeps) // 2
    keep = np.ones(len(sweeps[middle]), dtype=bool)
    for other in per_sweep[:middle] + per_sweep[middle + 1 :]:
        keep &= np.isin(per_sweep[middle], other)
    return sweeps[middle][keep]


class Calibrator:
    def __init__(self, params: CalibrationParams):
        self.params = params

    def calibrate(
        self, sensors: list[SensorConfig], windows: list[dict[str, list[np.ndarray]]], progress=None
    ) -> list[SensorCalibration]:
        """Per sensor, its calibrated extrinsics; ``windows`` holds per window each sensor's sweeps.
        ``progress``: called with each sensor's ``SensorCalibration`` as it is done."""
        names = [s.name for s in sensors]
        ref = self.params.reference_sensor or names[0]
        if ref not in names:
            raise ValueError(f"reference sensor {ref!r} is not among the sensors {', '.join(names)}")
        guess = {s.name: extrinsics_matrix(s.extrinsics) for s in sensors}
        clouds = {
            name: [self._cloud(self._still_points(w.get(name, []), guess[name]), guess[name][:3, 3]) for w in windows]
            for name in names
        }
        results = [SensorCalibration(ref, sensors[names.index(ref)].extrinsics, 1.0, 0.0, "reference")]
        targets, done = clouds[ref], [ref]
        while len(done) < len(names):
            name = max((n for n in names if n not in done), key=lambda n: self._overlap(clouds[n], targets))
            at_guess, _ = self.quality([cloud.points for cloud in clouds[name]], targets)
            correction, constraint = self._register(clouds[name], targets, center=guess[name][:3, 3])
            clouds[name] = [cloud.moved(correction) for cloud in clouds[name]]
            x, y, z, roll, pitch, yaw = matrix_to_pose(correction @ guess[name])
            extrinsics = Extrinsics(x_m=x, y_m=y, z_m=z, roll_deg=roll, pitch_deg=pitch, yaw_deg=yaw)
            quality = self.quality([cloud.points for cloud in clouds[name]], targets)
            results.append(SensorCalibration(name, extrinsics, *quality, "+".join(done), constraint, at_guess))
            if progress is not None:
                progress(results[-1])
            targets = [target.joined(cloud) for target, cloud in zip(targets, clouds[name])]
            done.append(name)
        return results

    # ----------------------------------------------------------------- internals

    def _still_points(self, sweeps: list[np.ndarray], to_yard: np.ndarray) -> np.ndarray:
        points = transform_points(to_yard, still_points(sweeps))
        return voxel_centroids(points, self.params.voxel_size_m, float64=True)[0] if len(points) else points

    def _cloud(self, points: np.ndarray, viewpoint: np.ndarray) -> WindowCloud:
        import open3d as o3d

        if len(points) < 3:
            empty = np.zeros((0, 3))
            return WindowCloud(empty, np.zeros((0, 3, 3)), empty)
        cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
        cloud.estimate_covariances(o3d.geometry.KDTreeSearchParamHybrid(radius=self.params.normal_radius_m, max_nn=50))
        _, axes = np.linalg.eigh(np.asarray(cloud.covariances))  # ascending: the normal first
        covariances = np.einsum("nij,j,nkj->nik", axes, [PLANE_FLATNESS, 1.0, 1.0], axes)
        normals = axes[:, :, 0]
        normals *= np.where(np.einsum("ij,ij->i", normals, viewpoint - points) < 0, -1.0, 1.0)[:, None]
        return WindowCloud(points, covariances, normals)

    def _overlap(self, clouds: list[WindowCloud], targets: list[WindowCloud]) -> int:
        reach = self.params.max_correspondence_m
        return sum(len(t.match(c.points, reach)[0]) for c, t in zip(clouds, targets) if len(c.points) and len(t.points))

    def _register(self, sources: list[WindowCloud], targets: list[WindowCloud], center: np.ndarray):
        """(correction (4x4, yard frame) that moves the sensor's windows onto the targets, the
        weakest horizontal direction's information in points at the end)."""
        transform = np.eye(4)
        for reach in (self.params.max_correspondence_m, self.params.max_correspondence_m / 4):
            for _ in range(self.params.max_iterations):
                hessian, gradient = self._normal_equations(sources, targets, transform, center, reach)
                step = rigid_step(constrained_step(hessian, gradient), center)
                transform = step @ transform
                if np.abs(step - np.eye(4)).max() < CONVERGED:
                    break
        return transform, weakest_horizontal_points(hessian)

    def _normal_equations(self, sources, targets, transform, center, reach):
        """(Hessian, gradient) of the Cauchy-weighted plane-to-plane cost in (rotation vector about
        ``center``, translation); the ground speaks only to roll, pitch and z, the structure only to
        yaw, x and y."""
        hessian, gradient = np.zeros((6, 6)), np.zeros(6)
        rotation = transform[:3, :3]
        scale = (reach / 3.0) ** 2 / (2.0 * PLANE_FLATNESS)  # a normal offset of reach / 3 weighs half
        for source, target in zip(sources, targets):
            if not len(source.points) or not len(target.points):
                continue
            moved = transform_points(transform, source.points)
            rows, nearest = target.match(moved, reach)
            rows, nearest = self._same_side(source, target, rows, nearest, rotation)
            moved, residual = moved[rows], moved[rows] - target.points[nearest]
            combined = target.covariances[nearest] + rotation @ source.covariances[rows] @ rotation.T
            information = np.linalg.inv(combined)
            jacobian = np.zeros((len(rows), 3, 6))
            jacobian[:, :, :3] = -skew(moved - center)
            jacobian[:, :, 3:] = np.eye(3)
            structure = is_structure(target.normals[nearest])
            jacobian[:, :, GROUND_DOF] *= ~structure[:, None, None]
            jacobian[:, :, STRUCTURE_DOF] *= structure[:, None, None]
            distance2 = np.einsum("ni,nij,nj->n", residual, information, residual)
            weight = 1.0 / (1.0 + distance2 / scale)
            weighted = np.einsum("nij,njk,n->nik", information, jacobian, weight)
            hessian += np.einsum("nji,njk->ik", jacobian, weighted)
            gradient += np.einsum("nji,nj->i", weighted, residual)
        return hessian, gradient

    @staticmethod
    def _same_side(source: WindowCloud, target: WindowCloud, rows, nearest, rotation):
        """The correspondences on the ground, and those on the structure whose two normals (each
        turned towards its sensor) agree: two faces of an object seen by two sensors are not one
        surface. (The ground's normals are not compared: on sparse rings far out a 2 m radius holds
        one ring, a line whose smallest axis is any direction across it; compared, a 1.5 s
        recording's l3 ended 6.9 cm off in height and pitch, 1.2 cm not compared.)"""
        agree = np.einsum("ij,ij->i", source.normals[rows] @ rotation.T, target.normals[nearest]) > SAME_SIDE_COS
        keep = agree | ~is_structure(target.normals[nearest])
        return rows[keep], nearest[keep]

    def quality(self, points: list[np.ndarray], targets: list[WindowCloud]) -> tuple[float, float]:
        """(fitness, point-to-plane RMSE in m) of the registered windows' structure (module docstring)."""
        overlapping, residuals = 0, []
        for window, target in zip(points, targets):
            if not len(window) or not len(target.points):
                continue
            rows, nearest = target.match(window, self.params.max_correspondence_m)
            normals = target.normals[nearest]
            structure = is_structure(normals)
            overlapping += int(structure.sum())
            offsets = window[rows[structure]] - target.points[nearest[structure]]
            residual = np.einsum("ij,ij->i", offsets, normals[structure])
            residuals.append(residual[np.abs(residual) < self.params.fitness_distance_m])
        inliers = np.concatenate(residuals) if residuals else np.zeros(0)
        if not overlapping or not len(inliers):
            return 0.0, float("inf")
        return float(len(inliers) / overlapping), float(np.sqrt(np.mean(inliers**2)))


def _scaled(hessian: np.ndarray) -> np.ndarray:
    """The Hessian with rotations counted as the motion at LEVER_M."""
    return hessian / np.outer(LEVER_SCALE, LEVER_SCALE)


def weakest_horizontal_points(hessian: np.ndarray) -> float:
    """The information of the weakest direction in (yaw, x, y), in points: one structure point
    exactly on its surface, along its normal, counts 1 (its information is 1 / (2 PLANE_FLATNESS))."""
    block = _scaled(hessian)[np.ix_(STRUCTURE_DOF, STRUCTURE_DOF)]
    return float(np.linalg.eigvalsh(block)[0] * 2.0 * PLANE_FLATNESS)


def constrained_step(hessian: np.ndarray, gradient: np.ndarray) -> np.ndarray:
    """The Gauss-Newton step, per block (ground, structure), along the directions the points
    constrain at all (rotations counted as the motion at LEVER_M). Weakly constrained directions
    are followed: tried keeping their value below 0.3 % of the block's strongest, the sloped
    docking's l2 on three draws ended 26-42 cm off (its guess's error) against 6-26 cm followed."""
    hessian, gradient = _scaled(hessian), gradient / LEVER_SCALE
    step = np.zeros(6)
    for block in (GROUND_DOF, STRUCTURE_DOF):
        values, vectors = np.linalg.eigh(hessian[np.ix_(block, block)])
        strong = values > SINGULAR * max(values.max(), 1e-300)
        vectors = vectors[:, strong]
        step[block] = -vectors @ ((vectors.T @ gradient[block]) / values[strong])
    return step / LEVER_SCALE


def skew(vectors: np.ndarray) -> np.ndarray:
    """(n, 3, 3) cross-product matrices: skew(a) @ b = a x b."""
    result = np.zeros((len(vectors), 3, 3))
    result[:, 0, 1], result[:, 0, 2] = -vectors[:, 2], vectors[:, 1]
    result[:, 1, 0], result[:, 1, 2] = vectors[:, 2], -vectors[:, 0]
    result[:, 2, 0], result[:, 2, 1] = -vectors[:, 1], vectors[:, 0]
    return result


def rigid_step(delta: np.ndarray, center: np.ndarray) -> np.ndarray:
    """4x4 of a small motion: rotation vector ``delta[:3]`` about ``center``, then ``delta[3:]``."""
    from scipy.spatial.transform import Rotation

    step = np.eye(4)
    step[:3, :3] = Rotation.from_rotvec(delta[:3]).as_matrix()
    step[:3, 3] = center + delta[3:] - step[:3, :3] @ center
    return step
