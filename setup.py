"""The packages of the wheel (metadata: pyproject.toml). The repository's ``samples/`` folder ships
inside it as ``i2v_loc/samples`` (found through importlib.resources, see i2v_loc/resources.py), so a
non-editable install (``pip install .``, the Dockerfile) has the sample recordings and the suites;
``params/presets`` as ``i2v_loc/presets`` (the pipelines' presets, i2v_loc/pipelines/presets.py)."""

from setuptools import find_namespace_packages, setup

setup(
    packages=[*find_namespace_packages(include=["i2v_loc*", "service*"]), "i2v_loc.samples", "i2v_loc.presets"],
    package_dir={"i2v_loc.samples": "samples", "i2v_loc.presets": "params/presets"},
    package_data={
        "service": ["static/*"],
        "i2v_loc.samples": ["**/*.yaml", "**/*.jsonl", "**/*.json", "**/*.npz", "**/*.md"],
        "i2v_loc.presets": ["*.yaml"],
    },
)
