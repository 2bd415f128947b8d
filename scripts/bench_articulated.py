"""Time of the articulated estimator per vehicle and frame on one core: the hinged fit, the UKF
predict + update, and the tracker's whole step (gate, fit, filter, dimensions), on constructed
frames of a turning vehicle seen by the paper's four sensors (points 0.25 m apart on the faces
each sensor sees: about an OS1-32 x 1024 at 20 m, 16 points per m2; then the pipeline's 0.1 m
voxel grid).

    PYTHONPATH=$PWD python scripts/bench_articulated.py [vehicle] [frames]
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from hinged_points import vehicle_points  # noqa: E402

from i2v_loc.params import Params  # noqa: E402
from i2v_loc.sim.kinematics import Articulation, step  # noqa: E402
from i2v_loc.stages.hinged_fit import fit  # noqa: E402
from i2v_loc.stages.primitives import voxel_centroids  # noqa: E402
from i2v_loc.stages.vehicle_model import VehicleModel  # noqa: E402
from i2v_loc.stages.vehicle_tracker import VehicleTracker  # noqa: E402

SENSORS = ((-7.5, 14.36, 4.0), (-20.25, 0.0, 4.0), (20.25, 0.0, 4.0), (7.5, 14.36, 4.0))  # the paper's field


def frames(name: str, n: int):
    params = Params()
    model = VehicleModel.from_config(name, params.vehicles[name])
    art = Articulation.from_vehicle(params.vehicles[name])
    state = np.array([-12.0, 6.0, 0.0, 0.0])
    for k in range(n):
        cloud = vehicle_points(
            model, state[0], state[1], state[2], state[3] - state[2], sensors=SENSORS, spacing=0.25, seed=k
        )
        yield k * 0.1, voxel_centroids(cloud, params.concatenation.voxel_size_m)[0]
        state = step(state, 2.5, float(np.clip(0.3 * (k * 0.1 - 2.0), 0.0, 0.4)), art, 0.1)


def main() -> None:
    name = sys.argv[1] if len(sys.argv) > 1 else "man_tgx"
    n = int(sys.argv[2]) if len(sys.argv) > 2 else 100
    params = Params()
    data = list(frames(name, n))
    tracker = VehicleTracker(params.articulated, params.vehicles)
    step_ms, fit_ms, filter_ms, points = [], [], [], []
    flat = lambda x, y: 0.0  # noqa: E731
    with threadpool_limits(1):
        for t, cloud in data:
            started = bool(tracker.tracks)
            t0 = time.perf_counter()
            tracker.process(cloud, flat, t)
            t1 = time.perf_counter()
            if not started or not tracker.tracks:
                continue
            step_ms.append((t1 - t0) * 1e3)
            track = tracker.tracks[0]
            prior = tracker._prior(track, t, flat)  # the filter is at t already: a zero-length predict
            mine = cloud[tracker._claim(cloud, [prior], [False]) == 0]  # its tractor not lost
            points.append(len(mine))
            t2 = time.perf_counter()
            m = fit(mine, prior, params.articulated)
            t3 = time.perf_counter()
            f = track.filter
            x, p, stamp = f.ukf.x.copy(), f.ukf.P.copy(), f.stamp_s
            t4 = time.perf_counter()
            f.predict(t + 0.1)
            f.update(m.vector, m.covariance)
            t5 = time.perf_counter()
            f.ukf.x, f.ukf.P, f.stamp_s = x, p, stamp
            fit_ms.append((t3 - t2) * 1e3)
            filter_ms.append((t5 - t4) * 1e3)
    for label, values in (
        ("points per vehicle", points),
        ("fit ms", fit_ms),
        ("UKF predict+update ms", filter_ms),
        ("tracker step ms (gate+fit+filter+dimensions)", step_ms),
    ):
        v = np.asarray(values, float)
        print(
            f"{label:>46}: median {np.median(v):7.3f}  p90 {np.percentile(v, 90):7.3f}  min {v.min():7.3f}  (n={len(v)})"
        )


if __name__ == "__main__":
    main()
