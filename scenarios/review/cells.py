"""The numbers a page shows, each tied to the file and key it comes from.

Every number read from a file is a ``Cell`` carrying the file's name, the key path
and the value at full precision; the template writes them as ``data-source``,
``data-key`` and ``data-value`` beside the rounded text, so a reader (and
tests/scenarios/test_report.py) can check the page against summary.json and
daily.csv.  Numbers the page works out itself (3 × a daily RMS) are ``Cell``s with
no source, and say how they were made.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass, field

DIGITS = 4   # significant digits shown; data-value keeps the file's own


@dataclass(frozen=True)
class Cell:
    text: str
    source: str | None = None       # the file the value comes from
    key: str | None = None          # its key path there: a.b[2], or row:column for a CSV
    value: str | None = None        # the value as the file gives it (JSON text)
    css: str = ""


@dataclass(frozen=True)
class Table:
    id: str
    columns: list[str]
    rows: list[list[Cell]]
    caption: str = ""


@dataclass(frozen=True)
class Verdict:
    label: str
    status: str                     # "met", "not met" or "not tested"
    parts: list = field(default_factory=list)   # text and Cells, in reading order


def fmt(value) -> str:
    """A value as shown: 4 significant digits, booleans as yes/no, a missing one as a
    dash."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "—"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isinf(value):
            return "∞" if value > 0 else "−∞"
        if 1e4 <= abs(value) < 1e12 or (value.is_integer() and abs(value) < 1e12):
            # 86399.488 s as 86399 (within the four digits' tolerance), not 8.64e+04.
            return str(round(value))
        return f"{value:.{DIGITS}g}"
    return str(value)


def cell(value, source: str | None = None, key: str | None = None, unit: str = "",
         css: str = "") -> Cell:
    """A number from ``source`` at ``key`` (or one the page computed: no source)."""
    shown = fmt(value)
    if unit and shown != "—":
        shown += unit if unit.startswith("°") else f" {unit}"
    raw = None if source is None else json.dumps(_plain(value))
    numeric = isinstance(value, int | float) and not isinstance(value, bool)
    return Cell(shown, source, key, raw, " ".join(filter(None, (css, "num" if numeric else ""))))


def text(s: str, css: str = "") -> Cell:
    return Cell(s, css=css)


def _name(prefix: str, key) -> str:
    """``prefix.key``; a key that holds a dot or a bracket (montecarlo.json's
    dispersions, by scenario key path) quoted: ``prefix["spacecraft.inertia_kgm2"]``."""
    k = str(key)
    if "." in k or "[" in k or '"' in k:
        return f"{prefix}[{json.dumps(k)}]"
    return f"{prefix}.{k}" if prefix else k


_PART = re.compile(r'\.?([^.\[\]]+)|\[(\d+)\]|\[("(?:[^"\\]|\\.)*")\]')


def lookup(data, key: str):
    """The value at a key path of ``cell``'s form (``a.b[2]``, ``a["b.c"].d``) in loaded
    JSON."""
    node, pos = data, 0
    while pos < len(key):
        m = _PART.match(key, pos)
        if m is None:
            raise KeyError(f"{key}: bad key path at {pos}")
        name, index, quoted = m.groups()
        node = node[name] if name is not None else (
            node[int(index)] if index is not None else node[json.loads(quoted)])
        pos = m.end()
    return node


def flatten(node, prefix: str = "") -> list[tuple[str, object]]:
    """Every scalar of a JSON tree with its key path (lists element by element), in
    the file's order."""
    if isinstance(node, dict):
        pairs = [(_name(prefix, k), v) for k, v in node.items()]
    elif isinstance(node, list):
        pairs = [(f"{prefix}[{i}]", v) for i, v in enumerate(node)]
    else:
        return [(prefix, node)]
    return [item for path, v in pairs for item in flatten(v, path)]


# Dicts keyed by a state's column name (roll_deg, …) whose values are ratios.
UNITLESS = ("nees_mean_per_state", "per_state_mean_after_convergence", "per_state_bounds_95",
            "per_state_test_95", "nees")
SUFFIXES = (("_Nm_per_deg", "N m/°"), ("_degps", "°/s"), ("_deg", "°"), ("_Nms", "N m s"),
            ("_Nm2s", "(N m)² s"), ("_Nm", "N m"), ("_h", "h"), ("_s", "s"), ("_min", "min"),
            ("_rpm", "rpm"), ("_Am2", "A m²"), ("_kgm2", "kg m²"))


def unit_of(key: str) -> str:
    """The unit a key path's names carry (the files' convention: the unit in the name),
    the innermost name that has one: nonlinear_vs_linear.yaw_deg.rms_real is in
    degrees; a ratio keyed by a state's column (nees_mean_per_state.yaw_deg) has none."""
    names = [n.strip('"') for n in re.findall(r'"[^"]*"|[^.\[\]]+', key) if not n.isdigit()]
    if any(n in UNITLESS for n in names):
        return ""
    for name in reversed(names):
        for suffix, unit in SUFFIXES:
            if name.endswith(suffix):
                return unit
    return ""


def _plain(value):
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if hasattr(value, "item"):
        return _plain(value.item())
    return value
