"""``i2v-loc params``: show, check and export the parameter model."""

from __future__ import annotations

import json

from i2v_loc.params import dump_yaml, json_schema, load_params


def register(sub) -> None:
    p = sub.add_parser("params", help="dump defaults, check files, export the JSON Schema")
    ps = p.add_subparsers(dest="params_command", metavar="ACTION", required=True)

    dump = ps.add_parser("dump", help="print the merged parameters (defaults if no file) as YAML")
    dump.add_argument("files", nargs="*", help="parameter files merged in order over the defaults")
    dump.add_argument("--section", action="append", help="only these top-level sections (repeatable)")
    dump.set_defaults(func=_dump)

    check = ps.add_parser("check", help="validate parameter files; exit 2 with the errors if invalid")
    check.add_argument("files", nargs="+")
    check.set_defaults(func=_check)

    schema = ps.add_parser("schema", help="print the JSON Schema of the parameter model")
    schema.add_argument(
        "--state", action="store_true", help="the schema of the state line (run JSONL, WebSocket) instead"
    )
    schema.set_defaults(func=_schema)


def _dump(args) -> int:
    print(dump_yaml(load_params(*args.files), args.section), end="")
    return 0


def _check(args) -> int:
    params = load_params(*args.files)
    print(f"ok: {', '.join(args.files)} ({len(params.sensors)} sensors, {len(params.vehicles)} vehicles)")
    return 0


def _schema(args) -> int:
    if args.state:
        from i2v_loc.formats.state_schema import state_json_schema

        print(json.dumps(state_json_schema(), indent=2))
        return 0
    print(json.dumps(json_schema(), indent=2))
    return 0
