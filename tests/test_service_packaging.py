"""A non-editable install (a wheel, as ``pip install .`` and the Dockerfile make) finds its data:
the sample recordings and the benchmark suites travel inside the package."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest
from conftest import REPO

pytestmark = pytest.mark.timeout(600)


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """A fresh venv holding the wheel of this checkout; the dependencies come from the test's own
    environment through a path file (installing open3d and the rest again would take minutes)."""
    tmp = tmp_path_factory.mktemp("wheel")
    build = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(tmp / "dist"), str(REPO)],
        capture_output=True,
        text=True,
        check=False,
    )
    assert build.returncode == 0, build.stderr
    (wheel,) = (tmp / "dist").glob("i2v_loc-*.whl")
    venv = tmp / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True)
    python = venv / "bin" / "python"
    site = Path(
        subprocess.run(
            [str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
    )
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    install = subprocess.run(
        [sys.executable, "-m", "pip", "--python", str(python), "install", "--no-deps", "--no-index", "-q", str(wheel)],
        capture_output=True,
        text=True,
        env=env,
        check=False,
    )
    assert install.returncode == 0, install.stderr
    # After the install (else pip finds the checkout's editable install there and installs nothing).
    (site / "dependencies.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    run_dir = tmp / "elsewhere"  # not the checkout: nothing found by accident
    run_dir.mkdir()
    return venv, site, env, run_dir


def _run(installed, *args):
    venv, _, env, run_dir = installed
    return subprocess.run(
        [str(venv / "bin" / "i2v-loc"), *args],
        capture_output=True,
        text=True,
        env=env,
        cwd=run_dir,
        timeout=500,
        check=False,
    )


def test_the_wheel_holds_the_samples_and_imports_from_the_venv(installed):
    venv, site, env, run_dir = installed
    code = (
        "import i2v_loc, i2v_loc.resources as r; print(i2v_loc.__file__); print(r.samples_dir()); "
        "print(sorted(p.name for p in r.suites_dir().glob('*.yaml')))"
    )
    done = subprocess.run(
        [str(venv / "bin" / "python"), "-c", code], capture_output=True, text=True, env=env, cwd=run_dir, check=True
    )
    module, samples, suites = done.stdout.splitlines()
    assert module.startswith(str(site)) and samples == str(site / "i2v_loc" / "samples")
    assert "paper.yaml" in suites
    assert (site / "i2v_loc" / "samples" / "man_tgx_docking" / "scans" / "l1.npz").is_file()


def test_bench_runs_on_the_packaged_sample(installed):
    _, site, _, _ = installed
    sample = site / "i2v_loc" / "samples" / "man_tgx_docking"
    quick = ["--scaling", "none", "--no-open3d", "--realdata", "none", "--warmup", "5"]
    done = _run(installed, "bench", str(sample), "--json", "-", "--method", "paper", *quick)
    assert done.returncode == 0, done.stderr
    figures = json.loads(done.stdout)
    assert figures["recording"] == str(sample)
    assert figures["frames"] == 60 - 5  # the sample's frames less the warm-up


def test_sim_finds_the_packaged_suites(installed, tmp_path):
    # An unknown suite name: the answer lists the suites the installed package ships.
    done = _run(installed, "sim", "--suite", "no_such_suite", "--out", str(tmp_path / "out"))
    assert done.returncode == 2 and "paper" in done.stderr.split("one of:")[1], done.stderr
