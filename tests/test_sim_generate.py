"""Generated recordings: ground truth consistency, timing, determinism, the command."""

import json
import math

import numpy as np
import pytest
import yaml

from i2v_loc.cli import main
from i2v_loc.geometry import extrinsics_matrix, pose_matrix, transform_points, wrap_deg
from i2v_loc.params import load_params
from i2v_loc.recording import Recording
from i2v_loc.sim.generate import SimConfig, run, simulate


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    out = tmp_path_factory.mktemp("sim") / "rec"
    run(SimConfig(vehicles=["man_tgx"], scenario="docking", seed=3, duration_s=1.0, start_s=12.0, columns=512), out)
    return Recording(out)


def test_ground_truth_hitch_is_trailer_yaw_minus_truck_yaw(recording):
    gt = recording.ground_truth()
    assert len(gt) == len(recording) == 10
    hitches = []
    for line in gt:
        v = line["vehicles"][0]
        assert v["hitch_deg"] == pytest.approx(wrap_deg(v["trailer"]["yaw_deg"] - v["truck"]["yaw_deg"]), abs=1e-3)
        hitches.append(v["hitch_deg"])
        # tractor_to_trailer maps truck-frame points into the trailer frame.
        t_truck = pose_matrix(*v["truck"]["center"], 0, 0, v["truck"]["yaw_deg"])
        t_trailer = pose_matrix(*v["trailer"]["center"], 0, 0, v["trailer"]["yaw_deg"])
        np.testing.assert_allclose(v["tractor_to_trailer"], np.linalg.inv(t_trailer) @ t_truck, atol=1e-3)
    assert max(abs(h) for h in hitches) > 5.0  # the docking clip is articulated


def test_ground_truth_boxes_contain_the_points_counted_for_them(recording):
    params = load_params(recording.sensors_file)
    k = 5
    frame, gt = recording.frame(k), recording.ground_truth()[k]
    pts = np.vstack(
        [
            transform_points(extrinsics_matrix(params.sensor(n).extrinsics), s.points.astype(float))
            for n, s in frame.scans.items()
        ]
    )
    v = gt["vehicles"][0]
    for unit, dims in (("truck", v["truck"]), ("trailer", v["trailer"])):
        local = transform_points(np.linalg.inv(pose_matrix(*dims["center"], 0, 0, dims["yaw_deg"])), pts)
        inside = int(np.all(np.abs(local) <= np.array(dims["dimensions"]) / 2 + 0.2, axis=1).sum())
        assert dims["points"] > 100, unit
        # Wheels, rails and legs lie outside the Table-1 box: most, not all, counted points are inside.
        assert 0.7 * dims["points"] <= inside <= 1.1 * dims["points"], unit
        assert dims["center"][2] == pytest.approx(
            dims["dimensions"][2] / 2 + (1.2 if unit == "trailer" else 0.45), abs=0.01
        )


def test_sweep_timing_phase_and_clock_offset(recording):
    meta = recording.meta
    for sensor in meta["sensors"]:
        scans = recording.scans(sensor["name"])
        assert 0.0 <= sensor["phase_s"] < 0.1 and abs(sensor["clock_offset_s"]) <= 0.005
        expected = (np.arange(len(recording)) / 10.0 + sensor["phase_s"] + sensor["clock_offset_s"]) * 1e9
        np.testing.assert_allclose(scans.stamp_ns, expected, atol=2)
        t = scans.column_time_ns
        assert t[0] == 0 and np.all(np.diff(t) > 0) and 99_000_000 < t[-1] < 100_000_000
        offsets = recording.frame(0, [sensor["name"]]).scans[sensor["name"]].time_offset_s
        assert offsets.min() >= 0.0 and offsets.max() < 0.1
    assert len({s["phase_s"] for s in meta["sensors"]}) == len(meta["sensors"])


def test_true_sensors_undo_the_clock_offsets_and_the_guess_does_not(recording):
    true, guess = load_params(recording.sensors_file), load_params(recording.sensors_guess_file)
    for sensor in recording.meta["sensors"]:
        name = sensor["name"]
        assert true.sensor(name).time_offset_s == -sensor["clock_offset_s"]
        assert guess.sensor(name).time_offset_s == 0.0
        # stamp + time_offset_s is the sweep start on the common clock: frame / rate + phase
        stamps_s = recording.scans(name).stamp_ns * 1e-9 + true.sensor(name).time_offset_s
        np.testing.assert_allclose(stamps_s, np.arange(len(recording)) / 10.0 + sensor["phase_s"], atol=2e-9)
    assert len({s.time_offset_s for s in true.sensors}) == len(true.sensors)  # really per sensor, not all 0


def test_sensors_guess_perturbs_all_but_the_reference(recording):
    true = load_params(recording.sensors_file)
    guess = load_params(recording.sensors_guess_file)
    assert guess.sensor("l1").extrinsics == true.sensor("l1").extrinsics
    for name in ("l2", "l3", "l4"):
        t, g = true.sensor(name).extrinsics, guess.sensor(name).extrinsics
        np.testing.assert_allclose(np.abs([g.x_m - t.x_m, g.y_m - t.y_m, g.z_m - t.z_m]), 0.3, atol=1e-9)
        np.testing.assert_allclose(
            np.abs([g.roll_deg - t.roll_deg, g.pitch_deg - t.pitch_deg, g.yaw_deg - t.yaw_deg]), 2.0, atol=1e-9
        )


def test_openlabel_has_truck_and_trailer_cuboids(recording):
    ol = recording.openlabel()["openlabel"]
    assert ol["metadata"]["schema_version"] == "1.0.0"
    assert sorted(o["type"] for o in ol["objects"].values()) == ["TRAILER", "TRUCK"]
    frame = ol["frames"]["3"]["objects"]
    gt = recording.ground_truth()[3]["vehicles"][0]
    for obj in frame.values():
        val = obj["object_data"]["cuboid"]["val"]
        assert len(val) == 10
        yaw = math.degrees(2 * math.atan2(val[5], val[6]))
        assert any(
            np.allclose(val[:3], gt[u]["center"]) and abs(wrap_deg(yaw - gt[u]["yaw_deg"])) < 1e-3
            for u in ("truck", "trailer")
        )


def test_same_seed_gives_identical_arrays_and_other_seed_differs():
    cfg = dict(vehicles=["twizy"], scenario="single_turn", duration_s=0.3, columns=512)
    _, a, gt_a = simulate(SimConfig(seed=7, **cfg))
    _, b, gt_b = simulate(SimConfig(seed=7, **cfg))
    _, c, _ = simulate(SimConfig(seed=8, **cfg))
    for name in a:
        np.testing.assert_array_equal(a[name].range_mm, b[name].range_mm)
        np.testing.assert_array_equal(a[name].stamp_ns, b[name].stamp_ns)
    assert gt_a == gt_b
    assert not np.array_equal(a["l2"].range_mm, c["l2"].range_mm)


def test_two_vehicles_do_not_overlap():
    _, _, gt = simulate(
        SimConfig(vehicles=["man_tgx", "volvo_fh"], scenario="straight", seed=1, duration_s=0.2, columns=512)
    )
    a, b = gt[0]["vehicles"]
    assert (a["vehicle"], b["vehicle"]) == ("man_tgx", "volvo_fh")
    assert math.dist(a["trailer"]["center"][:2], b["trailer"]["center"][:2]) > 4.0


def test_command_writes_recording_and_preview(tmp_path, capsys):
    out = tmp_path / "rec"
    code = main(
        [
            "sim",
            "--vehicle",
            "volvo_fh",
            "--scenario",
            "u_turn",
            "--seed",
            "2",
            "--duration",
            "0.3",
            "--columns",
            "512",
            "--out",
            str(out),
            "--preview",
            str(out / "preview.png"),
        ]
    )
    assert code == 0
    rec = Recording(out)
    assert len(rec) == 3 and rec.meta["scenario"] == "u_turn" and rec.meta["sensors"][0]["columns"] == 512
    assert (out / "preview.png").stat().st_size > 10_000
    assert yaml.safe_load((out / "sensors.yaml").read_text())["sensors"][0]["columns"] == 512
    assert json.loads((out / "ground_truth.jsonl").read_text().splitlines()[0])["vehicles"][0]["vehicle"] == "volvo_fh"


def test_command_refuses_unknown_vehicle(tmp_path, capsys):
    assert main(["sim", "--vehicle", "bus", "--out", str(tmp_path / "x")]) == 2
    assert "unknown vehicle" in capsys.readouterr().err


def test_footprint_points_fill_rotated_rectangles_one_or_many():
    from i2v_loc.sim.yard import footprint_points

    one = footprint_points((10.0, 5.0), 4.0, 2.0, math.pi / 2, step_m=1.0)
    assert one.shape == (15, 2)  # 5 x 3 grid
    np.testing.assert_allclose(one.min(axis=0), [9.0, 3.0], atol=1e-12)  # heading north: 2 m wide in x, 4 m long in y
    np.testing.assert_allclose(one.max(axis=0), [11.0, 7.0], atol=1e-12)
    many = footprint_points([[10.0, 5.0], [0.0, 0.0]], 4.0, 2.0, [math.pi / 2, 0.0], step_m=1.0)
    np.testing.assert_allclose(many[:15], one)
    np.testing.assert_allclose(many[15:], footprint_points((0.0, 0.0), 4.0, 2.0, 0.0, step_m=1.0))


def test_ground_truth_counts_each_units_points_per_sensor(recording):
    """Per sensor: the points of that sensor's sweep inside the unit's box, as for the total."""
    params = load_params(recording.sensors_file)
    k = 5
    frame, gt = recording.frame(k), recording.ground_truth()[k]
    v = gt["vehicles"][0]
    for unit in ("truck", "trailer"):
        by_sensor = v[unit]["points_by_sensor"]
        assert set(by_sensor) == set(frame.scans) and sum(by_sensor.values()) == v[unit]["points"]
        dims = v[unit]
        for name, scan in frame.scans.items():
            pts = transform_points(extrinsics_matrix(params.sensor(name).extrinsics), scan.points.astype(float))
            local = transform_points(np.linalg.inv(pose_matrix(*dims["center"], 0, 0, dims["yaw_deg"])), pts)
            inside = int(np.all(np.abs(local) <= np.array(dims["dimensions"]) / 2 + 0.2, axis=1).sum())
            assert 0.7 * by_sensor[name] - 5 <= inside <= 1.1 * by_sensor[name] + 5, (unit, name)
