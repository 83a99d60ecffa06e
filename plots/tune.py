"""The tune figure: the likelihood along each determined noise parameter, the
normalised innovation squares per hour and the innovations' autocorrelation, each
for the scenario's noise and the tuned noise.

Draws only what it is given (plain arrays and numbers); no physics here.
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

KINDS = ("roll", "yaw", "h")


def plot_tune(profiles: dict, nis_hourly: dict, nis_bounds: dict, rho: dict, lag_s: float,
              pairs: dict, title: str):
    """Three panels.

    ``profiles``: name -> (ln θ/θ̂ offsets, Δln L, σ of ln θ), drawn with the parabola
    through them against the quadratic −½(Δ/σ)² of the information.  ``nis_hourly``:
    setting ("scenario" or "tuned") -> kind -> (hours, mean NIS), with ``nis_bounds``
    kind -> (lo, hi) of one hour's mean.  ``rho``: setting -> kind -> ρ(k) at lags
    k·``lag_s``, with the ±1.96/√N band from ``pairs`` (kind -> N)."""
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.6), constrained_layout=True)
    ax = axes[0]
    x = np.linspace(-2.5, 2.5, 101)
    ax.plot(x, -0.5 * x**2, color="0.6", lw=1.0, label="quadratic (Fisher information)")
    for k, (name, (dl, dll, s)) in enumerate(profiles.items()):
        xs, ys = np.r_[dl / s, 0.0], np.r_[dll, 0.0]
        ax.plot(xs, ys, "o", color=f"C{k}", ms=6, label=f"{name} (σ of ln θ {s:.2g})")
        if len(xs) >= 3:   # the parabola through the points: the likelihood's own curvature
            c = np.polyfit(xs, ys, 2)
            ax.plot(x, np.polyval(c, x), color=f"C{k}", lw=1.0, ls="--")
    ax.axhline(-1.92, color="0.3", ls=":", lw=0.8, label="95% (Δln L = −1.92)")
    ax.set_xlabel("ln θ − ln θ̂, in σ")
    ax.set_ylabel("ln L − max ln L")
    ax.set_title("likelihood along each determined parameter", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="lower center")
    ax = axes[1]
    # The tuned curves broad and pale, the scenario's thin, dashed and on top: where
    # tuning leaves a kind unchanged (yaw when only q_w moves), both still show.
    styles = {"scenario": dict(ls="--", lw=1.0, zorder=3),
              "tuned": dict(ls="-", lw=2.4, alpha=0.5, zorder=2)}
    for setting, by_kind in nis_hourly.items():
        for k, kind in enumerate(KINDS):
            if kind not in by_kind:
                continue
            h, v = by_kind[kind]
            ax.semilogy(h, v, color=f"C{k}", label=f"{kind}, {setting}'s noise",
                        **styles[setting])
    ax.axhline(1.0, color="0.3", lw=0.8)
    ax.set_xlabel("time (h)")
    ax.set_ylabel("mean ν²/S per hour")
    ax.set_title("normalised innovation squares (consistent: 1)", fontsize=10)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7, ncol=2)
    ax = axes[2]
    for setting, by_kind in rho.items():
        for k, kind in enumerate(KINDS):
            if kind not in by_kind:
                continue
            r = by_kind[kind]
            ax.plot(np.arange(1, len(r)) * lag_s, r[1:], color=f"C{k}",
                    label=f"{kind}, {setting}'s noise", **styles[setting])
    for k, kind in enumerate(KINDS):
        if kind in pairs and pairs[kind] > 0:
            b = 1.96 / np.sqrt(pairs[kind])
            ax.axhspan(-b, b, color=f"C{k}", alpha=0.12, lw=0)
    ax.set_xlabel("lag (s)")
    ax.set_ylabel("ρ of ν/√S")
    ax.set_title("innovation autocorrelation (white: inside the bands)", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    fig.suptitle(title, fontsize=10)
    return fig
