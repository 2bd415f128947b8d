"""The command line imports only what the subcommand that runs needs; ``--version`` nothing heavy."""

from __future__ import annotations

import os
import subprocess
import sys

from conftest import REPO

HEAVY = ("numpy", "pydantic", "scipy", "numba", "open3d", "i2v_loc.params")


def imported_after(code: str) -> set[str]:
    script = f"import sys\n{code}\nprint(' '.join(sorted(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", script], cwd=REPO, capture_output=True, text=True, check=True)
    return set(out.stdout.split())


def test_version_imports_no_heavy_library():
    modules = imported_after("from i2v_loc.cli import main\nassert main(['--version']) == 0")
    assert not modules & set(HEAVY), modules & set(HEAVY)


def test_a_subcommand_registers_only_its_own_module():
    modules = imported_after("from i2v_loc.cli import build_parser\nbuild_parser('params')")
    commands = {m for m in modules if m.startswith("i2v_loc.commands.")}
    assert commands == {"i2v_loc.commands.params"}
    everything = imported_after("from i2v_loc.cli import build_parser\nbuild_parser()")
    assert {"i2v_loc.commands.bench", "i2v_loc.commands.sim", "i2v_loc.commands.serve"} <= everything


def test_a_command_runs_numpy_on_one_blas_thread_unless_told_otherwise():
    probe = (
        "import os\n"
        "from i2v_loc.cli import main\n"
        "main(['params', 'check', 'params/sensors_paper_field.yaml'])\n"
        "import numpy  # noqa: F401\nfrom threadpoolctl import threadpool_info\n"
        "print(sorted({p['num_threads'] for p in threadpool_info() if p['user_api'] == 'blas'}))"
    )
    clean = {k: v for k, v in os.environ.items() if not k.endswith("_NUM_THREADS")}
    pinned = subprocess.run([sys.executable, "-c", probe], cwd=REPO, env=clean, capture_output=True, text=True)
    assert pinned.stdout.strip().splitlines()[-1] == "[1]", pinned.stdout + pinned.stderr
    told = subprocess.run(
        [sys.executable, "-c", probe],
        cwd=REPO,
        env={**clean, "OPENBLAS_NUM_THREADS": "2"},
        capture_output=True,
        text=True,
    )
    assert told.stdout.strip().splitlines()[-1] == "[2]", told.stdout + told.stderr
