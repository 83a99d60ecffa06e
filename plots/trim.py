"""The trim figure: the estimated solar torque against the true one, roll and yaw.

Draws only what it is given (plain arrays); no physics here.
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .decor import figure_legend, shade_mask, time_axis  # noqa: E402
from .palette import PALETTE  # noqa: E402


def plot_trim(shape_t_s: np.ndarray, shape_xz: np.ndarray, kappa_Nm: float, sigma_Nm: float,
              rows_t_s: np.ndarray, filter_xz: np.ndarray, title: str,
              truth_t_s: np.ndarray | None = None, truth_xz: np.ndarray | None = None):
    """Two panels (roll, yaw torque against time): the fitted solar torque κ̂ · shape
    with its ±3σ band (σ of κ̂ times |shape|; ±3σ like every other figure of the tool,
    and an outlined band, since ±1σ is a few percent of the torque and did not show),
    the filter's running torque estimate less the fitted constants, and the true
    solar torque when given.  Eclipses are shaded.  One legend, below the axes, so
    that it covers no curve."""
    t_h = np.asarray(shape_t_s) / 3600.0
    fig, axes = plt.subplots(2, 1, figsize=(11, 6.5), sharex=True, constrained_layout=True)
    eclipse = ~np.any(shape_xz != 0, axis=1)
    for i, (ax, name) in enumerate(zip(axes, ("roll", "yaw"), strict=True)):
        fit = kappa_Nm * shape_xz[:, i]
        band = sigma_Nm * np.abs(shape_xz[:, i])
        shade_mask(ax, t_h, eclipse, "eclipse" if i == 0 else None,
                   **PALETTE["eclipse"].mpl())
        ax.plot(np.asarray(rows_t_s) / 3600.0, filter_xz[:, i], lw=0.8, color="0.45",
                label="filter's running estimate, less the fitted constant")
        if truth_t_s is not None:
            ax.plot(np.asarray(truth_t_s) / 3600.0, truth_xz[:, i], lw=1.6, color="C1",
                    ls="--", label="true solar torque")
        ax.fill_between(t_h, fit - 3 * band, fit + 3 * band, facecolor="C0", alpha=0.3,
                        edgecolor="C0", lw=0.6,
                        label=f"±3σ of κ̂ (σ = {sigma_Nm:.2g} N m) × |unit solar torque|")
        ax.plot(t_h, fit, lw=1.0, color="C0", label="κ̂ × unit solar torque")
        ax.set_ylabel(f"{name} torque (N m)")
        ax.grid(alpha=0.3)
    time_axis(axes[-1], t_h)
    fig.suptitle(title, fontsize=10)
    figure_legend(fig, axes, ncol=3)
    return fig


def plot_batch_study(table: dict, labels, level_Nm: float):
    """σ(κ̂) against batch length per season: the covariance (a line, finely, and
    markers at the Monte Carlo's lengths) and the Monte Carlo RMS of κ̂ − κ."""
    fig, ax = plt.subplots(figsize=(8, 5), constrained_layout=True)
    for k, (season, t) in enumerate(table.items()):
        color = f"C{k}"
        days = np.asarray(t["batch_s"]) / 86400.0
        ax.loglog(t["fine_days"], t["fine_sigma_covariance_Nm"], color=color, lw=1.2,
                  label=f"{season}: filter covariance")
        ax.loglog(days, t["sigma_mc_Nm"], "o", color=color, mfc="none", ms=7,
                  label=f"{season}: Monte Carlo RMS ({t['cases']} cases)")
    ax.axhline(level_Nm, color="0.3", ls="--", lw=0.8, label=f"{level_Nm:g} N m (paper: trimmed)")
    ax.set_xticks(days, labels, rotation=20)
    ax.minorticks_off()
    ax.set_xlabel("batch length (from the start of the run)")
    ax.set_ylabel("σ(κ̂) (N m)")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    ax.set_title("Solar imbalance from the torque states: accuracy against batch length",
                 fontsize=10)
    return fig


def plot_trim_loop(loop: dict, daily: dict, title: str):
    """The trim loop (trim_loop.csv beside daily.csv) against the day of the run: the
    true κ and each κ̂ ± 3σ; the tab flown; the wheel momentum the torquers must
    unload and their time at the limit; the true attitude; the gap-end yaw error
    with the filter's ±3σ."""
    day = np.asarray(loop["day"]) + 0.5
    fig, axes = plt.subplots(5, 1, figsize=(10, 12), sharex=True,
                             gridspec_kw={"height_ratios": [3, 1.1, 2, 2, 2.2]})
    ax = axes[0]
    ax.step(day, loop["kappa_true_Nm"], where="mid", color="k", lw=1.2, label="true κ")
    est = np.isfinite(loop["kappa_Nm"])
    ax.errorbar(np.asarray(loop["day"])[est] + 1.0, loop["kappa_Nm"][est],
                yerr=3 * loop["kappa_sigma_Nm"][est], fmt="o", ms=4, color="tab:red",
                capsize=3, label="κ̂ ± 3σ from the span just ended")
    ax.set_yscale("symlog", linthresh=1e-7, linscale=0.6)
    ax.axhspan(-1e-7, 1e-7, color="tab:green", alpha=0.12, lw=0, label="±1e-7 N m (trimmed)")
    ax.set_ylabel("solar imbalance κ (N m)")
    ax.legend(loc="upper right", fontsize=8)
    ax.set_title(title, fontsize=9)

    ax = axes[1]
    ax.step(day, loop["trim_tab_deg"], where="mid", color="tab:purple")
    ax.set_ylabel("tab flown (deg)")

    ax = axes[2]
    ax.plot(day, loop["h_rms_Nms"], "-o", ms=3, color="tab:blue")
    ax.set_ylabel("wheel momentum h,\nRMS of the day (N m s)", color="tab:blue")
    ax2 = ax.twinx()
    ax2.plot(day, 100 * np.asarray(loop["torquer_saturated_fraction"]), "--",
             color="tab:orange")
    ax2.set_ylabel("torquers at their limit (%)", color="tab:orange")
    ax2.set_ylim(0, 105)

    ax = axes[3]
    ax.plot(day, loop["roll_rms_deg"], "-", label="roll")
    ax.plot(day, loop["yaw_rms_deg"], "-", label="yaw")
    ax.set_ylabel("true attitude,\nRMS of the day (deg)")
    ax.legend(loc="upper right", fontsize=8)

    ax = axes[4]
    dd = np.asarray(daily["day"]) + 0.5
    err, sig = daily["gap_end_yaw_error_deg"], daily["gap_end_yaw_sigma_deg"]
    has = np.isfinite(sig)
    ax.fill_between(dd, -3 * sig, 3 * sig, where=has, color="tab:blue", alpha=0.18, lw=0,
                    label="filter ±3σ at the gap end")
    ax.plot(dd, err, "o", ms=3, color="tab:red", label="gap-end yaw error")
    ax.axhline(0, color="0.6", lw=0.6)
    ax.set_ylabel("estimated − true\nyaw (deg)")
    ax.set_xlabel("day of the run")
    ax.legend(loc="upper right", fontsize=8)
    for a in axes:
        a.grid(alpha=0.3)
    fig.tight_layout()
    return fig
