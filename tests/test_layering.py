"""The import rules of docs/architecture.md, checked on the source.

Between packages: estimator never imports sim (nor scenarios or plots), sim never
imports estimator, the shared packages (rollout, eom) import neither, plots imports
no physics, and nothing imports the dynprop facade.

Inside scenarios (the application) and inside estimator, each room has a rank, and
a module may import only its own room and rooms of a lower rank (docs/architecture.md,
"Import rules" and "The rooms of estimator/"): a lower room never imports a higher
one, and rooms of one rank (files and bridge; trim, linearization, montecarlo, tune,
batch and export; studies and review; augmented, pitch, ekf and tuning; batch and
analysis) never import each other.  Only ``figures`` imports ``plots``.  Every import
counts, relative or absolute, at module level or inside a function.

The house: no folder of package code holds more than 16 modules, and no module of it
imports, directly or through others, a module that imports it back (no import cycle,
lazy imports inside functions included).
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
# The rooms of estimator/ by rank (docs/architecture.md, "The rooms of estimator/").
ESTIMATOR_RANKS = {
    "__init__": 0, "linear": 0,
    "kalman": 1,
    "augmented": 2, "pitch": 2, "ekf": 2, "tuning": 2,
    "batch": 3, "analysis": 3,
}
ROOMS = {"scenarios": RANKS, "estimator": ESTIMATOR_RANKS}
PACKAGE_CODE = ("dynprop", "sim", "estimator", "scenarios", "plots", "rollout", "eom")
MAX_MODULES = 16


def _package(dotted: str) -> str:
    """The package an absolute import names: the folder under the dynprop namespace
    (``dynprop.sim.truth`` → ``sim``), ``dynprop`` for the facade itself."""
    parts = dotted.split(".")
    if parts[0] == "dynprop" and len(parts) > 1 and parts[1] in FORBIDDEN:
        return parts[1]
    return parts[0]


def imported_modules(path: Path, module: str) -> set[str]:
    """Every module ``path`` (the module ``module``, dotted, e.g.
    ``dynprop.scenarios.run.stream.windows``) imports, as absolute dotted names; ``from X
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


def room_of(dotted: str, package: str = "scenarios") -> str | None:
    """The room of ``package`` (scenarios or estimator) a dotted module name lies in
    (None outside it); a module directly in the package is a room of its own name
    (scenarios' base modules), the package's ``__init__`` is ``__init__``."""
    parts = dotted.split(".")
    if parts[:2] != ["dynprop", package]:
        return None
    return parts[2] if len(parts) > 2 else "__init__"


def _dotted(path: Path, package: str = "scenarios") -> str:
    rel = path.relative_to(ROOT / package).with_suffix("")
    parts = [p for p in rel.parts if p != "__init__"]
    return ".".join(["dynprop", package, *parts]) if parts else f"dynprop.{package}"


def room_violations(files, package: str = "scenarios") -> list[str]:
    ranks = ROOMS[package]
    bad = []
    for path, dotted in files:
        room = room_of(dotted, package)
        if room not in ranks:
            bad.append(f"{dotted}: room {room} has no rank in docs/architecture.md")
            continue
        for name in imported_modules(path, dotted):
            other = room_of(name, package)
            if _package(name) == "plots" and room != "figures":
                bad.append(f"{dotted} imports {name}: only figures imports plots")
            if other is None or other == room or other not in ranks:
                continue
            if ranks[other] >= ranks[room]:
                bad.append(f"{dotted} ({room}, rank {ranks[room]}) imports {name} "
                           f"({other}, rank {ranks[other]})")
    return sorted(set(bad))


def _package_files(package: str = "scenarios"):
    return [(p, _dotted(p, package)) for p in sorted((ROOT / package).rglob("*.py"))]


@pytest.mark.parametrize("package", sorted(FORBIDDEN))
def test_package_imports_only_what_the_data_flow_allows(package):
    files = sorted((ROOT / package).rglob("*.py"))
    assert files
    bad = {f"{f.relative_to(ROOT)} imports {name}" for f in files
           for name in imported_packages(f) & FORBIDDEN[package]}
    assert not bad, sorted(bad)


@pytest.mark.parametrize("package", sorted(ROOMS))
def test_every_room_imports_only_lower_rooms(package):
    files = _package_files(package)
    rooms = {room_of(d, package) for _, d in files}
    assert rooms == set(ROOMS[package]), "every room has a rank, every rank a room"
    assert room_violations(files, package) == []


def test_estimator_modules_live_in_rooms():
    """estimator/ holds rooms only: a module dropped loose beside them has no rank."""
    loose = [p.name for p in (ROOT / "estimator").glob("*.py") if p.name != "__init__.py"]
    assert loose == []


@pytest.mark.parametrize("package", sorted(ROOMS))
def test_every_room_says_what_it_is_and_what_it_may_import(package):
    for init in sorted((ROOT / package).glob("*/__init__.py")):
        doc = ast.get_docstring(ast.parse(init.read_text())) or ""
        assert "May import" in doc, f"{init.relative_to(ROOT)}: no import rule in its doc"
        assert f"``{init.parent.name}``" in ARCHITECTURE.read_text() \
            or f"{init.parent.name}/" in ARCHITECTURE.read_text(), init.parent.name


def _rank_table(header: str) -> dict[str, int]:
    """The rank table of docs/architecture.md whose header row is ``header``."""
    table, inside = {}, False
    for line in ARCHITECTURE.read_text().splitlines():
        if line.startswith("|"):
            inside = inside or line == header
        else:
            inside = False
        m = re.fullmatch(r"\| (\d) \| (.*) \|", line)
        if inside and m:
            for room in re.findall(r"`(\w+)`", m[2]):
                table[room] = int(m[1])
    return table


@pytest.mark.parametrize(("package", "header"), [("scenarios", "| rank | rooms |"),
                                                  ("estimator", "| estimator rank | rooms |")])
def test_the_architecture_document_states_the_same_ranks(package, header):
    """docs/architecture.md's rank tables are the ones this test enforces."""
    want = {k: v for k, v in ROOMS[package].items() if k != "__init__"}
    assert _rank_table(header) == want


@pytest.mark.parametrize("package", PACKAGE_CODE)
def test_no_folder_holds_more_than_16_modules(package):
    crowded = {str(d.relative_to(ROOT)): n for d in [ROOT / package, *(ROOT / package).rglob("*")]
               if d.is_dir() and d.name != "__pycache__"
               and (n := len([p for p in d.glob("*.py") if p.name != "__init__.py"])) > MAX_MODULES}
    assert crowded == {}


def _module_graph() -> dict[str, set[str]]:
    """Every module of the package code and the modules it imports (at module level
    or in a function): ``from P import name`` is an arrow to P.name when that is a
    module, else to P."""
    files = {}
    for package in PACKAGE_CODE:
        for path in sorted((ROOT / package).rglob("*.py")):
            rel = path.relative_to(ROOT / package).with_suffix("")
            parts = [p for p in rel.parts if p != "__init__"]
            top = ["dynprop"] + ([package] if package != "dynprop" else [])
            files[".".join(top + parts)] = path
    graph = {}
    for dotted, path in files.items():
        names = imported_modules(path, dotted)
        graph[dotted] = {n for n in names if n in files and n != dotted}
    return graph


def import_cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_no_import_cycle_in_the_package_code():
    assert import_cycles(_module_graph()) == []


def test_the_cycle_check_sees_a_lazy_cycle():
    """api and results importing each other, one of them inside a function, as they
    once did."""
    graph = {"dynprop.api": {"dynprop.results"}, "dynprop.results": {"dynprop.api"},
             "dynprop.x": {"dynprop.api"}}
    assert import_cycles(graph) == [["dynprop.api", "dynprop.results"]]


def test_the_check_sees_a_forbidden_import(tmp_path):
    f = tmp_path / "x.py"
    f.write_text("import numpy\nfrom dynprop.sim.truth import TruthStream\nfrom . import model\n"
                 "import dynprop\n")
    assert imported_packages(f) == {"numpy", "sim", "dynprop"}


def test_the_check_sees_a_lower_room_importing_a_higher_one(tmp_path):
    """A planted module in files/ that reaches up into run/ (relatively, inside a
    function) and one in run/ drawing with plots directly."""
    low = tmp_path / "low.py"
    low.write_text("def f():\n    from ..run.stream.windows import windows_of\n"
                   "    return windows_of\n")
    sibling = tmp_path / "sib.py"
    sibling.write_text("from ..bridge import inputs\n")
    drawer = tmp_path / "draw.py"
    drawer.write_text("from dynprop.plots.errors import plot_errors\n")
    bad = room_violations([(low, "dynprop.scenarios.files.low"),
                           (sibling, "dynprop.scenarios.files.sib"),
                           (drawer, "dynprop.scenarios.run.draw")])
    assert any("files.low" in b and "run.stream.windows" in b for b in bad), bad
    assert any("files.sib" in b and "bridge" in b for b in bad), bad
    assert any("only figures imports plots" in b for b in bad), bad
    ok = tmp_path / "ok.py"
    ok.write_text("from ..files.columns import estimate_columns\nfrom .. import units\n")
    assert room_violations([(ok, "dynprop.scenarios.run.ok")]) == []


def test_the_check_sees_an_estimator_room_importing_a_higher_one(tmp_path):
    """A planted module in estimator/linear/ that reaches up into kalman/ (relatively,
    inside a function), one in pitch/ importing its sibling ekf/, and one in kalman/
    importing analysis/ absolutely."""
    up = tmp_path / "up.py"
    up.write_text("def f():\n    from ..kalman.filter import kalman_filter\n")
    sib = tmp_path / "sib.py"
    sib.write_text("from ..ekf import model as m\n")
    absolute = tmp_path / "abs.py"
    absolute.write_text("from dynprop.estimator.analysis.covariance import reduced\n")
    bad = room_violations([(up, "dynprop.estimator.linear.up"),
                           (sib, "dynprop.estimator.pitch.sib"),
                           (absolute, "dynprop.estimator.kalman.abs")], "estimator")
    assert any("linear.up" in b and "kalman.filter" in b for b in bad), bad
    assert any("pitch.sib" in b and "ekf" in b for b in bad), bad
    assert any("kalman.abs" in b and "analysis" in b for b in bad), bad
    ok = tmp_path / "ok.py"
    ok.write_text("from ..linear.model import N_STATES\nfrom .steps import pack\n")
    assert room_violations([(ok, "dynprop.estimator.kalman.ok")], "estimator") == []
