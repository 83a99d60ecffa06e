"""Pieces the pages of the other commands' directories share (``pages``): verdict
statuses, a record's every figure as a table, a figure of points with error bars,
a markdown report as readable preformatted text, and the closing sections with
the run directory's scenario.

`trim`, `tune` and `batch` write a subdirectory of the run they read
(RUN_DIR/trim/, …): its scenario.yaml is the run's, one level up, so the page
shows that one (docs/outputs.md, "Trim", "Tune", "Batch").
"""

from __future__ import annotations

import dataclasses
import math
import textwrap
from pathlib import Path

import numpy as np
import yaml

from . import provenance
from . import traces as tr
from .cells import Table, Verdict, cell, flatten, lookup, text, unit_of
from .render import Page, Section
from .source import Source

# A palette of ten (plotly's default) for figures with one trace per state.
PALETTE = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2",
           "#7f7f7f", "#bcbd22", "#17becf")


def status(ok: bool | None) -> str:
    """"met", "not met", or "not tested" when nothing was judged (never "met" on
    nothing)."""
    return "not tested" if ok is None else ("met" if ok else "not met")


def verdict(label: str, ok: bool | None, parts: list) -> Verdict:
    return Verdict(label, status(ok), parts)


def finite(v) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)


def record_table(id: str, record: dict, source: str, caption: str, skip=(),
                 prefix: str = "") -> Table:
    """Every scalar of ``record`` (a JSON tree, or one branch of it at ``prefix``)
    with its key path and unit, as run_page's summary table, but for the keys
    named in ``skip`` (at any depth: shown in a table of their own)."""
    rows = []
    for key, value in flatten(record, prefix):
        if any(part.split("[")[0] in skip for part in key.split(".")):
            continue
        rows.append([text(key), cell(value, source, key), text(unit_of(key))])
    return Table(id, ["key", "value", "unit"], rows, caption)


def points_figure(groups: list[dict], panels: list[dict], height: int = 360,
                  log: tuple = ()) -> dict:
    """Points with error bars on side-by-side panels of categories (no time axis):
    each group ``{"panel", "name", "x", "y", "err", "color", "symbol"}`` is one
    trace on panel ``panel`` (0, 1, …), ``err`` its ±half-widths (None: none)."""
    n = len(panels)
    gap = 0.08 if n > 1 else 0.0
    w = (1.0 - gap * (n - 1)) / n
    layout = {"height": height, "margin": {"l": 80, "r": 20, "t": 40, "b": 60},
              "template": "plotly_white", "hovermode": "closest",
              "legend": {"orientation": "h", "y": 1.02, "yanchor": "bottom"}}
    for i, p in enumerate(panels):
        sx = "" if i == 0 else str(i + 1)
        layout[f"xaxis{sx}"] = {"domain": [i * (w + gap), i * (w + gap) + w],
                                "anchor": f"y{sx}", "type": "category",
                                "title": {"text": p.get("x_title", "")}}
        layout[f"yaxis{sx}"] = {"anchor": f"x{sx}", "title": {"text": p["title"]},
                                "exponentformat": "power", "zeroline": True}
        if i in log:
            layout[f"yaxis{sx}"]["type"] = "log"
    data = []
    for g in groups:
        sx = "" if g["panel"] == 0 else str(g["panel"] + 1)
        trace = {"type": "scatter", "mode": "markers", "name": g["name"], "x": list(g["x"]),
                 "y": [_js(v) for v in g["y"]], "xaxis": f"x{sx}", "yaxis": f"y{sx}",
                 "marker": {"color": g["color"], "size": g.get("size", 10),
                            "symbol": g.get("symbol", "circle")},
                 "showlegend": g.get("show", True), "legendgroup": g.get("group", g["name"]),
                 "hovertemplate": "%{x}: %{y:.4g}<extra>" + g["name"] + "</extra>"}
        if g.get("err") is not None:
            err = g["err"]
            minus = g.get("err_minus", err)
            trace["error_y"] = {"type": "data", "array": [_js(v) for v in err],
                                "arrayminus": [_js(v) for v in minus], "visible": True,
                                "color": g["color"], "thickness": 1.5, "width": 6}
        data.append(trace)
    return {"data": data, "layout": layout}


def _js(v):
    """A number for a figure's plain list: None where JSON has no number."""
    return float(v) if finite(v) else None


def vline(x: float, color: str = "#555555", dash: str = "dot") -> dict:
    """A vertical line across every panel (a convergence time, a batch's epoch)."""
    return {"type": "line", "xref": "x", "yref": "paper", "x0": x, "x1": x, "y0": 0,
            "y1": 1, "line": {"color": color, "width": 1.2, "dash": dash}}


def spread_band(x, half, name: str, color: str, yaxis: str, opacity: float = 0.3,
                group: str | None = None, show: bool = True) -> list[dict]:
    """±``half`` about zero as a filled band; beyond ``tr.MAX_POINTS`` rows the
    largest half-width of each bin (as ``tr.sigma_band``: the band at its widest)."""
    x, h = np.asarray(x, dtype=float), np.asarray(half, dtype=float)
    starts = tr.bin_starts(len(x))
    if starts is not None:
        x, h = x[starts], np.fmax.reduceat(h, starts)
    return tr.band(x, -h, h, name, color, yaxis, opacity, group=group, show=show)


def run_dir_of(src: Source, hint: str | None = None) -> Path | None:
    """The run directory a `trim`/`tune`/`batch` directory was made from: the one
    its record names (``hint``), else its parent; None when neither holds a
    scenario.yaml."""
    for d in filter(None, (Path(hint) if hint else None, src.path.parent)):
        if (d / "scenario.yaml").is_file() and d.resolve() != src.path.resolve():
            return d
    return None


def closing(src: Source, command: str | None, kind: str, run_dir: Path | None = None,
            scenario: dict | None = None) -> list[Section]:
    """provenance.sections, with the run directory's scenario.yaml shown (and its
    name, seed and epoch in the provenance table) when the directory has none of
    its own; ``scenario``: the run's figures to show there when there is no file
    at all (report.json's ``meta``)."""
    out = []
    own = src.path / "scenario.yaml"
    if run_dir is not None and not own.is_file():
        body = (run_dir / "scenario.yaml").read_text()
        out.append(Section("scenario", "Scenario", f"scenario.yaml of the run this was made "
                           f"from ({run_dir}), as the run resolved it.", pre=body))
        try:
            parsed = yaml.safe_load(body)
        except yaml.YAMLError:
            parsed = None
        if isinstance(parsed, dict):
            scenario = parsed
    if scenario is not None and src.scenario is None:
        src = dataclasses.replace(src, scenario=scenario)
    return out + provenance.sections(src, command, kind)


def before_after_rows(before: dict, after: dict, source: str, prefix: str = "") -> list:
    """Every figure of ``before`` beside the same key of ``after`` ("—" where it has
    none) and the key's unit: ``source``'s ``{prefix}before.<key>`` and
    ``{prefix}after.<key>``; an ``.inside`` verdict that fails after is marked."""
    rows = []
    for key, value in flatten(before):
        try:
            other = lookup(after, key)
        except (KeyError, IndexError, TypeError):
            other = None
        flag = "failed" if key.endswith(".inside") and other is False else ""
        rows.append([text(key), cell(value, source, f"{prefix}before.{key}"),
                     cell(other, source, f"{prefix}after.{key}", css=flag) if other is not None
                     else text("—"), text(unit_of(key))])
    return rows


def page(src: Source, command: str | None, kind: str, title: str, subtitle: str,
         sections: list[Section], run_dir: Path | None = None,
         scenario: dict | None = None) -> Page:
    """A command's page: its sections, then the closing ones (``closing``)."""
    return Page(title, kind, subtitle, sections + closing(src, command, kind, run_dir, scenario))


def run_scale(meta: dict) -> str:
    """'seed S, epoch E, D days at Δt s, dynprop V': a scenario's (or a record's meta)
    run, for a page's subtitle."""
    return (f"seed {meta.get('seed')}, epoch {meta.get('epoch_utc')}, "
            f"{float(meta.get('duration_s') or 0) / 86400:.3g} days at "
            f"{meta.get('sample_interval_s')} s, dynprop {meta.get('dynprop_version')}")


def as_written(src: Source, name: str, intro: str = "The report as written.") -> list[Section]:
    """The command's own markdown report ``name`` (trim.md, tune.md, report.md) as a
    section, its long paragraphs wrapped, when the directory holds it."""
    md = src.path / name
    if not md.is_file():
        return []
    return [Section(f"{Path(name).stem}-md", name, intro, pre=wrap_markdown(md.read_text()))]


def wrap_markdown(md: str, width: int = 120) -> str:
    """A markdown report as preformatted text a reader can read without scrolling
    sideways: each paragraph (one long line in the file) wrapped, list items under
    their bullet; tables and fenced code (a command to copy) left as they are."""
    out, fenced = [], False
    for line in md.splitlines():
        if line.lstrip().startswith("```"):
            fenced = not fenced
        keep = fenced or line.startswith(("|", "    ")) or len(line) <= width
        indent = "  " if line.startswith(("- ", "* ")) else ""
        out.append(line if keep else textwrap.fill(line, width, subsequent_indent=indent,
                                                   break_long_words=False,
                                                   break_on_hyphens=False))
    return "\n".join(out) + "\n"
