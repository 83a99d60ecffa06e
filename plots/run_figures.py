"""Figures of one estimation run: errors, torques, consistency, telemetry overview.

Draws only what it is given (plain numpy arrays in seconds, degrees, N m, N m s and
rpm); no physics and no imports from ``sim`` or ``estimator``.

Runs are long (two days at 0.512 s is ~340,000 samples per trace), so every trace
is reduced FOR DRAWING ONLY: noisy traces to a min/max envelope per time bin (one bin
per ~pixel column, which looks the same as the full trace), point clouds to a stride
subsample. The caller's arrays are never modified: every reduction works on copies.
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.ticker import (  # noqa: E402
    FixedLocator,
    FuncFormatter,
    LogLocator,
    MultipleLocator,
    NullLocator,
)

from .truth import shade_intervals  # noqa: E402

#: The paper's yaw 1σ (Eq. 56), in degrees. Duplicated from ``estimator.covariance``
#: because ``plots`` does not import ``estimator``.
PAPER_SIGMA_YAW_DEG = 0.040

GAP_LABEL = "no Sun-sensor yaw"
_NBINS = 2000            # drawing bins across the time axis (~1 per pixel column at 120 dpi)
_MAX_DOTS = 10000        # points drawn for a per-sample scatter
_MAX_SHADED = 400        # beyond this many gap intervals, shade a per-bin mask instead
_GAP_COLOR = "0.85"


# --------------------------------------------------------------------------- reductions
def _f(a) -> np.ndarray:
    """A float array view/copy of ``a``; never written to."""
    return np.asarray(a, dtype=float)


def _bins(n: int, nbins: int = _NBINS):
    """Start and end (inclusive) indices of ``nbins`` equal-count bins, or None if n is small."""
    if n <= 2 * nbins:
        return None
    starts = np.linspace(0, n, nbins + 1)[:-1].astype(int)
    ends = np.r_[starts[1:], n] - 1
    return starts, ends


def _minmax_line(t_h: np.ndarray, y) -> tuple[np.ndarray, np.ndarray]:
    """(x, y) to draw as a line: per bin the minimum then the maximum (NaN-aware).

    At one bin per pixel column this draws the same picture as the full trace.
    A bin with no finite value gives NaN, so data gaps stay gaps.
    """
    y = _f(y)
    b = _bins(y.size)
    if b is None:
        return t_h, y
    starts, ends = b
    lo = np.fmin.reduceat(y, starts)
    hi = np.fmax.reduceat(y, starts)
    x = np.column_stack([t_h[starts], t_h[ends]]).ravel()
    return x, np.column_stack([lo, hi]).ravel()


def _band(t_h: np.ndarray, lower, upper) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(x, lo, hi) for fill_between: the per-bin min of ``lower`` and max of ``upper``."""
    lower, upper = _f(lower), _f(upper)
    b = _bins(lower.size)
    if b is None:
        return t_h, lower, upper
    starts, ends = b
    x = np.column_stack([t_h[starts], t_h[ends]]).ravel()
    return (x, np.repeat(np.fmin.reduceat(lower, starts), 2),
            np.repeat(np.fmax.reduceat(upper, starts), 2))


def _stride(t_h: np.ndarray, y, n_max: int = _MAX_DOTS):
    y = _f(y)
    step = max(1, y.size // n_max)
    return t_h[::step], y[::step]


def _finite(a) -> np.ndarray:
    a = _f(a)
    return a[np.isfinite(a)]


def _pct(a, q: float, default: float = 0.0) -> float:
    a = _finite(a)
    return float(np.percentile(a, q)) if a.size else default


def _running_mean(y, window: int) -> np.ndarray:
    """Centred running mean ignoring NaN; NaN where under half the window is finite."""
    y = _f(y)
    ok = np.isfinite(y)
    window = int(min(max(window, 1), y.size))
    c = np.r_[0.0, np.cumsum(np.where(ok, y, 0.0))]
    k = np.r_[0, np.cumsum(ok)]
    half = window // 2
    idx = np.arange(y.size)
    a = np.clip(idx - half, 0, y.size)
    b = np.clip(idx - half + window, 0, y.size)
    cnt = k[b] - k[a]
    out = np.full(y.size, np.nan)
    good = cnt >= max(1, window // 2)
    out[good] = (c[b] - c[a])[good] / cnt[good]
    return out


def _window(t_s: np.ndarray, seconds: float) -> int:
    if t_s.size < 2:
        return 1
    dt = float(np.median(np.diff(t_s)))
    return max(1, int(round(seconds / dt))) if dt > 0 else 1


# --------------------------------------------------------------------------- decorations
def _shade_gaps(ax, t_h: np.ndarray, gap: np.ndarray, label: str | None) -> None:
    """Sun-gap bands via ``truth.shade_intervals``.

    With hundreds of intervals (dropout flicker) a drawing bin is shaded when most of
    its samples are in a gap: the same picture at pixel resolution, drawn fast.
    """
    gap = np.asarray(gap, dtype=bool)
    if not gap.any():
        return
    n_intervals = int(np.count_nonzero(np.diff(np.r_[0, gap.astype(np.int8), 0]) == 1))
    if n_intervals <= _MAX_SHADED:
        shade_intervals(ax, t_h, gap, label)
        return
    starts, ends = _bins(gap.size, 1000) or (np.arange(gap.size), np.arange(gap.size))
    mostly = np.add.reduceat(gap.astype(np.int64), starts) * 2 >= (ends - starts + 1)
    x = np.column_stack([t_h[starts], t_h[ends]]).ravel()
    ax.fill_between(x, 0, 1, where=np.repeat(mostly, 2), transform=ax.get_xaxis_transform(),
                    color=_GAP_COLOR, zorder=0, lw=0, label=label)


def _gap_ends(t_s: np.ndarray, gap: np.ndarray, min_gap_s: float = 0.0) -> np.ndarray:
    """Indices of the last sample of every gap that ends inside the record (a falling
    edge of ``gap``) and lasted at least ``min_gap_s``."""
    gap = np.asarray(gap, dtype=bool)
    edges = np.diff(np.r_[0, gap.astype(np.int8), 0])
    first = np.flatnonzero(edges == 1)
    last = np.flatnonzero(edges == -1) - 1
    keep = (last < gap.size - 1) & (t_s[last] - t_s[first] >= min_gap_s)
    return last[keep]


def _time_axis(ax, t_h: np.ndarray) -> None:
    span = float(t_h[-1] - t_h[0]) if t_h.size > 1 else 0.0
    if span > 0:
        for step in (0.01, 0.02, 0.05, 0.1, 0.25, 0.5, 1, 2, 3, 6, 12, 24, 48, 168):
            if span / step <= 16:
                ax.xaxis.set_major_locator(MultipleLocator(step))
                break
        ax.set_xlim(t_h[0], t_h[-1])
    ax.set_xlabel("time (h)")


def _legend_right(ax, **kw) -> None:
    """Legend outside the axes, to the right, so it never covers data."""
    ax.legend(loc="upper left", bbox_to_anchor=(1.005, 1.0), fontsize=8, borderaxespad=0.0,
              markerscale=kw.pop("markerscale", 1.0), **kw)


def _engineering_axis(ax) -> str:
    """Tick labels in units of 10^(3k) so no offset text is needed; returns the factor."""
    top = max(abs(v) for v in ax.get_ylim())
    if not np.isfinite(top) or top == 0:
        return ""
    e = int(np.floor(np.log10(top) / 3.0)) * 3
    if e == 0 or (-3 <= e < 0 and top >= 1e-3):   # 0.001 ... 999: plain decimals read best
        ax.ticklabel_format(axis="y", style="plain", useOffset=False)
        return ""
    scale = 10.0 ** e
    ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v / scale:g}".replace("-", "−")))
    sup = str(e).translate(str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹"))
    return f"10{sup} "


def _nice_ticks(linthresh: float, top: float) -> list[float]:
    """Symmetric tick values for a symlog axis: 0, then 1-2-5 (or sparser) decades."""
    lo_dec = int(np.floor(np.log10(linthresh)))
    hi_dec = int(np.ceil(np.log10(top)))
    for mants in ((1, 2, 5), (1, 3), (1,)):
        vals = [m * 10.0 ** d for d in range(lo_dec, hi_dec + 1) for m in mants]
        vals = [v for v in vals if 0.9 * linthresh <= v <= top]
        if len(vals) <= 5:
            break
    return sorted([-v for v in vals] + [0.0] + vals)


def _fmt(v: float) -> str:
    return "0" if v == 0 else f"{v:.3g}".replace("-", "−")


# --------------------------------------------------------------------------- 1. errors
def _error_limits(errors: list[np.ndarray], three_sigma: np.ndarray,
                  must_show: float = 0.0) -> tuple[float, float | None]:
    """Half-range of a symmetric y-axis and, if the σ spans too much, a symlog threshold.

    The half-range covers the larger of the 99th-percentile |error| and the 3σ envelope
    (99th percentile, so the gap-end envelope shows). If the sunlit envelope (10th
    percentile of 3σ) would then fill less than ~1/8 of the half-range, the axis is
    symlog, linear inside ±(sunlit 3σ): the sunlit envelope and the gap growth are both
    visible.
    """
    p_err = max([_pct(np.abs(e), 99) for e in errors] + [0.0])
    s_med = _pct(three_sigma, 50)
    s_hi = _pct(three_sigma, 99)
    s_lo = _pct(three_sigma, 10)
    half = 1.15 * max(p_err, s_med, s_hi, must_show)
    if half <= 0 or not np.isfinite(half):
        return 1.0, None
    if s_lo > 0 and half / s_lo > 8.0:
        return half, s_lo
    return half, None


def plot_errors(t_s, gap, series: dict, title: str, min_gap_s: float = 600.0):
    """Estimation error vs time for roll, yaw and h, one panel each.

    ``series[name]`` = {"unit": "deg" | "N m s", "real": estimate − nonlinear truth,
    "linear": estimate − linear-twin truth, "sigma": filter 1σ, "smoothed": smoother
    error or None}. ``gap`` is True where there is no Sun-sensor yaw. The yaw panel also
    carries the paper's σ_yaw = 0.040° (Eq. 56) at every gap end (falling edge of
    ``gap``), and the filter's σ at the last gap end. Gaps shorter than ``min_gap_s``
    (sensor dropouts, not Sun gaps) are shaded but get no paper marks.
    """
    t_s = _f(t_s)
    t_h = t_s / 3600.0
    gap = np.asarray(gap, dtype=bool)
    names = [n for n in ("roll", "yaw", "h") if n in series]
    fig, axes = plt.subplots(len(names), 1, figsize=(13, 3.4 * len(names) + 0.8), sharex=True,
                             constrained_layout=True, squeeze=False)
    ends = _gap_ends(t_s, gap, min_gap_s)
    for ax, name in zip(axes[:, 0], names, strict=True):
        s = series[name]
        unit = s["unit"]
        real, lin, sig = _f(s["real"]), _f(s["linear"]), _f(s["sigma"])
        smoothed = None if s.get("smoothed") is None else _f(s["smoothed"])
        three = 3.0 * np.abs(sig)
        yaw_marks = name == "yaw" and unit == "deg" and ends.size > 0
        must = 3.0 * PAPER_SIGMA_YAW_DEG * 1.1 if yaw_marks else 0.0
        errs = [real, lin] + ([smoothed] if smoothed is not None else [])
        half, linthresh = _error_limits(errs, three, must)

        _shade_gaps(ax, t_h, gap, GAP_LABEL)
        x, lo, hi = _band(t_h, -three, three)
        ax.fill_between(x, lo, hi, color="C2", alpha=0.28, lw=0, zorder=1,
                        label="filter ±3σ")
        # Envelope edges above the error traces, so ±3σ shows even where errors cover it.
        ax.plot(x, hi, color="darkgreen", lw=1.0, zorder=5)
        ax.plot(x, lo, color="darkgreen", lw=1.0, zorder=5)
        # The nonlinear-run error is usually the larger one: draw it underneath, so the
        # linear-twin error stays visible on top of it.
        ax.plot(*_minmax_line(t_h, real), color="C3", lw=0.7, zorder=2,
                label="error vs nonlinear truth")
        ax.plot(*_minmax_line(t_h, lin), color="C0", lw=0.6, zorder=3,
                label="error vs linear-twin truth")
        if smoothed is not None:
            ax.plot(*_minmax_line(t_h, smoothed), color="k", lw=0.4, alpha=0.6, zorder=4,
                    label="smoother error (nonlinear truth)")
        ax.axhline(0.0, color="0.4", lw=0.5, zorder=1)

        if yaw_marks:
            p = PAPER_SIGMA_YAW_DEG
            te = t_h[ends]
            for k, lev in enumerate((p, 3 * p)):
                ax.plot(np.r_[te, te], np.r_[np.full(te.size, lev), np.full(te.size, -lev)],
                        ls="none", marker="_", ms=16 if k else 11, mew=2.6 if k else 1.6,
                        color="m", zorder=6,
                        label=f"paper σ_yaw = {p:.3f}° (Eq. 56): marks at ±1σ, ±3σ"
                        if k == 0 else "_paper 3σ_yaw")
            i_last = ends[-1]
            s_last = abs(float(sig[i_last]))
            ax.plot([t_h[i_last]] * 2, [3 * s_last, -3 * s_last], ls="none", marker="o",
                    mfc="none", mec="k", ms=7, mew=1.3, zorder=7,
                    label="filter ±3σ at last gap end")
            ax.annotate(f"last gap end, t = {t_h[i_last]:.2f} h:\n"
                        f"filter σ_yaw = {s_last:.4f}° (paper {p:.3f}°)",
                        xy=(t_h[i_last], -3 * s_last), xycoords="data",
                        xytext=(1.005, 0.02), textcoords="axes fraction", fontsize=8,
                        ha="left", va="bottom",
                        bbox=dict(boxstyle="round", fc="w", ec="0.6"),
                        arrowprops=dict(arrowstyle="->", color="k", lw=0.8))

        label = f"{name} error ({unit})"
        if linthresh is not None:
            ax.set_yscale("symlog", linthresh=linthresh, linscale=1.0)
            ax.yaxis.set_major_locator(FixedLocator(_nice_ticks(linthresh, half)))
            ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: _fmt(v)))
            ax.yaxis.set_minor_locator(FixedLocator([]))
            for sgn in (1, -1):
                ax.axhline(sgn * linthresh, color="0.5", lw=0.5, ls=":", zorder=1)
            label += f"\nsymlog: linear within ±{linthresh:.2g} {unit}"
        ax.set_ylim(-half, half)
        if linthresh is None:
            factor = _engineering_axis(ax)
            if factor:
                label = f"{name} error ({factor}{unit})"
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
        _legend_right(ax)
        ax.set_title(f"{name}: estimate − truth, filter ±3σ", loc="left", fontsize=9)
    _time_axis(axes[-1, 0], t_h)
    fig.suptitle(f"Estimation error vs time — {title}")
    return fig


# --------------------------------------------------------------------------- 2. torques
TORQUE_NAMES = ("N_px", "N_pz", "N_cx", "N_cz")
_TORQUE_DESC = {"N_px": "periodic torque, x", "N_pz": "periodic torque, z",
                "N_cx": "constant torque, x", "N_cz": "constant torque, z"}


def plot_torques(t_s, gap, estimated: dict, truth: dict, sigma: dict, title: str):
    """Estimated periodic and constant torques against the true torques projected onto
    the same model, with the filter's ±3σ band about the estimate (2×2 panels, N m)."""
    t_s = _f(t_s)
    t_h = t_s / 3600.0
    gap = np.asarray(gap, dtype=bool)
    names = [n for n in TORQUE_NAMES if n in estimated] + \
        [n for n in estimated if n not in TORQUE_NAMES]
    ncol = 2
    nrow = max(1, int(np.ceil(len(names) / ncol)))
    fig, axes = plt.subplots(nrow, ncol, figsize=(14, 3.8 * nrow + 0.8), sharex=True,
                             constrained_layout=True, squeeze=False)
    for k, ax in enumerate(axes.ravel()):
        if k >= len(names):
            ax.set_visible(False)
            continue
        name = names[k]
        est, sig = _f(estimated[name]), np.abs(_f(sigma[name]))
        tru = _f(truth[name]) if name in truth else None
        _shade_gaps(ax, t_h, gap, GAP_LABEL)
        x, lo, hi = _band(t_h, est - 3 * sig, est + 3 * sig)
        ax.fill_between(x, lo, hi, color="C0", alpha=0.25, lw=0, zorder=1,
                        label="estimate ±3σ")
        ax.plot(*_minmax_line(t_h, est), color="C0", lw=0.8, zorder=2, label="estimate")
        if tru is not None:
            ax.plot(*_minmax_line(t_h, tru), color="k", lw=1.0, ls="--", zorder=3,
                    label="truth (projected)")
        # Limits: the truth and the bulk of the estimate, plus the typical 3σ band; the
        # initial transient (large σ) is allowed to leave the axes.
        ref = tru if tru is not None else est
        c = 0.5 * (_pct(ref, 0.5) + _pct(ref, 99.5))
        half = max(_pct(np.abs(est - c), 99), _pct(np.abs(ref - c), 100),
                   1.5 * _pct(3 * sig, 50))
        if half > 0 and np.isfinite(half):
            ax.set_ylim(c - 1.2 * half, c + 1.2 * half)
        ax.set_ylabel(f"{name} ({_engineering_axis(ax)}N m)")
        ax.set_title(f"{name}: {_TORQUE_DESC.get(name, 'torque')}", loc="left", fontsize=9)
        ax.grid(alpha=0.3)
        if k % ncol == ncol - 1 or k == len(names) - 1:
            _legend_right(ax)
    for ax in axes[-1]:
        if ax.get_visible():
            _time_axis(ax, t_h)
    fig.suptitle(f"Estimated torques vs true torques projected onto the filter model — {title}")
    return fig


# --------------------------------------------------------------------------- 3. consistency
def _in_bounds(y: np.ndarray, lo: float, hi: float) -> str:
    y = _finite(y)
    if not y.size:
        return "no samples"
    return f"{100.0 * np.mean((y >= lo) & (y <= hi)):.1f}% in 95% bounds"


def _log_limits(ax, arrays: list[np.ndarray], lo: float, hi: float) -> None:
    """Log-axis limits: the bounds with margin and the data, ignoring near-zero χ² draws."""
    vals = np.concatenate([_finite(a) for a in arrays] + [np.empty(0)])
    vals = vals[vals > 0]
    bottom = lo / 10.0 if lo > 0 else (_pct(vals, 1, 1e-3) if vals.size else 1e-3)
    top = max(hi * 3.0, (_pct(vals, 100) * 2.0) if vals.size else hi * 3.0)
    ax.set_ylim(bottom, top)
    ax.yaxis.set_major_locator(LogLocator(base=10.0, numticks=12))
    ax.yaxis.set_minor_locator(NullLocator())   # decades only: faster and less clutter


def plot_consistency(t_s, nees_real, nees_linear, nees_dof: int, nees_bounds, nis: dict,
                     nis_bounds, title: str, mean_window_s: float = 600.0):
    """Filter consistency: NEES (nonlinear run and linear twin) and the NIS of each
    measurement against their per-sample χ² 95% bounds, with running means; log y."""
    t_s = _f(t_s)
    t_h = t_s / 3600.0
    win = _window(t_s, mean_window_s)
    wlabel = f"{mean_window_s / 60:g}-min mean"
    nis_names = [n for n in ("roll", "yaw", "h") if n in nis] + \
        [n for n in nis if n not in ("roll", "yaw", "h")]
    n_rows = 1 + len(nis_names)
    fig, axes = plt.subplots(n_rows, 1, figsize=(13, 2.9 * n_rows + 0.8), sharex=True,
                             constrained_layout=True, squeeze=False)
    axes = axes[:, 0]
    # No gap input here: the Sun gaps are where the yaw NIS is absent (NaN).
    gap = ~np.isfinite(_f(nis["yaw"])) if "yaw" in nis else np.zeros(t_s.size, bool)
    if gap.all():
        gap = np.zeros(t_s.size, bool)
    gap_label = "no Sun-sensor yaw (yaw NIS absent)"
    for ax in axes:
        _shade_gaps(ax, t_h, gap, gap_label)

    ax = axes[0]
    lo, hi = (float(v) for v in nees_bounds)
    arrays = []
    for y, color, name in ((nees_linear, "C0", "linear twin"), (nees_real, "C3", "nonlinear")):
        y = _f(y)
        arrays.append(y)
        ax.plot(*_stride(t_h, y), ".", ms=1.0, color=color, alpha=0.25, zorder=2,
                rasterized=False, label=f"NEES {name} per sample ({_in_bounds(y, lo, hi)})")
        ax.plot(*_stride(t_h, _running_mean(y, win), 4000), color=color, lw=1.4, zorder=4,
                label=f"NEES {name}, {wlabel}")
    ax.axhline(nees_dof, color="k", lw=0.9, ls="-", zorder=3, label=f"E[NEES] = {nees_dof}")
    ax.axhline(lo, color="k", lw=0.9, ls="--", zorder=3,
               label=f"χ²({nees_dof}) 95%: [{lo:.3g}, {hi:.3g}]")
    ax.axhline(hi, color="k", lw=0.9, ls="--", zorder=3)
    ax.set_yscale("log")
    _log_limits(ax, arrays, lo, hi)
    ax.set_ylabel(f"NEES ({nees_dof} states,\ndimensionless)")
    ax.set_title("NEES: (x̂ − x)ᵀ P⁻¹ (x̂ − x)", loc="left", fontsize=9)
    ax.grid(alpha=0.3, which="major")
    _legend_right(ax, markerscale=8)

    lo, hi = (float(v) for v in nis_bounds)
    for ax, name in zip(axes[1:], nis_names, strict=True):
        y = _f(nis[name])
        ax.plot(*_stride(t_h, y), ".", ms=1.0, color="C1", alpha=0.3, zorder=2,
                label=f"per sample ({_in_bounds(y, lo, hi)})")
        rm = _running_mean(y, win)
        ax.plot(*_stride(t_h, rm, 4000), color="C4", lw=1.4, zorder=4, label=wlabel)
        ax.axhline(1.0, color="k", lw=0.9, zorder=3, label="E[NIS] = 1")
        ax.axhline(lo, color="k", lw=0.9, ls="--", zorder=3,
                   label=f"χ²(1) 95%: [{lo:.2g}, {hi:.3g}]")
        ax.axhline(hi, color="k", lw=0.9, ls="--", zorder=3)
        n_eff = int(np.median(np.convolve(np.isfinite(y), np.ones(win), mode="valid"))) \
            if y.size >= win else 0
        if n_eff > 1:
            d = 1.96 * np.sqrt(2.0 / n_eff)
            ax.axhspan(max(1 - d, 1e-12), 1 + d, color="C4", alpha=0.3, lw=0, zorder=1,
                       label=f"{wlabel}: 95% if white (N = {n_eff})")
        ax.set_yscale("log")
        _log_limits(ax, [y, rm], lo, hi)
        ax.set_ylabel(f"NIS {name}\n(dimensionless)")
        ax.set_title(f"NIS, {name} measurement: ν² / S", loc="left", fontsize=9)
        ax.grid(alpha=0.3, which="major")
        _legend_right(ax, markerscale=8)
    _time_axis(axes[-1], t_h)
    fig.suptitle(f"Filter consistency (NEES, NIS) — {title}")
    return fig


# --------------------------------------------------------------------------- 4. telemetry
def plot_telemetry_overview(t_s, measured: dict, truth: dict, wheels_rpm: dict, gap,
                            title: str):
    """Roll, pitch and yaw measured vs true (deg), and wheel speeds relative to their
    first value (rpm); Sun-sensor gaps shaded."""
    t_s = _f(t_s)
    t_h = t_s / 3600.0
    gap = np.asarray(gap, dtype=bool)
    fig, axes = plt.subplots(4, 1, figsize=(13, 11), sharex=True, constrained_layout=True)
    for ax, name in zip(axes[:3], ("roll", "pitch", "yaw"), strict=True):
        _shade_gaps(ax, t_h, gap, GAP_LABEL)
        if name in measured:
            m = _f(measured[name])
            src = "Sun sensor" if name == "yaw" else "Earth sensor"
            how = "; min/max per pixel column" if _bins(m.size) is not None else ""
            ax.plot(*_minmax_line(t_h, m), color="C0", lw=0.6, alpha=0.8, zorder=2,
                    label=f"measured ({src}{how})")
        if name in truth:
            ax.plot(*_minmax_line(t_h, truth[name]), color="k", lw=1.0, zorder=3, label="true")
        ax.set_ylabel(f"{name} (deg)")
        ax.grid(alpha=0.3)
        _legend_right(ax)
    ax = axes[3]
    _shade_gaps(ax, t_h, gap, GAP_LABEL)
    for k, (name, rpm) in enumerate(wheels_rpm.items()):
        rpm = _f(rpm)
        fin = _finite(rpm)
        first = float(fin[0]) if fin.size else 0.0
        ax.plot(*_minmax_line(t_h, rpm - first), color=f"C{k}", lw=0.8, zorder=2,
                label=f"{name} (initial {first:.1f} rpm)")
    ax.set_ylabel("wheel speed − initial\nvalue (rpm)")
    ax.grid(alpha=0.3)
    _legend_right(ax)
    _time_axis(ax, t_h)
    fig.suptitle(f"Telemetry overview — {title}")
    return fig
