"""Concatenation stage: extrinsics, voxel centroids (Eq. 1-2), synchronisation (Eq. 3), faults."""

import numpy as np
import pytest

from i2v_loc.frame import SensorScan
from i2v_loc.params import ConcatenationParams, Extrinsics, SensorConfig
from i2v_loc.stages.concatenation import Concatenation, MotionHint
from i2v_loc.stages.primitives import voxel_centroids

SENSORS = [
    SensorConfig(name="a", extrinsics=Extrinsics(x_m=10, y_m=0, z_m=4, yaw_deg=90)),
    SensorConfig(name="b", extrinsics=Extrinsics(x_m=0, y_m=0, z_m=4)),
]


def scan(name, stamp, points, offsets=None):
    return SensorScan(name, stamp, np.asarray(points, dtype=np.float32), offsets)


def test_points_reach_the_yard_frame_through_the_extrinsics():
    stage = Concatenation(ConcatenationParams(voxel_size_m=0), SENSORS)
    result = stage.process({"a": scan("a", 1.0, [[5, 0, -4]]), "b": scan("b", 1.0, [[3, 2, -3]])})
    assert sorted(map(tuple, np.round(result.points, 4).tolist())) == [(3.0, 2.0, 1.0), (10.0, 5.0, 0.0)]
    assert result.faults == {} and result.stamp_s == 1.0


def test_voxel_centroids_average_the_points_of_each_voxel():
    pts = np.array([[0.01, 0.01, 0.01], [0.09, 0.05, 0.03], [1.05, 0, 0]], dtype=np.float32)
    centroids, _ = voxel_centroids(pts, 0.1)
    assert sorted(centroids.tolist()) == [pytest.approx([0.05, 0.03, 0.02]), pytest.approx([1.05, 0, 0])]


def test_sweeps_outside_the_tolerance_are_dropped_and_the_reference_is_the_earliest_in_sync():
    sensors = SENSORS + [SensorConfig(name="c", time_offset_s=-0.5)]
    stage = Concatenation(ConcatenationParams(voxel_size_m=0, sync_tolerance_s=0.05), sensors)
    result = stage.process(
        {"a": scan("a", 2.02, [[5, 0, -4]]), "b": scan("b", 2.0, [[3, 2, -3]]), "c": scan("c", 2.6, [[1, 1, 1]])}
    )  # c on the common clock: 2.1
    assert result.faults == {"c": "out_of_sync"}
    assert result.dropped["out_of_sync"] == 1
    assert result.stamp_s == pytest.approx(2.0)
    assert len(result.points) == 2


def test_the_merge_tells_each_used_sweeps_rows_and_sensor_position():
    """Rays need their origins: the merged cloud's rows of each sweep in sync and where its sensor
    stands (yard frame); a sweep out of sync is left out of both."""
    sensors = SENSORS + [SensorConfig(name="c", extrinsics=Extrinsics(x_m=-3, y_m=7, z_m=5), time_offset_s=-0.5)]
    stage = Concatenation(ConcatenationParams(voxel_size_m=0, sync_tolerance_s=0.05), sensors)
    scans = {"a": scan("a", 2.0, [[5, 0, -4], [6, 0, -4]]), "b": scan("b", 2.0, [[3, 2, -3]])}
    merged = stage.merge({**scans, "c": scan("c", 2.6, [[1, 1, 1]] * 4)})  # c out of sync
    assert merged.sweep_bounds.tolist() == [0, 2, 3]
    assert merged.sweep_origins.tolist() == [[10.0, 0.0, 4.0], [0.0, 0.0, 4.0]]
    merged = stage.merge({**scans, "c": scan("c", 2.5, [[1, 1, 1]] * 4)})  # c in sync, after a and b
    assert merged.sweep_bounds.tolist() == [0, 2, 3, 7] and merged.sweep_origins[2].tolist() == [-3.0, 7.0, 5.0]
    gathered = SensorScan("b", 2.0, np.array([[3, 2, -3]], dtype=np.float32), None, from_sensor=False)
    merged = stage.merge({"a": scans["a"], "b": gathered})  # a cloud gathered elsewhere: its origin is not known
    assert merged.sweep_origins[0].tolist() == [10.0, 0.0, 4.0] and np.isnan(merged.sweep_origins[1]).all()


def test_the_rays_that_returned_nothing_reach_as_far_as_their_sensor_in_the_yard_frame():
    """A sweep's rays that returned nothing end where its sensor's reach does, turned and moved by
    its extrinsics (sensor a: turned 90 deg, at x 10 m); a sweep that does not tell them, or is out
    of sync, adds none; none told at all: not known."""
    sensors = [*SENSORS, SensorConfig(name="c", time_offset_s=-0.5)]
    stage = Concatenation(ConcatenationParams(voxel_size_m=0, sync_tolerance_s=0.05), sensors)
    east_and_down = np.array([[1, 0, 0], [0, 0, -1]], dtype=np.float32)
    told = SensorScan("a", 2.0, np.array([[5, 0, -4]], dtype=np.float32), None, unreturned=east_and_down)
    late = SensorScan("c", 2.6, np.array([[1, 1, 1]], dtype=np.float32), None, unreturned=east_and_down)
    merged = stage.merge({"a": told, "b": scan("b", 2.0, [[3, 2, -3]]), "c": late})
    reach = SENSORS[0].max_range_m
    np.testing.assert_allclose(merged.unreturned.ends, [[10.0, reach, 4.0], [10.0, 0.0, 4.0 - reach]], atol=1e-3)
    assert merged.unreturned.origins.tolist() == [[10.0, 0.0, 4.0]]
    assert stage.merge({"b": scan("b", 2.0, [[3, 2, -3]])}).unreturned is None


def test_rays_that_returned_nothing_given_when_asked_are_picked_out_only_when_their_ends_are():
    """A reader may defer picking out a sweep's rays that returned nothing (a recording's four
    sweeps cost 1.3 ms a frame, and only a vehicle's start asks): the merge does not ask, their
    ends are those of the rays given at once, and they are picked out once."""
    stage = Concatenation(ConcatenationParams(voxel_size_m=0), SENSORS)
    east_and_down = np.array([[1, 0, 0], [0, 0, -1]], dtype=np.float32)
    asked = []

    def deferred():
        asked.append(1)
        return east_and_down

    points = np.array([[5, 0, -4]], dtype=np.float32)
    merged = stage.merge({"a": SensorScan("a", 2.0, points, None, unreturned=deferred)})
    assert asked == []
    given = stage.merge({"a": SensorScan("a", 2.0, points, None, unreturned=east_and_down)})
    np.testing.assert_array_equal(merged.unreturned.ends, given.unreturned.ends)
    assert merged.unreturned.bounds.tolist() == [0, 2] and asked == [1]


def test_missing_empty_and_nan_are_counted_not_raised():
    sensors = SENSORS + [SensorConfig(name="c")]
    stage = Concatenation(ConcatenationParams(voxel_size_m=0), sensors)
    bad = [[np.nan, 0, 0], [np.inf, 1, 1], [3, 0, 0]]
    result = stage.process(
        {"a": scan("a", 1.0, np.zeros((0, 3))), "b": scan("b", 1.0, bad), "x": scan("x", 1.0, [[1, 1, 1]])}
    )
    assert result.faults == {"a": "empty", "b": "nan_points", "c": "missing", "x": "unknown_sensor"}
    assert result.dropped == {"out_of_sync": 0, "empty": 1, "missing": 1, "nan_points": 2}
    assert result.points.tolist() == [[3.0, 0.0, 4.0]]
    assert np.isfinite(result.points).all()


def test_no_usable_sweep_gives_an_empty_cloud():
    result = Concatenation(ConcatenationParams(), SENSORS).process({})
    assert result.points.shape == (0, 3) and np.isnan(result.stamp_s)


def test_motion_interpolation_moves_points_of_a_moving_object_to_the_reference_time():
    stage = Concatenation(ConcatenationParams(voxel_size_m=0, reference="earliest"), SENSORS[1:])
    # two points captured 0.05 s after the sweep start; one on a vehicle moving +x at 2 m/s
    pts = [[10, 0, -3], [30, 0, -3]]
    hint = MotionHint((10.0, 0.0), 0.0, 3.0, 1.5, (2.0, 0.0))
    result = stage.process({"b": scan("b", 1.0, pts, [0.05, 0.05])}, [hint])
    # back to t_ref = 1.0: the moving point goes 0.1 m back, the static one stays
    assert result.points[:, 0].tolist() == pytest.approx([9.9, 30.0], abs=1e-5)
    off = Concatenation(ConcatenationParams(voxel_size_m=0, motion_interpolation=False), SENSORS[1:])
    assert off.process({"b": scan("b", 1.0, pts, [0.05, 0.05])}, [hint]).points[:, 0].tolist() == [10.0, 30.0]


def test_a_hint_with_an_age_catches_the_points_captured_after_its_pose():
    """The last frame's box (0.1 s before the reference) of a vehicle moving +x at 4 m/s spans x 7..13;
    a point at x 13.8 captured 0.15 s after the reference lies beyond it, but inside the box where it
    stood at the point's capture time (8..14). With the age the point goes back by 0.6 m; without
    it, it is left where it was (and distorts the vehicle's front)."""
    stage = Concatenation(ConcatenationParams(voxel_size_m=0, reference="earliest"), SENSORS[1:])
    late = {"b": scan("b", 1.0, [[13.8, 0.0, -3.0]], [0.15])}
    result = stage.process(late, [MotionHint((10.0, 0.0), 0.0, 3.0, 1.5, (4.0, 0.0), 0.0, 0.1)])
    assert result.points[0, 0] == pytest.approx(13.8 - 0.6, abs=1e-5)
    result = stage.process(late, [MotionHint((10.0, 0.0), 0.0, 3.0, 1.5, (4.0, 0.0), 0.0)])
    assert result.points[0, 0] == pytest.approx(13.8, abs=1e-5)


def test_a_turning_hint_with_an_age_is_turned_to_the_capture_time():
    """A box turning at 1 rad/s on the spot: a point 2.5 m ahead and 1.7 m aside is outside it at its
    pose (half width 1.5) and inside 0.25 s later, turned by 0.25 rad; it goes back along the turn."""
    stage = Concatenation(ConcatenationParams(voxel_size_m=0, reference="earliest"), SENSORS[1:])
    late = {"b": scan("b", 1.0, [[12.5, 1.7, -3.0]], [0.15])}
    result = stage.process(late, [MotionHint((10.0, 0.0), 0.0, 3.0, 1.5, (0.0, 0.0), 1.0, 0.1)])
    assert result.points[0, :2].tolist() == pytest.approx([12.5 + 0.15 * 1.7, 1.7 - 0.15 * 2.5], abs=1e-5)
    result = stage.process(late, [MotionHint((10.0, 0.0), 0.0, 3.0, 1.5, (0.0, 0.0), 1.0)])
    assert result.points[0, :2].tolist() == pytest.approx([12.5, 1.7], abs=1e-5)


def test_a_disabled_sensor_is_left_out_and_said_so_not_missed():
    """``enabled: false`` (a sensor whose calibration was refused): its sweep is not merged, the
    frame says why, and its absence is no fault either."""
    sensors = SENSORS + [SensorConfig(name="c", enabled=False, extrinsics=Extrinsics(x_m=50.0))]
    stage = Concatenation(ConcatenationParams(voxel_size_m=0), sensors)
    scans = {"a": scan("a", 1.0, [[3, 0, 0]]), "b": scan("b", 1.0, [[0, 2, 0]])}
    result = stage.process({**scans, "c": scan("c", 1.0, [[1, 1, 1]])})
    assert result.faults == {"c": "disabled"}
    assert sorted(np.round(result.points, 4).tolist()) == [[0.0, 2.0, 4.0], [10.0, 3.0, 4.0]]
    assert stage.process(scans).faults == {}
