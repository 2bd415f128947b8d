"""Centroid stage: Eq. 6 centroid and the Eq. 7 correction for occluded faces, in the unit's axes."""

import numpy as np
import pytest

from i2v_loc.params import CentroidParams, UnitDimensions
from i2v_loc.stages.centroid import CentroidCorrector

DIMS = UnitDimensions(length_m=12.0, width_m=2.5, height_m=2.6, floor_m=1.2)


def l_shaped_view(center_xy, yaw_deg, visible_fraction=1.0, spacing=0.1):
    """A long side (v = -W/2) and the front face (u = +L/2) of a box; only the front part of the side."""
    L, W = DIMS.length_m, DIMS.width_m
    u_side = np.arange(L / 2 - visible_fraction * L, L / 2, spacing)
    side = np.column_stack([u_side, np.full_like(u_side, -W / 2)])
    v_front = np.arange(-W / 2, W / 2, spacing)
    front = np.column_stack([np.full_like(v_front, L / 2), v_front])
    local = np.vstack([side, front])
    z_levels = np.arange(1.3, 3.8, 0.5)
    yaw = np.radians(yaw_deg)
    rot = np.array([[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]])
    xy = local @ rot.T + center_xy
    return np.vstack([np.column_stack([xy, np.full(len(xy), z)]) for z in z_levels])


@pytest.mark.parametrize("fraction", [1.0, 0.5, 0.25])
def test_l_shaped_partial_view_is_corrected_to_the_box_centre(fraction):
    true_center = np.array([10.0, -4.0])
    points = l_shaped_view(true_center, 35.0, fraction)
    unit = CentroidCorrector(CentroidParams()).process(points, DIMS, ground_z_m=0.0)
    raw_error = np.hypot(*(unit.centroid[:2] - true_center))
    assert raw_error > 1.0  # the raw centroid is biased towards the seen faces
    assert unit.center[:2] == pytest.approx(true_center, abs=0.06)
    assert unit.center[2] == pytest.approx(1.2 + 1.3)
    assert np.degrees(unit.axis_yaw_rad) % 180 == pytest.approx(35.0, abs=0.5)


def test_yaw_hint_sets_the_axes():
    true_center = np.array([0.0, 0.0])
    points = l_shaped_view(true_center, -60.0, 0.3)
    unit = CentroidCorrector(CentroidParams()).process(points, DIMS, yaw_hint_rad=np.radians(120.0))
    assert unit.center[:2] == pytest.approx(true_center, abs=0.06)


def test_disabled_correction_returns_the_raw_centroid():
    points = l_shaped_view(np.array([0.0, 0.0]), 0.0, 0.5)
    unit = CentroidCorrector(CentroidParams(enabled=False)).process(points, DIMS)
    assert unit.center == pytest.approx(points.mean(axis=0))
