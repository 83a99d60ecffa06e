"""Figures of a Monte Carlo set (`dynprop montecarlo`).

Plain arrays in, figures out (no physics here).  Every figure carries a caption
with the scenario, seed, number of runs and the reproducing command, so that a
figure lifted into a review still says where it came from.  Legends sit below the
axes (one per figure), time axes are laid out by ``decor.time_axis``, and a panel
with nothing to show says why ("not tested: …").
"""

from __future__ import annotations

import textwrap

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .decor import figure_legend, time_axis  # noqa: E402
from .palette import PALETTE  # noqa: E402

STATE_LABELS = ("roll", "roll rate", "yaw", "yaw rate", "h", "N_px", "N_pz", "N_cx", "N_cz")
_GAP = PALETTE["sun_gap"]


_CAPTION_PT = 14.0      # the caption's strip at the bottom: 8 pt text and its margin


def _caption(fig, caption: str, legend_axes=(), ncol: int = 4) -> None:
    """The caption in a strip at the foot of the figure and, just above it and below
    the axes, one legend for ``legend_axes`` (``decor.figure_legend``)."""
    strip = _CAPTION_PT / (72.0 * fig.get_figheight())
    fig.get_layout_engine().set(rect=(0, strip, 1, 1 - strip))
    fig.text(0.5, 0.003, caption, ha="center", va="bottom", fontsize=8, color="0.3")
    figure_legend(fig, legend_axes, ncol=ncol)
    if fig.legends:
        # An outside legend sits at the figure's edge, while the layout keeps its room
        # above the caption's strip: lift it by the strip.
        leg = fig.legends[-1]
        leg.borderaxespad = _CAPTION_PT / leg.prop.get_size_in_points()


def _shade(ax, gaps_h, label=True) -> None:
    for k, (a, b) in enumerate(np.reshape(gaps_h, (-1, 2))):
        ax.axvspan(a, b, **_GAP.mpl(), lw=0, zorder=0, label="Sun gap (median)" if label and k == 0
                   else None)


def _inside(fraction: dict | None, converged_h: float) -> str:
    return "not tested: no sample after the convergence time" if fraction is None \
        else f"{100 * fraction['inside']:.0f}% inside after {converged_h:g} h"


def note(ax, text: str) -> None:
    """Why a panel has nothing to show, written in the panel itself."""
    ax.text(0.5, 0.5, text, transform=ax.transAxes, ha="center", va="center", fontsize=10,
            color="0.2", bbox=dict(facecolor="white", edgecolor="0.6", lw=0.5))


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
        if "rms_ekf" in d:
            ax.plot(t_h, d["rms_ekf"][:, k], color="C4", lw=1, ls=":",
                    label="ensemble RMS error, EKF on the same telemetry")
        ax.plot(t_h, d["sigma_rms"][:, k], color="C3", lw=1.4, label="filter σ (RMS over runs)")
        ax.plot(t_h, np.abs(d["mean_err"][:, k]), color="0.5", lw=0.5, alpha=0.6,
                label="|ensemble mean error|")
        if k == 2:
            ax.axhline(eq55_deg, color="k", ls="-.", lw=1, label=f"Eq. 55 σ = {eq55_deg:.4f}°")
        _converged(ax, converged_h)
        ax.set_yscale("log")
        ax.set_ylabel(f"{name} ({unit})")
        ax.grid(True, which="both", alpha=0.25)
    time_axis(axes[-1], t_h)
    test = (f"dotted line: {converged_h:g} h, the start of the NEES test"
            if np.any(t_h > converged_h) else
            f"no NEES test: the runs end by its start, {converged_h:g} h")
    axes[0].set_title(f"Monte Carlo accuracy: ensemble RMS error against the filter's σ ({test})")
    _caption(fig, caption, axes, ncol=3)
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
    # Black and grey: the per-state panel below uses the colour cycle, one per state.
    ax.plot(t_h, d["nees_avg"], color="k", lw=1,
            label="averaged NEES, nonlinear truth "
            f"({_inside(n['fraction_after_convergence'], converged_h)})")
    if "nees_avg_linear" in d:
        ax.plot(t_h, d["nees_avg_linear"], color="0.5", lw=1, ls="--",
                label="averaged NEES, linear twin "
                f"({_inside(n['linear']['fraction_after_convergence'], converged_h)})")
    if "nees_avg_ekf" in d:
        ax.plot(t_h, d["nees_avg_ekf"], color="k", lw=1.2, ls=":",
                label="averaged NEES, EKF "
                f"({_inside(summary['ekf']['nees']['fraction_after_convergence'], converged_h)})")
    ax.axhspan(lo, hi, color="C1", alpha=0.2,
               label=f"95% bounds for {n['runs']} runs: [{lo:.2f}, {hi:.2f}]")
    ax.axhline(n["dof"], color="C1", lw=1, label=f"expected value {n['dof']}")
    _converged(ax, converged_h)
    ax.set_yscale("log")
    ax.set_ylabel("NEES averaged over runs (9 states)")
    ax.grid(True, which="both", alpha=0.25)
    # The diagnosis above the panel, where it can cover no trace.
    fig.suptitle("Filter consistency over the ensemble")
    ax.set_title("\n".join(textwrap.wrap(n["diagnosis"], 150)), loc="left", fontsize=8)
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
    time_axis(ax, t_h)
    ax.grid(True, which="both", alpha=0.25)
    _caption(fig, caption, axes, ncol=5)
    return fig


def _jitter(n: int, width: float) -> np.ndarray:
    """Deterministic spread within a column (golden-ratio sequence): the same set
    draws the same figure, byte for byte."""
    return ((np.arange(n) * 0.6180339887) % 1.0 - 0.5) * width


def _quantile_text(g: dict) -> str:
    """The 68.3% and 99.7% quantiles of |e|, named as quantiles; flagged when the
    set is too small for them to have a 95% upper bound (montecarlo.json's
    abs_quantile_ci95_deg, open above)."""
    q, ci = g["abs_quantile_deg"], g.get("abs_quantile_ci95_deg", {})
    level = g.get("abs_quantile_level", {"1sigma": 0.682689492, "3sigma": 0.997300204})
    keys = ("1sigma", "3sigma")
    text = (f"{' / '.join(f'{100 * level[k]:.1f}%' for k in keys)} quantiles of |e|:\n"
            f"{' / '.join(f'{q[k]:.4f}°' for k in keys)}")
    if any(ci.get(k, [0, 0])[1] is None for k in keys):
        text += f"\n(poorly determined from N = {g['n']})"
    return text


def plot_gap_end_yaw(d: dict, summary: dict, caption: str):
    """Strip plot of the yaw error at the end of each Sun gap in units of each case's
    own filter σ: one column per gap end, one dot per case, with the ±1/2/3 levels a
    consistent filter puts 68 / 95 / 99.7% of its cases inside.  A histogram of a
    handful of cases says nothing a dot per case does not say better.  Without a gap
    end in the runs the panel says "not tested" and why.  (At least 10 in wide: the
    caption, a reproducing command, must fit.)"""
    gaps = summary["gap_end_yaw"]
    fig, ax = plt.subplots(figsize=(max(10.0, 3.2 * len(gaps) + 3.0), 6.4),
                           constrained_layout=True)
    twin = any(f"gap{g['gap']}_yaw_error_linear_deg" in d for g in gaps)
    off = 0.17 if twin else 0.0
    extent, ticks = 3.0, []
    for x, g in enumerate(gaps):
        j = g["gap"]
        sig = np.asarray(d[f"gap{j}_yaw_sigma_deg"], dtype=float)
        series = [("nonlinear truth", d[f"gap{j}_yaw_error_deg"], "C0", "o", -off)]
        if f"gap{j}_yaw_error_linear_deg" in d:
            series.append(("linear twin", d[f"gap{j}_yaw_error_linear_deg"], "C2", "s", off))
        for label, e, color, marker, dx in series:
            z = np.asarray(e, dtype=float) / sig
            extent = max(extent, float(np.max(np.abs(z))) if z.size else 0.0)
            ax.scatter(x + dx + _jitter(z.size, 0.22 if twin else 0.4), z, s=22 if
                       z.size <= 200 else 8, color=color, marker=marker,
                       alpha=0.85 if z.size <= 200 else 0.4, edgecolor="none",
                       label=f"{label}, e / σ of its own filter" if x == 0 else None)
        w = g["fraction_within"]
        within = " / ".join(f"{round(w[f'{k}sigma'] * g['n'])}" for k in (1, 2, 3))
        ticks.append(f"gap {j} end, {g['end_h_median']:.1f} h\n"
                     f"N = {g['n']}; within 1σ / 2σ / 3σ: {within}\n"
                     f"(Gaussian: 68 / 95 / 99.7%)\nfilter σ {g['predicted_sigma_deg']:.4f}° "
                     f"(RMS over cases)\n{_quantile_text(g)}")
    for k, ls in ((1, "-"), (2, "--"), (3, ":")):
        for sign in (1, -1):
            ax.axhline(sign * k, color="C3", ls=ls, lw=1.0,
                       label=f"±{k} filter σ" if sign > 0 else None)
    ax.axhline(0, color="0.5", lw=0.6)
    span = 1.1 * extent
    ax.set_ylim(-span, span)
    ax.set_xlim(-0.6, len(gaps) - 0.4)
    ax.set_xticks(range(len(gaps)), ticks, fontsize=8.5)
    ax.set_ylabel("yaw error at the end of the Sun gap / filter σ at that time")
    ax.grid(True, axis="y", alpha=0.25)
    if not gaps:
        t_s = np.asarray(d.get("t_s", []), dtype=float)
        length = f" (their record ends at {t_s[-1] / 3600:.3g} h)" if t_s.size else ""
        note(ax, f"not tested: no Sun gap ends within the runs{length}")
    ax.set_title("Yaw at the end of each Sun gap, one dot per case, in units of the "
                 "filter's own σ", fontsize=10.5)
    _caption(fig, caption, [ax], ncol=4)
    return fig
