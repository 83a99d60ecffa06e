"""Figures of one estimation run, and the torque figure itself.

``errors.py`` (errors.png, or estimates.png without a truth), ``consistency.py``
(consistency.png), ``telemetry.py`` (telemetry_overview.png) and the torques below
(torques.png) draw only what they are given: plain numpy arrays in seconds,
degrees, N m, N m s and rpm; no physics and no imports from ``sim`` or
``estimator``.  Long traces are reduced for drawing only (``reduce.py``); the
caller's arrays are never modified.
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .consistency import nees_verdict, plot_consistency  # noqa: E402, F401
from .decor import (  # noqa: E402
    GAP_LABEL,
    engineering_axis,
    figure_legend,
    note_clipped,
    robust_half,
    shade_gaps,
    time_axis,
)
from .decor import gap_labels as gap_label_pair  # noqa: E402
from .errors import plot_errors, plot_estimates  # noqa: E402, F401
from .reduce import band, f64, minmax_line, pct  # noqa: E402
from .telemetry import plot_telemetry_overview  # noqa: E402, F401

TORQUE_NAMES = ("N_px", "N_pz", "N_cx", "N_cz")
_TORQUE_DESC = {"N_px": "periodic torque, x", "N_pz": "periodic torque, z",
                "N_cx": "constant torque, x", "N_cz": "constant torque, z"}


def _torque_panel(ax, t_h, name: str, est, sig, tru) -> None:
    """With a truth: estimate − truth and ±3σ about zero (as every other figure), the
    true torque dotted for scale.  Without: the estimate with ±3σ about it."""
    three = 3.0 * sig
    if tru is not None:
        err = est - tru
        x, lo, hi = band(t_h, -three, three)
        ax.fill_between(x, lo, hi, color="C2", alpha=0.22, lw=0, zorder=1, label="filter ±3σ")
        ax.plot(x, hi, color="darkgreen", lw=0.8, zorder=4)
        ax.plot(x, lo, color="darkgreen", lw=0.8, zorder=4)
        ax.plot(*minmax_line(t_h, tru), color="0.35", lw=1.0, ls=":", zorder=2,
                label="true torque projected onto the model (for scale)")
        ax.plot(*minmax_line(t_h, err), color="C3", lw=0.9, zorder=3,
                label="estimate − truth (projected)")
        ax.axhline(0.0, color="0.4", lw=0.5, zorder=1)
        # σ counts as data here: its start (the prior) is within a few times its end.
        c, data = 0.0, {"estimate − truth": err, "true torque": tru}
        half = robust_half([*data.values(), three])
        what = f"{name} error"
    else:
        x, lo, hi = band(t_h, est - three, est + three)
        ax.fill_between(x, lo, hi, color="C0", alpha=0.22, lw=0, zorder=1,
                        label="estimate ± filter 3σ")
        ax.plot(*minmax_line(t_h, est), color="C0", lw=0.9, zorder=3, label="estimate")
        c = pct(est, 50)
        data = {"estimate": est}
        half = robust_half([est - c], [three + np.abs(est - c)])
        what = name
    ax.set_ylim(c - half, c + half)
    note_clipped(ax, t_h, {**data, "filter 3σ": c + three}, c - half, c + half, "N m")
    ax.set_ylabel(f"{what} ({engineering_axis(ax)}N m)")
    # Short: the suptitle says what is drawn, and a clipping note may share the line.
    ax.set_title(f"{name}: {_TORQUE_DESC.get(name, 'torque')}", loc="left", fontsize=9)
    ax.grid(alpha=0.3)


def plot_torques(t_s, gap, estimated: dict, sigma: dict, title: str, truth: dict | None = None,
                 *, min_gap_s: float = 0.0, gap_labels: tuple[str, str] | None = None):
    """The filter's torque states (2×2 panels, N m): estimate − the true torques
    projected onto the same model, with the filter's ±3σ (or, without a truth, the
    estimate ±3σ)."""
    t_s = f64(t_s)
    t_h = t_s / 3600.0
    gap = np.asarray(gap, dtype=bool)
    # Sun gaps (at least min_gap_s) and shorter yaw outages, shaded apart.
    labels = gap_labels or (gap_label_pair(min_gap_s) if min_gap_s > 0 else (GAP_LABEL, GAP_LABEL))
    names = [n for n in TORQUE_NAMES if n in estimated] + \
        [n for n in estimated if n not in TORQUE_NAMES]
    ncol = 2
    nrow = max(1, int(np.ceil(len(names) / ncol)))
    fig, axes = plt.subplots(nrow, ncol, figsize=(14, 3.6 * nrow + 1.6), sharex=True,
                             layout="constrained", squeeze=False)
    for k, ax in enumerate(axes.ravel()):
        if k >= len(names):
            ax.set_visible(False)
            continue
        name = names[k]
        shade_gaps(ax, t_s, t_h, gap, min_gap_s, labels)
        tru = f64(truth[name]) if truth and name in truth else None
        _torque_panel(ax, t_h, name, f64(estimated[name]), np.abs(f64(sigma[name])), tru)
    for ax in axes[-1]:
        if ax.get_visible():
            time_axis(ax, t_h)
    figure_legend(fig, [ax for ax in axes.ravel() if ax.get_visible()], ncol=4)
    what = "estimate − truth" if truth else "estimates"
    fig.suptitle(f"Torque states of the filter: {what} with ±3σ — {title}")
    return fig
