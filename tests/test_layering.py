"""The one-way data flow of DESIGN.md, checked on the source: estimator never
imports sim (nor scenarios or plots), sim never imports estimator, the shared
packages (rollout, eom) import neither, plots imports no physics, and nothing
imports the dynprop facade."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
FORBIDDEN = {
    "estimator": {"sim", "scenarios", "plots", "dynprop"},
    "sim": {"estimator", "scenarios", "plots", "dynprop"},
    "eom": {"sim", "estimator", "scenarios", "plots", "rollout", "dynprop"},
    "rollout": {"sim", "estimator", "scenarios", "plots", "eom", "dynprop"},
    "plots": {"sim", "estimator", "scenarios", "eom", "rollout", "dynprop"},
    # The API is a facade over scenarios: nothing below it may depend on it.
    "scenarios": {"dynprop"},
}


def _package(dotted: str) -> str:
    """The package an absolute import names: the folder under the dynprop namespace
    (``dynprop.sim.truth`` → ``sim``), ``dynprop`` for the facade itself."""
    parts = dotted.split(".")
    if parts[0] == "dynprop" and len(parts) > 1 and parts[1] in FORBIDDEN:
        return parts[1]
    return parts[0]


def imported_packages(path: Path) -> set[str]:
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names |= {_package(a.name) for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(_package(node.module))
    return names


@pytest.mark.parametrize("package", sorted(FORBIDDEN))
def test_package_imports_only_what_the_data_flow_allows(package):
    files = sorted((ROOT / package).rglob("*.py"))
    assert files
    bad = {f"{f.relative_to(ROOT)} imports {name}" for f in files
           for name in imported_packages(f) & FORBIDDEN[package]}
    assert not bad, sorted(bad)


def test_the_check_sees_a_forbidden_import(tmp_path):
    f = tmp_path / "x.py"
    f.write_text("import numpy\nfrom dynprop.sim.truth import TruthStream\nfrom . import model\n"
                 "import dynprop\n")
    assert imported_packages(f) == {"numpy", "sim", "dynprop"}
