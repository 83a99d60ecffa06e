"""Truth-history figure: attitude, wheel momentum and torques by source.

Draws only what it is given (plain arrays); no physics here.
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .decor import time_axis  # noqa: E402
from .palette import PALETTE  # noqa: E402


def shade_intervals(ax, t_h: np.ndarray, mask: np.ndarray, label: str | None) -> None:
    """Bands in the eclipse shade over the intervals where ``mask`` is true."""
    if not np.any(mask):
        return
    edges = np.flatnonzero(np.diff(np.r_[0, mask.astype(int), 0]))
    for k, (a, b) in enumerate(zip(edges[::2], edges[1::2], strict=True)):
        ax.axvspan(t_h[a], t_h[b - 1], **PALETTE["eclipse"].mpl(), lw=0, zorder=0,
                   label=label if k == 0 else None)


def plot_truth(t_s: np.ndarray, attitude_deg: dict[str, np.ndarray], h_Nms: np.ndarray,
               torques_Nm: dict[str, np.ndarray], eclipse: np.ndarray, title: str,
               mean_window_s: float = 300.0):
    """Three stacked panels against time in hours; eclipse intervals shaded."""
    t_h = np.asarray(t_s) / 3600.0
    fig, axes = plt.subplots(3, 1, figsize=(11, 9), sharex=True, constrained_layout=True)
    ax = axes[0]
    for name, series in attitude_deg.items():
        ax.plot(t_h, series, lw=0.8, label=name)
    ax.set_ylabel("attitude (deg)")
    shade_intervals(ax, t_h, eclipse, "eclipse")
    ax.legend(loc="upper right", ncol=4, fontsize=8)
    ax.grid(alpha=0.3)

    ax = axes[1]
    ax.plot(t_h, h_Nms, lw=0.8, color="C3")
    ax.set_ylabel("yaw wheel momentum h (N m s)")
    shade_intervals(ax, t_h, eclipse, None)
    ax.grid(alpha=0.3)

    ax = axes[2]
    window = int(round(mean_window_s / np.median(np.diff(t_s)))) if len(t_s) > 1 else 1
    # np.convolve(mode="same") returns the longer of its inputs: keep the window shorter.
    window = min(max(window, 1), len(t_s))
    kernel = np.ones(window) / window
    for name, torque in torques_Nm.items():
        # Vector mean over the window, then magnitude: white ripple-driven control
        # activity averages out and the slow torques that matter stay visible.
        mean = np.stack([np.convolve(torque[:, k], kernel, mode="same") for k in range(3)], 1)
        mag = np.linalg.norm(mean, axis=1)
        if np.any(mag > 0):
            ax.semilogy(t_h, np.where(mag > 0, mag, np.nan), lw=0.8, label=name)
    ax.set_ylabel(f"|torque|, {mean_window_s / 60:g}-min mean (N m)")
    time_axis(ax, t_h)      # hours, or days beyond three days
    shade_intervals(ax, t_h, eclipse, None)
    ax.legend(loc="upper right", ncol=3, fontsize=8)
    ax.grid(alpha=0.3, which="both")
    fig.suptitle(title)
    return fig
