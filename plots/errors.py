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
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .decor import (  # noqa: E402
    GAP_LABEL,
    engineering_axis,
    figure_legend,
    fmt,
    gap_ends,
    note_clipped,
    robust_half,
    shade_mask,
    symlog_axis,
    time_axis,
)
from .reduce import band, f64, interval_stats, max_abs, minmax_line, nice_interval_s, pct  # noqa: E402

#: The paper's yaw 1σ (Eq. 56), in degrees; callers pass ``estimator.covariance``'s.

REAL, LINEAR, SMOOTH, DIFF, SIGMA, EKF = "C3", "C0", "k", "C1", "darkgreen", "C4"
LABEL_REAL = "real: filter on nonlinear-truth telemetry, minus that truth"
LABEL_LINEAR = "linearized: filter on linear-twin telemetry, minus the twin"
LABEL_SMOOTH = "smoother, real"
LABEL_DIFF = "real − linearized"
LABEL_EKF = "EKF: extended Kalman filter on the same telemetry, minus the truth"


def times(ratio: float) -> str:
    """"54×", or "4.1×10⁶×" for large ratios."""
    if ratio < 1e4:
        return f"{ratio:.2g}×"
    e = int(np.floor(np.log10(ratio)))
    sup = str(e).translate(str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹"))
    return f"{ratio / 10**e:.2g}×10{sup}×"


def _minutes(interval_s: float) -> str:
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


def _envelope(ax, t_s, s: dict, interval_s: float) -> None:
    """A noisy error as statistics per interval: the real error's min–max band and
    the ±RMS of each run (real, linearized, smoother)."""
    x, lo, hi, rms = interval_stats(t_s, s["real"], interval_s)
    if s.get("real_min") is not None:
        # Decimated rows: the band is the full-rate min–max the run stored per row.
        lo = interval_stats(t_s, s["real_min"], interval_s)[1]
        hi = interval_stats(t_s, s["real_max"], interval_s)[2]
    ax.fill_between(x, lo, hi, color=REAL, alpha=0.25, lw=0, zorder=2,
                    label=f"real, min–max per {_minutes(interval_s)}")
    if s.get("linear") is not None:
        ax.plot(*_pm(x, interval_stats(t_s, s["linear"], interval_s)[3]), color=LINEAR,
                lw=2.6, alpha=0.45, zorder=3, label=LABEL_LINEAR)
    ax.plot(*_pm(x, rms), color=REAL, lw=0.9, zorder=4, label=LABEL_REAL)
    if s.get("smoothed") is not None:
        ax.plot(*_pm(x, interval_stats(t_s, s["smoothed"], interval_s)[3]), color=SMOOTH,
                lw=0.7, zorder=4, label=LABEL_SMOOTH)
    if s.get("ekf") is not None:
        ax.plot(*_pm(x, interval_stats(t_s, s["ekf"], interval_s)[3]), color=EKF, lw=0.9,
                ls="--", zorder=4, label=LABEL_EKF)


def _traces(ax, t_h, s: dict) -> None:
    """A slow error as its trace (min/max per pixel column: the full trace's picture).
    The linearized error is a wide pale line under the real one, so both show where
    they coincide (their difference has its own panel)."""
    if s.get("linear") is not None:
        ax.plot(*minmax_line(t_h, s["linear"]), color=LINEAR, lw=2.6, alpha=0.45, zorder=2,
                label=LABEL_LINEAR)
    if s.get("real_min") is not None:
        # Decimated rows: what happened between them, from the full-rate min–max.
        x, lo, hi = band(t_h, s["real_min"], s["real_max"])
        ax.fill_between(x, lo, hi, color=REAL, alpha=0.3, lw=0, zorder=2,
                        label=f"real, full-rate min–max per {s['row_interval']:g} s row")
    ax.plot(*minmax_line(t_h, s["real"]), color=REAL, lw=0.8, zorder=3, label=LABEL_REAL)
    if s.get("smoothed") is not None:
        ax.plot(*minmax_line(t_h, s["smoothed"]), color=SMOOTH, lw=0.5, alpha=0.7, zorder=4,
                label=LABEL_SMOOTH)
    if s.get("ekf") is not None:
        ax.plot(*minmax_line(t_h, s["ekf"]), color=EKF, lw=0.8, zorder=4, label=LABEL_EKF)


def _largest(arrays) -> np.ndarray:
    """Per sample, the value of largest magnitude among ``arrays`` (for one clipping
    note covering every error trace of a panel)."""
    out = None
    for a in arrays:
        a = f64(a)
        out = a if out is None else np.where(np.abs(a) > np.abs(out), a, out)
    return out


def _paper_marks(ax, t_h, sig, ends, paper: float) -> None:
    """The paper's σ_yaw at every gap end (±1σ, ±3σ ticks), and the filter's σ at
    the last one, written on the panel."""
    te = t_h[ends]
    for k, lev in enumerate((paper, 3 * paper)):
        ax.plot(np.r_[te, te], np.r_[np.full(te.size, lev), np.full(te.size, -lev)],
                ls="none", marker="_", ms=16 if k else 11, mew=2.6 if k else 1.6, color="m",
                zorder=6, label=f"paper σ_yaw = {paper:.3f}° (Eq. 56) at Sun-gap ends: "
                "±1σ, ±3σ" if k == 0 else "_paper 3σ_yaw")
    i = ends[-1]
    s_last = abs(float(sig[i]))
    ax.plot([t_h[i]] * 2, [3 * s_last, -3 * s_last], ls="none", marker="o", mfc="none",
            mec="k", ms=7, mew=1.3, zorder=7, label="filter ±3σ at the last Sun-gap end")
    ax.annotate(f"last Sun-gap end, t = {t_h[i]:.2f} h: filter σ_yaw = {s_last:.4f}° "
                f"(paper {paper:.3f}°)", xy=(t_h[i], -3 * s_last), xycoords="data",
                xytext=(0.99, 0.04), textcoords="axes fraction", fontsize=8, ha="right",
                va="bottom", zorder=9, bbox=dict(boxstyle="round", fc="w", ec="0.6", alpha=0.9),
                arrowprops=dict(arrowstyle="->", color="k", lw=0.8))


def _error_panel(ax, t_s, t_h, gap, name: str, s: dict, ends, paper: float,
                 interval_s: float) -> None:
    unit, sig = s["unit"], np.abs(f64(s["sigma"]))
    three = 3.0 * sig
    shade_mask(ax, t_h, gap, GAP_LABEL)
    _sigma_band(ax, t_h, sig)
    envelope = s.get("style") == "envelope"
    (_envelope(ax, t_s, s, interval_s) if envelope else _traces(ax, t_h, s))
    ax.axhline(0.0, color="0.4", lw=0.5, zorder=1)
    marks = name == "yaw" and unit == "deg" and ends.size > 0
    if marks:
        _paper_marks(ax, t_h, sig, ends, paper)
    errors = {"real error": s["real"], "linearized error": s.get("linear"),
              "EKF error": s.get("ekf"),
              "smoother error": s.get("smoothed"), "real min": s.get("real_min"),
              "real max": s.get("real_max")}
    errors = {k: v for k, v in errors.items() if v is not None}
    half = max(robust_half(errors.values(), [three]), 3.3 * paper if marks else 0.0)
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
    how = (f"lines ±RMS, band min–max per {_minutes(interval_s)}" if envelope
           else "min/max per pixel column")
    ax.set_title(f"{name}: estimate − truth ({how}), filter ±3σ", loc="left", fontsize=9)


def _difference_panel(ax, t_s, t_h, gap, name: str, s: dict, interval_s: float) -> None:
    """real − linearized on its own scale: the axis holds every value (and is at most
    ~1.2× the largest, or the reference σ when that is under 5× it), the largest is
    marked, and the reference σ is a dashed line when it fits or a written ratio
    when it does not.  Drawn in the style of its state's error (trace or envelope)."""
    unit = s["unit"]
    d = f64(s["difference"]) if s.get("difference") is not None \
        else f64(s["real"]) - f64(s["linear"])
    shade_mask(ax, t_h, gap, None)
    dmin, dmax = (f64(s[k]) if s.get(k) is not None else None
                  for k in ("difference_min", "difference_max"))
    if dmin is not None and s.get("style") != "envelope":
        x, lo, hi = band(t_h, dmin, dmax)
        ax.fill_between(x, lo, hi, color=DIFF, alpha=0.3, lw=0, zorder=2,
                        label=f"{LABEL_DIFF}, full-rate min–max per {s['row_interval']:g} s row")
    if s.get("style") == "envelope":
        x, lo, hi, rms = interval_stats(t_s, d, interval_s)
        if dmin is not None:
            lo = interval_stats(t_s, dmin, interval_s)[1]
            hi = interval_stats(t_s, dmax, interval_s)[2]
        ax.fill_between(x, lo, hi, color=DIFF, alpha=0.35, lw=0, zorder=2,
                        label=f"{LABEL_DIFF}, min–max per {_minutes(interval_s)}")
        ax.plot(*_pm(x, rms), color=DIFF, lw=1.0, zorder=3, label=LABEL_DIFF)
    else:
        ax.plot(*minmax_line(t_h, d), color=DIFF, lw=0.8, zorder=3, label=LABEL_DIFF)
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
        ax.plot([t_h[k]], [d[k]], "o", mfc="none", mec=DIFF, ms=7, mew=1.2, zorder=4)
        rms = float(np.sqrt(np.nanmean(d * d)))
        where = (f"max |Δ| = {fmt(worst, 2)} {unit} at {t_h[k]:.2f} h, "
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
    ax.set_ylabel(f"Δ {name}\n({factor}{unit})")
    ax.grid(alpha=0.3)
    how = (f"lines ±RMS, band min–max per {_minutes(interval_s)}"
           if s.get("style") == "envelope" else "min/max per pixel column")
    ax.set_title(f"{name}: real − linearized error ({how}), on its own scale\n{where}{rel}",
                 loc="left", fontsize=9)


def plot_errors(t_s, gap, series: dict, title: str, min_gap_s: float = 600.0, *,
                paper_sigma_deg: float):
    """Estimation error vs time for roll, yaw and h, and real − linearized beneath each.

    ``series[name]`` = {"unit": "deg" | "N m s", "real": estimate − nonlinear truth,
    "sigma": filter 1σ, "style": "envelope" (noisy: per-interval band and RMS) or
    "trace", and optionally "linear": estimate − linear-twin truth, "difference":
    real − linear computed at full precision, "smoothed": smoother error, "ekf": the
    extended Kalman filter's error on the same telemetry,
    "real_min"/"real_max" and "difference_min"/"difference_max": the full-rate
    extremes per row of decimated series (with "row_interval", s),
    "reference": (value, label) drawn or quoted in the difference panel (default: the
    median filter σ)}.  ``gap`` is True where there is no Sun-sensor yaw; Sun gaps
    of at least ``min_gap_s`` get the paper's σ_yaw (Eq. 56) marked at their ends.
    """
    t_s = f64(t_s)
    t_h = t_s / 3600.0
    gap = np.asarray(gap, dtype=bool)
    names = [n for n in ("roll", "yaw", "h") if n in series]
    diff = {n: series[n].get("linear") is not None or series[n].get("difference") is not None
            for n in names}
    rows = [(n, kind) for n in names for kind in ("error", "diff") if kind == "error" or diff[n]]
    ratios = [3.0 if kind == "error" else 1.7 for _, kind in rows]
    fig, axes = plt.subplots(len(rows), 1, figsize=(13, 0.95 * sum(ratios) + 1.8), sharex=True,
                             layout="constrained", squeeze=False,
                             gridspec_kw={"height_ratios": ratios})
    axes = axes[:, 0]
    ends = gap_ends(t_s, gap, min_gap_s)
    interval_s = nice_interval_s(float(t_s[-1] - t_s[0]) if t_s.size > 1 else 1.0)
    for ax, (name, kind) in zip(axes, rows, strict=True):
        if kind == "error":
            _error_panel(ax, t_s, t_h, gap, name, series[name], ends, paper_sigma_deg,
                         interval_s)
        else:
            _difference_panel(ax, t_s, t_h, gap, name, series[name], interval_s)
    time_axis(axes[-1], t_h)
    figure_legend(fig, axes, ncol=3)
    fig.suptitle(f"Estimation error vs time — {title}")
    return fig


def plot_estimates(t_s, gap, series: dict, title: str, min_gap_s: float = 600.0, *,
                   paper_sigma_deg: float):
    """Without a truth: the estimates of roll, yaw and h with the filter's ±3σ about
    them.  ``series[name]`` = {"unit", "estimate", "sigma"}."""
    t_s = f64(t_s)
    t_h = t_s / 3600.0
    gap = np.asarray(gap, dtype=bool)
    names = [n for n in ("roll", "yaw", "h") if n in series]
    fig, axes = plt.subplots(len(names), 1, figsize=(13, 3.0 * len(names) + 1.6), sharex=True,
                             layout="constrained", squeeze=False)
    axes = axes[:, 0]
    ends = gap_ends(t_s, gap, min_gap_s)
    for ax, name in zip(axes, names, strict=True):
        s = series[name]
        est, sig, unit = f64(s["estimate"]), np.abs(f64(s["sigma"])), s["unit"]
        shade_mask(ax, t_h, gap, GAP_LABEL)
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
            ax.text(0.99, 0.04, f"last Sun-gap end, t = {t_h[i]:.2f} h: filter σ_yaw = "
                    f"{sig[i]:.4f}° (paper {paper_sigma_deg:.3f}°)", transform=ax.transAxes,
                    ha="right", va="bottom", fontsize=8,
                    bbox=dict(boxstyle="round", fc="w", ec="0.6", alpha=0.9))
        ax.set_ylabel(f"{name} ({engineering_axis(ax)}{unit})")
        ax.grid(alpha=0.3)
        ax.set_title(f"{name}: estimate (min/max per pixel column) ± filter 3σ (median 3σ = "
                     f"{fmt(3 * pct(sig, 50))} {unit}); no truth given", loc="left", fontsize=9)
    time_axis(axes[-1], t_h)
    figure_legend(fig, axes, ncol=4)
    fig.suptitle(f"Estimates vs time — {title}")
    return fig
