"""Ground-truth loaders, interpolation to state stamps and the per-frame matching."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from i2v_loc.evaluation import dcap
from i2v_loc.evaluation import groundtruth as gtm
from i2v_loc.evaluation.matching import match_states
from i2v_loc.evaluation.summary import summarize
from i2v_loc.params import Params


def _unit(x, y, yaw, points=500, dims=(10.0, 2.5, 2.5)):
    return {"center": [x, y, 1.5], "dimensions": list(dims), "yaw_deg": yaw, "velocity": [0.0, 0.0], "points": points}


def _line(frame, truck, trailer, rate_hz=10.0, vid=1, maneuver="u_turn", vehicle="volvo_fh"):
    return {
        "frame": frame,
        "stamp_s": frame / rate_hz,
        "vehicles": [
            {
                "id": vid,
                "vehicle": vehicle,
                "maneuver": maneuver,
                "hitch_deg": gtm.wrap_deg(trailer["yaw_deg"] - truck["yaw_deg"]),
                "truck": truck,
                "trailer": trailer,
            }
        ],
        "distractors": [],
    }


def test_interpolation_is_linear_and_wraps_yaw():
    lines = [_line(0, _unit(0, 0, 179.0), _unit(-8, 0, 170.0)), _line(1, _unit(1, 2, -179.0), _unit(-7, 0, 176.0))]
    mid = gtm.interpolate_ground_truth(lines, 0.05)["vehicles"][0]
    assert mid["truck"]["center"][:2] == pytest.approx([0.5, 1.0])
    assert abs(gtm.wrap_deg(mid["truck"]["yaw_deg"] - 180.0)) == pytest.approx(0.0, abs=1e-9)  # not 0 deg
    assert mid["trailer"]["yaw_deg"] == pytest.approx(173.0)
    assert mid["hitch_deg"] == pytest.approx(-7.0)
    quarter = gtm.interpolate_ground_truth(lines, 0.075)["vehicles"][0]
    assert quarter["truck"]["yaw_deg"] == pytest.approx(-179.5)
    # the tractor_to_trailer of the interpolated poses maps the truck centre into the trailer frame
    t = np.asarray(mid["tractor_to_trailer"])
    yaw = math.radians(173.0)
    local = np.array([[math.cos(yaw), math.sin(yaw)], [-math.sin(yaw), math.cos(yaw)]]) @ (
        np.array([0.5, 1.0]) - [-7.5, 0.0]
    )
    assert t[:2, 3] == pytest.approx(local)


def test_interpolation_outside_the_span_and_missing_vehicles():
    lines = [_line(0, _unit(0, 0, 0.0), _unit(-8, 0, 0.0)), _line(1, _unit(1, 0, 0.0), _unit(-7, 0, 0.0), vid=2)]
    assert gtm.interpolate_ground_truth(lines, 0.05)["vehicles"] == []  # id 1 is not in both lines
    assert len(gtm.interpolate_ground_truth(lines, -0.04)["vehicles"]) == 1  # within half a frame: clamped
    assert gtm.interpolate_ground_truth(lines, -0.2)["vehicles"] == []
    assert gtm.interpolate_ground_truth(lines, 0.1)["vehicles"][0]["id"] == 2


def test_matching_measures_a_constant_bias_at_shifted_stamps():
    """States stamped 30 ms after each GT frame: the truth is interpolated to the state stamps,
    so a pure 1 deg yaw bias and a 0.2 m shift are measured exactly."""
    speed = 2.0
    dx, _, dz = dcap.straight_trailer_in_truck_frame(Params().vehicles["volvo_fh"])[:3, 3]
    lines = [_line(k, _unit(speed * k / 10, 0, 0.0), _unit(speed * k / 10 + dx, 0, 0.0)) for k in range(20)]
    for line in lines:
        line["vehicles"][0]["trailer"]["center"][2] += dz
    states = []
    for k in range(19):
        t = k / 10 + 0.03
        x = speed * t
        states.append(
            {
                "frame": k,
                "stamp_s": t,
                "latency_ms": {"clustering": 1.0, "total": 2.0 + k},
                "vehicles": [
                    {
                        "id": 7,
                        "vehicle": "volvo_fh",
                        "hitch_deg": 0.0,
                        "truck": {"track_id": 1, "center": [x + 0.2, 0, 1.5], "yaw_deg": 1.0},
                        "trailer": {"track_id": 2 if k < 10 else 3, "center": [x + dx, 0.2, 1.5 + dz], "yaw_deg": 1.0},
                    }
                ],
            }
        )
    states[5]["vehicles"].append(
        {
            "id": 9,
            "vehicle": "twizy",
            "hitch_deg": None,
            "truck": {"track_id": 5, "center": [50, 50, 1], "yaw_deg": 0.0},
            "trailer": None,
        }
    )
    records, frames = match_states(states, lines, Params())
    s = summarize(records, frames)
    assert s["truck_pos_rmse_m"] == pytest.approx(0.2)
    assert s["trailer_pos_rmse_m"] == pytest.approx(0.2)
    assert s["truck_yaw_rmse_deg"] == pytest.approx(1.0)
    assert s["hitch_rmse_deg"] == pytest.approx(0.0)
    assert s["heading_flip_rate"] == 0.0
    assert s["false_vehicles"] == 1
    assert s["trailer_id_switches"] == 1 and s["truck_id_switches"] == 0
    assert s["truck_detection_rate"] == 1.0
    assert s["latency_ms_p50"] == pytest.approx(11.0)
    assert s["latency_clustering_ms_mean"] == pytest.approx(1.0)
    # the common 1 deg yaw error rotates nothing between F and B: RRA 0, but the trailer shift shows
    assert s["rra_rad"] == pytest.approx(0.0, abs=1e-9)
    assert s["delta_T_m"] > 0.1
    assert s["static_delta_T_m"] == pytest.approx(0.0, abs=1e-9)  # straight as the baseline assumes
    assert s["static_rra_rad"] == pytest.approx(0.0, abs=1e-9)


def test_matching_counts_flips_and_unreported_units():
    lines = [_line(k, _unit(0, 0, 90.0, points=10), _unit(0, -8, 90.0)) for k in range(4)]
    states = [
        {
            "frame": k,
            "stamp_s": k / 10,
            "vehicles": [
                {
                    "id": 1,
                    "vehicle": "volvo_fh",
                    "hitch_deg": None,
                    "truck": None,
                    "trailer": {"track_id": 1, "center": [0, -8, 1], "yaw_deg": -90.0 if k < 1 else 90.0},
                }
            ],
        }
        for k in range(4)
    ]
    records, frames = match_states(states, lines, Params())
    s = summarize(records, frames)
    assert s["trailer_heading_flip_rate"] == pytest.approx(0.25)
    assert s["trailer_yaw_rmse_deg"] == pytest.approx(math.sqrt(180.0**2 / 4))
    assert math.isnan(s["truck_detection_rate"])  # only 10 GT points: not eligible
    assert s["truck_frames_in_gt"] == 4 and s["truck_frames_reported"] == 0
    assert math.isnan(s["hitch_rmse_deg"])


def test_a_state_after_the_last_truth_line_is_not_scored():
    lines = [_line(k, _unit(0, 0, 90.0), _unit(0, -8, 90.0)) for k in range(3)]
    vehicle = {
        "id": 1,
        "vehicle": "volvo_fh",
        "hitch_deg": 0.0,
        "truck": {"track_id": 1, "center": [0, 0, 1], "yaw_deg": 90.0},
        "trailer": {"track_id": 2, "center": [0, -8, 1], "yaw_deg": 90.0},
    }
    # the last sweep ends 0.08 s after the last GT line (0.2 s): no truth there, not a false vehicle
    states = [{"frame": k, "stamp_s": k / 10 + 0.08 * (k == 2), "vehicles": [vehicle]} for k in range(3)]
    records, frames = match_states(states, lines, Params())
    s = summarize(records, frames)
    assert s["false_vehicles"] == 0
    assert s["frames_outside_truth"] == 1 and s["frames"] == 3
    assert s["gt_vehicle_frames"] == 2
    assert [row["scored"] for row in frames] == [True, True, False]


def test_openlabel_tumtraf_frame(realdata):
    lines = gtm.load_openlabel(realdata / "tumtraf_s110_south" / "1646667315_454719936_s110_lidar_ouster_south.json")
    assert len(lines) == 1 and lines[0]["frame"] == 54
    (vehicle,) = lines[0]["vehicles"]
    assert vehicle["truck"]["points"] == 28 and vehicle["trailer"]["points"] == 6
    assert vehicle["truck"]["dimensions"][0] == pytest.approx(5.8323)
    assert vehicle["truck"]["yaw_deg"] == pytest.approx(-171.36, abs=0.05)
    assert abs(vehicle["hitch_deg"]) < 0.5
    assert vehicle["maneuver"] == gtm.UNLABELLED


def test_openlabel_folder_and_transform(realdata, tmp_path):
    lines = gtm.load_ground_truth(realdata / "tumtraf_s110_south", transform=np.diag([-1.0, -1.0, 1.0, 1.0]))
    assert [line["frame"] for line in lines] == sorted(line["frame"] for line in lines)
    with_trailer = [v for line in lines for v in line["vehicles"] if v["trailer"] is not None]
    assert with_trailer and with_trailer[0]["truck"]["center"][0] == pytest.approx(-46.98, abs=0.01)
    assert with_trailer[0]["truck"]["yaw_deg"] == pytest.approx(8.64, abs=0.05)  # rotated by 180 deg


def _labelcloud(tmp_path, name, objects):
    file = tmp_path / name
    file.write_text(json.dumps({"folder": "pointclouds", "filename": name, "path": name, "objects": objects}))
    return file


def test_labelcloud_centroid_formats(tmp_path):
    truck = {
        "name": "truck:man_tgx",
        "centroid": {"x": 10.0, "y": 5.0, "z": 1.9},
        "dimensions": {"length": 2.77, "width": 2.77, "height": 2.86},
        "rotations": {"x": 0, "y": 0, "z": 350.0},
    }
    trailer = {
        "name": "Trailer",
        "centroid": {"x": 3.0, "y": 6.0, "z": 2.5},
        "dimensions": {"length": 13.68, "width": 2.77, "height": 2.55},
        "rotations": {"x": 0, "y": 0, "z": 0.0},
    }
    _labelcloud(tmp_path, "frame_000012.json", [truck, trailer])
    rel = dict(truck, rotations={"x": 0, "y": 0, "z": -math.radians(10.0)})
    _labelcloud(tmp_path, "frame_000013.json", [rel, trailer])
    lines = gtm.load_ground_truth(tmp_path)
    assert [line["frame"] for line in lines] == [12, 13]
    assert lines[0]["stamp_s"] == pytest.approx(1.2)
    for line in lines:
        (v,) = line["vehicles"]
        assert v["vehicle"] == "man_tgx"
        assert v["truck"]["yaw_deg"] == pytest.approx(-10.0)
        assert v["hitch_deg"] == pytest.approx(10.0)


def test_labelcloud_vertices_format(tmp_path):
    # a 4 x 2 x 1 box at (1, 2, 0.5) heading +y: back-left-bottom first, as labelCloud orders them
    bottom = [[2, 0, 0], [2, 4, 0], [0, 4, 0], [0, 0, 0]]
    vertices = bottom + [[x, y, 1] for x, y, _ in bottom]
    _labelcloud(tmp_path, "0007.json", [{"name": "tractor", "vertices": vertices}])
    (line,) = gtm.load_labelcloud(tmp_path)
    unit = line["vehicles"][0]["truck"]
    assert unit["center"] == pytest.approx([1.0, 2.0, 0.5])
    assert unit["dimensions"] == pytest.approx([4.0, 2.0, 1.0])
    assert unit["yaw_deg"] == pytest.approx(90.0)
    assert line["vehicles"][0]["trailer"] is None


def test_bad_label_files_give_clear_errors(tmp_path):
    (tmp_path / "x.json").write_text("[1, 2]")
    with pytest.raises(gtm.GroundTruthError, match="JSON object"):
        gtm.load_ground_truth(tmp_path / "x.json")
    (tmp_path / "y.json").write_text(json.dumps({"objects": [{"name": "truck", "centroid": {"x": 1}}]}))
    with pytest.raises(gtm.GroundTruthError, match="centroid"):
        gtm.load_labelcloud(tmp_path / "y.json")
    with pytest.raises(gtm.GroundTruthError, match="no such"):
        gtm.load_jsonl(tmp_path / "missing.jsonl")


def test_openlabel_relations_pair_units_instead_of_distance(tmp_path):
    """A trailer whose front is 1 m from a truck is its trailer by distance; the file's isTowing
    relations say it belongs to the other truck, 30 m away, and the relations win."""

    def cuboid(x, y, length):
        return {"object_data": {"cuboid": {"name": "shape3D", "val": [x, y, 1.5, 0, 0, 0, 1, length, 2.5, 3.0]}}}

    objects = {
        "1": {"name": "TRUCK_1", "type": "TRUCK"},
        "2": {"name": "TRAILER_2", "type": "TRAILER"},
        "3": {"name": "TRUCK_3", "type": "TRUCK"},
    }
    frame = {"objects": {"1": cuboid(0.0, 0.0, 3.0), "2": cuboid(-7.0, 0.0, 14.0), "3": cuboid(30.0, 0.0, 3.0)}}
    relations = {
        "r": {
            "name": "towing",
            "type": "isTowing",
            "rdf_subjects": [{"uid": "3", "type": "object"}],
            "rdf_objects": [{"uid": "2", "type": "object"}],
        }
    }
    file = tmp_path / "labels.json"
    file.write_text(
        json.dumps(
            {
                "openlabel": {
                    "objects": objects,
                    "frames": {"0": {**frame, "relations": {"r": {}}}},
                    "relations": relations,
                }
            }
        )
    )
    (line,) = gtm.load_openlabel(file)
    pairs = sorted(
        (v["truck"] and v["truck"]["center"][0], v["trailer"] and v["trailer"]["center"][0])
        for v in line["vehicles"]
        if v["truck"] is not None
    )
    assert pairs == [(0.0, None), (30.0, -7.0)]
    file.write_text(json.dumps({"openlabel": {"objects": objects, "frames": {"0": frame}}}))
    (line,) = gtm.load_openlabel(file)  # no relations in the file: by distance
    assert sorted(
        (v["truck"] and v["truck"]["center"][0], v["trailer"] and v["trailer"]["center"][0])
        for v in line["vehicles"]
        if v["truck"] is not None
    ) == [(0.0, -7.0), (30.0, None)]


def test_a_sensor_subset_sees_a_unit_by_its_own_sensors_points():
    truck = {**_unit(0, 0, 90.0), "points": 300, "points_by_sensor": {"l1": 0, "l2": 250, "l3": 50}}
    trailer = {**_unit(0, -8, 90.0), "points": 900, "points_by_sensor": {"l1": 400, "l2": 500, "l3": 0}}
    lines = [
        {"frame": 0, "stamp_s": 0.0, "vehicles": [{"id": 1, "vehicle": "volvo_fh", "truck": truck, "trailer": trailer}]}
    ]
    (line,) = gtm.seen_by(lines, ["l1"])
    assert line["vehicles"][0]["truck"]["points"] == 0 and line["vehicles"][0]["trailer"]["points"] == 400
    (line,) = gtm.seen_by(lines, ["l2", "l3"])
    assert line["vehicles"][0]["truck"]["points"] == 300 and line["vehicles"][0]["trailer"]["points"] == 500
    assert lines[0]["vehicles"][0]["truck"]["points"] == 300  # the lines themselves unchanged
    plain = [{"frame": 0, "stamp_s": 0.0, "vehicles": [{"id": 1, "truck": _unit(0, 0, 90.0, points=42)}]}]
    assert gtm.seen_by(plain, ["l1"])[0]["vehicles"][0]["truck"]["points"] == 42  # no per-sensor counts: kept
