"""Telemetry figure: Earth-sensor and Sun-sensor readings against the truth (or
alone), samples coloured by Sun-sensor head, and the wheel speeds.

The ground yaw's error differs by two orders of magnitude between heads (DSS
σ ≈ 0.04°, CASS 1° growing to ~20° near the noon gap), so on one linear axis the
DSS segments vanish.  The yaw axis is therefore symlog, linear over the DSS range,
whenever the heads' ranges differ that much.

Draws only what it is given (plain arrays in degrees, seconds and rpm).
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .decor import (  # noqa: E402
    GAP_LABEL,
    dot_handle,
    engineering_axis,
    figure_legend,
    nice_up,
    note_clipped,
    robust_half,
    shade_gaps,
    symlog_axis,
    time_axis,
)
from .decor import gap_labels as gap_label_pair  # noqa: E402
from .reduce import band, f64, finite, max_abs, minmax_line, pct, stride  # noqa: E402

HEAD_NAMES = ("dss", "cass1", "cass2")
HEAD_COLORS = ("C3", "C9", "C6")   # apart from roll, pitch, yaw (C0, C1, C2)
_SYMLOG_SPREAD = 20.0   # heads' ranges differing more than this: symlog yaw axis


def _attitude_panel(ax, t_h, truth: dict) -> None:
    # Pitch first and pale: its control jitter would otherwise hide roll and yaw.
    for name, color, lw, alpha in (("pitch", "C1", 0.7, 0.6), ("roll", "C0", 1.3, 1.0),
                                   ("yaw", "C2", 1.3, 1.0)):
        if name in truth:
            ax.plot(*minmax_line(t_h, truth[name]), color=color, lw=lw, alpha=alpha,
                    label=f"true {name}")
    ax.set_ylabel("true attitude (deg)")
    ax.set_title("true attitude (Euler 3-1-2 from the orbit frame)", loc="left", fontsize=9)


def _earth_panel(ax, t_h, measured: dict, truth: dict | None) -> None:
    """Roll and pitch readings (minus the truth when given) as dots: the Earth sensor's
    0.01° quantum shows as lines, which an envelope would hide."""
    series = {}
    for name, color in (("roll", "C0"), ("pitch", "C1")):
        if name not in measured:
            continue
        y = f64(measured[name]) - (f64(truth[name]) if truth and name in truth else 0.0)
        series[name] = y
        ax.plot(*stride(t_h, y), ".", ms=1.2, color=color, alpha=0.5, zorder=2)
        dot_handle(ax, color, f"{name}, Earth sensor")
    c = 0.0 if truth else pct(np.concatenate([finite(v) for v in series.values()]), 50)
    half = robust_half([v - c for v in series.values()])
    ax.set_ylim(c - half, c + half)
    note_clipped(ax, t_h, series, c - half, c + half, "deg")
    what = "measured − true" if truth else "measured"
    ax.set_ylabel(f"Earth sensor,\n{what} ({engineering_axis(ax)}deg)")
    ax.set_title(f"roll and pitch: Earth sensor {what} (one dot per "
                 f"{max(1, len(t_h) // 10000)} samples)", loc="left", fontsize=9)


def _yaw_panel(ax, t_h, yaw, true_yaw, yaw_sigma, sun_head, gap) -> None:
    y = f64(yaw) - (f64(true_yaw) if true_yaw is not None else 0.0)
    head = np.full(y.size, np.nan) if sun_head is None else f64(sun_head)
    levels = []
    for k, (name, color) in enumerate(zip(HEAD_NAMES, HEAD_COLORS, strict=True)):
        use = (head == k) & np.isfinite(y)
        if not use.any():
            continue
        ax.plot(*stride(t_h[use], y[use], 8000), ".", ms=1.3, color=color, alpha=0.6, zorder=3)
        dot_handle(ax, color, f"yaw from {name.upper()}")
        levels.append(pct(np.abs(y[use]), 99.5))
    other = np.isfinite(y) & ~np.isin(head, (0, 1, 2))
    if other.any():   # a file without sun_head: one colour
        ax.plot(*stride(t_h[other], y[other], 8000), ".", ms=1.3, color="0.3", alpha=0.6,
                zorder=3)
        dot_handle(ax, "0.3", "yaw (head not given)")
        levels.append(pct(np.abs(y[other]), 99.5))
    if yaw_sigma is not None and true_yaw is not None:
        sig3 = 3.0 * np.abs(f64(yaw_sigma))
        x, lo, hi = band(t_h, -sig3, sig3)
        ax.plot(x, hi, color="k", lw=0.6, zorder=4, label="±3σ a priori (telemetry yaw_sigma_deg)")
        ax.plot(x, lo, color="k", lw=0.6, zorder=4)
    ax.axhline(0.0, color="0.4", lw=0.5, zorder=1)
    top = max_abs(y)
    what = "ground yaw − true" if true_yaw is not None else "ground yaw"
    small = min([v for v in levels if v > 0], default=0.0)
    if small > 0 and top / small > _SYMLOG_SPREAD:
        lin = nice_up(1.2 * small)
        half = 1.15 * top
        symlog_axis(ax, lin, half)
        ax.set_ylabel(f"{what} (deg)\nsymlog: linear within ±{lin:g}°")
    else:
        half = robust_half([y]) if top > 0 else 1.0
        ax.set_ylim(-half, half)
        ax.set_ylabel(f"{what} ({engineering_axis(ax)}deg)")
    note_clipped(ax, t_h, {"yaw": y}, -half, half, "deg")
    ax.set_title(f"yaw: {what}, by Sun-sensor head (none in the grey: {GAP_LABEL})",
                 loc="left", fontsize=9)


def _wheel_panel(ax, t_h, wheels_rpm: dict) -> None:
    for k, (name, rpm) in enumerate(wheels_rpm.items()):
        rpm = f64(rpm)
        fin = finite(rpm)
        first = float(fin[0]) if fin.size else 0.0
        ax.plot(*minmax_line(t_h, rpm - first), color=f"C{k + 4}", lw=0.9, zorder=2,
                label=f"{name.removesuffix('_rpm')} (initial {first:.1f} rpm)")
    ax.set_ylabel("wheel speed −\ninitial value (rpm)")
    ax.set_title("wheel tachometers", loc="left", fontsize=9)


def plot_telemetry_overview(t_s, measured: dict, truth: dict | None, wheels_rpm: dict, gap,
                            title: str, yaw_sigma=None, sun_head=None, *,
                            min_gap_s: float = 0.0,
                            gap_labels: tuple[str, str] | None = None):
    """Telemetry against time: the true attitude (with a truth), Earth-sensor roll and
    pitch and the ground yaw by Sun-sensor head (measured − true with a truth,
    measured without), and the wheel speeds relative to their first value.

    ``measured`` and ``truth`` map "roll", "pitch", "yaw" to degrees; ``sun_head``
    is 0 (dss), 1 (cass1), 2 (cass2) or NaN (no yaw); ``yaw_sigma`` the a-priori
    1σ of the ground yaw (deg); ``gap`` is True where there is no Sun-sensor yaw."""
    t_s = f64(t_s)
    t_h = t_s / 3600.0
    gap = np.asarray(gap, dtype=bool)
    # Sun gaps (at least min_gap_s) and shorter yaw outages, shaded apart.
    labels = gap_labels or (gap_label_pair(min_gap_s) if min_gap_s > 0 else (GAP_LABEL, GAP_LABEL))
    rows = (["attitude"] if truth else []) + ["earth", "yaw"] + (["wheels"] if wheels_rpm else [])
    heights = {"attitude": 2.2, "earth": 2.6, "yaw": 3.4, "wheels": 2.2}
    fig, axes = plt.subplots(len(rows), 1, figsize=(13, sum(heights[r] for r in rows) + 1.8),
                             sharex=True, layout="constrained", squeeze=False,
                             gridspec_kw={"height_ratios": [heights[r] for r in rows]})
    axes = axes[:, 0]
    for ax, row in zip(axes, rows, strict=True):
        shade_gaps(ax, t_s, t_h, gap, min_gap_s, labels)
        if row == "attitude":
            _attitude_panel(ax, t_h, truth)
        elif row == "earth":
            _earth_panel(ax, t_h, measured, truth)
        elif row == "yaw":
            _yaw_panel(ax, t_h, measured["yaw"], truth.get("yaw") if truth else None,
                       yaw_sigma, sun_head, gap)
        else:
            _wheel_panel(ax, t_h, wheels_rpm)
        ax.grid(alpha=0.3)
    time_axis(axes[-1], t_h)
    figure_legend(fig, axes, ncol=5)
    fig.suptitle(f"Telemetry — {title}")
    return fig
