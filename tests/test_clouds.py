"""Single cloud files: a file cut short is refused, never padded with made-up points."""

from __future__ import annotations

import numpy as np
import pytest

from i2v_loc.clouds import CloudError, read_cloud


def _write_pcd(path, points, ascii_data: bool):
    import open3d as o3d

    cloud = o3d.geometry.PointCloud()
    cloud.points = o3d.utility.Vector3dVector(points)
    assert o3d.io.write_point_cloud(str(path), cloud, write_ascii=ascii_data)
    return path


@pytest.mark.parametrize("ascii_data", [True, False])
def test_whole_pcd_reads_back_its_points(tmp_path, ascii_data):
    points = np.random.default_rng(1).uniform(1, 9, (5000, 3))
    read = read_cloud(_write_pcd(tmp_path / "c.pcd", points, ascii_data))
    np.testing.assert_allclose(read, points, atol=1e-5)


@pytest.mark.parametrize("ascii_data", [True, False])
def test_pcd_cut_in_half_is_refused(tmp_path, ascii_data):
    points = np.random.default_rng(2).uniform(1, 9, (5000, 3))
    path = _write_pcd(tmp_path / "c.pcd", points, ascii_data)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(CloudError, match=r"holds \d+ of the 5000 points its header declares"):
        read_cloud(path)
