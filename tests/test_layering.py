"""The import rules of docs/architecture.md, checked on the source.

Between packages: estimator never imports sim (nor scenarios or plots), sim never
imports estimator, the shared packages (rollout, eom) import neither, plots imports
no physics, and nothing imports the dynprop facade.

Inside scenarios (the application), each room has a rank, and a module may import
only its own room and rooms of a lower rank (docs/architecture.md, "Import rules"):
a lower room never imports a higher one, and rooms of one rank (files and bridge;
trim, linearization, montecarlo, tune, batch and export; studies and review) never
import each other.  Only ``figures``
imports ``plots``.  Every import counts, relative or absolute, at module level or
inside a function.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
ARCHITECTURE = ROOT / "docs" / "architecture.md"
FORBIDDEN = {
    "estimator": {"sim", "scenarios", "plots", "dynprop"},
    "sim": {"estimator", "scenarios", "plots", "dynprop"},
    "eom": {"sim", "estimator", "scenarios", "plots", "rollout", "dynprop"},
    "rollout": {"sim", "estimator", "scenarios", "plots", "eom", "dynprop"},
    "plots": {"sim", "estimator", "scenarios", "eom", "rollout", "dynprop"},
    # The API is a facade over scenarios: nothing below it may depend on it.
    "scenarios": {"dynprop"},
}
# The rooms of scenarios/ by rank (docs/architecture.md): a module imports its own
# room and lower ranks only.  The base modules sit at the bottom.
RANKS = {
    "units": 0, "samples": 0, "records": 0, "workers": 0, "__init__": 0,
    "config": 1,
    "files": 2, "bridge": 2,
    "figures": 3,
    "run": 4,
    "trim": 5, "linearization": 5, "montecarlo": 5, "tune": 5, "batch": 5, "export": 5,
    "studies": 6, "review": 6,
    "commands": 7, "arguments": 7, "console": 7,
    "cli": 8,
}


def _package(dotted: str) -> str:
    """The package an absolute import names: the folder under the dynprop namespace
    (``dynprop.sim.truth`` → ``sim``), ``dynprop`` for the facade itself."""
    parts = dotted.split(".")
    if parts[0] == "dynprop" and len(parts) > 1 and parts[1] in FORBIDDEN:
        return parts[1]
    return parts[0]


def imported_modules(path: Path, module: str) -> set[str]:
    """Every module ``path`` (the module ``module``, dotted, e.g.
    ``dynprop.scenarios.run.stream``) imports, as absolute dotted names; ``from X
    import name`` counts as X.name too, since the name may be a module."""
    is_package = path.name == "__init__.py"
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = module.split(".")[:len(module.split(".")) - node.level
                                         + (1 if is_package else 0)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module
            names.add(target)
            names |= {f"{target}.{a.name}" for a in node.names}
    return names


def imported_packages(path: Path) -> set[str]:
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names |= {_package(a.name) for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(_package(node.module))
    return names


def room_of(dotted: str) -> str | None:
    """The room of scenarios a dotted module name lies in (None outside scenarios)."""
    parts = dotted.split(".")
    if parts[:2] != ["dynprop", "scenarios"]:
        return None
    return parts[2] if len(parts) > 2 else "__init__"


def _dotted(path: Path) -> str:
    rel = path.relative_to(ROOT / "scenarios").with_suffix("")
    parts = [p for p in rel.parts if p != "__init__"]
    return ".".join(["dynprop", "scenarios", *parts]) if parts else "dynprop.scenarios"


def room_violations(files) -> list[str]:
    bad = []
    for path, dotted in files:
        room = room_of(dotted) if dotted != "dynprop.scenarios" else "__init__"
        if room not in RANKS:
            bad.append(f"{dotted}: room {room} has no rank in docs/architecture.md")
            continue
        for name in imported_modules(path, dotted):
            other = room_of(name)
            if _package(name) == "plots" and room != "figures":
                bad.append(f"{dotted} imports {name}: only figures imports plots")
            if other is None or other == room or other not in RANKS:
                continue
            if RANKS[other] >= RANKS[room]:
                bad.append(f"{dotted} ({room}, rank {RANKS[room]}) imports {name} "
                           f"({other}, rank {RANKS[other]})")
    return sorted(set(bad))


def _scenario_files():
    return [(p, _dotted(p)) for p in sorted((ROOT / "scenarios").rglob("*.py"))]


@pytest.mark.parametrize("package", sorted(FORBIDDEN))
def test_package_imports_only_what_the_data_flow_allows(package):
    files = sorted((ROOT / package).rglob("*.py"))
    assert files
    bad = {f"{f.relative_to(ROOT)} imports {name}" for f in files
           for name in imported_packages(f) & FORBIDDEN[package]}
    assert not bad, sorted(bad)


def test_every_room_of_scenarios_imports_only_lower_rooms():
    files = _scenario_files()
    rooms = {room_of(d) or "__init__" for _, d in files}
    assert rooms == set(RANKS), "every room has a rank, every rank a room"
    assert room_violations(files) == []


def test_every_room_says_what_it_is_and_what_it_may_import():
    for init in sorted((ROOT / "scenarios").glob("*/__init__.py")):
        doc = ast.get_docstring(ast.parse(init.read_text())) or ""
        assert "May import" in doc, f"{init.relative_to(ROOT)}: no import rule in its doc"
        assert f"``{init.parent.name}``" in ARCHITECTURE.read_text() \
            or f"{init.parent.name}/" in ARCHITECTURE.read_text(), init.parent.name


def test_the_architecture_document_states_the_same_ranks():
    """docs/architecture.md's rank table is the one this test enforces."""
    table = {}
    for line in ARCHITECTURE.read_text().splitlines():
        m = re.fullmatch(r"\| (\d) \| (.*) \|", line)
        if m:
            for room in re.findall(r"`(\w+)`", m[2]):
                table[room] = int(m[1])
    assert table == {k: v for k, v in RANKS.items() if k != "__init__"}


def test_the_check_sees_a_forbidden_import(tmp_path):
    f = tmp_path / "x.py"
    f.write_text("import numpy\nfrom dynprop.sim.truth import TruthStream\nfrom . import model\n"
                 "import dynprop\n")
    assert imported_packages(f) == {"numpy", "sim", "dynprop"}


def test_the_check_sees_a_lower_room_importing_a_higher_one(tmp_path):
    """A planted module in files/ that reaches up into run/ (relatively, inside a
    function) and one in run/ drawing with plots directly."""
    low = tmp_path / "low.py"
    low.write_text("def f():\n    from ..run.stream import windows_of\n    return windows_of\n")
    sibling = tmp_path / "sib.py"
    sibling.write_text("from ..bridge import inputs\n")
    drawer = tmp_path / "draw.py"
    drawer.write_text("from dynprop.plots.errors import plot_errors\n")
    bad = room_violations([(low, "dynprop.scenarios.files.low"),
                           (sibling, "dynprop.scenarios.files.sib"),
                           (drawer, "dynprop.scenarios.run.draw")])
    assert any("files.low" in b and "run.stream" in b for b in bad), bad
    assert any("files.sib" in b and "bridge" in b for b in bad), bad
    assert any("only figures imports plots" in b for b in bad), bad
    ok = tmp_path / "ok.py"
    ok.write_text("from ..files.columns import estimate_columns\nfrom .. import units\n")
    assert room_violations([(ok, "dynprop.scenarios.run.ok")]) == []
