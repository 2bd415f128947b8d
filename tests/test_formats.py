"""Recording layouts behind one interface (issue 12): a simulated recording written as Ouster
pcap, ROS 2 bags (sqlite3, MCAP) and a PCD folder gives the same points and the same states as the
native recording; OpenLABEL output reads back equal; bad files fail with one line, exit code 2."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml

from i2v_loc.cli import main
from i2v_loc.formats import convert_recording, open_recording
from i2v_loc.geometry import wrap_deg
from i2v_loc.recording import Recording, SensorScans, write_recording

SAMPLE = Path(__file__).resolve().parents[1] / "samples" / "man_tgx_docking"
FIRST, COUNT = 20, 30  # 3 s of the sample: the truck reversing towards the dock
# The layouts are compared on the states of the paper's pipeline: it tracks the MAN from the first
# frames. The default pipeline reports nothing before its background map is learned (5 s by default;
# 0.5 s with WARM_UP) and is checked on its own below.
METHOD = "paper"
WARM_UP = {"window_frames": 10, "learn_every_frames": 1, "min_samples": 5}


@pytest.fixture(scope="module")
def native(tmp_path_factory) -> Path:
    """Frames 20..49 of the committed docking sample as a recording of its own."""
    src = Recording(SAMPLE)
    scans = {}
    for name in src.sensor_names:
        s = src.scans(name)
        cut = slice(FIRST, FIRST + COUNT)
        scans[name] = SensorScans(
            s.range_mm[cut], s.stamp_ns[cut], s.column_time_ns, s.beam_altitude_deg, s.beam_azimuth_offset_deg
        )
    meta = {k: v for k, v in src.meta.items() if k not in ("n_frames", "format_version")}
    gt = src.ground_truth()[FIRST : FIRST + COUNT]
    out = tmp_path_factory.mktemp("native") / "rec"
    return write_recording(out, meta, scans, gt, src.sensors_file.read_text(), src.sensors_guess_file.read_text())


def run_states(rec: Path, out: Path, *extra: str, method: str = METHOD) -> list[dict]:
    assert main(["run", str(rec), "--out", str(out), "--quiet", "--method", method, *extra]) == 0
    return [json.loads(line) for line in out.read_text().splitlines()]


@pytest.fixture(scope="module")
def native_states(native, tmp_path_factory) -> list[dict]:
    states = run_states(native, tmp_path_factory.mktemp("states") / "native.jsonl")
    both = sum(any(v["truck"] and v["trailer"] for v in s["vehicles"]) for s in states)
    assert both >= COUNT // 2, "the reference run must track the truck and trailer, or the comparison says nothing"
    return states


@pytest.fixture(scope="module")
def default_states(native, tmp_path_factory) -> list[dict]:
    """The default (articulated) pipeline on the native recording, its background learned in 0.5 s."""
    folder = tmp_path_factory.mktemp("default")
    params = folder / "warm_up.yaml"
    params.write_text(yaml.safe_dump({"background": WARM_UP}))
    return run_states(native, folder / "states.jsonl", "--params", str(params), method="default")


def test_default_tracks_the_truck_and_trailer_in_most_frames(default_states):
    both = sum(any(v["truck"] and v["trailer"] for v in s["vehicles"]) for s in default_states)
    assert both >= COUNT // 2


def assert_same_states(got: list[dict], expected: list[dict]) -> None:
    """Same vehicles in every frame: centres within 1 cm, yaws and hitch within 0.05 deg."""
    assert len(got) == len(expected)
    for g, e in zip(got, expected):
        assert g["frame"] == e["frame"]
        assert (g["stamp_s"] is None) == (e["stamp_s"] is None)
        if e["stamp_s"] is not None:
            assert abs(g["stamp_s"] - e["stamp_s"]) < 1e-6
        assert len(g["vehicles"]) == len(e["vehicles"]), f"frame {e['frame']}"
        for gv, ev in zip(g["vehicles"], e["vehicles"]):
            for unit in ("truck", "trailer"):
                assert (gv[unit] is None) == (ev[unit] is None)
                if ev[unit] is None:
                    continue
                assert np.linalg.norm(np.subtract(gv[unit]["center"], ev[unit]["center"])) <= 0.01
                assert abs(wrap_deg(gv[unit]["yaw_deg"] - ev[unit]["yaw_deg"])) <= 0.05
            if ev["hitch_deg"] is not None:
                assert abs(wrap_deg(gv["hitch_deg"] - ev["hitch_deg"])) <= 0.05


def assert_same_points(rec_a, rec_b, frames=(0, 13, COUNT - 1)) -> None:
    for k in frames:
        a, b = rec_a.frame(k), rec_b.frame(k)
        assert sorted(a.scans) == sorted(b.scans)
        for name, scan in a.scans.items():
            other = b.scans[name]
            assert other.points.shape == scan.points.shape
            assert np.abs(other.points - scan.points).max() <= 0.01
            assert np.abs(other.time_offset_s - scan.time_offset_s).max() <= 1e-6
            assert abs(other.stamp_s - scan.stamp_s) <= 1e-6


@pytest.mark.parametrize(
    "fmt, layout", [("pcap", "ouster-pcap"), ("rosbag2", "rosbag2"), ("mcap", "rosbag2"), ("pcd", "pcd")]
)
def test_layout_gives_the_native_points_and_states(fmt, layout, native, native_states, tmp_path):
    out = convert_recording(Recording(native), tmp_path / fmt, fmt)
    rec = open_recording(out)
    assert rec.layout == layout
    assert len(rec) == COUNT and rec.sensor_names == Recording(native).sensor_names
    assert rec.rate_hz == pytest.approx(10.0)
    assert_same_points(Recording(native), rec)
    assert_same_states(run_states(out, tmp_path / "states.jsonl"), native_states)


def test_the_rays_that_returned_nothing_are_the_zero_ranges_where_the_layout_has_them(native, tmp_path):
    """A recording's and an Ouster pcap's sweeps tell the rays that returned nothing: one per zero
    range, along its beam (the pcap's through the SDK's lookup table, within 1 mrad of the
    recording's beam tables); a PCD folder's points do not tell them."""
    rec = Recording(native)
    pcap = open_recording(convert_recording(rec, tmp_path / "pcap", "pcap"))
    pcd = open_recording(convert_recording(rec, tmp_path / "pcd", "pcd"))
    for k in (0, COUNT - 1):
        for name, scan in rec.frame(k).scans.items():
            scans = rec.scans(name)
            beam, _ = np.nonzero(scans.range_mm[k] == 0)
            lost = scan.unreturned_directions()
            elevation = np.degrees(np.arcsin(lost[:, 2]))
            assert len(beam) > 0 and np.abs(elevation - scans.beam_altitude_deg[beam]).max() < 1e-3
            told = pcap.frame(k).scans[name].unreturned_directions()
            cosine = np.clip(np.sum(told * lost, axis=1), -1.0, 1.0)
            assert told.shape == lost.shape and np.arccos(cosine).max() < 1e-3
            assert pcd.frame(k).scans[name].unreturned_directions() is None


def test_mcap_storage_is_mcap(native, tmp_path):
    out = convert_recording(Recording(native), tmp_path / "bag", "mcap")
    info = yaml.safe_load((out / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert info["storage_identifier"] == "mcap"
    assert (out / info["relative_file_paths"][0]).read_bytes()[:8] == b"\x89MCAP0\r\n"


def test_ouster_metadata_carries_the_recording_beam_tables(native, tmp_path):
    from ouster.sdk import core

    out = convert_recording(Recording(native), tmp_path / "pcap", "pcap")
    scans = Recording(native).scans("l2")
    info = core.SensorInfo((out / "l2.json").read_text())
    assert info.prod_line == "OS-1-32" and info.h == 32 and info.w == scans.range_mm.shape[2]
    np.testing.assert_allclose(info.beam_altitude_angles, scans.beam_altitude_deg, atol=1e-6)
    np.testing.assert_allclose(info.beam_azimuth_angles, -scans.beam_azimuth_offset_deg, atol=1e-6)


def test_bag_extrinsics_from_tf_static(native, tmp_path):
    out = convert_recording(Recording(native), tmp_path / "bag", "rosbag2")
    (out / "sensors.yaml").unlink()
    rec = open_recording(out)
    generated = yaml.safe_load(rec.sensors_file.read_text())["sensors"]
    truth = {s["name"]: s["extrinsics"] for s in yaml.safe_load((native / "sensors.yaml").read_text())["sensors"]}
    assert [s["name"] for s in generated] == list(truth)
    for s in generated:
        for key, value in truth[s["name"]].items():
            assert s["extrinsics"][key] == pytest.approx(value, abs=1e-6), (s["name"], key)


def test_openlabel_written_and_read_back_equal(native, native_states, tmp_path):
    from i2v_loc.evaluation.groundtruth import load_ground_truth

    out = tmp_path / "states.openlabel.json"
    assert main(["run", str(native), "--out", str(out), "--quiet", "--method", METHOD, "--format", "openlabel"]) == 0
    data = json.loads(out.read_text())["openlabel"]
    types = {o["type"] for o in data["objects"].values()}
    assert types == {"TRUCK", "TRAILER"}
    assert all(r["type"] == "isTowing" for r in data["relations"].values()) and data["relations"]
    lines = load_ground_truth(out)
    stamped = [s for s in native_states if s["stamp_s"] is not None]
    assert len(lines) == len(stamped)
    origin = stamped[0]["stamp_s"]
    for line, state in zip(lines, stamped):
        assert line["frame"] == state["frame"]
        assert line["stamp_s"] == pytest.approx(state["stamp_s"] - origin, abs=1e-9)
        vehicles = [v for v in state["vehicles"] if v["truck"] or v["trailer"]]
        assert len(line["vehicles"]) == len(vehicles)
        for got, v in zip(line["vehicles"], vehicles):
            for unit in ("truck", "trailer"):
                assert (got[unit] is None) == (v[unit] is None)
                if v[unit] is None:
                    continue
                np.testing.assert_allclose(got[unit]["center"], v[unit]["center"], atol=1e-9)
                np.testing.assert_allclose(got[unit]["dimensions"], v[unit]["dimensions"], atol=1e-9)
                assert abs(wrap_deg(got[unit]["yaw_deg"] - v[unit]["yaw_deg"])) < 1e-6
                assert got[unit]["points"] == v[unit]["points"]
            if v["hitch_deg"] is not None:  # the loader derives it from the two yaws, each rounded to 1e-3 deg
                assert got["hitch_deg"] == pytest.approx(v["hitch_deg"], abs=2e-3)


# --------------------------------------------------------------------------- bad files


def one_error_line(capsys, argv) -> str:
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err
    return err


@pytest.fixture(scope="module")
def pcap_dir(native, tmp_path_factory) -> Path:
    return convert_recording(Recording(native), tmp_path_factory.mktemp("pcap") / "pcap", "pcap")


def test_truncated_pcap_is_one_error_line(pcap_dir, tmp_path, capsys):
    bad = tmp_path / "cut"
    shutil.copytree(pcap_dir, bad)
    data = (bad / "l3.pcap").read_bytes()
    (bad / "l3.pcap").write_bytes(data[: len(data) // 2 + 7])
    err = one_error_line(capsys, ["run", str(bad), "--out", str(tmp_path / "s.jsonl"), "--quiet"])
    assert "l3.pcap" in err and "truncated" in err


def test_metadata_of_another_sensor_is_one_error_line(pcap_dir, tmp_path, capsys):
    bad = tmp_path / "swapped"
    shutil.copytree(pcap_dir, bad)
    shutil.copyfile(pcap_dir / "l1.json", bad / "l2.json")
    err = one_error_line(capsys, ["run", str(bad), "--out", str(tmp_path / "s.jsonl"), "--quiet"])
    assert "l2.pcap" in err and "another sensor" in err


def test_metadata_of_a_64_beam_sensor_is_one_error_line(pcap_dir, tmp_path, capsys):
    from ouster.sdk import core

    bad = tmp_path / "os64"
    shutil.copytree(pcap_dir, bad)
    (bad / "l4.json").write_text(core.SensorInfo.from_default(core.LidarMode._1024x10).to_json_string())
    err = one_error_line(capsys, ["run", str(bad), "--out", str(tmp_path / "s.jsonl"), "--quiet"])
    assert "l4.pcap" in err and "no lidar packet matches" in err


def test_bag_without_the_topic_is_one_error_line(native, tmp_path, capsys):
    out = convert_recording(Recording(native), tmp_path / "bag", "rosbag2")
    sensors = yaml.safe_load((out / "sensors.yaml").read_text())
    sensors["sensors"].append({**sensors["sensors"][0], "name": "l5"})
    (out / "sensors.yaml").write_text(yaml.safe_dump(sensors))
    err = one_error_line(capsys, ["run", str(out), "--out", str(tmp_path / "s.jsonl"), "--quiet"])
    assert "/l5/points" in err and "/l1/points" in err


def _cloud_rows(n: int, rng) -> np.ndarray:
    return np.column_stack([rng.uniform(-50, 50, (n, 2)), rng.uniform(-2, 3, n)]).astype(np.float32)


def test_bin_layouts_recognised_by_content(tmp_path):
    rng = np.random.default_rng(4)
    xyz = _cloud_rows(1000, rng)  # 1000 points: 16000 and 20000 bytes both divide by 4 and 5 floats
    kitti = tmp_path / "kitti" / "lidar"
    nusc = tmp_path / "nusc" / "lidar"
    kitti.mkdir(parents=True)
    nusc.mkdir(parents=True)
    np.column_stack([xyz, rng.uniform(0, 1, 1000)]).astype(np.float32).tofile(kitti / "000000.bin")
    np.column_stack([xyz, rng.uniform(0, 255, 1000), rng.integers(0, 32, 1000)]).astype(np.float32).tofile(
        nusc / "000000.bin"
    )
    for folder, layout in ((kitti.parent, "bin"), (nusc.parent, "bin")):
        rec = open_recording(folder)
        assert rec.layout == layout
        np.testing.assert_allclose(rec.frame(0).scans["lidar"].points, xyz)


def test_bin_of_unknown_layout_names_the_option(tmp_path, capsys):
    folder = tmp_path / "clouds" / "lidar"
    folder.mkdir(parents=True)
    rng = np.random.default_rng(5)
    rng.normal(0, 30, 1000 * 20).astype(np.float32).tofile(folder / "000000.bin")  # no layout fits
    err = one_error_line(capsys, ["run", str(folder.parent), "--out", str(tmp_path / "s.jsonl"), "--quiet"])
    assert "000000.bin" in err and "--bin-layout kitti|nuscenes" in err
    # with the option the same bytes are read as asked
    rec = open_recording(folder.parent, bin_layout="nuscenes")
    assert len(rec.frame(0).scans["lidar"].points) == 1000 * 20 // 5


def test_unknown_folder_is_one_error_line(tmp_path, capsys):
    (tmp_path / "notes.txt").write_text("nothing here")
    err = one_error_line(capsys, ["run", str(tmp_path), "--out", str(tmp_path / "s.jsonl"), "--quiet"])
    assert "not a recording in any known layout" in err


# --------------------------------------------------------------------------- real recordings


def test_tumtraf_pcd_folder_runs(realdata, tmp_path):
    folder = realdata / "tumtraf_s110_south"
    rec = open_recording(folder)
    assert rec.layout == "pcd" and rec.sensor_names == ["s110_lidar_ouster_south"] and len(rec) == 2
    scan = rec.frame(1).scans["s110_lidar_ouster_south"]
    assert 49000 < len(scan.points) < 51000 and np.isfinite(scan.points).all()
    assert 0.09 < scan.time_offset_s.max() < 0.101  # the Ouster 't' field: one 10 Hz sweep
    params = tmp_path / "tumtraf.yaml"
    params.write_text(yaml.safe_dump({"sensors": [{"name": "s110_lidar_ouster_south", "extrinsics": {"z_m": 8.0}}]}))
    states = run_states(folder, tmp_path / "s.jsonl", "--params", str(params))
    assert [s["frame"] for s in states] == [0, 1]
    assert all(s["stamp_s"] is not None and "s110_lidar_ouster_south" not in s["faults"] for s in states)


def test_chengdu_background_is_learned(realdata):
    from i2v_loc.params import load_params
    from i2v_loc.pipelines import build_pipeline

    rec = open_recording(realdata / "roadside80_chengdu" / "frames")
    assert len(rec) == 20 and rec.sensor_names == ["frames"]
    params = load_params(rec.sensors_file).model_dump(mode="json")
    params["sensors"][0]["extrinsics"]["z_m"] = 7.5
    params["region"].update(x_min_m=-60, x_max_m=60, y_min_m=-60, y_max_m=60)
    params["background"].update(window_frames=10, learn_every_frames=1, min_samples=8)
    from i2v_loc.params import validate_params

    pipeline = build_pipeline(validate_params(params), "default")
    foreground = [len(pipeline.process(frame).foreground) for frame in rec.frames()]
    before, after = np.mean(foreground[:7]), np.mean(foreground[10:])
    assert before > 1000, "the region must hold non-ground points before the map is ready"
    assert after < 0.2 * before, f"background not removed: {before:.0f} -> {after:.0f} foreground points"


# --------------------------------------------------------------------------- live UDP


def _send_pcaps(
    folder: Path, ports: dict[str, int], drop: dict[str, set[int]], swap_every: int, received
) -> dict[str, int]:
    """The pcaps' lidar packets to ``ports`` on loopback, sensors interleaved in capture order;
    packet i of a sensor is left out when i is in ``drop[sensor]``, and within every sweep
    each ``swap_every``-th packet is sent after its successor. At most 16 packets are in flight
    (``received()`` counts the ones the source has taken): the kernel's receive buffer is small and
    a loaded test machine must not lose packets the test did not mean to lose. Returns packets
    sent per sensor."""
    import socket
    import time

    from ouster.sdk import pcap

    from i2v_loc.formats.ouster import read_metadata

    queue = []
    for name in ports:
        info = read_metadata(folder / f"{name}.json")
        source = pcap.PcapPacketSource(str(folder / f"{name}.pcap"), sensor_info=[info])
        packets = [(p.host_timestamp, bytes(p.buf)) for _, p in source]
        source.close()
        per_sweep = info.w // info.format.columns_per_packet
        order = list(range(len(packets)))
        for i in range(swap_every - 1, len(order) - 1, swap_every) if swap_every else ():
            if i % per_sweep != per_sweep - 1:  # never across a sweep's end
                order[i], order[i + 1] = order[i + 1], order[i]
        queue += [(packets[i][0], name, packets[j][1]) for i, j in enumerate(order) if j not in drop.get(name, set())]
    queue.sort(key=lambda item: item[0])
    sent = dict.fromkeys(ports, 0)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as out:
        for n, (_, name, data) in enumerate(queue):
            out.sendto(data, ("127.0.0.1", ports[name]))
            sent[name] += 1
            deadline = time.monotonic() + 10.0
            while n + 1 - received() >= 16 and time.monotonic() < deadline:
                time.sleep(0.0005)
    return sent


def _received(source) -> int:
    return sum(v for k, v in source.counters.items() if k.endswith(".packets"))


def _live_frames(pcap_dir: Path, drop: dict[str, set[int]]):
    from i2v_loc.formats.live import OusterUdpSource

    source = OusterUdpSource(pcap_dir, ports=[0, 0, 0, 0], in_order=True)  # every sweep, in order
    try:
        sent = _send_pcaps(pcap_dir, dict(source.ports), drop, swap_every=5, received=lambda: _received(source))
        frames = [source.frame(k) for k in range(COUNT)]
        return sent, frames, source.counters
    finally:
        source.close()


def test_service_udp_source_delivers_the_newest_sweeps(pcap_dir, native):
    """As the service reads it (serve --source ouster-udp:): a consumer that fell behind gets the
    newest sweep of every sensor, the skipped ones are counted."""
    from i2v_loc.sources import open_source

    source = open_source(f"ouster-udp:{pcap_dir}@0,0,0,0")
    try:
        import time

        sent = _send_pcaps(pcap_dir, dict(source.ports), {}, swap_every=0, received=lambda: _received(source))
        # until the receiver thread has decoded every packet (on a loaded host, 10 s was not enough:
        # the sweep before the newest was compared)
        deadline = time.monotonic() + 120.0
        while not all(source.counters[f"{n}.packets"] == sent[n] for n in sent) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert {n: source.counters[f"{n}.packets"] for n in sent} == sent
        frame = source.frame(0)
        counters = source.counters
        empty = source.frame(1)  # nothing new within the timeout: every sensor missing
    finally:
        source.close()
    expected = Recording(native).frame(COUNT - 1)
    assert sorted(frame.scans) == sorted(expected.scans)
    for name, scan in frame.scans.items():
        np.testing.assert_array_equal(scan.points, expected.scans[name].points)
        assert counters[f"{name}.late_sweeps"] == COUNT - 1
    assert empty.scans == {}


def test_ouster_udp_spec_errors_are_source_errors(tmp_path):
    from i2v_loc.sources import SourceError, open_source

    with pytest.raises(SourceError, match="no sensor metadata"):
        open_source(f"ouster-udp:{tmp_path}")
    with pytest.raises(SourceError, match="ports must be integers"):
        open_source(f"ouster-udp:{tmp_path}@x")


def test_live_udp_on_loopback_gives_the_native_states(pcap_dir, native_states):
    from i2v_loc.params import load_params
    from i2v_loc.pipelines import build_pipeline

    sent, frames, counters = _live_frames(pcap_dir, {})
    assert sum(counters[f"{s}.packets"] for s in sent) == sum(sent.values())
    assert all(counters[f"{s}.lost_packets"] == 0 and counters[f"{s}.foreign_packets"] == 0 for s in sent)
    pipeline = build_pipeline(load_params(pcap_dir / "sensors.yaml"), METHOD)
    assert_same_states([pipeline.process(f).to_json() for f in frames], native_states)


def test_live_udp_counts_lost_packets_and_undoes_reordering(pcap_dir, native):
    ref = Recording(native)
    per_sweep = 1024 // 16
    lost = {5 * per_sweep + 7, 9 * per_sweep + 20, 9 * per_sweep + 21}  # l2: sweeps 5 and 9 lose packets
    sent, frames, counters = _live_frames(pcap_dir, {"l2": lost})
    assert sent["l2"] == COUNT * per_sweep - len(lost)
    assert counters["l2.lost_packets"] == len(lost) and counters["l2.incomplete_sweeps"] == 2
    assert all(counters[f"{s}.lost_packets"] == 0 for s in ("l1", "l3", "l4"))
    for k, frame in enumerate(frames):
        expected = ref.frame(k)
        assert sorted(frame.scans) == ref.sensor_names
        for name, scan in frame.scans.items():
            if name == "l2" and k in (5, 9):  # a subset of the sweep: the lost columns are empty
                assert 0 < len(expected.scans[name].points) - len(scan.points) <= 2 * 16 * 32
                continue
            np.testing.assert_array_equal(scan.points, expected.scans[name].points)  # reordering undone
            np.testing.assert_allclose(scan.time_offset_s, expected.scans[name].time_offset_s, atol=1e-6)
            assert abs(scan.stamp_s - expected.scans[name].stamp_s) < 1e-6


def test_state_lines_follow_the_published_schema(native_states, capsys):
    import jsonschema

    assert main(["params", "schema", "--state"]) == 0
    schema = json.loads(capsys.readouterr().out)
    validator = jsonschema.Draft202012Validator(schema)
    for line in native_states:
        validator.validate(line)
    bad = {**native_states[-1], "vehicles": [{**native_states[-1]["vehicles"][0], "hitch_deg": "12"}]}
    assert not validator.is_valid(bad)
    assert not validator.is_valid({**native_states[0], "faults": {"l1": "on_fire"}})


def test_default_state_lines_follow_the_published_schema(default_states, capsys):
    import jsonschema

    assert main(["params", "schema", "--state"]) == 0
    validator = jsonschema.Draft202012Validator(json.loads(capsys.readouterr().out))
    found = [line for line in default_states if line["vehicles"]]
    assert found and all(v["kind"] == "articulated" for line in found for v in line["vehicles"])
    for line in default_states:
        validator.validate(line)


def test_ros1_bag_is_read(tmp_path):
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC)
    types = store.types
    rng = np.random.default_rng(1)
    clouds = [rng.uniform(-10, 10, (100, 3)).astype(np.float32) for _ in range(3)]
    bag = tmp_path / "yard.bag"
    with Writer(bag) as writer:
        conn = writer.add_connection("/front/points", "sensor_msgs/msg/PointCloud2", typestore=store)
        for k, xyz in enumerate(clouds):
            data = np.zeros(len(xyz), dtype=[("x", ">f4"), ("y", ">f4"), ("z", ">f4"), ("intensity", ">f4")])
            data["x"], data["y"], data["z"] = xyz.T
            data["x"][7] = np.nan  # a missing return
            fields = [
                types["sensor_msgs/msg/PointField"](name=n, offset=4 * i, datatype=7, count=1)
                for i, n in enumerate(("x", "y", "z", "intensity"))
            ]
            header = types["std_msgs/msg/Header"](
                seq=k, stamp=types["builtin_interfaces/msg/Time"](sec=100, nanosec=k * 100_000_000), frame_id="front"
            )
            msg = types["sensor_msgs/msg/PointCloud2"](
                header=header,
                height=1,
                width=len(xyz),
                fields=fields,
                is_bigendian=True,
                point_step=16,
                row_step=16 * len(xyz),
                data=data.view(np.uint8).reshape(-1),
                is_dense=False,
            )
            writer.write(
                conn, 100_000_000_000 + k * 100_000_000, store.serialize_ros1(msg, "sensor_msgs/msg/PointCloud2")
            )
    rec = open_recording(bag)
    assert rec.layout == "rosbag1" and rec.sensor_names == ["front"] and len(rec) == 3
    assert rec.rate_hz == pytest.approx(10.0)
    scan = rec.frame(2).scans["front"]
    assert scan.stamp_s == pytest.approx(100.2)
    np.testing.assert_array_equal(scan.points, np.delete(clouds[2], 7, axis=0))


@pytest.mark.parametrize("fmt", ["rosbag2", "mcap"])
def test_run_writes_its_states_to_a_bag(fmt, native, native_states, tmp_path):
    from rosbags.highlevel import AnyReader

    out = tmp_path / "states_bag"
    assert (
        main(["run", str(native), "--out", str(out), "--quiet", "--method", METHOD, "--format", fmt, "--frames", "4"])
        == 0
    )
    with AnyReader([out]) as reader:
        assert [c.topic for c in reader.connections] == ["/i2v_loc/states"]
        lines = [json.loads(reader.deserialize(raw, c.msgtype).data) for c, _, raw in reader.messages()]

    def strip(line):
        return {k: v for k, v in line.items() if k != "latency_ms"}

    assert [strip(line) for line in lines] == [strip(line) for line in native_states[:4]]


def test_pcap_with_lost_packets_is_read_and_counted(pcap_dir, native, tmp_path, capsys):
    from ouster.sdk import pcap

    from i2v_loc.formats.ouster import read_metadata

    bad = tmp_path / "lossy"
    shutil.copytree(pcap_dir, bad)
    source = pcap.PcapPacketSource(str(pcap_dir / "l2.pcap"), sensor_info=[read_metadata(pcap_dir / "l2.json")])
    kept = [p for i, (_, p) in enumerate(source) if i not in (64 + 10, 64 + 11, 3 * 64 + 63)]  # sweeps 1 and 3
    source.close()
    (bad / "l2.pcap").unlink()
    pcap.record(kept, str(bad / "l2.pcap"))
    rec = open_recording(bad)
    assert rec.counters["l2.lost_packets"] == 3 and rec.counters["l2.incomplete_sweeps"] == 2
    assert len(rec) == COUNT
    ref = Recording(native)
    for k in range(5):
        got, expected = len(rec.frame(k).scans["l2"].points), len(ref.frame(k).scans["l2"].points)
        assert (got < expected) if k in (1, 3) else (got == expected)
    assert main(["run", str(bad), "--out", str(tmp_path / "s.jsonl"), "--quiet", "--frames", "2"]) == 0
    assert "source: l2.incomplete_sweeps 2, l2.lost_packets 3" in capsys.readouterr().out


def test_bench_reports_latency_on_the_chengdu_frames(realdata, tmp_path, capsys):
    params = tmp_path / "chengdu.yaml"
    params.write_text(
        yaml.safe_dump(
            {
                "sensors": [{"name": "frames", "extrinsics": {"z_m": 7.5}}],
                "background": {"window_frames": 10, "learn_every_frames": 1, "min_samples": 8},
            }
        )
    )
    folder = realdata / "roadside80_chengdu" / "frames"
    quick = ["--scaling", "none", "--no-open3d", "--realdata", "none", "--json", "-"]
    assert main(["bench", str(folder), "--params", str(params), "--method", "default", "--warmup", "10", *quick]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["frames"] == 10
    assert {"merge", "front_end", "candidates", "vehicles", "total"} == set(report["latency_ms"])
    assert report["latency_ms"]["total"]["p95"] >= report["latency_ms"]["total"]["p50"] > 0


def test_every_pcd_variant_ply_and_npy_give_the_same_points(tmp_path):
    import open3d as o3d
    from pypcd4 import Encoding, PointCloud

    rng = np.random.default_rng(7)
    xyz = _cloud_rows(600, rng)
    organized = np.full((20, 40, 3), np.nan, dtype=np.float32)  # 800 cells, 600 returns, NaN elsewhere
    cells = np.sort(rng.choice(800, 600, replace=False))
    organized.reshape(-1, 3)[cells] = xyz
    for encoding in ("ascii", "binary", "binary_compressed"):
        folder = tmp_path / encoding / "lidar"
        folder.mkdir(parents=True)
        flat = organized.reshape(-1, 3)
        cloud = PointCloud.from_points([flat[:, 0], flat[:, 1], flat[:, 2]], ("x", "y", "z"), (np.float32,) * 3)
        cloud.metadata.width, cloud.metadata.height = 40, 20  # organized: rows of the sensor
        cloud.save(folder / "1700000000_100000000.pcd", encoding=Encoding(encoding))
    (tmp_path / "npy" / "lidar").mkdir(parents=True)
    np.save(tmp_path / "npy" / "lidar" / "000000.npy", np.column_stack([xyz, np.ones(600)]))
    (tmp_path / "ply" / "lidar").mkdir(parents=True)
    o3d.io.write_point_cloud(
        str(tmp_path / "ply" / "lidar" / "000000.ply"),
        o3d.geometry.PointCloud(o3d.utility.Vector3dVector(xyz.astype(np.float64))),
    )
    for layout in ("ascii", "binary", "binary_compressed", "npy", "ply"):
        rec = open_recording(tmp_path / layout)
        scan = rec.frame(0).scans["lidar"]
        np.testing.assert_allclose(scan.points, xyz, atol=1e-5 if layout == "ascii" else 0, err_msg=layout)
        if layout in ("ascii", "binary", "binary_compressed"):
            assert scan.stamp_s == pytest.approx(1700000000.1), layout  # from the file name


def test_eval_task_on_a_pcap_folder_equals_the_native_one(pcap_dir, native):
    from i2v_loc.evaluation.runner import Task, base_params, run_task

    params = base_params(None)
    results = [run_task(Task(str(path), "paper", None, params)) for path in (native, pcap_dir)]
    rows = [
        [
            {k: v for k, v in row.items() if "latency" not in k and k != "recording"}
            for row in r["records"] + r["frames"]
        ]
        for r in results
    ]
    assert rows[0] and json.dumps(rows[0], default=str) == json.dumps(rows[1], default=str)  # NaN-safe
