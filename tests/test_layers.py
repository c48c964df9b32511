"""The layer contract of docs/DESIGN.md section 1: no module imports from a layer above its own.

The contract is import-linter's, in pyproject.toml (``[tool.importlinter]``): the ``layers`` contract and
a ``forbidden`` one (the store never imports the simulator). These tests run it on this checkout
(top-level and lazy imports alike), check that the layers name every module directly under ``twisted/``
(so a new module cannot slip past them), and show that it does fail: a copy of the tree with one import
pointing up breaks it.
"""

from __future__ import annotations

import pkgutil
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

pytest.importorskip("importlinter")

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("twisted", "cli", "migrations")
# import-linter puts the working directory first on sys.path, so the tree in `cwd` is the one analysed
LINT = (
    "import sys; from importlinter.cli import lint_imports; "
    "sys.exit(lint_imports(no_cache=True, no_logo=True))"
)


def _lint(root: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-c", LINT], cwd=root, capture_output=True, text=True, timeout=120, check=False
    )


def _contract(contract_id: str) -> dict:
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["importlinter"]
    (contract,) = [c for c in config["contracts"] if c["id"] == contract_id]
    return contract


def _layer_modules(contract_id: str = "layers") -> set[str]:
    names = set()
    for layer in _contract(contract_id)["layers"]:
        for part in layer.replace(":", "|").split("|"):
            names.add(part.strip().strip("()"))
    return names


def test_the_code_keeps_the_layer_contract() -> None:
    result = _lint(ROOT)
    assert result.returncode == 0, result.stdout + result.stderr
    assert ", 0 broken" in result.stdout and "KEPT" in result.stdout


def test_the_contract_names_every_module_of_twisted() -> None:
    present = {f"twisted.{m.name}" for m in pkgutil.iter_modules([str(ROOT / "twisted")])}
    missing = present - _layer_modules()
    assert not missing, f"add to a layer in pyproject.toml [tool.importlinter]: {sorted(missing)}"


def test_the_render_contract_names_every_part_of_twisted_render() -> None:
    """render is split into parts (geometry, draw, gl, stored); a new part must take its place."""
    (container,) = _contract("render-parts")["containers"]
    present = {
        m.name for m in pkgutil.iter_modules([str(ROOT / "twisted" / "render")]) if not m.name.startswith("_")
    }
    assert container == "twisted.render" and present == _layer_modules("render-parts")


def _lint_with(tmp_path: Path, module: str, wrong_import: str) -> subprocess.CompletedProcess[str]:
    """The contracts run on a copy of the tree in which ``module`` (a path) imports ``wrong_import``."""
    for package in PACKAGES:
        shutil.copytree(ROOT / package, tmp_path / package, ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copy(ROOT / "pyproject.toml", tmp_path / "pyproject.toml")
    with (tmp_path / module).open("a") as f:
        f.write(f"\n\ndef _wrong() -> None:\n    import {wrong_import}  # noqa: F401\n")
    return _lint(tmp_path)


def test_an_import_from_a_higher_layer_breaks_the_contract(tmp_path: Path) -> None:
    result = _lint_with(tmp_path, "twisted/topology.py", "twisted.planner")
    assert result.returncode != 0
    assert "twisted.topology is not allowed to import twisted.planner" in result.stdout, result.stdout


def test_a_drawing_that_reads_the_store_breaks_the_render_contracts(tmp_path: Path) -> None:
    result = _lint_with(tmp_path, "twisted/render/draw.py", "twisted.store.models")
    assert result.returncode != 0
    assert "twisted.render.draw is not allowed to import twisted.store" in result.stdout, result.stdout
