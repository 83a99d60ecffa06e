"""season.png: a long run's days, from daily.csv's columns.

Against the day of the year (continuous across New Year, labelled by month):
the gap-end yaw error with the filter's ±3σ and Eq. 55's ±3σ; the eclipse
minutes per day (the two eclipse seasons); the real and linearized yaw RMS and the
RMS of their difference.  Draws only what it is given.
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

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


def plot_season(daily: dict[str, np.ndarray], title: str):
    x = continuous_day(daily["day_of_year"])
    fig, axes = plt.subplots(3, 1, figsize=(11, 9.5), sharex=True,
                             gridspec_kw={"height_ratios": [3, 1.3, 2]})
    ax = axes[0]
    err, sig = daily["gap_end_yaw_error_deg"], daily["gap_end_yaw_sigma_deg"]
    eq55 = float(np.nanmax(daily["eq55_sigma_yaw_deg"]))
    out, n = outside_3sigma(err, sig)
    has = np.isfinite(sig)
    ax.fill_between(x, -3 * sig, 3 * sig, where=has, color="tab:blue", alpha=0.18, lw=0,
                    label="filter ±3σ at the gap end")
    ax.axhline(3 * eq55, color="k", ls="--", lw=1, label=f"Eq. 55 ±3σ ({3 * eq55:.3f}°)")
    ax.axhline(-3 * eq55, color="k", ls="--", lw=1)
    ax.plot(x, err, "o", ms=3, color="tab:red",
            label=f"gap-end yaw error ({out} of {n} outside ±3σ)")
    ax.axhline(0, color="0.6", lw=0.6)
    ax.set_ylabel("yaw at Sun-gap end (deg)")
    top = np.nanmax(np.abs(np.r_[err[has], 3 * sig[has], 3 * eq55])) if n else 3 * eq55
    ax.set_ylim(-1.15 * top, 1.15 * top)
    ax.legend(loc="upper right", fontsize=8)
    ax.set_title(title, fontsize=9)

    ax = axes[1]
    ax.bar(x, daily["eclipse_min"], width=1.0, color="0.35")
    ax.set_ylabel("eclipse (min/day)")
    peak = float(np.nanmax(daily["eclipse_min"])) if len(x) else 0.0
    ax.set_ylim(0, max(1.0, 1.15 * peak))

    ax = axes[2]
    for key, label, style in (("yaw_error_rms_deg", "real yaw RMS", "-"),
                              ("yaw_error_rms_linear_deg", "linearized yaw RMS", "--"),
                              ("yaw_error_rms_real_minus_linear_deg",
                               "RMS of real − linearized yaw", ":")):
        ax.plot(x, daily[key], style, lw=1.2, label=label)
    values = np.r_[daily["yaw_error_rms_deg"], daily["yaw_error_rms_real_minus_linear_deg"]]
    values = values[np.isfinite(values) & (values > 0)]
    if values.size and values.max() / values.min() > 30:
        ax.set_yscale("log")
    ax.set_ylabel("yaw error RMS per day (deg)")
    ax.legend(loc="upper right", fontsize=8)
    _month_ticks(ax, x)
    for a in axes:
        a.grid(alpha=0.3)
    fig.tight_layout()
    return fig
