"""Figures of the linearization report (`dynprop linearization`).

Each function takes plain numbers and arrays (no physics here) and returns a
figure; ``caption`` (scenario, seed, reproducing command) is printed under
every figure so that a figure lifted into a review still says where it came from.
Quantities that span decades are on log axes; signed ones on a symmetric-log axis.
A value a log axis cannot show (an exact zero, or one below the axis) is marked at
the axis and labelled, never left out: a missing bar reads as a missing number.
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

TINY = 1e-12  # floor for |values| on log axes (exact zeros)


def _caption(fig, caption: str) -> None:
    fig.text(0.5, 0.003, caption, ha="center", va="bottom", fontsize=8, color="0.3")


def _pos(a) -> np.ndarray:
    return np.maximum(np.abs(np.asarray(a, dtype=float)), TINY)


def _mark_off_axis(ax, y: float, v: float, floor: float, color) -> None:
    """A value a log axis starting at ``floor`` cannot draw: a marker at the axis and
    "0" (an exact zero) or the value itself (below the axis) beside it."""
    text = "0" if v == 0 else f"{v:.1e}"
    ax.plot(floor, y, marker="o" if v == 0 else "<", ms=6, mfc="white", mec=color,
            mew=1.3, clip_on=False, zorder=4)
    ax.annotate(text, (floor, y), xytext=(7, 0), textcoords="offset points", va="center",
                fontsize=7.5, color=color)


def plot_coefficients(names, series: dict[str, list[float]], caption: str,
                      floor: float = 1e-7):
    """Relative difference of each coefficient from the Jacobian, one bar per
    approximation (log scale).  Exact zeros and values below ``floor`` are marked
    at the axis, labelled "0" or with their value."""
    fig, ax = plt.subplots(figsize=(11, 6.2), constrained_layout=True)
    y = np.arange(len(names))
    height = 0.8 / len(series)
    for k, (label, vals) in enumerate(series.items()):
        v = np.abs(np.asarray(vals, dtype=float))
        yk = y + (k - (len(series) - 1) / 2) * height
        ax.barh(yk, np.where(v >= floor, v, np.nan), height, label=label, color=f"C{k}")
        for yi, vi in zip(yk[v < floor], v[v < floor], strict=True):
            _mark_off_axis(ax, yi, vi, floor, f"C{k}")
    ax.set_xscale("log")
    ax.set_yticks(y, names)
    ax.invert_yaxis()
    ax.set_xlim(floor, 2.0)
    ax.set_xlabel("|coefficient − Jacobian| / |Jacobian|  (○ 0: exact zero; "
                  f"◁: below {floor:.0e}, value beside it)")
    ax.grid(True, axis="x", which="both", alpha=0.3)
    ax.legend(loc="lower right", fontsize=9)
    ax.set_title("Eqs. 3a–3c coefficients: each approximation against the CasADi Jacobian")
    fig.get_layout_engine().set(rect=(0, 0.03, 1, 0.97))
    _caption(fig, caption)
    return fig


def plot_divergence_time(envelopes: dict, deltas, levels: dict[str, float], gap_h, caption: str,
                         model: str = "eq11"):
    """|linear − nonlinear| against time for each initial error: rows are the attitude
    and rate sweeps, columns roll and yaw."""
    fig, axes = plt.subplots(2, 2, figsize=(13, 8), sharex=True, constrained_layout=True)
    cmap = plt.get_cmap("viridis")
    for r, kind in enumerate(("attitude", "rate")):
        for c, axis in enumerate(("roll", "yaw")):
            ax = axes[r, c]
            for k, d in enumerate(deltas):
                env = envelopes[(kind, d)]
                ax.plot(env["t_s"] / 3600, _pos(env[f"{model}_{axis}"]), lw=0.8,
                        color=cmap(k / max(len(deltas) - 1, 1)), label=f"δ = {d:g}°")
            base = envelopes[("none", 0.0)]
            ax.plot(base["t_s"] / 3600, _pos(base[f"{model}_{axis}"]), lw=0.8, color="0.5",
                    label="δ = 0 (scenario's own motion)")
            for (label, level), ls in zip(levels[axis].items(), ("--", ":"), strict=False):
                ax.axhline(level, color="C3", ls=ls, lw=1.0, label=f"{label} {level:.2g}°")
            if gap_h is not None:
                ax.axvspan(*gap_h, color="0.85", zorder=0, label="first Sun gap")
            ax.set_yscale("log")
            ax.set_ylim(1e-7, None)
            ax.grid(True, which="both", alpha=0.3)
            ax.set_ylabel(f"|{axis} divergence| (deg)")
            ax.set_title(f"{kind} sweep: {axis}")
            if r == 1:
                ax.set_xlabel("time (h)")
    axes[0, 1].legend(fontsize=7, loc="lower right", ncol=2)
    fig.suptitle("Eq. 11 propagated beside the nonlinear truth from the same start, same "
                 "torques (max |·| per 33 s)")
    fig.get_layout_engine().set(rect=(0, 0.03, 1, 0.97))
    _caption(fig, caption)
    return fig


def plot_divergence_sweep(deltas, values: dict, levels: dict[str, float], caption: str):
    """Maximum divergence against the initial error, log–log, with slope-1 and
    slope-2 guides.  ``values[kind][label]`` is a list over ``deltas``."""
    fig, axes = plt.subplots(1, 2, figsize=(13, 5.4), constrained_layout=True)
    d = np.asarray(deltas, dtype=float)
    for ax, kind in zip(axes, ("attitude", "rate"), strict=True):
        for label, v in values[kind].items():
            style = "-o" if "Eq. 11" in label else "--s"
            ax.plot(d, _pos(v), style, ms=4, label=label)
        ref = _pos(values[kind][next(iter(values[kind]))])[-1]
        for slope, ls in ((1, ":"), (2, "-.")):
            ax.plot(d, ref * (d / d[-1]) ** slope, ls, color="0.6", lw=1,
                    label=f"slope {slope}")
        for label, level in levels.items():
            ax.axhline(level, color="C3", lw=0.8, ls="--")
            ax.text(d[0], level * 1.15, label, fontsize=7, color="C3")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.grid(True, which="both", alpha=0.3)
        ax.set_xlabel("initial error δ (deg; rate sweep: nutation-cone half-angle)")
        ax.set_ylabel("max |linear − nonlinear| (deg)")
        ax.set_title(f"{kind} sweep")
        ax.legend(fontsize=7)
    fig.suptitle("Divergence grows with the initial error: Eq. 11 (the filter's model) "
                 "and the exact Jacobian")
    fig.get_layout_engine().set(rect=(0, 0.04, 1, 0.96))
    _caption(fig, caption)
    return fig


def _linthresh(values) -> float:
    """The symmetric-log axis is linear within ± this: four decades under the largest
    |value|, a power of ten, so every row of interest sits on the log part."""
    big = float(np.max(np.abs(values))) if np.size(values) else 0.0
    return 10.0 ** (np.floor(np.log10(big)) - 4) if big > 0 else 1e-8


def plot_budget(labels, columns: dict[str, list[float]], total: dict[str, float],
                in_scenario, caption: str, ideal: dict[str, float] | None = None):
    """Signed contribution of each effect to the yaw error at the Sun-gap end
    (symmetric-log axis: left of 0 negative, right positive), with the scenario's
    total (and the ideal configuration's own error) as rows of their own and the
    totals as dashed lines, so that a row beyond its total's line, or on the other
    side of 0, shows terms cancelling.  Exact zeros are marked "0"."""
    extra = [("ideal configuration (nonlinearity alone)", ideal)] if ideal else []
    extra += [("total: scenario as configured", total)]
    names = [f"{lab}{'' if flag else ' (not in scenario)'}"
             for lab, flag in zip(labels, in_scenario, strict=True)] + [e[0] for e in extra]
    rows = {c: list(v) + [e[1][c] for e in extra] for c, v in columns.items()}
    every = np.concatenate([np.asarray(v, dtype=float) for v in rows.values()])
    thresh = _linthresh(every)
    fig, ax = plt.subplots(figsize=(12, 7.0), constrained_layout=True)
    y = np.arange(len(names))
    height = 0.8 / len(rows)
    for k, (label, vals) in enumerate(rows.items()):
        v = np.asarray(vals, dtype=float)
        yk = y + (k - (len(rows) - 1) / 2) * height
        bars = ax.barh(yk, v, height, label=label, color=f"C{k}")
        for b in bars[len(labels):]:         # the total rows: hatched
            b.set_hatch("///")
            b.set_edgecolor("k")
        for yi, vi in zip(yk, v, strict=True):
            if vi == 0:
                ax.plot(0, yi, marker="o", ms=6, mfc="white", mec=f"C{k}", mew=1.3, zorder=4)
            ax.annotate("0" if vi == 0 else f"{vi:+.2g}".replace("-", "−"), (vi, yi),
                        xytext=(4 if vi >= 0 else -4, 0), textcoords="offset points",
                        ha="left" if vi >= 0 else "right", va="center", fontsize=7,
                        color=f"C{k}")
        if label in total:
            ax.axvline(total[label], color=f"C{k}", ls="--", lw=1,
                       label=f"total ({label}): {total[label]:+.3g}°".replace("-", "−"))
    ax.axvline(0, color="k", lw=0.8)
    ax.axhline(len(labels) - 0.5, color="0.5", lw=0.8)
    ax.set_xscale("symlog", linthresh=thresh, linscale=0.5)
    lim = 10 ** np.ceil(np.log10(max(float(np.max(np.abs(every))), thresh) * 1.5))
    ax.set_xlim(-lim, lim)
    ax.set_yticks(y, names)
    ax.invert_yaxis()
    ax.grid(True, axis="x", which="major", alpha=0.3)
    ax.set_xlabel(f"signed yaw error of Eq. 11 at the Sun-gap end contributed (deg); "
                  f"symmetric log, linear within ±{thresh:.0e}")
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.09), ncol=4)
    ax.set_title("Error budget: each effect switched on alone in the ideal configuration "
                 "(← negative | positive →)")
    fig.get_layout_engine().set(rect=(0, 0.03, 1, 0.97))
    _caption(fig, caption)
    return fig


def _note(ax, text: str) -> None:
    """Why a panel has nothing to show, written in the panel itself."""
    ax.text(0.5, 0.5, text, transform=ax.transAxes, ha="center", va="center", fontsize=9,
            color="0.2", bbox=dict(facecolor="white", edgecolor="0.6", lw=0.5))


def plot_estimation(deltas, est: dict, nees_bounds, caption: str,
                    why_empty: str = "not tested: the run has no Sun-gap end"):
    """Filter on nonlinear and on linear telemetry against the initial error: yaw
    error at the last Sun-gap end (with the filter's 3σ) and mean NEES.  A panel
    without a single finite value (no Sun-gap end in the run) carries ``why_empty``
    instead of an empty log axis."""
    fig, axes = plt.subplots(2, 2, figsize=(13, 8), constrained_layout=True, sharex=True)
    d = np.asarray(deltas, dtype=float)
    for c, kind in enumerate(("attitude", "rate")):
        e = est[kind]
        ax = axes[0, c]
        ax.plot(d, _pos(e["real"]), "-o", ms=4, label="real (nonlinear telemetry)")
        ax.plot(d, _pos(e["linear"]), "--s", ms=4, label="linearized (linear telemetry)")
        ax.plot(d, 3 * np.asarray(e["sigma"]), ":", color="C2", label="filter 3σ")
        ax.set_yscale("log")
        ax.set_ylabel("|yaw error| at last gap end (deg)")
        ax.set_title(f"{kind} sweep")
        tested = np.isfinite(np.r_[e["real"], e["linear"], e["sigma"]].astype(float))
        if tested.any():
            ax.legend(fontsize=8)
        else:           # no y-ticks: an empty log axis would read as data near 1°
            ax.set_yscale("linear")
            ax.set_yticks([])
            _note(ax, why_empty)
        ax = axes[1, c]
        ax.plot(d, e["nees_real"], "-o", ms=4, label="real")
        ax.plot(d, e["nees_linear"], "--s", ms=4, label="linearized")
        ax.axhline(9, color="0.4", lw=0.8, label="E[χ²(9)] = 9")
        ax.axhspan(*nees_bounds, color="C2", alpha=0.12, label="95% χ²(9) per sample")
        ax.set_yscale("log")
        ax.set_xscale("log")
        ax.set_xlabel("initial error δ (deg)")
        ax.set_ylabel("mean NEES, second half of the run")
        ax.legend(fontsize=8)
    for ax in axes.ravel():
        ax.grid(True, which="both", alpha=0.3)
    fig.suptitle("Estimation consequence: the same filter on nonlinear and on linear telemetry")
    fig.get_layout_engine().set(rect=(0, 0.03, 1, 0.97))
    _caption(fig, caption)
    return fig
