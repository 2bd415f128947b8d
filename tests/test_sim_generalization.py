"""The generalization suite: simulator-only vehicles (--vehicles-file), a sensor layout not in
params/, two vehicles with clutter beside them, a sloped yard."""

import json
import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy.spatial import cKDTree

from i2v_loc.cli import main
from i2v_loc.commands.sim import SUITES_DIR, suite_case
from i2v_loc.evaluation.matching import match_frame
from i2v_loc.geometry import extrinsics_matrix, pose_matrix, transform_points
from i2v_loc.params import Params, ParamsError, load_params
from i2v_loc.recording import Recording
from i2v_loc.sim.generate import SimConfig, build_simulation, load_vehicles_file
from i2v_loc.sim.sensor_model import model_beam_table
from i2v_loc.sim.yard import CONTAINER_SIZE_M, footprint_points

SUITE = SUITES_DIR / "generalization.yaml"
LAYOUT = SUITES_DIR / "layouts" / "one_side_6m.yaml"
UNKNOWN = SUITES_DIR / "vehicles_unknown.yaml"

# A trailer with figures found nowhere else, so that their absence from the recording's files means something.
ODD_VEHICLE = {
    "description": "test tractor with a 10.537 m semitrailer",
    "truck": {
        "length_m": 2.61,
        "width_m": 2.513,
        "height_m": 2.9,
        "floor_m": 0.5,
        "wheelbase_m": 3.8,
        "front_overhang_m": 1.4,
        "hitch_behind_rear_axle_m": -0.4,
    },
    "trailer": {
        "length_m": 10.537,
        "width_m": 2.513,
        "height_m": 2.7,
        "floor_m": 1.2,
        "hitch_to_axle_m": 6.3,
        "hitch_to_front_m": 1.2,
    },
    "vehicle_volume_tolerance_m3": 200.0,
    "trailer_volume_tolerance_m3": 40.0,
}


def _write(path: Path, data) -> Path:
    path.write_text(yaml.safe_dump(data))
    return path


def _points_in_box(points: np.ndarray, unit: dict, margin_m: float = 0.2) -> int:
    local = transform_points(np.linalg.inv(pose_matrix(*unit["center"], 0, 0, unit["yaw_deg"])), points)
    return int(np.all(np.abs(local) <= np.array(unit["dimensions"]) / 2 + margin_m, axis=1).sum())


def _yard_points(rec: Recording, k: int) -> dict[str, np.ndarray]:
    params = load_params(rec.sensors_file)
    return {
        n: transform_points(extrinsics_matrix(params.sensor(n).extrinsics), s.points.astype(float))
        for n, s in rec.frame(k).scans.items()
    }


# --------------------------------------------------------------------------- --vehicles-file


def test_vehicles_file_is_validated_with_the_parameter_model(tmp_path):
    bad = _write(
        tmp_path / "bad.yaml",
        {"vehicles": {"long": {**ODD_VEHICLE, "trailer": {**ODD_VEHICLE["trailer"], "length_m": 30.0}}}},
    )
    with pytest.raises(ParamsError, match=r"bad\.yaml: vehicles\.long\.trailer\.length_m = 30\.0.*<= 25"):
        load_vehicles_file(bad)
    typo = _write(tmp_path / "typo.yaml", {"vehicles": {"long": {**ODD_VEHICLE, "trailer_length": 3.0}}})
    with pytest.raises(ParamsError, match=r"typo\.yaml: vehicles\.long\.trailer_length"):
        load_vehicles_file(typo)
    other = _write(tmp_path / "other.yaml", {"vehicles": {"long": ODD_VEHICLE}, "sensors": []})
    with pytest.raises(ParamsError, match="one non-empty 'vehicles' mapping"):
        load_vehicles_file(other)
    clash = _write(tmp_path / "clash.yaml", {"vehicles": {"man_tgx": ODD_VEHICLE}})
    with pytest.raises(ParamsError, match="vehicles.man_tgx is a configured vehicle"):
        load_vehicles_file(clash, known=Params().vehicles)
    assert (
        load_vehicles_file(_write(tmp_path / "ok.yaml", {"vehicles": {"long": ODD_VEHICLE}}))["long"].trailer.length_m
        == 10.537
    )


def test_command_refuses_a_bad_vehicles_file_with_one_line(tmp_path, capsys):
    bad = _write(
        tmp_path / "bad.yaml",
        {"vehicles": {"long": {**ODD_VEHICLE, "truck": {**ODD_VEHICLE["truck"], "width_m": -1.0}}}},
    )
    assert main(["sim", "--vehicles-file", str(bad), "--vehicle", "long", "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err
    assert "bad.yaml: vehicles.long.truck.width_m = -1.0" in err
    assert not (tmp_path / "x").exists()


def test_vehicles_file_round_trip_names_unknown_and_hides_the_dimensions(tmp_path):
    vehicles_file = _write(tmp_path / "vehicles.yaml", {"vehicles": {"trailer_10m5": ODD_VEHICLE}})
    out = tmp_path / "rec"
    assert (
        main(
            [
                "sim",
                "--vehicles-file",
                str(vehicles_file),
                "--vehicle",
                "trailer_10m5",
                "--scenario",
                "straight",
                "--seed",
                "5",
                "--start",
                "3",
                "--duration",
                "0.3",
                "--columns",
                "512",
                "--out",
                str(out),
                "--preview",
            ]
        )
        == 0
    )
    assert (out / "preview.png").stat().st_size > 10_000  # --preview without a file: preview.png in the recording
    rec = Recording(out)
    gt = rec.ground_truth()
    assert len(gt) == 3
    for line in gt:
        (v,) = line["vehicles"]
        assert v["vehicle"] == "unknown_trailer_10m5"
        assert v["trailer"]["dimensions"] == [10.537, 2.513, 2.7]  # the truth keeps the real size
    assert gt[1]["vehicles"][0]["trailer"]["points"] > 100
    labels = rec.openlabel()["openlabel"]["objects"].values()
    assert {o["object_data"]["text"][0]["val"] for o in labels} == {"unknown_trailer_10m5"}
    assert rec.meta["vehicles"] == ["unknown_trailer_10m5"]
    # Nothing the pipeline reads carries the simulator-only vehicle or its figures.
    for name in ("sensors.yaml", "sensors_guess.yaml", "meta.yaml"):
        text = (out / name).read_text()
        assert "10.537" not in text and "2.513" not in text and "trailer_10m5:" not in text, name
    assert set(yaml.safe_load((out / "sensors.yaml").read_text())) == {"sensors"}
    assert set(load_params(rec.sensors_file).vehicles) == set(Params().vehicles)


def _unit(center, yaw_deg, dims):
    return {"center": center, "yaw_deg": yaw_deg, "dimensions": dims, "points": 500}


def test_evaluation_matches_an_unknown_vehicle_with_a_reported_vehicle_of_any_type():
    """Association is by position only: an unknown_* truth pairs with whatever type the pipeline
    reports; the DCAP errors need the vehicle's geometry and stay NaN."""
    gt = {
        "id": 1,
        "vehicle": "unknown_trailer_10m5",
        "maneuver": "straight",
        "hitch_deg": 0.0,
        "truck": _unit([10.0, 5.0, 1.95], 0.0, [2.6, 2.55, 2.9]),
        "trailer": _unit([2.4, 5.0, 2.55], 0.0, [10.5, 2.55, 2.7]),
    }
    est = {
        "id": 7,
        "vehicle": "man_tgx",
        "truck": _unit([10.3, 5.1, 1.9], 1.0, [2.77, 2.77, 2.86]),
        "trailer": _unit([2.0, 5.2, 2.5], -1.0, [13.68, 2.77, 2.55]),
    }
    (rec,) = match_frame({"frame": 0, "stamp_s": 0.0, "vehicles": [est]}, {"vehicles": [gt]}, Params(), gate_m=5.0)
    assert (rec["kind"], rec["vehicle"], rec["est_vehicle"], rec["est_id"]) == (
        "gt",
        "unknown_trailer_10m5",
        "man_tgx",
        7,
    )
    assert rec["truck_pos_err_m"] == pytest.approx(math.hypot(0.3, 0.1))
    assert rec["trailer_pos_err_m"] == pytest.approx(math.hypot(0.4, 0.2))
    assert math.isnan(rec["dcap_dT_m"])


# --------------------------------------------------------------------------- the one-side layout


def test_one_side_layout_is_new_and_tilted_towards_the_field():
    params = load_params(LAYOUT)
    assert [s.name for s in params.sensors] == ["s1", "s2", "s3"]
    assert all(
        s.extrinsics.z_m == 6.0 and s.extrinsics.y_m == 22.0 and s.extrinsics.pitch_deg == 10.0 for s in params.sensors
    )
    for path in (SUITES_DIR.parents[1] / "params").glob("*.yaml"):
        other = yaml.safe_load(path.read_text()).get("sensors")
        assert not other or [s["extrinsics"] for s in other] != [s.extrinsics.model_dump() for s in params.sensors]
    for s in params.sensors:  # each sensor's +x (the lowered side) points at the field centre (0, 6)
        t = extrinsics_matrix(s.extrinsics)
        forward = t[:3, 0]
        to_centre = np.array([0.0, 6.0]) - t[:2, 3]
        assert forward[2] == pytest.approx(-math.sin(math.radians(10.0)))
        assert (
            math.degrees(math.acos(forward[:2] @ to_centre / np.linalg.norm(forward[:2]) / np.linalg.norm(to_centre)))
            < 0.01
        )


@pytest.fixture(scope="module")
def suite_recordings(tmp_path_factory):
    """One short clip of each kind of the generalization suite, generated through --suite."""
    entries = yaml.safe_load(SUITE.read_text())["recordings"]
    picks = {}
    for e in entries:
        kind = e["name"].split("_")[0]
        picks.setdefault(kind, e)
    assert sorted(picks) == ["one", "slope", "two", "unknown"]
    root = tmp_path_factory.mktemp("gen")
    short = []
    for e in picks.values():
        e = dict(e, duration_s=2.0, start_s=6.0, columns=512)
        e.update({k: str(SUITE.parent / e[k]) for k in ("sensors", "vehicles_file") if k in e})
        short.append(e)
    suite_file = _write(root / "short.yaml", {"recordings": short})
    assert main(["sim", "--suite", str(suite_file), "--out", str(root / "out")]) == 0
    return {e["name"].split("_")[0]: (e, Recording(root / "out" / e["name"])) for e in short}


def test_one_side_sensors_each_see_the_vehicle_and_the_ground_from_10_m(suite_recordings):
    _, rec = suite_recordings["one"]
    assert rec.sensor_names == ["s1", "s2", "s3"]
    k = len(rec) // 2
    v = rec.ground_truth()[k]["vehicles"][0]
    for name, pts in _yard_points(rec, k).items():
        assert _points_in_box(pts, v["trailer"]) > 50, name
        assert _points_in_box(pts, v["truck"]) > 10, name
        sensor = load_params(rec.sensors_file).sensor(name).extrinsics
        ahead = pts - (sensor.x_m, sensor.y_m, 0.0)
        ground = (pts[:, 2] < 0.1) & (ahead[:, 1] < 0)  # on the yard side
        # The lowest beam (-20.5 deg on an OS1-32, uniform), tilted 10 deg down, meets the ground
        # 6 m / tan(30.5 deg) = 10.2 m away.
        lowest_deg = -float(model_beam_table("OS1-32", 1024).altitude_deg[-1]) + 10.0
        assert np.hypot(ahead[ground, 0], ahead[ground, 1]).min() == pytest.approx(
            6.0 / math.tan(math.radians(lowest_deg)), abs=0.4
        )


# --------------------------------------------------------------------------- the suite


def test_generalization_suite_parses_and_every_case_is_valid():
    entries = yaml.safe_load(SUITE.read_text())["recordings"]
    paper_seeds = {e["seed"] for e in yaml.safe_load((SUITES_DIR / "paper.yaml").read_text())["recordings"]}
    cases = [suite_case(SUITE, i, e, Params()) for i, e in enumerate(entries)]
    assert 10 <= len(cases) <= 14
    assert len({name for name, _, _ in cases}) == len(cases)
    assert not {e["seed"] for e in entries} & paper_seeds
    assert all(20.0 <= c["duration_s"] <= 30.0 for _, c, _ in cases)
    known = Params().vehicles
    unknown_lengths = sorted(
        {v.trailer.length_m for _, c, _ in cases for n, v in c["extra_vehicles"].items() if n in c["vehicles"]}
    )
    assert unknown_lengths[0] >= 6.0 and unknown_lengths[-1] <= 16.0 and len(unknown_lengths) >= 4
    assert not set(unknown_lengths) & {v.trailer.length_m for v in known.values()}
    assert any(len(c["vehicles"]) == 2 and c.get("clutter_near") for _, c, _ in cases)
    assert any(0.03 <= abs(math.tan(math.radians(c.get("slope_deg", 0.0)))) <= 0.04 for _, c, _ in cases)
    assert any([s.name for s in p.sensors] == ["s1", "s2", "s3"] for _, _, p in cases)
    assert len({c["scenario"] for _, c, _ in cases}) >= 6
    for name, clean, params in cases:  # every case places its vehicles and yard
        sim = build_simulation(SimConfig(params=params, **clean))
        assert len(sim.vehicles) == len(clean["vehicles"]), name


def test_suite_refuses_unknown_keys_and_vehicles(tmp_path, capsys):
    bad = _write(tmp_path / "bad.yaml", {"recordings": [{"scenario": "straight", "slope": 2.0}]})
    assert main(["sim", "--suite", str(bad), "--out", str(tmp_path / "o")]) == 2
    assert "entry 0 needs 'scenario' and may have" in capsys.readouterr().err
    unknown = _write(tmp_path / "unknown.yaml", {"recordings": [{"scenario": "straight", "vehicle": "trailer_16m"}]})
    assert main(["sim", "--suite", str(unknown), "--out", str(tmp_path / "o")]) == 2
    assert "entry 0: unknown vehicle(s) trailer_16m" in capsys.readouterr().err
    steep = _write(tmp_path / "steep.yaml", {"recordings": [{"scenario": "straight", "slope_deg": 12.0}]})
    assert main(["sim", "--suite", str(steep), "--out", str(tmp_path / "o")]) == 2
    assert "entry 0: slope_deg must be within ±10 degrees, got 12.0" in capsys.readouterr().err
    late = _write(
        tmp_path / "late.yaml",
        {"recordings": [{"scenario": "straight", "duration_s": 0.2, "columns": 512}, {"scenario": "parking"}]},
    )
    assert main(["sim", "--suite", str(late), "--out", str(tmp_path / "o")]) == 2
    assert "entry 1: unknown scenario 'parking'" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()  # checked before anything is generated


def test_a_suite_is_generated_again_under_other_seeds(tmp_path, capsys):
    """--seed-offset draws every entry again (a held-out check); alone it is an error."""
    import yaml

    short = _write(tmp_path / "short.yaml", {"recordings": [{"scenario": "straight", "seed": 7, "duration_s": 0.2}]})
    scans = {}
    for offset in (0, 100):
        out = tmp_path / f"o{offset}"
        assert main(["sim", "--suite", str(short), "--out", str(out), "--seed-offset", str(offset)]) == 0
        meta = yaml.safe_load((out / "man_tgx_straight" / "meta.yaml").read_text())
        assert meta["seed"] == 7 + offset
        scans[offset] = sorted((out / "man_tgx_straight" / "scans").iterdir())[0].read_bytes()
    assert scans[0] != scans[100]  # other draws
    capsys.readouterr()
    assert main(["sim", "--out", str(tmp_path / "one"), "--seed-offset", "3"]) == 2
    assert "--seed-offset applies to --suite" in capsys.readouterr().err


def test_two_vehicles_with_clutter_beside_them_and_no_collision(suite_recordings):
    entry, rec = suite_recordings["two"]
    gt = rec.ground_truth()
    assert [v["vehicle"] for v in gt[0]["vehicles"]] == entry["vehicles"]
    static = [o for o in rec.meta["static_objects"] if o["kind"] in ("container", "parked_trailer")]
    assert (
        sum(o["kind"] == "parked_trailer" for o in static) == 2 and sum(o["kind"] == "container" for o in static) == 3
    )
    # Vehicle boxes over the clip never come within 1.5 m of a container or parked trailer.
    units = [u for line in gt for v in line["vehicles"] for u in (v["truck"], v["trailer"])]
    boxes = np.vstack(
        [footprint_points(u["center"][:2], *u["dimensions"][:2], math.radians(u["yaw_deg"]), 0.25) for u in units]
    )
    length = {"container": CONTAINER_SIZE_M[0], "parked_trailer": Params().vehicles["man_tgx"].trailer.length_m}
    for o in static:
        pts = footprint_points(o["center"], length[o["kind"]], 2.8, math.radians(o["yaw_deg"]), 0.25)
        assert cKDTree(boxes).query(pts)[0].min() > 1.5, o


def test_clutter_near_puts_containers_and_parked_trailers_beside_the_swept_area():
    def gaps(near: bool) -> list[float]:
        sim = build_simulation(
            SimConfig(
                vehicles=["man_tgx", "volvo_fh"], scenario="straight", seed=209, duration_s=25.0, clutter_near=near
            )
        )
        swept = cKDTree(np.vstack([v.footprint() for v in sim.vehicles]))
        size = {"container": CONTAINER_SIZE_M[:2], "parked_trailer": (13.68, 2.77)}
        return [
            float(swept.query(footprint_points(o["center"], *size[o["kind"]], math.radians(o["yaw_deg"])))[0].min())
            for o in sim.yard.static_objects
            if o["kind"] in size
        ]

    near, spread = gaps(True), gaps(False)
    assert len(near) == 5
    assert all(2.0 < g < 6.0 for g in near), near  # clear of the paths by the 2 m clearance, but right beside them
    assert np.median(spread) > 8.0


def test_sloped_case_has_the_grade_in_the_ground_points(suite_recordings):
    entry, rec = suite_recordings["slope"]
    pts = np.vstack(list(_yard_points(rec, 0).values()))
    ground = pts[np.abs(pts[:, 2] - math.tan(math.radians(entry["slope_deg"])) * pts[:, 0]) < 0.3]
    grade, _ = np.polyfit(ground[:, 0], ground[:, 2], 1)
    assert grade == pytest.approx(math.tan(math.radians(entry["slope_deg"])), abs=0.003)
    assert 0.03 <= abs(grade) <= 0.04
    assert rec.meta["slope_deg"] == entry["slope_deg"]


def test_unknown_case_ground_truth_and_recording(suite_recordings):
    entry, rec = suite_recordings["unknown"]
    extra = load_vehicles_file(UNKNOWN)
    v = rec.ground_truth()[5]["vehicles"][0]
    assert v["vehicle"] == "unknown_" + entry["vehicle"]
    assert v["trailer"]["dimensions"][0] == extra[entry["vehicle"]].trailer.length_m
    assert v["trailer"]["points"] > 100
    assert set(load_params(rec.sensors_file).vehicles) == set(Params().vehicles)
    assert json.loads((rec.path / "ground_truth.jsonl").read_text().splitlines()[0])["vehicles"][0][
        "vehicle"
    ].startswith("unknown_")
