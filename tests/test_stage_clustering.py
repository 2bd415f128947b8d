"""Clustering stage: Euclidean clusters (Eq. 4) and the volume gate (Eq. 5)."""

import numpy as np
import pytest

from i2v_loc.params import ClusteringParams, Params
from i2v_loc.stages.clustering import Clustering
from i2v_loc.stages.primitives import euclidean_labels, min_area_rect, oriented_box_volume


def solid_box(center, size, spacing=0.2):
    axes = [np.linspace(-s / 2, s / 2, int(round(s / spacing)) + 1) + c for c, s in zip(center, size)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)


@pytest.mark.parametrize("gap_m, expected", [(0.4, 1), (1.0, 2)])
def test_two_boxes_one_or_two_clusters_with_eps_0_7(gap_m, expected):
    a = solid_box((0, 0, 1), (2, 2, 2))
    b = solid_box((2 + gap_m, 0, 1), (2, 2, 2))
    labels = euclidean_labels(np.vstack([a, b]), 0.7)
    assert len(np.unique(labels)) == expected


def test_min_area_rect_of_a_rotated_rectangle():
    rng = np.random.default_rng(0)
    local = rng.uniform([-3, -1], [3, 1], (2000, 2))
    yaw = np.radians(30)
    rot = np.array([[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]])
    rect = min_area_rect(local @ rot.T + [5, -2])
    assert rect.length_m == pytest.approx(6, abs=0.05)
    assert rect.width_m == pytest.approx(2, abs=0.05)
    assert np.degrees(rect.yaw_rad) % 180 == pytest.approx(30, abs=0.5)
    assert rect.center_xy == pytest.approx([5, -2], abs=0.05)


def test_oriented_box_volume_is_rectangle_area_times_height():
    pts = solid_box((0, 0, 1.5), (4, 2, 3), spacing=0.1)
    volume, _ = oriented_box_volume(pts)
    assert volume == pytest.approx(24, rel=0.01)


def test_volume_gate_statuses():
    params = Params()
    twizy = params.vehicles["twizy"].model_copy(update={"vehicle_volume_tolerance_m3": 10.0})
    only_twizy = {"twizy": twizy}
    stage = Clustering(ClusteringParams(tolerance_m=0.7, min_points=5), only_twizy)
    v_e = twizy.vehicle_volume_m3  # about 15.6 m3, gate +- 10 m3
    inside = solid_box((0, 0, 1.25), (4.5, 1.6, v_e / (4.5 * 1.6)))
    huge = solid_box((30, 0, 1.5), (20, 3, 3))
    tiny = solid_box((-30, 0, 0.5), (1, 1, 1))
    result = Clustering(ClusteringParams(min_points=5), only_twizy).process(np.vstack([inside, huge, tiny]))
    statuses = sorted(c.status for c in result.clusters)
    assert statuses == ["candidate", "too_large", "too_small"]
    candidate = next(c for c in result.clusters if c.status == "candidate")
    assert candidate.candidates == ["twizy"]
    assert candidate.volume_m3 == pytest.approx(v_e, rel=0.05)
    assert stage.matching_vehicles(v_e + 11) == []


def test_clusters_below_min_points_are_counted_as_noise():
    pts = np.vstack([solid_box((0, 0, 1), (2, 2, 2)), [[20, 20, 1]], [[-20, 20, 1]]])
    result = Clustering(ClusteringParams(min_points=5), Params().vehicles).process(pts)
    assert len(result.clusters) == 1 and result.noise_clusters == 2
