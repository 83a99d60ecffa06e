"""A telemetry gap, the yaw outages and screened values on the PNG figures and on
the review page (issue 43, item 7).

The directories are real `dynprop estimate` outputs: the session's 6 h run's
telemetry.csv with a 2 h block of rows deleted, estimated with the run's 64 s
truth (errors.png: 338 rows, the filter's rows inside the hole on its grid) and
without (estimates.png: every 0.512 s sample, so both drawings bin their rows).
What is judged is the drawing itself: the matplotlib artists (every line vertex,
every band polygon, the shaded spans) and the page's plotly JSON (every trace's
decoded points, the layout's rectangles), against the hole as it was cut from the
file.  Screened values (comparison.npz's ``screened_t_s``, written by the
telemetry screen) are added by hand to a copy.
"""

from __future__ import annotations

import base64
import functools
import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml
from matplotlib.colors import to_rgba

from scenarios.figures import run as figures_run

from .test_cli_run import run_cli

# The rows deleted from telemetry.csv, t in [7000, 14200): not the file's middle 2 h,
# which would put the break on an edge of the PNG's drawing bins (2,000 over the
# rows), where a bin spanning the hole would go unseen.
HOLE_S = (7000.0, 14200.0)
NOON_H = (4.6, 5.6)            # inside the noon yaw outage of the equinox run (4.46–5.8 h)
SCREENED_S = np.array([1800.25, 16000.0, 19000.5])


def _with_hole(run: Path, path: Path) -> Path:
    lines = (run / "telemetry.csv").read_text().splitlines(keepends=True)
    keep = [ln for ln in lines if ln.startswith(("#", "t_s"))
            or not HOLE_S[0] <= float(ln.split(",", 1)[0]) < HOLE_S[1]]
    assert len(keep) < len(lines) - 14000   # 2 h of 0.512 s rows gone
    path.write_text("".join(keep))
    return path


def _estimate(run: Path, telemetry: Path, out: Path, *extra: str) -> Path:
    rc, _, err = run_cli("estimate", str(telemetry), "--scenario", str(run / "scenario.yaml"),
                         "--out", str(out), *extra)
    assert rc == 0, err
    return out


@pytest.fixture(scope="module")
def hole(run6, tmp_path_factory) -> dict[str, Path]:
    tmp = tmp_path_factory.mktemp("hole")
    path = _with_hole(run6, tmp / "telemetry.csv")
    return {"errors": _estimate(run6, path, tmp / "truth", "--truth", str(run6 / "truth.csv")),
            "estimates": _estimate(run6, path, tmp / "no_truth")}


@pytest.fixture(scope="module")
def screened(hole, tmp_path_factory) -> Path:
    """A copy of the estimate with truth: three screened samples in comparison.npz,
    and Sun gaps of 1 h or more (scenario.yaml, summary.json), so that the noon
    outage is drawn as a Sun gap."""
    out = tmp_path_factory.mktemp("screened") / "est"
    shutil.copytree(hole["errors"], out)
    with np.load(out / "comparison.npz") as npz:
        arrays = {k: npz[k] for k in npz.files}
    np.savez(out / "comparison.npz", **arrays, screened_t_s=SCREENED_S)
    scenario = yaml.safe_load((out / "scenario.yaml").read_text())
    scenario["estimator"]["sun_gap_min_h"] = 1.0
    (out / "scenario.yaml").write_text(yaml.safe_dump(scenario, sort_keys=False))
    t, present = arrays["t_s"] / 3600.0, arrays["yaw_present"] < 0.5
    noon = present & (t > 4.0)
    summary = json.loads((out / "summary.json").read_text())
    summary["sun_gaps_h"] = [[float(t[noon][0]), float(t[noon][-1])]]
    (out / "summary.json").write_text(json.dumps(summary))
    return out


# --------------------------------------------------------------------- the PNGs


@functools.cache
def run_figure(directory: Path, name: str):
    """The figure as `estimate` saved it (drawn once per directory; only read)."""
    return figures_run.run_figure(directory, name)


def _panels(fig) -> list:
    return [ax for ax in fig.axes if ax.axison]


def _covers(patch, a: float, b: float) -> bool:
    x = patch.get_path().transformed(patch.get_patch_transform()).vertices[:, 0] \
        if hasattr(patch, "get_patch_transform") else patch.get_path().vertices[:, 0]
    return x.min() <= a and x.max() >= b


def _span_color(ax, a_h: float, b_h: float):
    """The face colour of the shaded span covering [a_h, b_h] drawn last (on top)."""
    spans = [p for p in ax.patches if _covers(p, a_h, b_h)]
    return to_rgba(spans[-1].get_facecolor()) if spans else None


def _crossings(ax, lo_h: float, hi_h: float) -> list[str]:
    """Every data-space line or band with a finite vertex strictly inside (lo, hi),
    or an edge from one side of it to the other."""
    bad = []
    # (name, vertices, joined by edges): dots (a line without a line style) are not.
    paths = [(f"line {ln.get_label()}", ln.get_xydata(), ln.get_linestyle() != "None")
             for ln in ax.lines if ln.get_transform() == ax.transData]
    for coll in ax.collections:
        if coll.get_transform() == ax.transData:
            paths += [(f"band {coll.get_label()}", p.vertices, True) for p in coll.get_paths()]
    for name, xy, joined in paths:
        xy = np.asarray(xy, dtype=float)
        ok = np.isfinite(xy).all(axis=1)
        x = xy[:, 0]
        inside = ok & (x > lo_h) & (x < hi_h)
        across = joined & ok[:-1] & ok[1:] & (np.minimum(x[:-1], x[1:]) < hi_h) \
            & (np.maximum(x[:-1], x[1:]) > lo_h)
        if inside.any() or across.any():
            bad.append(name)
    return bad


@pytest.mark.parametrize("figure", ["errors", "estimates"])
def test_png_shades_the_hole_apart_and_draws_nothing_across_it(hole, figure):
    fig = run_figure(hole[figure], figure)
    lo, hi = HOLE_S[0] / 3600.0, HOLE_S[1] / 3600.0
    for ax in _panels(fig):
        title = ax.get_title(loc="left").split("\n")[0]
        hole_color = _span_color(ax, lo, hi)
        assert hole_color is not None, f"{title}: the 2 h hole is not shaded"
        # Shaded as itself, not as the noon yaw outage beside it.
        assert hole_color != _span_color(ax, *NOON_H), title
        assert not _crossings(ax, lo, hi), f"{title}: drawn across the hole"


def test_png_marks_screened_values_only_when_there_are_some(hole, screened):
    def rugs(fig):
        return [ln for ax in _panels(fig) for ln in ax.lines if ln.get_marker() == "|"]
    def labels(fig):
        return [t.get_text() for leg in fig.legends for t in leg.get_texts()]
    clean = run_figure(hole["errors"], "errors")
    assert not rugs(clean) and not any("screened" in t for t in labels(clean))
    fig = run_figure(screened, "errors")
    marks = rugs(fig)
    assert len(marks) == 4      # roll, yaw, h and pitch errors: one tick row each
    for ln in marks:
        np.testing.assert_allclose(ln.get_xdata(), SCREENED_S / 3600.0, rtol=1e-12)
    assert sum("screened" in t for t in labels(fig)) == 1


# --------------------------------------------------------------------- the page


@functools.cache
def _page(directory: Path) -> dict[str, dict]:
    """The page's figures, each as plotly.js gets it (made once per directory)."""
    rc, _, err = run_cli("report", str(directory))
    assert rc == 0, err
    html = (directory / "report.html").read_text()
    specs = re.findall(r'<script type="application/json" class="plot-spec" '
                       r'data-target="plot-([^"]+)"[^>]*>(.*?)</script>', html, re.S)
    return {name: json.loads(text.replace("<\\/", "</")) for name, text in specs}


def _values(v) -> np.ndarray:
    if isinstance(v, dict):    # plotly.js's typed array: base64 of little-endian values
        return np.frombuffer(base64.b64decode(v["bdata"]), dtype=v["dtype"]).astype(float)
    return np.array([np.nan if a is None else a for a in v], dtype=float)


def _rgba(css: str) -> tuple:
    r, g, b, a = (float(v) for v in re.findall(r"[\d.]+", css))
    return (r / 255, g / 255, b / 255, a)


def _rect_color(figure: dict, a_h: float, b_h: float):
    rects = [s for s in figure["layout"].get("shapes", [])
             if s.get("type") == "rect" and s["x0"] <= a_h and s["x1"] >= b_h]
    return _rgba(rects[-1]["fillcolor"]) if rects else None


def test_page_shades_the_hole_apart_and_draws_nothing_across_it(hole):
    lo, hi = HOLE_S[0] / 3600.0, HOLE_S[1] / 3600.0
    for kind, directory in hole.items():
        figures = {k: f for k, f in _page(directory).items() if k != "season"}
        assert {"errors", "consistency", "torques", "telemetry"} <= set(figures)
        for name, f in figures.items():
            color = _rect_color(f, lo, hi)
            assert color is not None, f"{kind} {name}: the hole is not shaded"
            assert color != _rect_color(f, *NOON_H), f"{kind} {name}"
            for trace in f["data"]:
                x, y = _values(trace["x"]), _values(trace["y"])
                ok = np.isfinite(x) & np.isfinite(y)
                inside = ok & (x > lo) & (x < hi)
                assert not inside.any(), f"{kind} {name} {trace['name']}: points in the hole"
                if "lines" in trace.get("mode", ""):
                    across = ok[:-1] & ok[1:] & (x[:-1] < hi) & (x[1:] > lo)
                    assert not across.any(), f"{kind} {name} {trace['name']}: across the hole"


def test_page_marks_screened_values_only_when_there_are_some(hole, screened):
    def rugs(figure):
        return [t for t in figure["data"] if "screened" in t["name"]]
    assert not rugs(_page(hole["errors"])["errors"])
    marks = rugs(_page(screened)["errors"])
    assert marks and sum(t["showlegend"] for t in marks) == 1
    for t in marks:   # float32 on the page: to its 24 bits
        np.testing.assert_allclose(_values(t["x"]), SCREENED_S / 3600.0, rtol=1e-7)


def test_png_and_page_shade_and_mark_each_kind_in_one_colour(hole, screened):
    """Sun gap, yaw outage, telemetry gap and screened value: the colour of the
    PNG's legend entry (errors.png's figure legend) is the page's (its legend entry
    for the kind, and its rectangles or ticks)."""
    kinds = {"sun_gap": ("Sun gap", "Sun gap"), "outage": ("yaw outage", "yaw outage"),
             "telemetry_gap": ("telemetry gap", "telemetry gap"),
             "screened": ("screened", "screened")}
    seen = {}
    for directory in (hole["errors"], screened):
        fig = run_figure(directory, "errors")
        png = {t.get_text(): h for leg in fig.legends
               for t, h in zip(leg.get_texts(), leg.legend_handles, strict=True)}
        page = {t["name"]: t for t in _page(directory)["errors"]["data"]
                if t.get("showlegend", True)}
        for kind, (png_word, page_word) in kinds.items():
            handle = [h for label, h in png.items() if png_word in label]
            entry = [t for name, t in page.items() if page_word in name]
            if not handle:
                continue
            assert len(handle) == 1 and len(entry) == 1, kind
            h = handle[0]
            png_color = to_rgba(h.get_color() if hasattr(h, "get_marker") else
                                h.get_facecolor(), h.get_alpha())
            assert png_color == pytest.approx(_rgba_or_hex(entry[0]["marker"]["color"]),
                                              abs=1e-3), kind
            seen[kind] = png_color
    assert set(seen) == set(kinds)
    assert len(set(seen.values())) == len(kinds)    # four kinds, four colours


def _rgba_or_hex(css: str) -> tuple:
    return _rgba(css) if css.startswith("rgba") else to_rgba(css)
