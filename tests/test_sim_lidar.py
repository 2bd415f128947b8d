"""Ray-cast LiDAR model: ranges against known geometry, sweep timing."""

import numpy as np
import pytest

from i2v_loc.geometry import pose_matrix
from i2v_loc.sim import meshes as m
from i2v_loc.sim.lidar import LidarModel, MovingObject, YardCaster


def _lidar(noise=0.0, dropout=0.0, columns=1024) -> LidarModel:
    return LidarModel(name="s", model="OS1-32", beams=32, columns=columns, rate_hz=10, pose=np.eye(4),
                      range_noise_m=noise, dropout_rate=dropout)


def _wall_at_10m() -> m.Mesh:
    # Face at x = 10 m, wide and tall enough to catch every beam of the column looking along +x.
    return m.box_between(10.0, 11.0, -20.0, 20.0, -20.0, 20.0)


def test_ray_hits_box_face_at_known_range_without_noise():
    caster = YardCaster(_wall_at_10m(), [])
    lidar = _lidar()
    ranges, hit = caster.measure(lidar, 0.0, np.random.default_rng(0))
    # Column 0 looks along +x: every beam sees the face at range 10 / cos(altitude).
    alt = np.radians(lidar.beam_altitude_deg)
    np.testing.assert_allclose(ranges[:, 0], 10.0 / np.cos(alt), atol=1e-4)
    assert np.all(hit[:, 0] == -1)
    assert np.all(np.isnan(ranges[:, 512]))  # column 512 looks along -x: nothing there
    # A horizontal beam (33 beams put one at 0 degrees) measures exactly 10.000 m.
    level = LidarModel(name="s", model="test", beams=33, columns=1024, rate_hz=10, pose=np.eye(4), range_noise_m=0.0, dropout_rate=0.0)
    ranges, _ = caster.measure(level, 0.0, np.random.default_rng(0))
    assert level.beam_altitude_deg[16] == 0.0
    assert ranges[16, 0] == pytest.approx(10.0, abs=1e-5)


def test_ray_range_noise_has_the_configured_spread():
    caster = YardCaster(_wall_at_10m(), [])
    lidar = _lidar(noise=0.03)
    ranges, _ = caster.measure(lidar, 0.0, np.random.default_rng(1))
    alt = np.radians(lidar.beam_altitude_deg)[:, None]
    az = np.radians(np.arange(1, 40) * 360 / 1024)[None, :]  # columns 1..39 (clockwise: azimuth -az)
    truth = 10.0 / (np.cos(alt) * np.cos(az))
    err = (ranges[:, 1:40] - truth).ravel()
    assert abs(np.mean(err)) < 0.005
    assert 0.025 < np.std(err) < 0.035


def test_dropouts_remove_about_the_configured_share():
    caster = YardCaster(m.box_between(-300, 300, -300, 300, -5.0, -4.0), [])  # floor: every beam below 0 hits
    ranges, _ = caster.measure(_lidar(dropout=0.05), 0.0, np.random.default_rng(2))
    lower = ranges[20:]  # beams 8.7 to 22.5 degrees down: all hit the floor within 30 m
    assert 0.04 < np.isnan(lower).mean() < 0.06


def test_moving_object_is_seen_where_it_is_during_each_slice():
    # A tall box moves along +y at 50 m/s, 10 m ahead: from azimuth -26.6 deg at the sweep start to
    # -1.8 deg at the end. Column c looks at azimuth -c * 360/1024 (clockwise), so slice 0 sees it
    # at its 6.25 ms position, and the last slice (mid time 93.75 ms) sees its left edge at
    # columns 1021-1023 (azimuth +0.35 ... +1.05 deg), where it could never be at the sweep start.
    box = m.box((0, 0, 0), (1.0, 1.0, 30.0))

    def pose_at(t):
        return np.stack([pose_matrix(10.0, -5.0 + 50.0 * ti, 0, 0, 0, 0) for ti in np.atleast_1d(t)])

    caster = YardCaster(m.box_between(200, 201, -1, 1, -1, 1), [MovingObject(7, box, pose_at)], slices=8)
    _, hit = caster.cast_sweep(_lidar(), sweep_start_s=0.0)
    cols = np.nonzero(hit[16] == 7)[0]
    first = cols[cols < 128]
    az_first = -first * 360 / 1024
    centre_at_slice0 = np.degrees(np.arctan2(-5.0 + 50.0 * 0.00625, 10.0))
    assert abs(np.mean(az_first) - centre_at_slice0) < 1.5
    assert {1021, 1022, 1023} <= set(cols.tolist())
    assert not np.any((cols >= 128) & (cols < 896))


def test_column_timestamps_span_one_sweep():
    lidar = _lidar()
    t = lidar.column_time_ns
    assert t[0] == 0 and np.all(np.diff(t) > 0)
    assert t[-1] == pytest.approx(100e6 * 1023 / 1024, abs=1)
    assert _lidar(columns=2048).column_time_ns[-1] < 100_000_000


def test_beam_altitudes_are_uniform_over_45_degrees():
    alt = _lidar().beam_altitude_deg
    assert alt[0] == pytest.approx(22.5) and alt[-1] == pytest.approx(-22.5)
    np.testing.assert_allclose(np.diff(alt), -45.0 / 31, atol=1e-5)
