"""The error figure of a run (``errors.png``) and, without a truth, the estimate
figure (``estimates.png``).

The comparison the tool exists for is real against linearized: the filter run on
telemetry of the nonlinear truth, and the same filter on telemetry of the paper's
linear twin.  The two errors lie on top of each other at the scale of the filter's
σ, so each state gets a second panel with their difference on its own scale.

Draws only what it is given (plain arrays in seconds, degrees and N m s); no
physics and no imports from ``sim`` or ``estimator``.
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import numpy as np  # noqa: E402

from .decor import (  # noqa: E402
    at_time,
    dot_handle,
    engineering_axis,
    figure_legend,
    fmt,
    gap_ends,
    gap_labels,
    mark_screened,
    note_clipped,
    panel_figure,
    robust_half,
    shade_gaps,
    symlog_axis,
    time_axis,
)
from .events import mark_events  # noqa: E402
from .reduce import (  # noqa: E402
    band,
    f64,
    interval_stats,
    max_abs,
    median_step,
    minmax_line,
    nice_interval_s,
    pct,
    stride,
)

REAL, LINEAR, SMOOTH, DIFF, SIGMA, EKF, PAPER = "C3", "C0", "k", "C1", "darkgreen", "C4", "m"
LABEL_REAL = "real: filter on nonlinear-truth telemetry, minus that truth"
LABEL_LINEAR = "linearized: filter on linear-twin telemetry, minus the twin"
LABEL_SMOOTH = "smoother, real"
LABEL_DIFF = "real − linearized"
LABEL_EKF = "EKF: extended Kalman filter on the same telemetry, minus the truth"
LABEL_EKF_DIFF = "EKF − paper filter (their estimates' difference)"
#: Share of samples outside ±3σ for a Gaussian error of that σ.
OUTSIDE_3SIGMA = 0.0027


def times(ratio: float) -> str:
    """"54×", or "4.1×10⁶×" for large ratios."""
    if ratio < 1e4:
        return f"{ratio:.2g}×"
    e = int(np.floor(np.log10(ratio)))
    sup = str(e).translate(str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹"))
    return f"{ratio / 10**e:.2g}×10{sup}×"


def _minutes(interval_s: float) -> str:
    if interval_s >= 3600:
        return f"{interval_s / 3600:g} h"
    return f"{interval_s / 60:g} min" if interval_s >= 60 else f"{interval_s:g} s"


def _sigma_band(ax, t_h, sig, k: float = 3.0, label: str = "filter ±3σ") -> None:
    """±kσ about zero: a light band with dark edges drawn over the error traces, so
    the envelope shows even where errors cover it."""
    x, lo, hi = band(t_h, -k * sig, k * sig)
    ax.fill_between(x, lo, hi, color="C2", alpha=0.13, lw=0, zorder=1, label=label)
    ax.plot(x, hi, color=SIGMA, lw=0.9, zorder=5)
    ax.plot(x, lo, color=SIGMA, lw=0.9, zorder=5)


def _pm(x, v):
    """(x, y) of the +v and −v step lines joined by a NaN (one artist, one label)."""
    return np.r_[x, np.nan, x], np.r_[v, np.nan, -v]


def _samples(ax, t_h, y, envelope: bool, color: str, label: str, **line) -> None:
    """An error at every stored row: dots for a noisy one (a subsample when there
    are more rows than dots), a line for a slow one (min/max per pixel column
    beyond 2,000 columns: the same picture)."""
    if envelope:
        ax.plot(*stride(t_h, y), ".", ms=1.6, color=color, alpha=0.45, zorder=2)
        dot_handle(ax, color, label)
    else:
        ax.plot(*minmax_line(t_h, y), color=color, label=label, **line)


def _rms(ax, t_s, y, interval_s: float, color: str, label: str, **line) -> None:
    x, _, _, rms = interval_stats(t_s, y, interval_s)
    ax.plot(*_pm(x, rms), color=color, label=label, **line)


def _errors(ax, t_s, t_h, s: dict, envelope: bool, interval_s: float, rows: str) -> None:
    """Each run's error, every panel alike: the real error at every stored row, and
    for a noisy error (roll, h) each run's ±RMS per interval, for a slow one (yaw)
    each run's trace.  Both are comparable with ±3σ: a row outside it is a sample
    outside it, not the extreme of many (the full-rate min–max per row is not drawn
    here for that reason)."""
    others = [(k, c, lab, st) for k, c, lab, st in (
        ("linear", LINEAR, LABEL_LINEAR, dict(lw=2.6, alpha=0.45, zorder=3)),
        ("smoothed", SMOOTH, LABEL_SMOOTH, dict(lw=0.7, alpha=0.8, zorder=4)),
        ("ekf", EKF, LABEL_EKF, dict(lw=0.9, ls="--", zorder=4))) if s.get(k) is not None]
    if envelope:
        _samples(ax, t_h, s["real"], True, REAL, f"real, every {rows} row (dots)")
        _rms(ax, t_s, s["real"], interval_s, REAL, LABEL_REAL, lw=0.9, zorder=4)
        for key, color, label, style in others:
            _rms(ax, t_s, s[key], interval_s, color, label, **style)
    else:
        # The twin's wide pale line under the real one, so both show where they coincide.
        for key, color, label, style in others:
            if key == "linear":
                _samples(ax, t_h, s[key], False, color, label, **style)
        _samples(ax, t_h, s["real"], False, REAL, LABEL_REAL, lw=0.8, zorder=3)
        for key, color, label, style in others:
            if key != "linear":
                _samples(ax, t_h, s[key], False, color, label, **style)


def _largest(arrays) -> np.ndarray:
    """Per sample, the value of largest magnitude among ``arrays`` (for one clipping
    note covering every error trace of a panel)."""
    out = None
    for a in arrays:
        a = f64(a)
        out = a if out is None else np.where(np.abs(a) > np.abs(out), a, out)
    return out


def _paper_lines(ax, t_h, sig, ends, ref: tuple[float, str]) -> None:
    """The paper's σ_yaw as ±3σ lines across the panel (what a gap-end error is
    judged against), and the filter's ±3σ at the last Sun-gap end, written out."""
    value, label = ref
    for sgn in (1, -1):
        ax.axhline(sgn * 3 * value, color=PAPER, lw=1.2, ls=(0, (6, 3)), zorder=6,
                   label=f"paper ±3σ_yaw at Sun-gap ends ({label})" if sgn > 0
                   else "_paper −3σ")
    if not ends.size:
        return
    i = ends[-1]
    s_last = abs(float(sig[i]))
    ax.plot([t_h[i]] * 2, [3 * s_last, -3 * s_last], ls="none", marker="o", mfc="none",
            mec="k", ms=7, mew=1.3, zorder=7, label="filter ±3σ at the last Sun-gap end")
    ax.annotate(f"last Sun-gap end, t = {at_time(t_h, t_h[i])}: filter σ_yaw = {s_last:.4f}° "
                f"({label})", xy=(t_h[i], -3 * s_last), xycoords="data",
                xytext=(0.99, 0.04), textcoords="axes fraction", fontsize=8, ha="right",
                va="bottom", zorder=9, bbox=dict(boxstyle="round", fc="w", ec="0.6", alpha=0.9),
                arrowprops=dict(arrowstyle="->", color="k", lw=0.8))


def _outside(real, three) -> str:
    """The share of rows outside ±3σ, and what a consistent filter would give."""
    real, three = f64(real), f64(three)
    ok = np.isfinite(real) & np.isfinite(three)
    if not ok.any():
        return ""
    share = float(np.mean(np.abs(real[ok]) > three[ok]))
    return (f"\n{100 * share:.2g}% of rows outside the filter's ±3σ "
            f"({100 * OUTSIDE_3SIGMA:g}% if Gaussian and consistent)")


def _error_panel(ax, t_s, t_h, shade, name: str, s: dict, ends, ref, interval_s: float,
                 rows: str) -> None:
    unit, sig = s["unit"], np.abs(f64(s["sigma"]))
    three = 3.0 * sig
    shade(ax, True)
    _sigma_band(ax, t_h, sig)
    ekf_three = None
    if s.get("ekf_sigma") is not None:
        ekf_three = 3.0 * np.abs(f64(s["ekf_sigma"]))
        x, lo, hi = band(t_h, -ekf_three, ekf_three)
        ax.plot(*_pm(x, hi), color=EKF, lw=1.2, ls=(0, (2, 2)), zorder=6, label="EKF ±3σ")
    envelope = s.get("style") == "envelope"
    _errors(ax, t_s, t_h, s, envelope, interval_s, rows)
    ax.axhline(0.0, color="0.4", lw=0.5, zorder=1)
    marks = name == "yaw" and unit == "deg" and ref is not None
    if marks:
        _paper_lines(ax, t_h, sig, ends, ref)
    errors = {"real error": s["real"], "linearized error": s.get("linear"),
              "EKF error": s.get("ekf"), "smoother error": s.get("smoothed")}
    errors = {k: v for k, v in errors.items() if v is not None}
    soft = [three] + ([ekf_three] if ekf_three is not None else [])
    half = max(robust_half(errors.values(), soft), 3.3 * ref[0] if marks else 0.0)
    # When the sunlit σ would be a sliver of an axis sized for the gap growth, the
    # axis is symlog, linear inside ±(sunlit 3σ): both stay readable.
    lit = pct(three, 10)
    label = f"{name} error ({unit})"
    if lit > 0 and half / lit > 8.0:
        symlog_axis(ax, lit, half)
        label += f"\nsymlog: linear within ±{lit:.2g} {unit}"
    else:
        ax.set_ylim(-half, half)
        factor = engineering_axis(ax)
        label = f"{name} error ({factor}{unit})"
    note_clipped(ax, t_h, {"error": _largest(errors.values()), "filter 3σ": three}, -half, half,
                 unit)
    ax.set_ylabel(label)
    ax.grid(alpha=0.3)
    how = (f"dots: every {rows} row; lines: ±RMS per {_minutes(interval_s)}" if envelope
           else f"lines: every {rows} row")
    ax.set_title(f"{name}: estimate − truth ({how}), filter ±3σ{_outside(s['real'], three)}",
                 loc="left", fontsize=9)


def _difference_panel(ax, t_s, t_h, shade, name: str, s: dict, interval_s: float, rows: str,
                      what: str = "linear") -> None:
    """A difference of two errors on its own scale (``what`` "linear": real −
    linearized; "ekf": EKF − paper filter): the axis holds every value (and is at
    most ~1.2× the largest, or the reference σ when that is under 5× it), the largest
    is marked, and the reference σ is a dashed line when it fits or a written ratio
    when it does not.  Drawn as the state's error panel: every stored row as dots
    (noisy) or a line (slow), with ±RMS per interval for a noisy one, and the
    full-rate min–max per row when the run stored it."""
    unit = s["unit"]
    envelope = s.get("style") == "envelope"
    if what == "ekf":
        d, dmin, dmax = f64(s["ekf"]) - f64(s["real"]), None, None
        label, color, title = LABEL_EKF_DIFF, EKF, "EKF − paper filter"
    else:
        d = f64(s["difference"]) if s.get("difference") is not None \
            else f64(s["real"]) - f64(s["linear"])
        dmin, dmax = (f64(s[k]) if s.get(k) is not None else None
                      for k in ("difference_min", "difference_max"))
        label, color, title = LABEL_DIFF, DIFF, "real − linearized error"
    shade(ax, False)
    if dmin is not None:
        x, lo, hi = band(t_h, dmin, dmax)
        ax.fill_between(x, lo, hi, color=color, alpha=0.3, lw=0, zorder=2,
                        label=f"{label}, full-rate min–max per {s['row_interval']:g} s row")
    _samples(ax, t_h, d, envelope, color, f"{label}, every {rows} row (dots)" if envelope
             else label, lw=0.8, zorder=3)
    if envelope:
        _rms(ax, t_s, d, interval_s, color, label, lw=1.0, zorder=3)
    ax.axhline(0.0, color="0.4", lw=0.5, zorder=1)
    worst = max_abs(d)
    if dmin is not None:    # the largest difference may fall between two rows
        k_full = max(max_abs(dmin), max_abs(dmax))
        if k_full > worst:
            worst = k_full
            d = np.where(np.abs(dmax) >= np.abs(dmin), dmax, dmin)
    ref, ref_label = s.get("reference") or (pct(np.abs(f64(s["sigma"])), 50),
                                            f"filter σ_{name} (median)")
    if worst > 0:
        k = int(np.nanargmax(np.abs(d)))
        # The reference σ joins the axis when that keeps Δ at a fifth of it or more.
        half = 1.15 * (max(ref, worst) if ref <= 5 * worst else worst)
        ax.plot([t_h[k]], [d[k]], "o", mfc="none", mec=color, ms=7, mew=1.2, zorder=4)
        rms = float(np.sqrt(np.nanmean(d * d)))
        where = (f"max |Δ| = {fmt(worst, 2)} {unit} at {at_time(t_h, t_h[k])}, "
                 f"RMS {fmt(rms, 2)} {unit}")
    else:
        half, where = 1.0, "identical: max |Δ| = 0"
    ax.set_ylim(-half, half)
    if worst > 0 and ref <= half:
        for sgn in (1, -1):
            ax.axhline(sgn * ref, color="k", lw=0.9, ls="--", zorder=2)
        rel = f"; dashed: ±{ref_label} = {fmt(ref)} {unit}"
    elif worst > 0:
        rel = f"; {ref_label} = {fmt(ref)} {unit} = {times(ref / worst)} max |Δ|, off scale"
        if ref > 1e5 * worst:
            rel += ": Δ is rounding"
    else:
        rel = ""
    factor = engineering_axis(ax)
    ax.set_ylabel(f"Δ{' EKF' if what == 'ekf' else ''} {name}\n({factor}{unit})")
    ax.grid(alpha=0.3)
    how = (f"dots: every {rows} row; lines: ±RMS per {_minutes(interval_s)}" if envelope
           else f"line: every {rows} row")
    ax.set_title(f"{name}: {title} ({how}), on its own scale\n{where}{rel}",
                 loc="left", fontsize=9)


def row_label(t_s, series: dict) -> str:
    """The stored rows' spacing, as the panels name it ("64 s")."""
    given = [s.get("row_interval") for s in series.values() if s.get("row_interval")]
    if given:
        return f"{given[0]:g} s"
    return f"{median_step(t_s):.3g} s"


def _to_hours(t: float) -> float:
    return t / 3600.0


def _hours(t_s):
    return None if t_s is None else f64(t_s) / 3600.0


def _shader(t_s, t_h, gap, min_gap_s: float, labels):
    labels = labels or gap_labels(min_gap_s)
    return lambda ax, labelled: shade_gaps(ax, t_s, t_h, gap, min_gap_s,
                                           labels if labelled else None)


def plot_errors(t_s, gap, series: dict, title: str, min_gap_s: float = 600.0, *,
                paper_sigma_deg: float, paper_sigma_label: str | None = None,
                gap_labels: tuple[str, str] | None = None, warnings=None,
                screened_t_s=None, events=None):
    """Estimation error vs time for roll, yaw and h, and beneath each real −
    linearized (with the twin) and EKF − paper filter (with the EKF); and pitch (the
    Eq. 3b filter's, a series of its own) when given.

    ``series[name]`` = {"unit": "deg" | "N m s", "real": estimate − nonlinear truth,
    "sigma": filter 1σ, "style": "envelope" (noisy: dots and ±RMS per interval) or
    "trace" (slow: lines), and optionally "linear": estimate − linear-twin truth,
    "difference": real − linear computed at full precision, "smoothed": smoother
    error, "ekf" and "ekf_sigma": the extended Kalman filter's error on the same
    telemetry and its 1σ, "difference_min"/"difference_max": the full-rate extremes
    of real − linear per row of decimated series (with "row_interval", s),
    "reference": (value, label) drawn or quoted in the difference panel (default:
    the median filter σ)}.  ``gap`` is True where there is no Sun-sensor yaw: gaps
    of at least ``min_gap_s`` (Sun gaps) and shorter outages are shaded apart, with
    ``gap_labels`` (Sun gap, shorter).  The yaw panel draws the paper's ±3σ_yaw
    (``paper_sigma_deg``, written as ``paper_sigma_label``).  ``warnings``: the
    run's warning messages, written under the figure in red.  ``t_s`` may hold
    breaks (NaN rows, ``reduce``): telemetry gaps, shaded and never drawn across.
    ``screened_t_s``: the times (s) of samples with a screened value, ticked at the
    top of each error panel.  ``events``: the run's scheduled events (summary.json's
    dicts, ``t_s`` and ``end_s`` in the rows' seconds), marked on every panel
    (``events.mark_events``).
    """
    t_s = f64(t_s)
    t_h = t_s / 3600.0
    gap = np.asarray(gap, dtype=bool)
    names = [n for n in ("roll", "yaw", "h", "pitch") if n in series]

    def kinds(s):
        yield "error"
        if s.get("linear") is not None or s.get("difference") is not None:
            yield "diff"
        if s.get("ekf") is not None:
            yield "ekf"
    rows = [(n, kind) for n in names for kind in kinds(series[n])]
    ratios = [3.0 if kind == "error" else 1.7 for _, kind in rows]
    fig, axes = panel_figure(ratios, warnings, 0.95)
    ends = gap_ends(t_s, gap, min_gap_s)
    # An RMS per interval over at least 8 rows: over fewer it is as noisy as the rows.
    interval_s = nice_interval_s(float(t_s[-1] - t_s[0]) if t_s.size > 1 else 1.0,
                                 min_s=8.0 * median_step(t_s))
    shade = _shader(t_s, t_h, gap, min_gap_s, gap_labels)
    ref = (paper_sigma_deg, paper_sigma_label or f"Eq. 56: {paper_sigma_deg:.3f}°")
    step = row_label(t_s, series)
    for ax, (name, kind) in zip(axes, rows, strict=True):
        if kind == "error":
            _error_panel(ax, t_s, t_h, shade, name, series[name], ends, ref, interval_s, step)
            mark_screened(ax, _hours(screened_t_s), label=True)
        else:
            _difference_panel(ax, t_s, t_h, shade, name, series[name], interval_s, step,
                              "ekf" if kind == "ekf" else "linear")
        mark_events(ax, events, _to_hours)
    time_axis(axes[-1], t_h)
    figure_legend(fig, axes, ncol=3)
    fig.suptitle(f"Estimation error vs time — {title}")
    return fig


def plot_estimates(t_s, gap, series: dict, title: str, min_gap_s: float = 600.0, *,
                   paper_sigma_deg: float, paper_sigma_label: str | None = None,
                   gap_labels: tuple[str, str] | None = None, warnings=None,
                   screened_t_s=None, events=None):
    """Without a truth: the estimates of roll, yaw, h (and pitch when given) with the
    filter's ±3σ about them.  ``series[name]`` = {"unit", "estimate", "sigma"}; the
    other arguments as ``plot_errors``."""
    t_s = f64(t_s)
    t_h = t_s / 3600.0
    gap = np.asarray(gap, dtype=bool)
    names = [n for n in ("roll", "yaw", "h", "pitch") if n in series]
    fig, axes = panel_figure([3.0] * len(names), warnings, 1.0, 1.6)
    ends = gap_ends(t_s, gap, min_gap_s)
    shade = _shader(t_s, t_h, gap, min_gap_s, gap_labels)
    ref = paper_sigma_label or f"Eq. 56: {paper_sigma_deg:.3f}°"
    step = row_label(t_s, {})
    for ax, name in zip(axes, names, strict=True):
        s = series[name]
        est, sig, unit = f64(s["estimate"]), np.abs(f64(s["sigma"])), s["unit"]
        shade(ax, True)
        mark_screened(ax, _hours(screened_t_s), label=True)
        mark_events(ax, events, _to_hours)
        x, lo, hi = band(t_h, est - 3 * sig, est + 3 * sig)
        ax.fill_between(x, lo, hi, color="C0", alpha=0.22, lw=0, zorder=1,
                        label="estimate ± filter 3σ")
        ax.plot(*minmax_line(t_h, est), color="C0", lw=0.8, zorder=3, label="estimate")
        # Centred on the middle of the estimate's range (not on zero: h is not).
        c = 0.5 * (pct(est, 0.5) + pct(est, 99.5))
        reach = np.abs(est - c) + 3 * sig
        half = robust_half([est - c], [reach])
        ax.set_ylim(c - half, c + half)
        note_clipped(ax, t_h, {"estimate": est, "estimate ± 3σ": c + reach}, c - half,
                     c + half, unit)
        if name == "yaw" and unit == "deg" and ends.size:
            i = ends[-1]
            ax.text(0.99, 0.04, f"last Sun-gap end, t = {at_time(t_h, t_h[i])}: filter σ_yaw = "
                    f"{sig[i]:.4f}° ({ref})", transform=ax.transAxes,
                    ha="right", va="bottom", fontsize=8,
                    bbox=dict(boxstyle="round", fc="w", ec="0.6", alpha=0.9))
        ax.set_ylabel(f"{name} ({engineering_axis(ax)}{unit})")
        ax.grid(alpha=0.3)
        ax.set_title(f"{name}: estimate (line: every {step} row) ± filter 3σ (median 3σ = "
                     f"{fmt(3 * pct(sig, 50))} {unit}); no truth given", loc="left", fontsize=9)
    time_axis(axes[-1], t_h)
    figure_legend(fig, axes, ncol=4)
    fig.suptitle(f"Estimates vs time — {title}")
    return fig
