"""Plotly figure specifications (plain dicts, drawn by plotly.js in the page) from
arrays.

A page must open in seconds whatever the run's length, so no trace carries more
than ``MAX_POINTS`` points: a longer series is cut into bins of whole rows and each
bin gives its minimum and maximum, drawn as a band.  The extremes, not a mean,
because a reviewer looks for the worst excursion and an average would hide it.
Arrays go into the page as little-endian float32 in base64 (plotly.js's typed-array
form): a quarter of the text of decimal numbers, and float32 is what
comparison.npz stores.

An x array may hold breaks (NaN rows, ``figures.marks``: a telemetry gap between
the rows either side): no bin spans one, and plotly.js breaks a line at it.
"""

from __future__ import annotations

import base64
import math
from dataclasses import dataclass

import numpy as np

from ..figures.marks import PALETTE

MAX_POINTS = 3000        # per trace: two days' 2,700 rows as they are; a year's 493,000
                         # rows in bins of 165
COLORS = {"real": "#1f5fa8", "linear": "#e07b00", "ekf": "#2a9d3a", "smoothed": "#7a3fb0",
          "sigma": "#555555", "truth": "#111111", "paper": "#b22222", "band": "#1f5fa8",
          "teal": "#0097a7"}
# The PNG figures' colours for the same kinds (plots.palette): one scheme.
SHADES = {kind: shade.rgba() for kind, shade in PALETTE.items()}


def typed(a) -> dict:
    """An array as plotly.js's typed-array spec: float32, base64.  NaN stays NaN: a
    gap in a line."""
    data = np.ascontiguousarray(np.asarray(a, dtype="<f4"))
    return {"dtype": "f4", "bdata": base64.b64encode(data.tobytes()).decode("ascii")}


def time_unit(duration_s: float) -> tuple[float, str]:
    """Seconds per unit of the time axis and its label: hours up to three days, days
    beyond (as the PNG figures)."""
    return (86400.0, "days") if duration_s > 3 * 86400.0 else (3600.0, "hours")


def bin_starts(n: int, max_points: int = MAX_POINTS, x=None) -> np.ndarray | None:
    """Row index where each bin starts, or None when ``n`` rows fit as they are.
    With ``x``, each break (a NaN) is a bin of its own: no bin spans a gap."""
    if n <= max_points:
        return None
    starts = np.arange(0, n, math.ceil(n / max_points))
    brk = np.flatnonzero(np.isnan(np.asarray(x, dtype=float))) if x is not None else []
    if len(brk):
        starts = np.unique(np.concatenate([starts, brk, brk + 1]))
        starts = starts[starts < n]
    return starts


def extremes(y, starts: np.ndarray, low=None, high=None) -> tuple[np.ndarray, np.ndarray]:
    """The smallest and largest value in each bin, ignoring NaN (an all-NaN bin gives
    NaN).  ``low``/``high``: per-row extremes already known (comparison.npz's
    full-rate ``*_min``/``*_max``), folded in with the row values."""
    y = np.asarray(y, dtype=float)
    lo = y if low is None else np.fmin(y, low)
    hi = y if high is None else np.fmax(y, high)
    return np.fmin.reduceat(lo, starts), np.fmax.reduceat(hi, starts)


def line(x, y, name: str, color: str, yaxis: str = "y", dash: str | None = None,
         width: float = 1.2, group: str | None = None, show: bool = True,
         mode: str = "lines") -> dict:
    trace = {"type": "scatter", "mode": mode, "name": name, "x": typed(x), "y": typed(y),
             "yaxis": yaxis, "line": {"color": color, "width": width},
             "legendgroup": group or name, "showlegend": show,
             "hovertemplate": "%{y:.4g}<extra>" + name + "</extra>"}
    if mode == "markers":
        trace["marker"] = {"color": color, "size": 3}
        del trace["line"]
    if dash:
        trace["line"]["dash"] = dash
    return trace


def band(x, low, high, name: str, color: str, yaxis: str = "y", opacity: float = 0.35,
         group: str | None = None, show: bool = True) -> list[dict]:
    """A filled band between ``low`` and ``high``: one closed outline per stretch of
    finite values (a NaN row, a gap in the telemetry, ends one), filled."""
    x = np.asarray(x, dtype=float)
    lo, hi = np.asarray(low, dtype=float), np.asarray(high, dtype=float)
    ok = np.isfinite(lo) & np.isfinite(hi)
    xs, ys = [], []
    for a, b in _runs(ok):
        xs += [x[a:b], x[a:b][::-1], [np.nan]]
        ys += [hi[a:b], lo[a:b][::-1], [np.nan]]
    fill = _rgba(color, opacity)
    return [{"type": "scatter", "mode": "lines", "x": typed(np.concatenate(xs or [[]])),
             "y": typed(np.concatenate(ys or [[]])), "yaxis": yaxis, "fill": "toself",
             "fillcolor": fill, "line": {"width": 0.5, "color": fill}, "name": name,
             "legendgroup": group or name, "showlegend": show, "hoverinfo": "skip"}]


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) of each run of True."""
    edges = np.flatnonzero(np.diff(np.concatenate(([0], mask.astype(np.int8), [0]))))
    return list(zip(edges[::2].tolist(), edges[1::2].tolist(), strict=True))


def robust_range(values: list, x, skip_s: float, scale: float, pad: float = 1.12):
    """A symmetric y range holding every value after the filter's start-up (the first
    ``skip_s``, where a large initial σ would flatten everything after it); None when
    nothing is left to scale by."""
    keep = np.asarray(x, dtype=float) * scale >= skip_s
    peaks = [np.nanmax(np.abs(np.asarray(v, dtype=float)[keep])) for v in values
             if v is not None and np.isfinite(np.asarray(v, dtype=float)[keep]).any()]
    top = max(peaks, default=0.0)
    return None if not (top > 0 and np.isfinite(top)) else (-pad * top, pad * top)


@dataclass(frozen=True)
class Reduced:
    """A series as the page draws it: its rows (``step`` 0: ``x``, ``y`` and the
    full-rate extremes ``lo``, ``hi`` or None), or each bin's first x and its
    smallest and largest value (``step``: the rows of a bin, for the label)."""
    x: np.ndarray
    y: np.ndarray | None
    lo: np.ndarray | None
    hi: np.ndarray | None
    step: int = 0


def reduced(x, y, low=None, high=None) -> Reduced:
    """``y`` over ``x`` reduced for drawing (``bin_starts``, ``extremes``)."""
    x = np.asarray(x, dtype=float)
    starts = bin_starts(len(x), x=x)
    if starts is None:
        return Reduced(x, y, low, high)
    lo, hi = extremes(y, starts, low, high)
    return Reduced(x[starts], None, lo, hi, int(starts[1] - starts[0]) if len(starts) > 1
                   else 1)


def series(x, y, name: str, color: str, yaxis: str = "y", low=None, high=None,
           group: str | None = None, show: bool = True, mode: str = "lines",
           outline: bool = False) -> list[dict]:
    """One series as the page draws it: the row values as a line when they fit,
    with the full-rate extremes between rows (``low``, ``high``) as a faint band
    behind them; beyond ``MAX_POINTS`` rows only the band of each bin's extremes
    (``outline``: its two edges as thin lines, for a series drawn over another's
    band, where two fills would blend into a third colour)."""
    return draw(reduced(x, y, low, high), name, color, yaxis, group, show, mode, outline)


def draw(r: Reduced, name: str, color: str, yaxis: str = "y", group: str | None = None,
         show: bool = True, mode: str = "lines", outline: bool = False) -> list[dict]:
    """``series``'s traces of a series already reduced."""
    if not r.step:
        out = []
        if r.lo is not None and r.hi is not None:
            out += band(r.x, r.lo, r.hi, f"{name} (full-rate extremes)", color, yaxis, 0.18,
                        group=group, show=False)
        return out + [line(r.x, r.y, name, color, yaxis, group=group, show=show, mode=mode)]
    label = f"{name} (min–max per {r.step} rows)"
    if outline:
        return [line(np.concatenate([r.x, [np.nan], r.x]),
                     np.concatenate([r.lo, [np.nan], r.hi]), label, color, yaxis, width=0.8,
                     group=group, show=show)]
    return band(r.x, r.lo, r.hi, label, color, yaxis, 0.55, group=group, show=show)


def sigma_band(x, sigma, yaxis: str, name: str = "±3σ (filter)", color: str = COLORS["sigma"],
               dash: str = "dash", group: str | None = None, show: bool = True) -> list[dict]:
    """±3σ as two lines; binned, as two bands, each spanning the smallest to the
    largest 3σ of the bin (σ swings through the day: a line through either would
    zigzag)."""
    x = np.asarray(x, dtype=float)
    s = 3.0 * np.asarray(sigma, dtype=float)
    starts = bin_starts(len(x), x=x)
    g = group or name
    if starts is not None:
        lo, hi = extremes(s, starts)
        return (band(x[starts], lo, hi, f"{name} (min–max per {_bin_label(x, starts)})",
                     color, yaxis, 0.30, group=g, show=show)
                + band(x[starts], -hi, -lo, name, color, yaxis, 0.30, group=g, show=False))
    return [line(x, s, name, color, yaxis, dash=dash, width=1.0, group=g, show=show),
            line(x, -s, name, color, yaxis, dash=dash, width=1.0, group=g, show=False)]


def stacked_layout(panels: list[dict], x_title: str, height_per_panel: int = 210,
                   shapes: list | None = None, x_range=None) -> dict:
    """One x axis under several stacked y panels (each ``{"title": ...}``, top first),
    so every panel zooms and pans together."""
    n = len(panels)
    gap = 0.045 if n > 1 else 0.0
    h = (1.0 - gap * (n - 1)) / n
    layout = {"height": max(300, height_per_panel * n + 80),
              "margin": {"l": 80, "r": 45, "t": 30, "b": 50},
              "hovermode": "x", "legend": {"orientation": "h", "y": 1.0, "yanchor": "bottom"},
              "xaxis": {"title": {"text": x_title}, "anchor": f"y{n if n > 1 else ''}",
                        "showline": True, "zeroline": False},
              # Every time figure starts on the run's own span (markers would pad it).
              "shapes": shapes or [], "template": "plotly_white"}
    if x_range is not None:
        layout["xaxis"]["range"] = [float(x_range[0]), float(x_range[1])]
    for i, p in enumerate(panels):
        top = 1.0 - i * (h + gap)
        key = "yaxis" if i == 0 else f"yaxis{i + 1}"
        layout[key] = {"domain": [max(0.0, top - h), top], "title": {"text": p["title"]},
                       "zeroline": True, "exponentformat": "power", "anchor": "x"}
        if p.get("range") is not None:
            layout[key]["range"] = list(p["range"])
    return layout


def axis(i: int) -> str:
    """The trace-side name of panel i's y axis: "y", "y2", …"""
    return "y" if i == 0 else f"y{i + 1}"


def spans(t_unit, mask) -> list[tuple[float, float]]:
    """[start, end) of each run of True in ``mask``, in the axis unit (a span ends at
    the first row after it, so a one-row span still shows; at its last row when a
    break follows it)."""
    t = np.asarray(t_unit, dtype=float)
    runs = _runs(np.asarray(mask, dtype=bool))
    ends = [min(b, len(t) - 1) for _, b in runs]
    return [(float(t[a]), float(t[e] if np.isfinite(t[e]) else t[e - 1]))
            for (a, _), e in zip(runs, ends, strict=True)]


def shades(intervals, kind: str) -> list[dict]:
    """Rectangles across every panel (``yref: paper``) behind the traces."""
    return [{"type": "rect", "xref": "x", "yref": "paper", "x0": a, "x1": b, "y0": 0, "y1": 1,
             "fillcolor": SHADES[kind], "line": {"width": 0}, "layer": "below"}
            for a, b in intervals]


def hline(y: float, yaxis: str, color: str, dash: str = "dot") -> dict:
    """A horizontal line across one panel (a bound, a requirement)."""
    ref = "y" if yaxis == "y" else yaxis
    return {"type": "line", "xref": "paper", "x0": 0, "x1": 1, "yref": ref, "y0": y, "y1": y,
            "line": {"color": color, "width": 1.2, "dash": dash}}


def legend_only(name: str, color: str, kind: str = "rect") -> dict:
    """A legend entry for a shading (shapes have none of their own)."""
    return {"type": "scatter", "mode": "markers", "x": [None], "y": [None], "name": name,
            "marker": {"symbol": "square", "size": 12, "color": color}, "hoverinfo": "skip"}


def _bin_label(x: np.ndarray, starts: np.ndarray) -> str:
    rows = int(starts[1] - starts[0]) if len(starts) > 1 else 1
    return f"{rows} rows"


def _rgba(color: str, alpha: float) -> str:
    c = color.lstrip("#")
    r, g, b = (int(c[i:i + 2], 16) for i in (0, 2, 4))
    return f"rgba({r}, {g}, {b}, {alpha})"
