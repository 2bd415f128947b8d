"""The parameter model: defaults, YAML files, validation messages, patches, schema."""

from __future__ import annotations

import json
import math

import pytest
from conftest import REPO

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


def test_paper_field_distances_match_the_paper():
    params = load_params(REPO / "params" / "sensors_paper_field.yaml")
    pos = {s.name: (s.extrinsics.x_m, s.extrinsics.y_m) for s in params.sensors}
    dist = lambda a, b: math.dist(pos[a], pos[b])  # noqa: E731
    assert dist("l1", "l2") == pytest.approx(19.2, abs=0.02)
    assert dist("l2", "l3") == pytest.approx(40.5, abs=0.02)
    assert dist("l3", "l4") == pytest.approx(19.2, abs=0.02)
    assert dist("l1", "l4") == pytest.approx(15.0, abs=0.02)
    assert all(s.model == "OS1-32" and s.beams == 32 for s in params.sensors)


def test_default_vehicles_hold_table_1_volumes():
    vehicles = Params().vehicles
    # Table 1 of the paper, volume in m^3 (H x W x L)
    expected = {"twizy": (4.71, 10.94), "man_tgx": (21.94, 96.63), "volvo_fh": (15.94, 39.38)}
    assert set(vehicles) == set(expected)
    for name, (truck_m3, trailer_m3) in expected.items():
        assert vehicles[name].truck.volume_m3 == pytest.approx(truck_m3, abs=0.02)
        assert vehicles[name].trailer.volume_m3 == pytest.approx(trailer_m3, abs=0.02)


def test_committed_sensor_file_equals_the_model_defaults():
    data = read_yaml(REPO / "params" / "sensors_paper_field.yaml")
    assert data == {"sensors": Params().model_dump(mode="json")["sensors"]}


def test_vehicle_data_lives_in_the_model_only():
    assert not (REPO / "params" / "vehicles.yaml").exists()


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


# ------------------------------------------------------------------ physical bounds


def _numeric_fields(schema: dict):
    """(path, property schema) of every number or integer field of the model."""
    for model_name, model in schema["$defs"].items():
        for field, prop in model.get("properties", {}).items():
            if prop.get("type") in ("number", "integer") and "enum" not in prop:
                yield f"{model_name}.{field}", prop


def test_every_number_has_physical_bounds():
    fields = list(_numeric_fields(json_schema()))
    assert len(fields) > 50  # every section is walked
    unbounded = [
        path
        for path, prop in fields
        if not ({"minimum", "exclusiveMinimum"} & set(prop) and {"maximum", "exclusiveMaximum"} & set(prop))
    ]
    assert unbounded == []


@pytest.mark.parametrize(
    "patch, field",
    [
        ({"vehicles": {"twizy": None, "man_tgx": None, "volvo_fh": None}}, "vehicles"),
        ({"sensors": [{"name": "l1", "extrinsics": {"x_m": 1e300}}]}, "sensors.0.extrinsics.x_m"),
        ({"classification": {"min_truck_points": 10**20}}, "classification.min_truck_points"),
        ({"tracking": {"measurement_noise_m": 1e-300}}, "tracking.measurement_noise_m"),
        ({"tracking": {"process_noise": 1e300}}, "tracking.process_noise"),
        ({"region": {"x_max_m": 1e300}}, "region.x_max_m"),
        ({"vehicles": {"twizy": {"vehicle_volume_tolerance_m3": 1e300}}}, "vehicles.twizy.vehicle_volume_tolerance_m3"),
    ],
)
def test_absurd_values_are_refused(patch, field):
    with pytest.raises(ParamsError, match=field.replace(".", r"\.")):
        apply_patch(Params(), patch)


def test_many_unknown_keys_are_refused_without_rebuilding_the_schema(monkeypatch):
    from i2v_loc import params as params_module

    params_module._cached_schema.cache_clear()
    built = []
    original = Params.model_json_schema.__func__
    monkeypatch.setattr(
        Params, "model_json_schema", classmethod(lambda cls, *a, **k: built.append(1) or original(cls, *a, **k))
    )
    with pytest.raises(ParamsError) as err:
        apply_patch(Params(), {"clustering": {f"unknown_{i}": 1 for i in range(200)}})
    assert len(built) == 1
    lines = str(err.value).splitlines()
    assert lines[0] == "patch: 200 errors; the first 20 follow, 180 more not listed"
    assert len(lines) == 21 and all("Extra inputs are not permitted" in line for line in lines[1:])
    params_module._cached_schema.cache_clear()


# ------------------------------------------------------------------ the parameter file


def test_saved_file_is_flushed_and_keeps_the_previous_version(tmp_path, monkeypatch):
    import os

    synced = []
    real_fsync = os.fsync
    monkeypatch.setattr(os, "fsync", lambda fd: synced.append(fd) or real_fsync(fd))
    path = tmp_path / "p.yaml"
    first = apply_patch(Params(), {"clustering": {"tolerance_m": 0.5}})
    second = apply_patch(Params(), {"clustering": {"tolerance_m": 0.6}})
    save_params(first, path)
    save_params(second, path)
    assert len(synced) >= 2
    assert load_params(path) == second
    assert load_params(tmp_path / "p.yaml.prev") == first
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p.yaml", "p.yaml.prev"]


@pytest.mark.parametrize("keep", [0.5, 0.9])
def test_a_saved_file_cut_short_is_refused_naming_the_lost_sections(tmp_path, keep):
    path = tmp_path / "p.yaml"
    save_params(Params(), path)
    save_params(Params(), path)
    text = path.read_text()
    cut = text[: int(len(text) * keep)]
    cut = cut[: cut.rindex("\n") + 1]  # cut at a line end, so what is left is valid YAML
    path.write_text(cut)
    present = set(read_yaml_sections(cut))
    lost = [s for s in Params.model_fields if s not in present]
    with pytest.raises(ParamsError) as err:
        load_params(path)
    message = str(err.value)
    assert "\n" not in message and str(path) in message and "incomplete" in message
    assert f"{path}.prev" in message
    if lost:
        assert "sections lost: " + ", ".join(lost) in message


def read_yaml_sections(text: str) -> list[str]:
    return [line.split(":")[0] for line in text.splitlines() if line and line[0].isalpha()]


def test_hand_written_subset_file_still_loads(tmp_path):
    path = tmp_path / "p.yaml"
    path.write_text("clustering:\n  tolerance_m: 0.5\n")
    assert load_params(path).clustering.tolerance_m == 0.5


def test_parameter_reference_in_docs_is_generated_from_the_model():
    from i2v_loc.params_doc import render

    committed = (REPO / "docs" / "parameters.md").read_text()
    assert committed == render(), "docs/parameters.md drifted: python -m i2v_loc.params_doc > docs/parameters.md"
    for section in Params.model_fields:
        assert f"## `{section}`" in committed
    assert "| `measurement_noise_m` | number | 0.15 | >= 0.001, <= 10 |" in committed
