"""Recordings in any supported layout behind the interface of ``i2v_loc.recording.Recording``.

``open_recording(path)`` recognises the layout by itself (docs/formats.md):

- the project's recording folder (``meta.yaml`` + ``scans/*.npz``)
- Ouster pcap + metadata JSON per sensor (``ouster-sdk``)
- ROS 2 bags, sqlite3 or MCAP, and ROS 1 bags, with ``sensor_msgs/PointCloud2`` (``rosbags``)
- folders of point-cloud files: PCD, PLY, NPY, KITTI / nuScenes BIN (``pypcd4``, open3d, numpy)
"""

from __future__ import annotations

from pathlib import Path

from i2v_loc.formats.base import FormatError, PointRecording
from i2v_loc.recording import Recording, RecordingError

LAYOUTS = ("recording", "ouster-pcap", "rosbag2", "rosbag1", "pcd", "ply", "npy", "kitti-bin", "nuscenes-bin")
WRITE_FORMATS = ("native", "pcap", "rosbag2", "mcap", "pcd")

__all__ = [
    "FormatError",
    "PointRecording",
    "open_recording",
    "looks_like_recording",
    "convert_recording",
    "LAYOUTS",
    "WRITE_FORMATS",
]


def open_recording(path: str | Path, bin_layout: str | None = None, topics: dict[str, str] | None = None):
    """The recording at ``path`` in whatever layout it is; RecordingError (one line) if none fits.

    ``bin_layout``: ``kitti`` (x y z intensity) or ``nuscenes`` (x y z intensity ring) for ``.bin``
    files whose content fits both. ``topics``: sensor name → PointCloud2 topic of a bag."""
    path = Path(str(path).removeprefix("replay:"))
    if not path.exists():
        raise RecordingError(f"{path}: no such recording directory or file")
    if path.is_dir() and (path / "meta.yaml").is_file():
        return Recording(path)
    from i2v_loc.formats import rosbag

    if rosbag.is_bag(path):
        return rosbag.BagRecording(path, topics=topics)
    from i2v_loc.formats import ouster

    pairs = ouster.ouster_pairs(path)
    if pairs:
        return ouster.OusterRecording(path, pairs)
    from i2v_loc.formats import files

    recording = files.open_cloud_folder(path, bin_layout=bin_layout)
    if recording is not None:
        return recording
    raise RecordingError(
        f"{path}: not a recording in any known layout (a recording folder with meta.yaml, Ouster <sensor>.pcap + .json, "
        f"a ROS bag, or a folder of .pcd/.ply/.npy/.bin clouds; see `i2v-loc sources --help`)"
    )


def looks_like_recording(path: str | Path) -> bool:
    """Cheap check (names only, nothing decoded): could ``open_recording`` read ``path``?"""
    from i2v_loc.formats.files import SUFFIXES

    path = Path(path)
    if path.is_file():
        return path.suffix.lower() in (*SUFFIXES, ".pcap", ".bag", ".mcap", ".db3")
    if not path.is_dir():
        return False
    if (path / "meta.yaml").is_file() or (path / "metadata.yaml").is_file() or any(path.glob("*.pcap")):
        return True

    def has_clouds(folder: Path) -> bool:
        return any(p.suffix.lower() in SUFFIXES for p in folder.iterdir() if p.is_file())

    return has_clouds(path) or any(
        has_clouds(d) for d in path.iterdir() if d.is_dir() and not (d / "meta.yaml").is_file()
    )


def convert_recording(recording, out: str | Path, fmt: str) -> Path:
    """Write a native ``Recording`` in another layout (``pcap``, ``rosbag2``, ``mcap``, ``pcd``)."""
    out = Path(out)
    if fmt == "pcap":
        from i2v_loc.formats.ouster import write_ouster

        return write_ouster(recording, out)
    if fmt in ("rosbag2", "mcap"):
        from i2v_loc.formats.rosbag import write_bag

        return write_bag(recording, out, storage="mcap" if fmt == "mcap" else "sqlite3")
    if fmt == "pcd":
        from i2v_loc.formats.files import write_pcd_folder

        return write_pcd_folder(recording, out)
    raise RecordingError(f"unknown output format {fmt!r}; known: {', '.join(WRITE_FORMATS)}")
