"""The ``i2v-loc`` command. Each subcommand lives in ``i2v_loc.commands.<name>`` and exposes
``register(subparsers)``; only the module of the subcommand that runs is imported (all of them
for the overview help), so heavy libraries load only for the subcommand that needs them, and
``--version`` loads none."""

from __future__ import annotations

import argparse
import importlib
import os
import sys

from i2v_loc import __version__

COMMANDS = ["sim", "realism", "params", "calibrate", "run", "detect", "eval", "sweep", "serve", "bench", "sources"]


class UserError(Exception):
    """An error caused by the user's input: printed without a traceback, exit code 2."""


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The parser with every subcommand, or with ``only`` that one."""
    parser = argparse.ArgumentParser(prog="i2v-loc", description=__doc__.split("\n")[0] if __doc__ else None)
    parser.add_argument("--version", action="version", version=f"i2v-loc {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in [only] if only else COMMANDS:
        try:
            module = importlib.import_module(f"i2v_loc.commands.{name}")
        except ModuleNotFoundError as err:
            if err.name == f"i2v_loc.commands.{name}":
                continue
            raise
        module.register(sub)
    return parser


MATH_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "OMP_NUM_THREADS")


def pin_math_threads() -> None:
    """One BLAS / OpenMP thread unless the environment already says how many. A frame's small
    matrices gain nothing from more, and a multi-threaded BLAS sums in an order that depends on
    the machine's load, so the same recording could give other estimates on a busy machine. Set
    before numpy loads; spawned evaluation workers inherit it."""
    for name in MATH_THREAD_VARIABLES:
        os.environ.setdefault(name, "1")


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    pin_math_threads()
    if argv == ["--version"]:
        print(f"i2v-loc {__version__}")
        return 0
    parser = build_parser(argv[0] if argv and argv[0] in COMMANDS else None)
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    from i2v_loc.params import ParamsError

    try:
        return int(args.func(args) or 0)
    except (UserError, ParamsError, FileNotFoundError) as err:
        print(f"i2v-loc {args.command}: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # The reader went away (e.g. `i2v-loc run ... | head`): not an error of ours.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0


if __name__ == "__main__":
    # Run through the package so exception classes are the ones the commands import.
    from i2v_loc.__main__ import main as _main  # noqa: F401  (runs and exits)
