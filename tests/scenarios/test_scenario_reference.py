"""docs/scenario-reference.md against the schema and the loader (issue 13).

The document is generated (``python -m scenarios.config.reference --out ...``, ``make docs``).
Besides checking that the committed file is current, these tests read the committed
file as a user would and check what it says against what the loader does, without
the generator's help: a key marked "(required)" is rejected when left out; every
other key's printed default, written into a scenario file, gives the same scenario
as leaving the key out, whether its section is left out or given without it; every
printed range is the one validation enforces; and every description and section
text is printed whole.
"""

from __future__ import annotations

import inspect
import math
import re
from dataclasses import dataclass
from pathlib import Path

import pytest
from pydantic import BaseModel

from scenarios.config import reference
from scenarios.config.events import EventEntry
from scenarios.config.loader import ScenarioError, load_scenario, validate
from scenarios.config.montecarlo import Normal, Uniform
from scenarios.config.schema import Scenario, leaf_paths

REPO = Path(__file__).resolve().parents[2]
DOC = REPO / "docs" / "scenario-reference.md"
ENTRY = "<key>"
ENTRY_KEY = "initial_state.yaw_deg"  # a dispersible key, standing in for <key>
# The smallest valid entry of each kind, and the model documented for it.
ENTRY_KINDS = {"normal": ({"distribution": "normal", "sigma": "0.1"}, Normal),
               "uniform": ({"distribution": "uniform", "low": "-0.1", "high": "0.1"}, Uniform)}
# Rows of the `events` entries' section (kind "event"): an entry at `<i>`, written as the
# smallest valid entry of a kind that does not use the row's key.
INDEX = "<i>"
EVENT_ENTRIES = {"time_s": {"kind": "trim_tab", "time_utc": "2026-03-20T12:00:00Z",
                            "angle_deg": "1"},
                 "angle_deg": {"kind": "sensor_outage", "time_s": "0", "duration_s": "1",
                               "sensor": "sun"}}
EVENT_ENTRY = {"kind": "trim_tab", "time_s": "0", "angle_deg": "1"}


@dataclass(frozen=True)
class Row:
    path: str
    type: str
    default: str | None  # YAML text, or None for "(required)"
    description: str
    kind: str | None  # the entry kind, for rows of a `montecarlo.dispersions.<key>` section


@dataclass(frozen=True)
class Heading:
    title: str
    intro: str


def _cells(line: str) -> list[str]:
    cells = re.split(r"(?<!\\)\|", line.strip())[1:-1]
    return [c.strip().replace("\\|", "|") for c in cells]


def parse(text: str) -> tuple[list[Heading], list[Row]]:
    headings, rows = [], []
    title, intro, kind = None, [], None
    for line in text.splitlines():
        if line.startswith("## "):
            title, intro = line[3:], []
            m = re.search(r"`distribution: (\w+)`", title)
            kind = m.group(1) if m else "event" if title == "`events` entries" else None
            headings.append(Heading(title, ""))
        elif title is None:
            continue
        elif line.startswith("| `"):
            path, type_, default, desc = _cells(line)
            rows.append(Row(path.strip("`"), type_,
                            None if default == "(required)" else default.strip("`"),
                            desc, kind))
        elif line and not line.startswith("|"):
            intro.append(line)
            headings[-1] = Heading(title, " ".join(intro))
    return headings, rows


@pytest.fixture(scope="module")
def doc():
    return parse(DOC.read_text())


def _rows():
    return parse(DOC.read_text())[1]


def _ids(rows):
    return [f"{r.path}[{r.kind}]" if r.kind else r.path for r in rows]


# --------------------------------------------------------------------------- current


def test_committed_reference_is_current():
    assert DOC.read_text() == reference.render(), \
        "docs/scenario-reference.md is stale: regenerate with `make docs` " \
        "(python -m scenarios.config.reference --out docs/scenario-reference.md)"


def test_check_and_out_options(tmp_path, capsys):
    assert reference.main(["--check", str(DOC)]) == 0
    stale = tmp_path / "ref.md"
    stale.write_text(DOC.read_text().replace("(required)", "", 1))
    assert reference.main(["--check", str(stale)]) == 1
    assert "stale" in capsys.readouterr().err
    assert reference.main(["--out", str(stale)]) == 0
    assert stale.read_text() == reference.render()
    assert reference.main(["--check", str(stale)]) == 0


def test_every_schema_key_has_one_row(doc):
    _, rows = doc
    plain = [r.path for r in rows if r.kind is None]
    assert sorted(plain) == sorted(leaf_paths(Scenario))
    assert [r.path for r in rows if r.kind == "event"] == \
        [f"events.{INDEX}.{name}" for name in EventEntry.model_fields]
    for kind, (_, model) in ENTRY_KINDS.items():
        assert [r.path for r in rows if r.kind == kind] == \
            [f"montecarlo.dispersions.{ENTRY}.{name}" for name in model.model_fields]


# --------------------------------------------------------------------------- required


def test_only_name_and_dispersion_entry_parameters_are_required(doc):
    """The Sun-sensor heads' keys were marked required: their defaults come from
    their section (per head), not from the fields."""
    _, rows = doc
    required = {(r.path, r.kind) for r in rows if r.default is None}
    e = f"montecarlo.dispersions.{ENTRY}."
    assert required == {("name", None), (f"events.{INDEX}.kind", "event"),
                        (e + "distribution", "normal"), (e + "sigma", "normal"),
                        (e + "distribution", "uniform"), (e + "low", "uniform"),
                        (e + "high", "uniform")}
    assert all(r.default is not None for r in rows if r.path.startswith("sensors."))


def _yaml(path: str, value: str | None, kind: str | None) -> str:
    """A scenario file giving ``path`` the YAML text ``value``; None leaves the key out
    but gives its section (as ``{}`` where nothing else is in it)."""
    if kind == "event":
        leaf = path.rsplit(".", 1)[1]
        entry = dict(EVENT_ENTRIES.get(leaf, EVENT_ENTRY))
        entry.pop(leaf, None)
        if value is not None:
            entry[leaf] = value
        flow = ", ".join(f"{k}: {v}" for k, v in entry.items())
        return f"name: x\nevents:\n  - {{{flow}}}\n"
    if kind is not None:
        entry = dict(ENTRY_KINDS[kind][0])
        leaf = path.rsplit(".", 1)[1]
        entry.pop(leaf, None)
        if value is not None:
            entry[leaf] = value
        flow = ", ".join(f"{k}: {v}" for k, v in entry.items())
        return f"name: x\nmontecarlo:\n  dispersions:\n    {ENTRY_KEY}: {{{flow}}}\n"
    *sections, leaf = path.split(".")
    lines = [] if path == "name" else ["name: x"]
    for depth, section in enumerate(sections):
        last = depth == len(sections) - 1
        lines.append("  " * depth + section + (": {}" if last and value is None else ":"))
    if value is not None:
        lines.append("  " * len(sections) + f"{leaf}: {value}")
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize("row", [r for r in _rows() if r.default is None],
                         ids=_ids([r for r in _rows() if r.default is None]))
def test_a_key_marked_required_is_rejected_when_left_out(tmp_path, row):
    path = tmp_path / "s.yaml"
    path.write_text(_yaml(row.path, None, row.kind))
    with pytest.raises(ScenarioError) as exc_info:
        load_scenario(path)
    key = row.path.replace(ENTRY, ENTRY_KEY).replace(f".{INDEX}.", "[0].")
    # A missing discriminator is reported on the entry it would classify.
    where = key.rsplit(".", 1)[0] if key.endswith(".distribution") else key
    assert any(line.startswith(f"{where}:") for line in exc_info.value.problems), \
        str(exc_info.value)


@pytest.mark.parametrize("row", [r for r in _rows() if r.default is not None],
                         ids=_ids([r for r in _rows() if r.default is not None]))
def test_every_printed_default_is_what_a_scenario_gets_without_the_key(tmp_path, row):
    """The default, as printed, written into a file gives the same scenario as leaving
    the key out with its section given, and as leaving the whole section out."""
    given, omitted = tmp_path / "given.yaml", tmp_path / "omitted.yaml"
    given.write_text(_yaml(row.path, row.default, row.kind))
    omitted.write_text(_yaml(row.path, None, row.kind))
    if row.kind is None:
        bare = validate({"name": "x"})
    else:
        bare = load_scenario(omitted)
    assert load_scenario(given) == bare, given.read_text()
    assert load_scenario(omitted) == bare, omitted.read_text()


# --------------------------------------------------------------------------- ranges


def _bounds(type_cell: str) -> list[tuple[str, float]]:
    """(operator, bound) pairs of a type cell: ``float, 0 < x ≤ 1.024`` gives
    [(">", 0), ("≤", 1.024)]."""
    m = re.search(r"(-?[\d.e+-]+) (<|≤) x (<|≤) (-?[\d.e+-]+)", type_cell)
    if m:
        flip = {"<": ">", "≤": "≥"}
        return [(flip[m.group(2)], float(m.group(1))), (m.group(3), float(m.group(4)))]
    m = re.search(r"^\w+ (>|≥|<|≤) (-?[\d.e+-]+)$", type_cell)
    return [(m.group(1), float(m.group(2)))] if m else []


RANGED = [r for r in _rows() if _bounds(r.type)]


def test_ranges_are_found(doc):
    assert {"sample_interval_s", "duration_s", "seed", "estimator.max_gap_s"} <= \
        {r.path for r in RANGED}


def _problems_of(path: str, value) -> list[str]:
    raw: dict = {"name": "x"}
    node = raw
    *sections, leaf = path.split(".")
    for s in sections:
        node = node.setdefault(s, {})
    node[leaf] = value
    try:
        validate(raw)
    except ScenarioError as exc:
        return [line for line in exc.problems if line.startswith(f"{path}:")]
    return []


@pytest.mark.parametrize("row", RANGED, ids=_ids(RANGED))
def test_every_printed_range_is_the_one_validation_enforces(row):
    is_int = row.type.startswith("int")
    for op, bound in _bounds(row.type):
        value = int(bound) if is_int else bound
        outward = -1 if op in (">", "≥") else 1
        if op in ("≥", "≤"):
            # the bound itself is allowed, the next number beyond it is not
            assert not _problems_of(row.path, value), (row.path, value)
            beyond = value + outward if is_int else math.nextafter(bound, outward * math.inf)
            assert _problems_of(row.path, beyond), (row.path, beyond)
        else:
            assert _problems_of(row.path, value), (row.path, value)


def test_step_limit_stated_is_the_schema_bound(doc):
    """The doc said the loop "goes unstable above ~2.2 s" while 1.024 s is the cap."""
    (row,) = [r for r in doc[1] if r.path == "sample_interval_s"]
    cap = next(m.le for m in Scenario.model_fields["sample_interval_s"].metadata
               if hasattr(m, "le"))
    assert f"≤ {cap:g}" in row.type
    assert f"at most {cap:g} s" in row.description
    assert not _problems_of("sample_interval_s", cap)
    assert _problems_of("sample_interval_s", math.nextafter(cap, math.inf))


# --------------------------------------------------------------------------- whole text


def _field(row: Row):
    if row.kind == "event":
        return EventEntry.model_fields[row.path.rsplit(".", 1)[1]]
    if row.kind is not None:
        return ENTRY_KINDS[row.kind][1].model_fields[row.path.rsplit(".", 1)[1]]
    model: type[BaseModel] = Scenario
    *sections, leaf = row.path.split(".")
    for s in sections:
        model = model.model_fields[s].annotation
    return model.model_fields[leaf]


def _model_of(title: str) -> type[BaseModel] | None:
    kind = re.search(r"`distribution: (\w+)`", title)
    if kind:
        return ENTRY_KINDS[kind.group(1)][1]
    if title == "`events` entries":
        return EventEntry
    if title == "Top level":
        return Scenario
    model = Scenario
    for s in title.strip("`").split("."):
        model = model.model_fields[s].annotation
    return model


def _closed(text: str) -> bool:
    """Not visibly cut: brackets and backticks balanced, and no trailing separator."""
    pairs = {"(": ")", "[": "]", "{": "}"}
    stack = []
    for ch in text:
        if ch in pairs:
            stack.append(pairs[ch])
        elif ch in pairs.values() and (not stack or stack.pop() != ch):
            return False
    return not stack and text.count("`") % 2 == 0 and not re.search(r"[,;:–—-]$", text)


def test_every_description_is_printed_whole(doc):
    for row in doc[1]:
        field = _field(row)
        assert field.description, f"{row.path} has no description"
        assert row.description == " ".join(field.description.split()), row.path
        assert _closed(row.description), row.path


def test_every_section_text_is_its_whole_docstring(doc):
    """The montecarlo section's text stopped at "`dynprop run` ignores": only the
    first line of a docstring was printed."""
    headings, _ = doc
    documented = 0
    for h in headings:
        model = _model_of(h.title)
        if model.__doc__ is None:
            continue
        documented += 1
        whole = " ".join(inspect.cleandoc(model.__doc__).split()).replace("``", "`")
        assert h.intro == whole, h.title
        assert h.intro.endswith("."), h.title
    assert documented >= 8
    (mc,) = [h for h in headings if h.title == "`montecarlo`"]
    assert mc.intro.endswith("except with `--montecarlo-case K`.")


def test_defaults_are_yaml_not_python_reprs(doc):
    for row in doc[1]:
        if row.default is None:
            continue
        assert not re.search(r"e[-+]0\d", row.default), (row.path, row.default)
        assert row.default not in ("True", "False", "None"), row.path
        assert "(" not in row.default, row.path
