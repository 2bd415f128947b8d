"""Recording writer and reader: round trip and the point convention of docs/formats.md."""

import numpy as np
import pytest

from i2v_loc.recording import Recording, RecordingError, SensorScans, meters_to_range_mm, write_recording

BEAMS, COLUMNS, FRAMES = 4, 8, 3


def _scans(seed: int) -> SensorScans:
    rng = np.random.default_rng(seed)
    ranges = rng.integers(500, 60000, size=(FRAMES, BEAMS, COLUMNS)).astype(np.uint16)
    ranges[rng.random(ranges.shape) < 0.2] = 0
    return SensorScans(
        range_mm=ranges,
        stamp_ns=np.array([12_000_000, 112_000_000, 212_000_000]) + seed,
        column_time_ns=np.arange(COLUMNS) * 100_000_000 // COLUMNS,
        beam_altitude_deg=np.linspace(10, -10, BEAMS),
        beam_azimuth_offset_deg=np.zeros(BEAMS),
    )


def _write(tmp_path):
    scans = {"l1": _scans(1), "l2": _scans(2)}
    gt = [{"frame": k, "stamp_s": k / 10, "vehicles": [], "distractors": []} for k in range(FRAMES)]
    meta = {"generator": "test", "seed": 0, "rate_hz": 10, "sensors": [{"name": "l1"}, {"name": "l2"}]}
    write_recording(tmp_path / "rec", meta, scans, gt, "sensors: []\n", "sensors: []\n", openlabel={"openlabel": {}})
    return scans, gt


def test_round_trip_points_stamps_and_ground_truth(tmp_path):
    scans, gt = _write(tmp_path)
    rec = Recording(tmp_path / "rec")
    assert len(rec) == FRAMES and rec.sensor_names == ["l1", "l2"] and rec.rate_hz == 10
    assert rec.ground_truth() == gt
    assert rec.sensors_file.is_file() and rec.sensors_guess_file.is_file()
    for name, original in scans.items():
        read = rec.scans(name)
        np.testing.assert_array_equal(read.range_mm, original.range_mm)
        np.testing.assert_array_equal(read.stamp_ns, original.stamp_ns)
    frame = rec.frame(1)
    scan = frame.scans["l2"]
    assert scan.stamp_s == pytest.approx(0.112000002)
    # Every non-zero range gives one point at that range (mm precision).
    nonzero = scans["l2"].range_mm[1][scans["l2"].range_mm[1] > 0]
    assert len(scan.points) == len(nonzero)
    np.testing.assert_allclose(np.sort(np.linalg.norm(scan.points, axis=1)), np.sort(nonzero / 1000.0), atol=1e-3)
    assert len(list(rec.frames(sensors=["l1"]))) == FRAMES


def test_point_convention_column_zero_looks_along_x_and_sweeps_clockwise(tmp_path):
    ranges = np.zeros((1, 1, 4), dtype=np.uint16)
    ranges[0, 0, :] = 10_000
    scans = SensorScans(ranges, [0], [0, 25_000_000, 50_000_000, 75_000_000], [0.0], [0.0])
    pts, offsets = scans.points(0)
    # columns at azimuth 360, 270, 180, 90 degrees: clockwise seen from above.
    np.testing.assert_allclose(pts, [[10, 0, 0], [0, -10, 0], [-10, 0, 0], [0, 10, 0]], atol=1e-4)
    np.testing.assert_allclose(offsets, [0.0, 0.025, 0.05, 0.075])


def test_meters_to_range_mm_marks_invalid_as_no_return():
    np.testing.assert_array_equal(meters_to_range_mm(np.array([10.0, np.nan, -1.0, 70.0, 0.0005])), [10000, 0, 0, 0, 0])


def test_inconsistent_inputs_are_refused(tmp_path):
    with pytest.raises(RecordingError, match="ground-truth lines"):
        write_recording(tmp_path / "bad", {"sensors": [{"name": "l1"}]}, {"l1": _scans(1)}, [], "", "")
    with pytest.raises(RecordingError, match="meta.yaml missing"):
        Recording(tmp_path)
    with pytest.raises(RecordingError, match="beam_altitude_deg"):
        SensorScans(np.zeros((1, 2, 4)), [0], np.zeros(4), [0.0], [0.0, 0.0])
