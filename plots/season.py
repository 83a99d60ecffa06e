"""season.png: a long run's days, from daily.csv's columns.

Against the day of the year (continuous across New Year, labelled by month):
the gap-end yaw error, on a scale set by the errors themselves, with the filter's
±3σ and Eq. 55's ±3σ (said in the panel when they reach beyond it); the eclipse
minutes per day (the two eclipse seasons); the real and linearized yaw RMS and the
RMS of their difference.  The headline gives the gap-end verdict computed from the
rows ("not tested" without a gap end); a panel with nothing to show says why.
Draws only what it is given.
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import numpy as np  # noqa: E402

from .decor import figure_legend, panel_figure  # noqa: E402
from .events import mark_events  # noqa: E402

MONTH_STARTS = (1, 32, 60, 91, 121, 152, 182, 213, 244, 274, 305, 335)
MONTHS = ("Jan", "Feb", "Mar", "Apr", "May", "Jun", "Jul", "Aug", "Sep", "Oct", "Nov", "Dec")


def continuous_day(day_of_year) -> np.ndarray:
    """Day of year made increasing across New Year (365 → 366 → 367 …)."""
    d = np.asarray(day_of_year, dtype=float).copy()
    wraps = np.cumsum(np.r_[0, np.diff(d) < 0])
    return d + 365.0 * wraps


def _month_ticks(ax, x) -> None:
    lo, hi = np.nanmin(x), np.nanmax(x)
    if hi - lo < 45:        # a short run: plain days read better
        ax.set_xlabel("day of year")
        return
    ticks, labels = [], []
    for year in range(int(lo // 365), int(hi // 365) + 1):
        for start, name in zip(MONTH_STARTS, MONTHS, strict=True):
            t = start + 365 * year
            if lo - 1 <= t <= hi + 1:
                ticks.append(t)
                labels.append(name)
    ax.set_xticks(ticks, labels)
    ax.set_xlabel("day of year (month starts)")


def outside_3sigma(error, sigma) -> tuple[int, int]:
    """(gap ends outside ±3σ, gap ends) over the rows that have one."""
    e, s = np.asarray(error, float), np.asarray(sigma, float)
    ok = np.isfinite(e) & np.isfinite(s)
    return int(np.sum(np.abs(e[ok]) > 3 * s[ok])), int(np.sum(ok))


def headline(daily: dict[str, np.ndarray]) -> str:
    """What the figure shows, with the gap-end verdict computed from the rows: N of M
    within ±3σ and the worst |e|/σ (its day of year), or "not tested" without a gap end."""
    e = np.asarray(daily["gap_end_yaw_error_deg"], float)
    s = np.asarray(daily["gap_end_yaw_sigma_deg"], float)
    out, n = outside_3sigma(e, s)
    days = len(e)
    ends = int(np.sum(np.isfinite(s)))
    if n == 0 and ends:
        verdict = f"not tested (no truth: the filter's ±3σ at {ends} Sun-gap ends only)"
    elif n == 0:
        verdict = f"not tested (no Sun-gap end in these {days} days)"
    else:
        z = np.where(np.isfinite(e) & np.isfinite(s), np.abs(e) / s, -1.0)
        k = int(np.argmax(z))
        verdict = (f"{n - out} of {n} within ±3σ, worst |e|/σ = {z[k]:.2f} "
                   f"(day of year {int(daily['day_of_year'][k])})")
    return (f"Yaw error at each day's Sun-gap end against the filter's ±3σ: {verdict}\n"
            "with the eclipse minutes and the real and linearized yaw error RMS of each day")


def _error_half_range(err, band, eq55_3s: float) -> tuple[float, list[str]]:
    """Half-range of the gap-end panel, chosen from the errors so that they read: the
    ±3σ levels are held too when they are within 4× the largest error, otherwise they
    lie beyond the axes and the returned notes name them (the panel then shows the
    errors' own spread, never a flat row on a σ-sized scale)."""
    top = float(np.max(np.abs(err))) if err.size else 0.0
    refs = {"filter ±3σ": band, "Eq. 55 ±3σ": np.array([eq55_3s])}
    refs = {k: v[np.isfinite(v)] for k, v in refs.items()}
    if top == 0:        # no error to scale on: the levels set the axis
        return 1.15 * max([float(v.max()) for v in refs.values() if v.size] + [1e-3]), []
    held = [float(v.max()) for v in refs.values() if v.size and v.max() <= 4 * top]
    half = 1.15 * max([top, *held])
    notes = []
    for name, v in refs.items():
        if v.size and v.max() > half:
            lo, hi = float(v.min()), float(v.max())
            span = f"{lo:.3f}°" if np.isclose(lo, hi, rtol=5e-3) else f"{lo:.3f}–{hi:.3f}°"
            notes.append(f"{name} {span}")
    return half, notes


def plot_season(daily: dict[str, np.ndarray], title: str, warnings=(), events=None):
    """season.png; ``title`` (scenario, seed, epoch) goes under a headline computed from
    the rows (``headline``).  One legend for the figure, below the axes, off the data;
    the run's ``warnings`` (messages), when any, above the panels: a long run's truth
    drifting out of the linear range is said where the season is drawn.  ``events``:
    the run's scheduled events (summary.json's dicts, ``t_s`` and ``end_s`` in seconds
    from the start of the first row's day), marked on every panel."""
    x = continuous_day(daily["day_of_year"])
    fig, axes = panel_figure([3, 1.3, 2], warnings, inch=1.3, width_in=11.0)
    ax = axes[0]
    err = np.asarray(daily["gap_end_yaw_error_deg"], float)
    sig = np.asarray(daily["gap_end_yaw_sigma_deg"], float)
    eq55 = float(np.nanmax(daily["eq55_sigma_yaw_deg"]))
    out, n = outside_3sigma(err, sig)
    has = np.isfinite(sig)
    ax.fill_between(x, -3 * sig, 3 * sig, where=has, color="tab:blue", alpha=0.18, lw=0,
                    label="filter ±3σ at the gap end")
    ax.axhline(3 * eq55, color="k", ls="--", lw=1, label=f"Eq. 55 ±3σ ({3 * eq55:.3f}°)")
    ax.axhline(-3 * eq55, color="k", ls="--", lw=1)
    ax.plot(x, err, "o", ms=4, color="tab:red",
            label=f"gap-end yaw error ({out} of {n} outside ±3σ)")
    ax.axhline(0, color="0.6", lw=0.6)
    ax.set_ylabel("yaw error at Sun-gap end (deg)")
    ok = np.isfinite(err) & has
    half, notes = _error_half_range(err[ok], 3 * sig[has], 3 * eq55)
    ax.set_ylim(-half, half)
    if notes:
        ax.set_title(f"scaled to the errors; beyond the axes: {', '.join(notes)}",
                     loc="right", fontsize=8, color="0.15")
    if n == 0 and has.any():
        # A telemetry file without a truth: the filter's own σ, no error to judge.
        _note(ax, f"not tested: no truth to judge the errors at these {int(has.sum())} "
                  "Sun-gap ends against")
    elif n == 0:
        _note(ax, f"not tested: no Sun-gap end in these {len(x)} days")

    ax = axes[1]
    ax.bar(x, daily["eclipse_min"], width=1.0, color="0.35")
    ax.set_ylabel("eclipse (min/day)")
    known = np.isfinite(daily["eclipse_min"])
    peak = float(np.max(daily["eclipse_min"][known])) if known.any() else 0.0
    ax.set_ylim(0, max(1.0, 1.15 * peak))
    if not known.any():
        # A telemetry file's days: the shadow is the truth's, which a file lacks.
        _note(ax, "eclipse not known: the telemetry does not say when it was in shadow")
    elif not peak > 0:
        _note(ax, "no eclipse on any of these days (outside the eclipse seasons)")

    ax = axes[2]
    for key, label, style in (("yaw_error_rms_deg", "real yaw RMS", "-"),
                              ("yaw_error_rms_linear_deg", "linearized yaw RMS", "--"),
                              ("yaw_error_rms_real_minus_linear_deg",
                               "RMS of real − linearized yaw", ":")):
        if np.isfinite(daily[key]).any() or key == "yaw_error_rms_deg":
            ax.plot(x, daily[key], style, lw=1.2, label=label)
    if not np.isfinite(daily["yaw_error_rms_deg"]).any():
        _note(ax, "not tested: no truth, so no errors to take the RMS of")
    values = np.r_[daily["yaw_error_rms_deg"], daily["yaw_error_rms_real_minus_linear_deg"]]
    values = values[np.isfinite(values) & (values > 0)]
    if values.size and values.max() / values.min() > 30:
        ax.set_yscale("log")
    ax.set_ylabel("yaw error RMS per day (deg)")
    _month_ticks(ax, x)
    for a in axes:
        a.grid(alpha=0.3)
        # A row's point and eclipse bar are centred on its day: the first day spans
        # x[0] ± 0.5, and an event falls inside its own day's bar.
        mark_events(a, events, lambda t: x[0] - 0.5 + t / 86400.0)
    fig.suptitle(f"{headline(daily)}\n{title}", fontsize=9.5)
    figure_legend(fig, axes, ncol=3)
    return fig


def _note(ax, text: str) -> None:
    """Why a panel has nothing to show, in the panel itself."""
    ax.text(0.5, 0.5, text, transform=ax.transAxes, ha="center", va="center", fontsize=9,
            color="0.2", bbox=dict(facecolor="white", edgecolor="0.6", lw=0.5))
