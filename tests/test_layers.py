"""Imports point down only (docs/pipeline.md, Layers): a stage never imports a pipeline, a command,
the service or the evaluation; neither do the plain values the pipelines share."""

import ast
from pathlib import Path

import pytest
from conftest import REPO

ABOVE_STAGES = ("i2v_loc.pipelines", "i2v_loc.commands", "i2v_loc.evaluation", "i2v_loc.cli", "service")


def imported_modules(source: str, package: str) -> set[str]:
    """Every module (and imported name) ``source`` imports, at any depth (also inside functions);
    relative imports resolved from ``package``."""
    found = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom):
            parts = package.split(".")
            base = ".".join([*parts[: len(parts) - node.level + 1], node.module or ""] if node.level else [node.module])
            found |= {base} | {f"{base}.{alias.name}" for alias in node.names}
    return found


def upward(source: str, package: str) -> list[str]:
    return sorted(
        m for m in imported_modules(source, package) if any(m == f or m.startswith(f + ".") for f in ABOVE_STAGES)
    )


def module_source(path: Path) -> tuple[str, str]:
    return path.read_text(), ".".join(path.relative_to(REPO).parts[:-1])


@pytest.mark.parametrize("path", sorted((REPO / "i2v_loc" / "stages").glob("*.py")), ids=lambda p: p.name)
def test_stages_import_no_layer_above_them(path):
    assert upward(*module_source(path)) == []


@pytest.mark.parametrize("name", ["results.py", "params.py", "geometry.py", "frame.py", "clouds.py"])
def test_shared_values_import_no_layer_above_the_stages(name):
    assert upward(*module_source(REPO / "i2v_loc" / name)) == []


def test_the_walk_finds_lazy_and_relative_imports():
    source = "import numpy\n\ndef f():\n    from ..pipelines.paper import PaperPipeline\n    import service.core\n"
    assert upward(source, "i2v_loc.stages") == [
        "i2v_loc.pipelines.paper",
        "i2v_loc.pipelines.paper.PaperPipeline",
        "service.core",
    ]
    assert upward("from .primitives import voxel_keys\n", "i2v_loc.stages") == []
