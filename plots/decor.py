"""Axes decoration shared by the run figures: shading, time axis, tick labels,
limits that never clip silently, and one legend per figure.

Draws only what it is given; no physics.
"""

from __future__ import annotations

import textwrap

import numpy as np
from matplotlib.ticker import FixedLocator, FuncFormatter, MultipleLocator

from .palette import PALETTE
from .reduce import bins, breaks, f64, finite, pct, runs_of

GAP_LABEL = "no Sun-sensor yaw"
TELEMETRY_GAP_LABEL = "telemetry gap: no rows, nothing drawn across it"
SCREENED_LABEL = "screened value (made a dropout, kept from the filter)"
DAYS_BEYOND_H = 72.0     # time axes in days for spans longer than this
_MAX_SHADED = 400        # beyond this many intervals, shade a per-bin mask instead


def shade_mask(ax, t_h: np.ndarray, mask, label: str | None,
               color: str = PALETTE["sun_gap"].color,
               alpha: float = PALETTE["sun_gap"].alpha) -> None:
    """Bands over the intervals where ``mask`` is true (by default in the Sun gaps'
    shade).

    With hundreds of intervals (dropout flicker) a drawing bin is shaded when most of
    its samples are masked: the same picture at pixel resolution, drawn fast.
    """
    mask = np.asarray(mask, dtype=bool)
    if not mask.any():
        return
    n_intervals = int(np.count_nonzero(np.diff(np.r_[0, mask.astype(np.int8), 0]) == 1))
    if n_intervals <= _MAX_SHADED:
        for k, (a, b) in enumerate(runs_of(mask)):
            ax.axvspan(t_h[a], t_h[b], color=color, alpha=alpha, lw=0, zorder=0,
                       label=label if k == 0 else None)
        return
    starts, ends = bins(mask.size, 1000, t_h) or (np.arange(mask.size), np.arange(mask.size))
    mostly = np.add.reduceat(mask.astype(np.int64), starts) * 2 >= (ends - starts + 1)
    x = np.column_stack([t_h[starts], t_h[ends]]).ravel()
    ax.fill_between(x, 0, 1, where=np.repeat(mostly, 2), transform=ax.get_xaxis_transform(),
                    color=color, alpha=alpha, zorder=0, lw=0, label=label)


def gap_ends(t_s: np.ndarray, gap, min_gap_s: float = 0.0) -> np.ndarray:
    """Indices of the last sample of every gap that ends inside the record (a falling
    edge of ``gap``) and lasted at least ``min_gap_s``."""
    gap = np.asarray(gap, dtype=bool)
    last = np.array([b for a, b in runs_of(gap)
                     if b < gap.size - 1 and t_s[b] - t_s[a] >= min_gap_s], dtype=np.int64)
    return last


def time_axis(ax, t_h: np.ndarray) -> None:
    """Hours on the time axis up to three days, days beyond (the data stay in hours:
    only the ticks and their labels change), with round steps of either."""
    span = float(t_h[-1] - t_h[0]) if t_h.size > 1 else 0.0
    days = span > DAYS_BEYOND_H
    if span > 0:
        steps = [24.0 * d for d in (1, 2, 5, 7, 10, 14, 30, 60, 91, 182, 365)] if days \
            else (0.01, 0.02, 0.05, 0.1, 0.25, 0.5, 1, 2, 3, 6, 12, 24, 48)
        step = next((s for s in steps if span / s <= 16), steps[-1])
        ax.xaxis.set_major_locator(MultipleLocator(step))
        ax.set_xlim(t_h[0], t_h[-1])
    if days:
        ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v / 24.0:g}"))
    ax.set_xlabel("time (days)" if days else "time (h)")


def shade_gaps(ax, t_s: np.ndarray, t_h: np.ndarray, gap, min_gap_s: float,
               labels: tuple[str, str] | None) -> None:
    """The yaw outages, in two shades: Sun gaps (at least ``min_gap_s``: no head sees
    the Sun) and shorter outages (at the default geometry the ~1.3 h noon band,
    where the Sun is too near the yaw axis for a yaw); and in a third the telemetry
    gaps, one at each break of ``t_s`` (a NaN row), from the row before it to the row
    after.  ``labels`` (Sun gap, short) or None for an unlabelled panel."""
    gap = np.asarray(gap, dtype=bool)
    long = np.zeros_like(gap)
    for a, b in runs_of(gap):
        if t_s[b] - t_s[a] >= min_gap_s:
            long[a:b + 1] = True
    long_label, short_label = labels if labels is not None else (None, None)
    shade_mask(ax, t_h, long, long_label)
    shade_mask(ax, t_h, gap & ~long, short_label, **PALETTE["outage"].mpl())
    for k, i in enumerate(breaks(t_h)):
        ax.axvspan(t_h[i - 1], t_h[i + 1], lw=0, zorder=0, **PALETTE["telemetry_gap"].mpl(),
                   label=TELEMETRY_GAP_LABEL if k == 0 and labels is not None else None)


def mark_screened(ax, t_h_screened, label: bool) -> None:
    """A tick at the top of the panel at each screened value's time (hours), in the
    screened values' colour; nothing, and no legend entry, without any."""
    t = f64(t_h_screened) if t_h_screened is not None else np.empty(0)
    if not t.size:
        return
    ax.plot(t, np.full(t.size, 0.985), transform=ax.get_xaxis_transform(), ls="none",
            marker="|", ms=9, mew=1.2, zorder=9, clip_on=True,
            color=PALETTE["screened"].color, alpha=PALETTE["screened"].alpha,
            label=SCREENED_LABEL if label else "_screened")


def gap_labels(min_gap_s: float) -> tuple[str, str]:
    """The two shades' labels when the caller knows no more than the threshold."""
    h = f"{min_gap_s / 3600:g} h"
    return (f"Sun gap (no Sun-sensor yaw for {h} or more)",
            f"shorter yaw outage (under {h})")


def time_unit(t_h: np.ndarray):
    """(format, unit) for times written on a figure, matching its time axis: hours
    ("12.34", "h") up to three days, days ("29.87", "d") beyond."""
    span = float(t_h[-1] - t_h[0]) if len(t_h) > 1 else 0.0
    if span > DAYS_BEYOND_H:
        return (lambda t: f"{t / 24.0:.2f}"), "d"
    return (lambda t: f"{t:.2f}"), "h"


def at_time(t_h: np.ndarray, t: float) -> str:
    """"12.34 h" or "29.87 d", as ``time_unit``."""
    n, u = time_unit(t_h)
    return f"{n(t)} {u}"


def minus(text: str) -> str:
    return text.replace("-", "−")


def fmt(v: float, digits: int = 3) -> str:
    return "0" if v == 0 else minus(f"{v:.{digits}g}")


def engineering_axis(ax) -> str:
    """Tick labels in units of 10^(3k) so no offset text is needed; returns the factor
    to put in the unit ("10⁻⁶ "), or "" for plain decimals."""
    top = max(abs(v) for v in ax.get_ylim())
    if not np.isfinite(top) or top == 0:
        return ""
    e = int(np.floor(np.log10(top) / 3.0)) * 3
    if e == 0 or (-3 <= e < 0 and top >= 1e-3):   # 0.001 ... 999: plain decimals read best
        ax.ticklabel_format(axis="y", style="plain", useOffset=False)
        return ""
    scale = 10.0 ** e
    ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: minus(f"{v / scale:g}")))
    sup = str(e).translate(str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹"))
    return f"10{sup} "


def nice_ticks(linthresh: float, top: float) -> list[float]:
    """Symmetric tick values for a symlog axis: 0, then 1-2-5 (or sparser) decades."""
    lo_dec = int(np.floor(np.log10(linthresh)))
    hi_dec = int(np.ceil(np.log10(top)))
    for mants in ((1, 2, 5), (1, 3), (1,)):
        vals = [m * 10.0 ** d for d in range(lo_dec, hi_dec + 1) for m in mants]
        vals = [v for v in vals if 0.9 * linthresh <= v <= top]
        if len(vals) <= 5:
            break
    return sorted([-v for v in vals] + [0.0] + vals)


def symlog_axis(ax, linthresh: float, half: float) -> None:
    """Symmetric log axis, linear within ±linthresh (dotted lines mark it)."""
    ax.set_yscale("symlog", linthresh=linthresh, linscale=1.0)
    ax.yaxis.set_major_locator(FixedLocator(nice_ticks(linthresh, half)))
    ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: fmt(v)))
    ax.yaxis.set_minor_locator(FixedLocator([]))
    for sgn in (1, -1):
        ax.axhline(sgn * linthresh, color="0.5", lw=0.5, ls=":", zorder=1)
    ax.set_ylim(-half, half)


def nice_up(v: float) -> float:
    """The next 1-2-5 value at or above ``v`` (> 0)."""
    d = 10.0 ** np.floor(np.log10(v))
    for m in (1, 2, 5, 10):
        if m * d >= v * (1 - 1e-12):
            return m * d
    return 10 * d


def robust_half(hard, soft=(), outlier: float = 3.0, margin: float = 1.12) -> float:
    """Half-range of a symmetric y-axis.

    ``hard`` arrays are data: the axis holds all of them, unless their largest |value|
    is more than ``outlier`` times their 99.5th percentile (a start-up transient, a
    spike), then it holds that percentile and the caller says what is clipped
    (``note_clipped``).  ``soft`` arrays (σ envelopes) are held from 5% of the run
    on: before, σ is the prior's, far larger than anything after.
    """
    top = 0.0
    for a in hard:
        a = np.abs(finite(a))
        if a.size:
            p = float(np.percentile(a, 99.5))
            m = float(a.max())
            top = max(top, m if m <= outlier * p or p == 0 else p)
    for a in soft:
        a = np.abs(f64(a))
        top = max(top, pct(a[a.size // 20:], 100))
    if top <= 0 or not np.isfinite(top):
        return 1.0
    return margin * top


def note_clipped(ax, t_h: np.ndarray, series: dict, lo: float, hi: float, unit: str,
                 digits: int = 3) -> list[str]:
    """Say what leaves the axes: for each named series with values outside
    [lo, hi], its share of samples, when, and its largest |value| and time; the
    largest is also marked at the axis edge.  The notes go in the panel's right
    title, where they cannot cover data.  Returns the notes."""
    notes = []
    for name, y in series.items():
        y = f64(y)
        out = np.isfinite(y) & ((y < lo) | (y > hi))
        if not out.any():
            continue
        idx = np.flatnonzero(out)
        k = idx[np.argmax(np.abs(y[idx]))]
        share = 100.0 * idx.size / max(1, np.count_nonzero(np.isfinite(y)))
        t0, t1 = t_h[idx[0]], t_h[idx[-1]]
        early = t0 - t_h[0] <= 0.01 * (t_h[-1] - t_h[0])
        n, u = time_unit(t_h)
        when = (f"t ≤ {n(t1)} {u}" if early and t1 - t0 < 0.1 * (t_h[-1] - t_h[0])
                else f"{n(t0)}–{n(t1)} {u}" if idx[-1] - idx[0] + 1 == idx.size
                else f"between {n(t0)} and {n(t1)} {u}")
        notes.append(f"{name} off scale: {share:.2g}% of samples ({when}), "
                     f"max {fmt(float(y[k]), digits)} {unit} at {n(t_h[k])} {u}")
        edge = hi if y[k] > hi else lo
        ax.plot([t_h[k]], [edge], marker="^" if y[k] > hi else "v", ms=7, color="k",
                clip_on=False, zorder=8, ls="none", label="_off-scale mark")
    if notes:
        ax.set_title("\n".join(notes), loc="right", fontsize=7.5, color="0.15")
    return notes


WARNING_COLOR = "#c00000"
WARNING_LINE_IN = 0.19   # inches per line of 9-point warning text


def warnings_text(messages, width: int = 160) -> str:
    """The run's warnings as one block, each wrapped, or "" when there are none."""
    messages = [m for m in (messages or []) if m]
    return "\n".join(textwrap.fill(f"WARNING: {m}", width, subsequent_indent="    ")
                     for m in messages)


def warnings_height_in(text: str) -> float:
    """Height (inches) of the axes row holding ``text``; 0 without warnings."""
    return WARNING_LINE_IN * (text.count("\n") + 1) + 0.1 if text else 0.0


def draw_warnings(ax, text: str) -> None:
    """The warnings in red in their own row above the panels (below them they would
    share the space of the figure's legend)."""
    ax.axis("off")
    ax.text(0.0, 1.0, text, transform=ax.transAxes, ha="left", va="top", fontsize=9,
            color=WARNING_COLOR, label="warnings")


def panel_figure(ratios, warnings, inch: float, extra: float = 1.8, width_in: float = 13.0):
    """A figure of stacked panels sharing the time axis (height ``inch`` per unit of
    ``ratios`` plus ``extra`` for titles and legend) and, above them when there are
    warnings, a row holding those.  Returns (figure, the panels' axes)."""
    import matplotlib.pyplot as plt
    # About 12 characters of 9-point text per inch: wrapped to the figure's width.
    text = warnings_text(warnings, width=int(12 * width_in))
    top = [warnings_height_in(text) / inch] if text else []
    fig, axes = plt.subplots(len(top) + len(ratios), 1, sharex=True, layout="constrained",
                             figsize=(width_in, inch * (sum(ratios) + sum(top)) + extra),
                             squeeze=False, gridspec_kw={"height_ratios": top + ratios})
    axes = axes[:, 0]
    if text:
        draw_warnings(axes[0], text)
    return fig, axes[len(top):]


def dot_handle(ax, color, label: str, alpha: float = 0.8) -> None:
    """An empty artist carrying a legend entry with a readable marker for a cloud of
    tiny dots (the dots themselves are drawn without a label)."""
    ax.plot([], [], ls="none", marker="o", ms=5, color=color, alpha=alpha, label=label)


def figure_legend(fig, axes, ncol: int = 4) -> None:
    """One legend for the whole figure, below the time axis (above it, it collides
    with the title): every labelled artist of every panel, each label once, in
    drawing order."""
    seen: dict[str, object] = {}
    for ax in axes:
        for h, lab in zip(*ax.get_legend_handles_labels(), strict=True):
            if lab and not lab.startswith("_") and lab not in seen:
                seen[lab] = h
    if seen:
        fig.legend(list(seen.values()), list(seen.keys()), loc="outside lower center",
                   ncol=min(ncol, len(seen)), fontsize=8, frameon=False)


