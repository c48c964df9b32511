"""The scripts in bench/ share code through the package bench/lib, never by importing one another.

A script is run as ``python bench/NAME.py``, so its folder is first on ``sys.path`` and ``from lib.steps
import ...`` finds bench/lib/steps.py. A name imported from bench/lib must be defined there, and a script
importing another script (which a deletion of that script would break unseen) fails here.
"""

from __future__ import annotations

import ast
import importlib
import sys
from pathlib import Path

BENCH = Path(__file__).resolve().parents[1] / "bench"
SCRIPTS = sorted(BENCH.glob("*.py"))
# bench/probe.py reads the trials of bench/probe_store.py, its other half (issue 37), when it is there.
SIBLINGS_ALLOWED = {("probe.py", "probe_store")}


def _imports(path: Path) -> list[tuple[str, list[str]]]:
    """(module, names) of every import in a file, lazy ones inside functions included."""
    found: list[tuple[str, list[str]]] = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found.append((node.module, [alias.name for alias in node.names]))
        elif isinstance(node, ast.Import):
            found += [(alias.name, []) for alias in node.names]
    return found


def test_no_script_imports_another_script() -> None:
    scripts = {p.stem for p in SCRIPTS}
    bad = [
        f"{p.name} imports {module}"
        for p in SCRIPTS
        for module, _ in _imports(p)
        if module.split(".")[0] in scripts and (p.name, module) not in SIBLINGS_ALLOWED
    ]
    assert not bad, bad


def test_the_names_scripts_import_from_bench_lib_exist() -> None:
    sys.path.insert(0, str(BENCH))
    try:
        missing = [
            f"{p.name}: {module}.{name}"
            for p in SCRIPTS
            for module, names in _imports(p)
            if module == "lib" or module.startswith("lib.")
            for name in names
            if not hasattr(importlib.import_module(module), name)
        ]
    finally:
        sys.path.remove(str(BENCH))
    assert not missing, missing
    assert any(module.startswith("lib.") for p in SCRIPTS for module, _ in _imports(p))
