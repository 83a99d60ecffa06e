"""Telemetry figure: ground yaw against truth, its error, and the Earth-sensor error.

Draws only what it is given (plain arrays in degrees and seconds).
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .truth import shade_intervals  # noqa: E402


def plot_telemetry(t_s, true_yaw_deg, yaw_deg, yaw_sigma_deg, sun_head, head_names,
                   roll_err_deg, pitch_err_deg, sun_gap, title: str):
    """Three panels against time in hours; Sun-sensor gaps shaded."""
    t_h = np.asarray(t_s) / 3600.0
    fig, axes = plt.subplots(3, 1, figsize=(11, 9), sharex=True, constrained_layout=True)
    ax = axes[0]
    ax.plot(t_h, true_yaw_deg, color="k", lw=1.0, label="true yaw")
    for k, name in enumerate(head_names):
        use = sun_head == k
        if np.any(use):
            step = max(1, int(use.sum() // 4000))  # enough dots to see, few enough to draw
            ax.plot(t_h[use][::step], yaw_deg[use][::step], ".", ms=1.5,
                    label=f"ground yaw ({name})")
    ax.set_ylabel("yaw (deg)")
    shade_intervals(ax, t_h, sun_gap, "no Sun-sensor yaw")
    ax.legend(loc="upper right", fontsize=8, ncol=2, markerscale=6)
    ax.grid(alpha=0.3)

    ax = axes[1]
    err = yaw_deg - true_yaw_deg
    have = np.isfinite(err)
    step = max(1, int(have.sum() // 20000))
    ax.plot(t_h[have][::step], err[have][::step], ".", ms=1, color="C0", label="ground − true")
    ax.plot(t_h, 3 * yaw_sigma_deg, color="C3", lw=0.8, label="±3σ a priori")
    ax.plot(t_h, -3 * yaw_sigma_deg, color="C3", lw=0.8)
    finite = np.abs(err[have])
    if finite.size:
        ax.set_ylim(-1.2 * np.percentile(finite, 99), 1.2 * np.percentile(finite, 99))
    ax.set_ylabel("yaw error (deg)")
    shade_intervals(ax, t_h, sun_gap, None)
    ax.legend(loc="upper right", fontsize=8, markerscale=6)
    ax.grid(alpha=0.3)

    ax = axes[2]
    step = max(1, len(t_h) // 20000)
    ax.plot(t_h[::step], roll_err_deg[::step], ".", ms=1, label="roll: Earth sensor − true")
    ax.plot(t_h[::step], pitch_err_deg[::step], ".", ms=1, label="pitch: Earth sensor − true")
    ax.set_ylabel("Earth-sensor error (deg)")
    ax.set_xlabel("time (h)")
    shade_intervals(ax, t_h, sun_gap, None)
    ax.legend(loc="upper right", fontsize=8, markerscale=6)
    ax.grid(alpha=0.3)
    fig.suptitle(title)
    return fig
