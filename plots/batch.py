"""The batch figure: the batch's yaw and roll errors beside the filter's and the
smoother's, each with its ±3σ, the Sun gaps shaded and the batches' epochs marked.

Draws only what it is given (plain arrays); no physics here.
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .decor import figure_legend, shade_mask, time_axis  # noqa: E402

SETTLE_H = 1.0   # the priors' first hour: left out of the axis limits


def _limit(t_h, errors: dict, sigmas: dict, i: int) -> float:
    """The panel's half-height: the largest error or 3σ after the first hour (the
    priors' own σ would flatten the rest), with a margin; every curve is drawn whole."""
    late = t_h >= t_h[0] + SETTLE_H if t_h[-1] - t_h[0] > 4 * SETTLE_H else slice(None)
    vals = [np.abs(e[late, i]) for e in errors.values()] + \
        [3 * s[late, i] for s in sigmas.values()]
    top = max((float(np.nanmax(v)) for v in vals if np.isfinite(v).any()), default=1.0)
    return 1.15 * top if top > 0 else 1.0


_STYLE = {"filter": ("C0", "filter"), "smoother": ("C2", "filter + RTS smoother"),
          "batch": ("C3", "batch")}


def plot_batch(t_s: np.ndarray, errors: dict, sigmas: dict, gap: np.ndarray, epochs_s,
               title: str, consider_sigma: dict | None = None):
    """Two panels (yaw, roll error in degrees against time): each estimator's error
    (``errors[name]``, (N, 2) yaw and roll) and its ±3σ band (``sigmas``); the batch's
    consider ±3σ dashed when given; ``gap``: samples inside a Sun gap."""
    t_h = np.asarray(t_s) / 3600.0
    fig, axes = plt.subplots(2, 1, figsize=(11, 6.5), sharex=True, constrained_layout=True)
    for i, (ax, name) in enumerate(zip(axes, ("yaw", "roll"), strict=True)):
        shade_mask(ax, t_h, gap, "Sun gap" if i == 0 else None)
        for key, err in errors.items():
            color, label = _STYLE[key]
            band = 3 * sigmas[key][:, i]
            ax.fill_between(t_h, -band, band, color=color, alpha=0.12, lw=0,
                            label=f"±3σ, {label}")
            ax.plot(t_h, err[:, i], color=color, lw=0.9, label=f"error, {label}")
        if consider_sigma is not None:
            c = 3 * consider_sigma[:, i]
            ax.plot(t_h, c, color="C3", ls="--", lw=0.8, label="±3σ with consider, batch")
            ax.plot(t_h, -c, color="C3", ls="--", lw=0.8)
        for t in epochs_s[1:]:
            ax.axvline(t / 3600.0, color="0.3", lw=0.6, ls=":")
        ax.set_ylabel(f"{name} error (deg)")
        ax.axhline(0, color="0.5", lw=0.5)
        time_axis(ax, t_h)
        ax.set_ylim(-_limit(t_h, errors, sigmas, i), _limit(t_h, errors, sigmas, i))
    axes[0].set_xlabel("")
    axes[0].set_title(title, fontsize=10)
    figure_legend(fig, axes, ncol=4)
    return fig
