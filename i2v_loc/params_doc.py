"""The parameter reference (docs/parameters.md), generated from the JSON Schema of the model.

    python -m i2v_loc.params_doc > docs/parameters.md

tests/test_params.py fails when the committed file differs from what this prints.
"""

from __future__ import annotations

import json
import sys

from i2v_loc.params import json_schema

HEADER = """# Parameters

Generated from the parameter model (`i2v_loc/params.py`) by `python -m i2v_loc.params_doc > docs/parameters.md`;
do not edit by hand (a test fails when this file and the model differ). Units are in the names. Every
number has physical bounds: a value outside them is refused (a 422 from the service, exit 2 from the CLI).
"""

BOUNDS = (("minimum", ">="), ("exclusiveMinimum", ">"), ("maximum", "<="), ("exclusiveMaximum", "<"))


def render() -> str:
    schema = json_schema()
    defs = schema["$defs"]
    out = [HEADER]
    for section, prop in schema["properties"].items():
        ref, shape = _container(prop)
        out.append(f"## `{section}`\n")
        described = prop.get("description", "").rstrip(".")
        sizes = [
            f"{word} {prop[key]}"
            for key, word in (
                ("minItems", "at least"),
                ("maxItems", "at most"),
                ("minProperties", "at least"),
                ("maxProperties", "at most"),
            )
            if key in prop
        ]
        size = f" ({', '.join(sizes)} entries)" if sizes else ""
        text = " ".join(
            filter(None, [described and described + ".", shape and f"A {shape} of the fields below{size}."])
        )
        if text:
            out.append(text + "\n")
        out.extend(_tables(defs, ref, section))
    return "\n".join(out).rstrip() + "\n"


def _container(prop: dict) -> tuple[str, str]:
    """(name of the model in $defs, 'list' / 'map from a name to' / '') of a section."""
    if "$ref" in prop:
        return _name(prop["$ref"]), ""
    if "items" in prop:
        return _name(prop["items"]["$ref"]), "list"
    return _name(prop["additionalProperties"]["$ref"]), "map from names to objects"


def _tables(defs: dict, model: str, path: str) -> list[str]:
    node = defs[model]
    rows = ["| field | type | default | allowed | meaning |", "|---|---|---|---|---|"]
    nested: list[tuple[str, str]] = []
    for field, prop in node.get("properties", {}).items():
        if "$ref" in prop:
            nested.append((_name(prop["$ref"]), f"{path}.{field}"))
            rows.append(f"| `{field}` | object | see `{path}.{field}` | | {_cell(prop.get('description', ''))} |")
            continue
        required = field in node.get("required", [])
        default = "required" if required else _cell(json.dumps(prop.get("default")))
        rows.append(
            f"| `{field}` | {_type(prop)} | {default} | {_allowed(prop)} | {_cell(prop.get('description', ''))} |"
        )
    out = []
    if node.get("description"):
        out.append(_cell(node["description"]) + "\n")
    out.append("\n".join(rows) + "\n")
    for ref, sub_path in nested:
        out.append(f"### `{sub_path}`\n")
        out.extend(_tables(defs, ref, sub_path))
    return out


def _type(prop: dict) -> str:
    if "enum" in prop:
        return "one of"
    if "anyOf" in prop:
        return " or ".join(p.get("type", "?") for p in prop["anyOf"])
    return prop.get("type", "?")


def _allowed(prop: dict) -> str:
    if "enum" in prop:
        return ", ".join(f"`{v}`" for v in prop["enum"])
    parts = [f"{sym} {prop[key]:g}" for key, sym in BOUNDS if key in prop]
    if "minLength" in prop or "maxLength" in prop:
        parts.append(f"{prop.get('minLength', 0)}-{prop.get('maxLength', '')} characters")
    if "pattern" in prop:
        parts.append(f"pattern `{prop['pattern']}`")
    return _cell(", ".join(parts))


def _cell(text: str) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def _name(ref: str) -> str:
    return ref.split("/")[-1]


if __name__ == "__main__":
    sys.stdout.write(render())
