"""Shared test fixtures: paths to the repository, samples and the shared real data."""

from __future__ import annotations

from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SAMPLES = REPO / "samples"
REALDATA = REPO.parent / "shared" / "realdata"


@pytest.fixture
def realdata() -> Path:
    if not REALDATA.is_dir():
        pytest.skip(f"real LiDAR recordings not found at {REALDATA} (see the project README)")
    return REALDATA


# metrics.json keys every evaluated vehicle carries (the paper's tables and dCAP)
REQUIRED = (
    "truck_pos_rmse_m",
    "trailer_pos_rmse_m",
    "truck_yaw_rmse_deg",
    "trailer_yaw_rmse_deg",
    "hitch_rmse_deg",
    "heading_flip_rate",
    "delta_T_m",
    "rra_rad",
    "latency_ms_p50",
    "truck_length_error_m",
    "trailer_length_error_m",
)
