"""The parameter model: defaults, YAML files, validation messages, patches, schema."""

from __future__ import annotations

import json
import math

import pytest

from i2v_loc.cli import main
from i2v_loc.params import (
    Params,
    ParamsError,
    apply_patch,
    deep_merge,
    json_schema,
    load_params,
    read_yaml,
    save_params,
)

from conftest import REPO


def test_paper_field_distances_match_the_paper():
    params = load_params(REPO / "params" / "sensors_paper_field.yaml")
    pos = {s.name: (s.extrinsics.x_m, s.extrinsics.y_m) for s in params.sensors}
    dist = lambda a, b: math.dist(pos[a], pos[b])  # noqa: E731
    assert dist("l1", "l2") == pytest.approx(19.2, abs=0.02)
    assert dist("l2", "l3") == pytest.approx(40.5, abs=0.02)
    assert dist("l3", "l4") == pytest.approx(19.2, abs=0.02)
    assert dist("l1", "l4") == pytest.approx(15.0, abs=0.02)
    assert all(s.model == "OS1-32" and s.beams == 32 for s in params.sensors)


def test_vehicle_file_holds_table_1_volumes():
    vehicles = load_params(REPO / "params" / "vehicles.yaml").vehicles
    # Table 1 of the paper, volume in m^3 (H x W x L)
    expected = {"twizy": (4.71, 10.94), "man_tgx": (21.94, 96.63), "volvo_fh": (15.94, 39.38)}
    for name, (truck_m3, trailer_m3) in expected.items():
        assert vehicles[name].truck.volume_m3 == pytest.approx(truck_m3, abs=0.02)
        assert vehicles[name].trailer.volume_m3 == pytest.approx(trailer_m3, abs=0.02)


@pytest.mark.parametrize("name", ["sensors_paper_field.yaml", "vehicles.yaml"])
def test_committed_parameter_files_equal_the_model_defaults(name):
    data = read_yaml(REPO / "params" / name)
    defaults = Params().model_dump(mode="json")
    for section, value in data.items():
        assert value == defaults[section], f"params/{name} section {section} drifted from the model"


def test_invalid_value_names_file_key_and_range(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("clustering:\n  tolerance_m: -1\n")
    with pytest.raises(ParamsError) as err:
        load_params(bad)
    text = str(err.value)
    assert str(bad) in text and "clustering.tolerance_m" in text and "> 0" in text


def test_unknown_key_is_an_error(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("clustering:\n  tolerance: 0.5\n")
    with pytest.raises(ParamsError, match="clustering.tolerance"):
        load_params(bad)


def test_patch_is_validated_and_leaves_the_original_untouched():
    params = Params()
    patched = apply_patch(params, {"clustering": {"tolerance_m": 0.4}})
    assert patched.clustering.tolerance_m == 0.4
    assert params.clustering.tolerance_m == 0.7
    with pytest.raises(ParamsError, match="tracking.min_hits"):
        apply_patch(params, {"tracking": {"min_hits": 0}})


def test_merge_patch_semantics():
    assert deep_merge({"a": {"b": 1, "c": 2}}, {"a": {"b": None, "d": 3}}) == {"a": {"c": 2, "d": 3}}


def test_save_and_load_round_trip(tmp_path):
    params = apply_patch(Params(), {"region": {"ground_distance_threshold_m": 0.25}})
    path = tmp_path / "p.yaml"
    save_params(params, path)
    assert load_params(path) == params
    assert not list(tmp_path.glob("*.tmp"))


def test_schema_exports_ranges_and_forbids_unknown_keys():
    schema = json_schema()
    tol = schema["$defs"]["ClusteringParams"]["properties"]["tolerance_m"]
    assert tol["exclusiveMinimum"] == 0 and tol["maximum"] == 5
    assert schema["$defs"]["ClusteringParams"]["additionalProperties"] is False


def test_cli_schema_and_check(tmp_path, capsys):
    assert main(["params", "schema"]) == 0
    assert "properties" in json.loads(capsys.readouterr().out)
    bad = tmp_path / "bad.yaml"
    bad.write_text("sensors: 3\n")
    assert main(["params", "check", str(bad)]) == 2
    assert "sensors" in capsys.readouterr().err


@pytest.mark.parametrize("value", [True, "0.6", [0.6]])
def test_values_are_not_coerced_across_types(value):
    with pytest.raises(ParamsError, match="clustering.tolerance_m"):
        apply_patch(Params(), {"clustering": {"tolerance_m": value}})
    assert apply_patch(Params(), {"clustering": {"tolerance_m": 1}}).clustering.tolerance_m == 1.0


def test_at_least_one_sensor_and_a_known_reference_sensor():
    with pytest.raises(ParamsError, match="sensors"):
        apply_patch(Params(), {"sensors": []})
    with pytest.raises(ParamsError, match="reference_sensor 'l9' is not a configured sensor"):
        apply_patch(Params(), {"calibration": {"reference_sensor": "l9"}})
    assert apply_patch(Params(), {"calibration": {"reference_sensor": "l3"}}).calibration.reference_sensor == "l3"


def test_malformed_yaml_gives_one_line_with_the_position(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("region:\n  x_min_m: [1, 2\n")
    with pytest.raises(ParamsError) as err:
        load_params(bad)
    message = str(err.value)
    assert "\n" not in message and f"{bad}:" in message and "not valid YAML" in message
