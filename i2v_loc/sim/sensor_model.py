"""What a simulated Ouster OS1 sees: its beam table and when a ray returns.

Beam tables. Every OS1 (Rev 6/7) has 128 detector channels; the 32- and 64-beam models read a
subset of them, chosen by the beam configuration Ouster sells: ``uniform`` (every 2nd or 4th
channel), ``below_horizon`` / ``above_horizon`` (the lower or upper consecutive channels) and
``gradient`` (denser near the horizon). The 128-channel fan spans +21.0° to -21.5° at 0.335°
pitch and the channels sit in four columns of the detector, 4.2° / 1.4° apart in azimuth: both
measured on the TUMTraf S110 south Ouster (``shared/realdata``), whose 64 rings are the
``below_horizon`` subset (-0.43° to -21.54°, azimuth offsets -4.4/-1.6/+1.2/+4.0°). A sensor
metadata JSON (what ``ouster-cli`` records and ouster-sdk reads) overrides the model's table.

Returns. The received signal of a Lambertian surface is proportional to reflectivity x cos(incidence)
/ range²; the sensor detects a return with a probability that rises smoothly with that signal
(logistic in its logarithm), reaching 90 % at the datasheet range (120 m at 80 %, 40 m at 10 %
reflectivity: the same signal, ``DETECTION_SIGNAL_90``). Range noise follows the datasheet's
repeatability against SNR (±1.5 cm at SNR 250, ±3 cm at 100, ±10 cm at 12), i.e. about
0.35 m / sqrt(SNR) with SNR = 12 at the 90 % signal: it grows with range, incidence and darkness.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

OS1_CHANNELS = 128
OS1_TOP_ALTITUDE_DEG = 21.03
OS1_CHANNEL_PITCH_DEG = 0.335
OS1_AZIMUTH_PATTERN_DEG = (-4.2, -1.4, 1.4, 4.2)  # our convention: added to the column's azimuth
OS1_MIN_RANGE_M = 0.5
BEAM_CONFIGS = ("uniform", "gradient", "below_horizon", "above_horizon")
COLUMNS = (512, 1024, 2048)


class SensorModelError(ValueError):
    """A beam table or sensor metadata file cannot be used (the message says why)."""


@dataclass(frozen=True)
class BeamTable:
    """Per-beam altitude and azimuth offset in degrees (beam 0 on top), columns per sweep.

    Azimuth of beam b in column c: 360 * (1 - c / columns) + azimuth_offset_deg[b] (the recording's
    convention; Ouster's metadata ``beam_azimuth_angles`` have the opposite sign)."""

    altitude_deg: np.ndarray
    azimuth_offset_deg: np.ndarray
    columns: int
    source: str

    @property
    def beams(self) -> int:
        return len(self.altitude_deg)


def os1_channel_altitudes_deg() -> np.ndarray:
    return OS1_TOP_ALTITUDE_DEG - OS1_CHANNEL_PITCH_DEG * np.arange(OS1_CHANNELS)


def os1_channels(beams: int, config: str) -> np.ndarray:
    """Indices of the 128 detector channels a ``beams``-beam OS1 reads in a beam configuration."""
    if config not in BEAM_CONFIGS:
        raise SensorModelError(f"unknown beam configuration {config!r}; known: {', '.join(BEAM_CONFIGS)}")
    if beams not in (32, 64, 128):
        raise SensorModelError(f"an OS1 has 32, 64 or 128 beams, not {beams}")
    if beams == OS1_CHANNELS or config == "uniform":
        return np.arange(0, OS1_CHANNELS, OS1_CHANNELS // beams)
    if config == "below_horizon":
        return np.arange(OS1_CHANNELS - beams, OS1_CHANNELS)
    if config == "above_horizon":
        return np.arange(beams)
    # gradient: channel pitch grows away from the horizon (|u|^1.7 spacing of a symmetric fan)
    u = np.linspace(-1.0, 1.0, beams)
    horizon = OS1_TOP_ALTITUDE_DEG / OS1_CHANNEL_PITCH_DEG
    spread = min(horizon, OS1_CHANNELS - 1 - horizon)
    index = np.rint(horizon + spread * np.sign(u) * np.abs(u) ** 1.7).astype(int)
    return _spread_unique(index)


def _spread_unique(index: np.ndarray) -> np.ndarray:
    """Sorted indices made strictly increasing (pushing duplicates near the horizon apart)."""
    steps = np.arange(len(index))
    # out[i] = max(index[i], out[i-1] + 1)  <=>  out - i is the running maximum of index - i
    out = np.maximum.accumulate(np.sort(index) - steps) + steps
    return np.clip(out, 0, OS1_CHANNELS - 1)


def model_beam_table(model: str, columns: int, config: str = "uniform") -> BeamTable:
    """The beam table of an OS1 model (``OS1-32``/``-64``/``-128``) from the model's data."""
    if columns not in COLUMNS:
        raise SensorModelError(f"columns must be one of {COLUMNS}, not {columns}")
    beams = int(model.split("-")[1])
    channels = os1_channels(beams, config)
    return BeamTable(
        altitude_deg=os1_channel_altitudes_deg()[channels].astype(np.float32),
        azimuth_offset_deg=np.asarray(OS1_AZIMUTH_PATTERN_DEG, np.float32)[channels % 4],
        columns=columns,
        source=f"{model} {config} model table",
    )


def metadata_beam_table(path: str | Path) -> BeamTable:
    """The beam table of an Ouster sensor-metadata JSON, parsed by ouster-sdk (any format it reads)."""
    from ouster.sdk.core import SensorInfo  # heavy: only when a sensor names a metadata file

    path = Path(path)
    try:
        info = SensorInfo(path.read_text())
    except FileNotFoundError:
        raise SensorModelError(f"{path}: sensor metadata file not found") from None
    except (RuntimeError, ValueError, json.JSONDecodeError) as err:
        raise SensorModelError(f"{path}: not an Ouster sensor metadata file ({err})") from None
    altitude = np.asarray(info.beam_altitude_angles, np.float32)
    azimuth = np.asarray(info.beam_azimuth_angles, np.float32)
    if len(altitude) == 0 or len(altitude) != len(azimuth):
        raise SensorModelError(f"{path}: {len(altitude)} beam altitudes and {len(azimuth)} azimuths")
    return BeamTable(altitude, -azimuth, int(info.format.columns_per_frame), f"metadata {path.name}")


@dataclass(frozen=True)
class ReturnModel:
    """When a ray returns and how noisy its range is (see the module docstring for the sources)."""

    detection_signal_90: float = 0.10 / 40.0**2  # reflectivity x cos / range² detected 90 % of the time
    transition_width: float = 0.3  # width of the logistic in ln(signal)
    max_return_probability: float = 0.995
    snr_at_detection_90: float = 12.0
    noise_at_unit_snr_m: float = 0.35
    min_noise_m: float = 0.012
    min_range_m: float = OS1_MIN_RANGE_M

    def signal(self, range_m: np.ndarray, reflectivity: np.ndarray, cos_incidence: np.ndarray) -> np.ndarray:
        r = np.maximum(np.asarray(range_m, np.float64), 1e-3)
        return np.asarray(reflectivity) * np.clip(cos_incidence, 0.0, 1.0) / r**2

    def return_probability(self, signal: np.ndarray) -> np.ndarray:
        ln_ratio = np.log(np.maximum(signal, 1e-30) / self.detection_signal_90)
        z = ln_ratio / self.transition_width + np.log(9.0)  # 90 % at the reference signal
        return self.max_return_probability / (1.0 + np.exp(-z))

    def noise_sigma_m(self, signal: np.ndarray) -> np.ndarray:
        snr = self.snr_at_detection_90 * np.maximum(signal, 1e-30) / self.detection_signal_90
        return np.maximum(self.min_noise_m, self.noise_at_unit_snr_m / np.sqrt(snr))

    def measure(
        self,
        range_m: np.ndarray,
        reflectivity: np.ndarray,
        cos_incidence: np.ndarray,
        rng: np.random.Generator,
        max_range_m: float,
    ) -> np.ndarray:
        """Measured ranges (NaN where no return) for true ranges (inf where the ray hit nothing)."""
        finite = np.isfinite(range_m)
        r = np.where(finite, range_m, 1.0)
        s = self.signal(r, reflectivity, cos_incidence)
        returned = finite & (rng.random(r.shape) < self.return_probability(s))
        noisy = r + rng.normal(0.0, 1.0, r.shape) * self.noise_sigma_m(s)
        valid = returned & (noisy >= self.min_range_m) & (noisy <= max_range_m)
        return np.where(valid, noisy, np.nan)

    def meta(self) -> dict:
        return {k: float(v) for k, v in asdict(self).items()}


# Diffuse reflectivity at 850 nm of each surface a mesh part can have.
REFLECTIVITY = {
    "white_paint": 0.75,
    "silver_paint": 0.45,
    "red_paint": 0.45,
    "blue_paint": 0.20,
    "dark_paint": 0.05,
    "paint": 0.35,  # unknown colour
    "glass": 0.02,  # specular: almost nothing scatters back
    "tarpaulin": 0.25,
    "trailer_panel": 0.55,
    "tyre": 0.03,
    "steel": 0.25,
    "container": 0.30,
    "asphalt": 0.12,
    "concrete": 0.35,
    "rubber": 0.04,
    "clothing": 0.30,
    "pole": 0.40,
}
