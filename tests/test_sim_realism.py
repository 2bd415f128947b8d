"""``i2v-loc realism`` on the real TUMTraf frames: the simulated sensor against real point counts."""

import json

import pytest
from conftest import REALDATA

from i2v_loc.cli import main

FRAMES = ["1646667315_454719936", "1646667310_053239541"]
FOLDER = REALDATA / "tumtraf_s110_south"


@pytest.mark.skipif(not FOLDER.is_dir(), reason="shared/realdata/tumtraf_s110_south not present")
@pytest.mark.parametrize("frame", FRAMES)
def test_simulated_point_counts_match_the_real_frame(frame, tmp_path, capsys):
    stem = FOLDER / f"{frame}_s110_lidar_ouster_south"
    out = tmp_path / "realism.json"
    assert main(["realism", str(stem.with_suffix(".pcd")), str(stem.with_suffix(".json")), "--json", str(out)]) == 0
    report = json.loads(out.read_text())
    labels = json.loads(stem.with_suffix(".json").read_text())["openlabel"]["frames"]
    n_cuboids = sum("cuboid" in o["object_data"] for f in labels.values() for o in f["objects"].values())
    assert len(report["objects"]) == n_cuboids >= 15
    assert {"type", "range_m", "real_points", "sim_points"} <= set(report["objects"][0])
    assert 0.75 <= report["median_ratio"] <= 1.33
    assert report["share_within_half_to_double"] >= 0.7
    assert len(report["beam_altitude_deg"]) == 64 and report["columns"] == 2048
    assert "median sim/real" in capsys.readouterr().out


def test_a_cloud_without_rings_is_refused_with_one_line(tmp_path, capsys):
    cloud = tmp_path / "plain.pcd"
    cloud.write_text(
        "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 1\nHEIGHT 1\n"
        "VIEWPOINT 0 0 0 1 0 0 0\nPOINTS 1\nDATA ascii\n1 2 3\n"
    )
    assert main(["realism", str(cloud), str(tmp_path / "labels.json")]) == 2
    assert "needs fields x y z ring" in capsys.readouterr().err
