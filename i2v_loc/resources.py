"""Data shipped with i2v-loc: the sample recordings and the benchmark suites.

A wheel carries the repository's ``samples/`` folder as ``i2v_loc/samples`` (see setup.py), found
here through ``importlib.resources``; a source checkout (editable install, PYTHONPATH) uses the
repository's ``samples/`` folder itself.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

REPO_SAMPLES = Path(__file__).resolve().parents[1] / "samples"


def samples_dir() -> Path:
    """The folder of the sample recordings and suites (``suites/``)."""
    packaged = resources.files("i2v_loc").joinpath("samples")
    if packaged.is_dir():  # installed from a wheel: a real folder (wheels install unzipped)
        return Path(str(packaged))
    return REPO_SAMPLES


def sample_recording(name: str) -> Path:
    """A committed sample recording, e.g. ``man_tgx_docking``."""
    return samples_dir() / name


def suites_dir() -> Path:
    """The folder of the benchmark suites (``paper.yaml``, ...)."""
    return samples_dir() / "suites"
