"""A pipeline's preset: a YAML file of ``params/presets`` holding its values where they differ from
the parameter model's defaults. It fills only the fields the given parameters leave at the model
default: a value the user set (any value other than the default) always wins over the preset."""

from __future__ import annotations

import functools
from importlib import resources
from pathlib import Path

from i2v_loc.params import Params, apply_patch, read_yaml

REPO_PRESETS = Path(__file__).resolve().parents[2] / "params" / "presets"


def preset_path(name: str) -> Path:
    """``params/presets/<name>.yaml``: in a wheel the folder ships as ``i2v_loc/presets`` (setup.py)."""
    packaged = resources.files("i2v_loc").joinpath("presets")
    folder = Path(str(packaged)) if packaged.is_dir() else REPO_PRESETS
    return folder / f"{name}.yaml"


@functools.cache
def _preset(name: str) -> dict:
    return read_yaml(preset_path(name))


def with_preset(params: Params, name: str) -> Params:
    """``params`` with the preset ``name`` filled in where they hold the model default."""
    patch = _unset_only(_preset(name), params.model_dump(mode="json"), Params().model_dump(mode="json"))
    return apply_patch(params, patch, source=f"preset {name}") if patch else params


def _unset_only(preset: dict, given: dict, defaults: dict) -> dict:
    """The part of ``preset`` whose fields are at their default in ``given``."""
    out = {}
    for key, value in preset.items():
        if isinstance(value, dict):
            sub = _unset_only(value, given.get(key, {}), defaults.get(key, {}))
            if sub:
                out[key] = sub
        elif given.get(key) == defaults.get(key):
            out[key] = value
    return out
