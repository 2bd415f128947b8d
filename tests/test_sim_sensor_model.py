"""Beam tables of the OS1 models, Ouster sensor metadata, and the real frame's table."""

import numpy as np
import pytest
from conftest import REALDATA

from i2v_loc.params import SensorConfig
from i2v_loc.sim.lidar import LidarModel
from i2v_loc.sim.sensor_model import (
    OS1_CHANNEL_PITCH_DEG,
    SensorModelError,
    metadata_beam_table,
    model_beam_table,
    os1_channels,
)

TUMTRAF = REALDATA / "tumtraf_s110_south" / "1646667315_454719936_s110_lidar_ouster_south"


def test_uniform_tables_take_every_nth_channel_of_the_fan():
    t32 = model_beam_table("OS1-32", 1024, "uniform")
    t128 = model_beam_table("OS1-128", 2048)
    assert t32.beams == 32 and t128.beams == 128 and t128.columns == 2048
    np.testing.assert_allclose(np.diff(t32.altitude_deg), -4 * OS1_CHANNEL_PITCH_DEG, atol=1e-5)
    np.testing.assert_allclose(t32.altitude_deg, t128.altitude_deg[::4])
    # four detector columns: offsets repeat every 4 channels, so every 4th channel shares one
    assert len(np.unique(t32.azimuth_offset_deg)) == 1 and len(np.unique(t128.azimuth_offset_deg)) == 4


def test_below_and_above_horizon_split_the_fan():
    below = model_beam_table("OS1-64", 1024, "below_horizon").altitude_deg
    above = model_beam_table("OS1-64", 1024, "above_horizon").altitude_deg
    assert above[0] > 21.0 and below[-1] < -21.0 and below.max() < 0
    assert above[-1] - below[0] == pytest.approx(OS1_CHANNEL_PITCH_DEG, abs=1e-5)
    np.testing.assert_allclose(np.diff(below), -OS1_CHANNEL_PITCH_DEG, atol=1e-5)


def test_gradient_is_densest_near_the_horizon():
    alt = model_beam_table("OS1-32", 1024, "gradient").altitude_deg
    pitch = -np.diff(alt)
    assert len(np.unique(os1_channels(32, "gradient"))) == 32
    near_horizon = np.argmin(np.abs(alt[:-1] + alt[1:]))
    assert pitch[near_horizon] < pitch[0] / 2 and pitch[near_horizon] < pitch[-1] / 2


def test_unknown_configuration_and_columns_are_refused():
    with pytest.raises(SensorModelError, match="beam configuration"):
        model_beam_table("OS1-32", 1024, "fan")
    with pytest.raises(SensorModelError, match="columns"):
        model_beam_table("OS1-32", 1000)


def _write_metadata(tmp_path, altitudes, azimuths, mode="1024x10"):
    from ouster.sdk import core

    info = core.SensorInfo.from_default(core.LidarMode(mode))
    info.beam_altitude_angles = list(altitudes)
    info.beam_azimuth_angles = list(azimuths)
    path = tmp_path / "os1.json"
    path.write_text(info.to_json_string())
    return path


def test_metadata_beam_table_is_read_through_ouster_sdk(tmp_path):
    altitudes = np.linspace(10.0, -20.0, 64)
    azimuths = np.tile([3.1, 1.0, -1.0, -3.1], 16)
    table = metadata_beam_table(_write_metadata(tmp_path, altitudes, azimuths, "2048x10"))
    assert table.columns == 2048 and table.beams == 64
    np.testing.assert_allclose(table.altitude_deg, altitudes, atol=1e-5)
    np.testing.assert_allclose(table.azimuth_offset_deg, -azimuths, atol=1e-5)  # Ouster's sign is the opposite


def test_a_sensor_entry_naming_metadata_uses_its_table(tmp_path):
    altitudes = np.linspace(5.0, -25.0, 64)
    path = _write_metadata(tmp_path, altitudes, np.zeros(64))
    cfg = SensorConfig(name="l1", model="OS1-64", columns=1024, metadata=str(path))
    np.testing.assert_allclose(LidarModel.from_config(cfg).beam_altitude_deg, altitudes, atol=1e-5)
    with pytest.raises(SensorModelError, match="64 beams x 1024 columns"):
        LidarModel.from_config(SensorConfig(name="l1", model="OS1-32", columns=1024, metadata=str(path)))
    (tmp_path / "bad.json").write_text("{}")
    with pytest.raises(SensorModelError, match="not an Ouster sensor metadata"):
        metadata_beam_table(tmp_path / "bad.json")


@pytest.mark.skipif(not TUMTRAF.with_suffix(".pcd").is_file(), reason="shared/realdata/tumtraf_s110_south not present")
def test_real_ouster_frame_is_the_below_horizon_table_of_the_model():
    from i2v_loc.sim.realism import read_real_frame, real_beam_table

    measured, _ = real_beam_table(read_real_frame(TUMTRAF.with_suffix(".pcd")))
    model = model_beam_table("OS1-64", 2048, "below_horizon")
    assert measured.columns == 2048
    # same span; the real fan is not quite linear (0.35 deg pitch on top, 0.32 below): within 0.45 deg
    assert measured.altitude_deg[0] == pytest.approx(model.altitude_deg[0], abs=0.05)
    assert measured.altitude_deg[-1] == pytest.approx(model.altitude_deg[-1], abs=0.05)
    np.testing.assert_allclose(measured.altitude_deg, model.altitude_deg, atol=0.45)
    # the real azimuth offsets carry the sensor's frame phase (about 180 deg): compare their pattern
    turned = measured.azimuth_offset_deg % 360 - 180  # the frame's phase: 180 deg
    pattern = turned - turned.mean()
    np.testing.assert_allclose(pattern, model.azimuth_offset_deg, atol=0.3)
