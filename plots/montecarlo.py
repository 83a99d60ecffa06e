"""Figures of a Monte Carlo set (`dynprop montecarlo`).

Plain arrays in, figures out (no physics here).  Every figure carries a caption
with the scenario, seed, number of runs and the reproducing command, so that a
figure lifted into a review still says where it came from.
"""

from __future__ import annotations

import textwrap

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

STATE_LABELS = ("roll", "roll rate", "yaw", "yaw rate", "h", "N_px", "N_pz", "N_cx", "N_cz")
_GAP = "0.88"


def _caption(fig, caption: str) -> None:
    fig.get_layout_engine().set(rect=(0, 0.03, 1, 0.97))
    fig.text(0.5, 0.003, caption, ha="center", va="bottom", fontsize=8, color="0.3")


def _shade(ax, gaps_h, label=True) -> None:
    for k, (a, b) in enumerate(np.reshape(gaps_h, (-1, 2))):
        ax.axvspan(a, b, color=_GAP, zorder=0, label="Sun gap (median)" if label and k == 0
                   else None)


def _inside(fraction: dict | None) -> str:
    return "run shorter than the convergence time" if fraction is None \
        else f"{100 * fraction['inside']:.0f}% inside"


def _converged(ax, t_h: float) -> None:
    ax.axvline(t_h, color="0.4", ls=":", lw=1)


def plot_ensemble_errors(d: dict, eq55_deg: float, n_runs: int, converged_h: float,
                         caption: str):
    """Ensemble RMS of the roll, yaw and h errors against time, next to the RMS of
    the filter's σ and (yaw) the Eq. 55 level: the paper's accuracy claim, N times."""
    t_h = d["t_s"] / 3600
    panels = ((0, "roll", "deg"), (2, "yaw", "deg"), (4, "h (yaw wheel momentum)", "N m s"))
    fig, axes = plt.subplots(3, 1, figsize=(11, 9.5), sharex=True, constrained_layout=True)
    for ax, (k, name, unit) in zip(axes, panels, strict=True):
        _shade(ax, d["gaps_h"], label=k == 0)
        ax.plot(t_h, d["rms"][:, k], color="C0", lw=1.2,
                label=f"ensemble RMS error, nonlinear truth ({n_runs} runs)")
        if "rms_linear" in d:
            ax.plot(t_h, d["rms_linear"][:, k], color="C2", lw=1, ls="--",
                    label="ensemble RMS error, linear twin")
        ax.plot(t_h, d["sigma_rms"][:, k], color="C3", lw=1.4, label="filter σ (RMS over runs)")
        ax.plot(t_h, np.abs(d["mean_err"][:, k]), color="0.5", lw=0.5, alpha=0.6,
                label="|ensemble mean error|")
        if k == 2:
            ax.axhline(eq55_deg, color="k", ls="-.", lw=1, label=f"Eq. 55 σ = {eq55_deg:.4f}°")
        _converged(ax, converged_h)
        ax.set_yscale("log")
        ax.set_ylabel(f"{name} ({unit})")
        ax.grid(True, which="both", alpha=0.25)
        ax.legend(loc="lower right", fontsize=8, ncol=3, framealpha=0.9)
    axes[-1].set_xlabel("time (h)")
    axes[0].set_title("Monte Carlo accuracy: ensemble RMS error against the filter's σ "
                      "(dotted line: start of the NEES test)")
    _caption(fig, caption)
    return fig


def plot_ensemble_nees(d: dict, summary: dict, converged_h: float, caption: str):
    """Averaged NEES against time with its χ² bounds for N runs, and its split into
    the states (each (e/σ)² averaged over the runs, χ²(N)/N bounds): where the NEES
    sits, and which states put it there."""
    t_h = d["t_s"] / 3600
    n = summary["nees"]
    lo, hi = n["bounds_95"]
    fig, axes = plt.subplots(2, 1, figsize=(11, 9.5), sharex=True, constrained_layout=True)
    ax = axes[0]
    _shade(ax, d["gaps_h"])
    ax.plot(t_h, d["nees_avg"], color="C0", lw=1,
            label=f"averaged NEES, nonlinear truth ({_inside(n['fraction_after_convergence'])} "
            f"after {converged_h:g} h)")
    if "nees_avg_linear" in d:
        ax.plot(t_h, d["nees_avg_linear"], color="C2", lw=1, ls="--",
                label="averaged NEES, linear twin "
                f"({_inside(n['linear']['fraction_after_convergence'])})")
    ax.axhspan(lo, hi, color="C1", alpha=0.2,
               label=f"95% bounds for {n['runs']} runs: [{lo:.2f}, {hi:.2f}]")
    ax.axhline(n["dof"], color="C1", lw=1, label=f"expected value {n['dof']}")
    _converged(ax, converged_h)
    ax.set_yscale("log")
    ax.text(0.01, 0.02, "\n".join(textwrap.wrap(n["diagnosis"], 150)), transform=ax.transAxes,
            fontsize=8, va="bottom", bbox=dict(facecolor="white", alpha=0.85, lw=0.5))
    ax.set_ylabel("NEES averaged over runs (9 states)")
    ax.grid(True, which="both", alpha=0.25)
    ax.legend(loc="upper right", fontsize=8)
    ax.set_title("Filter consistency over the ensemble")
    ax = axes[1]
    _shade(ax, d["gaps_h"], label=False)
    cmap = plt.get_cmap("tab10")
    for k, name in enumerate(STATE_LABELS):
        ax.plot(t_h, d["nsq"][:, k], lw=0.9, color=cmap(k), label=name,
                ls="-" if k < 5 else "--")
    b_lo, b_hi = d["nsq_bounds"]
    ax.axhspan(b_lo, b_hi, color="C1", alpha=0.2, label="95% bounds, one state")
    _converged(ax, converged_h)
    ax.set_yscale("log")
    ax.set_ylabel("(error/σ)² averaged over runs")
    ax.set_xlabel("time (h)")
    ax.grid(True, which="both", alpha=0.25)
    ax.legend(loc="lower right", fontsize=8, ncol=5)
    _caption(fig, caption)
    return fig


def plot_gap_end_yaw(d: dict, summary: dict, caption: str):
    """Histogram of the yaw error at the end of each Sun gap, with the ensemble's
    1σ/2σ/3σ (|error| quantiles) against the filter's predicted σ × 1, 2, 3."""
    gaps = summary["gap_end_yaw"]
    fig, axes = plt.subplots(1, max(1, len(gaps)), figsize=(6 * max(1, len(gaps)), 5.5),
                             squeeze=False, constrained_layout=True)
    for ax, g in zip(axes[0], gaps, strict=False):
        j = g["gap"]
        e = d[f"gap{j}_yaw_error_deg"]
        sig = g["predicted_sigma_deg"]
        span = max(3.3 * sig, float(np.max(np.abs(e))) * 1.05)
        bins = np.histogram_bin_edges(e, bins=max(10, int(np.sqrt(e.size) * 2)))
        ax.hist(e, bins=bins, color="C0", alpha=0.75, label=f"nonlinear truth (n = {g['n']})")
        if f"gap{j}_yaw_error_linear_deg" in d:
            ax.hist(d[f"gap{j}_yaw_error_linear_deg"], bins=bins, histtype="step", color="C2",
                    lw=1.3, label="linear twin")
        for m, q in enumerate(g["abs_quantile_deg"].values(), start=1):
            ax.axvline(q, color="C0", ls="-", lw=1.5 - 0.3 * m,
                       label=f"ensemble {m}σ (|error| quantile): {q:.4f}°")
            ax.axvline(-q, color="C0", ls="-", lw=1.5 - 0.3 * m)
            ax.axvline(m * sig, color="C3", ls="--", lw=1.5 - 0.3 * m,
                       label=f"filter {m}σ: {m * sig:.4f}°")
            ax.axvline(-m * sig, color="C3", ls="--", lw=1.5 - 0.3 * m)
        within = g["fraction_within"]
        ax.set_title(f"gap {j}, ending at {g['end_h_median']:.1f} h\n"
                     f"within filter 1σ/2σ/3σ: {100 * within['1sigma']:.0f}% / "
                     f"{100 * within['2sigma']:.0f}% / {100 * within['3sigma']:.0f}% "
                     "(Gaussian: 68 / 95 / 99.7)", fontsize=10)
        ax.set_xlim(-span, span)
        ax.set_xlabel("yaw error at the end of the Sun gap (deg)")
        ax.set_ylabel("runs")
        ax.legend(fontsize=7.5, loc="upper left")
        ax.grid(True, alpha=0.25)
    _caption(fig, caption)
    return fig
