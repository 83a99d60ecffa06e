"""The consistency figure of a run (``consistency.png``): NEES and NIS against their
χ² bounds, with a verdict written on the figure.

Draws only what it is given (plain arrays); the verdict is arithmetic on those
arrays, no physics and no imports from ``sim`` or ``estimator``.
"""

from __future__ import annotations

import textwrap

import matplotlib

matplotlib.use("Agg")
import numpy as np  # noqa: E402
from matplotlib.ticker import LogLocator, NullLocator  # noqa: E402

from .decor import (  # noqa: E402
    GAP_LABEL,
    dot_handle,
    figure_legend,
    panel_figure,
    shade_gaps,
    shade_mask,
    time_axis,
)
from .decor import gap_labels as decor_gap_labels  # noqa: E402
from .reduce import (  # noqa: E402
    every,
    f64,
    finite,
    minmax_line,
    pct,
    running_mean,
    runs_of,
    stride,
    window,
)

DSS_COLOR = "#f6c77c"
_NEES_COLORS = {"real": "C3", "linear": "C0"}
_NEES_NAMES = {"real": "real (nonlinear truth)", "linear": "linear twin"}
CONSISTENT_INSIDE = 0.90   # per-sample share inside the 95% bounds called consistent
# A state whose mean (e/σ)² is under QUIET_STATE (σ over ~2.2× its RMS error) is named
# as making the filter conservative (scenarios.files.checks uses the same 0.2); one
# over LOUD_STATE as making it over-confident.
QUIET_STATE = 0.2
LOUD_STATE = 2.0


def nees_verdict(nees, dof: int, bounds) -> dict | None:
    """Where the per-sample NEES sits against its χ² 95% bounds: shares inside,
    below and above, the mean, and a word for it.

    Consistent: at least 90% inside (95% expected; samples a few seconds apart are
    correlated, so a single run scatters by a few percent).  Otherwise
    conservative when more samples fall below than above (σ larger than the
    errors), over-confident when more fall above.  None without finite samples."""
    y = finite(nees)
    if not y.size:
        return None
    lo, hi = (float(v) for v in bounds)
    inside = float(np.mean((y >= lo) & (y <= hi)))
    below, above = float(np.mean(y < lo)), float(np.mean(y > hi))
    if inside >= CONSISTENT_INSIDE:
        word, why = _word(inside, 0.0, dof)
    else:
        # By the samples: more below than above is conservative.
        word, why = _word(inside, dof - 1.0 if below >= above else dof + 1.0, dof)
    return {"inside": inside, "below": below, "above": above, "mean": float(np.mean(y)),
            "dof": dof, "bounds": (lo, hi), "word": word, "why": why}


def _word(inside: float, mean: float, dof: int) -> tuple[str, str]:
    if inside >= CONSISTENT_INSIDE:
        return "consistent", "the errors match the filter's σ"
    if mean <= dof:
        return "conservative", "the filter's σ is larger than its errors"
    return "over-confident", "the errors are larger than the filter's σ"


def summary_verdict(summary: dict | None, which: str, dof: int, bounds,
                    rows: dict | None) -> dict | None:
    """The verdict from summary.json's full-rate NEES figures (``which`` "real" or
    "linear"), the shares below and above the bounds still from the drawn rows
    ``rows`` (summary.json holds the share inside only); ``rows`` itself when the
    summary lacks them."""
    sfx = "" if which == "real" else "_linear"
    mean = (summary or {}).get(f"nees_mean{sfx}")
    inside = (summary or {}).get(f"nees_fraction_inside_95{sfx}")
    if mean is None or inside is None:
        return rows
    word, why = _word(float(inside), float(mean), dof)
    return {"inside": float(inside), "mean": float(mean), "dof": dof, "word": word,
            "why": why, "bounds": tuple(bounds), "full_rate": True,
            "below": None if rows is None else rows["below"],
            "above": None if rows is None else rows["above"]}


def per_state_text(per_state: dict | None, dof: int, quiet: float = QUIET_STATE,
                   loud: float = LOUD_STATE) -> str:
    """Which states make the NEES depart from ``dof``, from summary.json's
    ``nees_mean_per_state`` (mean (e/σ)² per state, expected 1 each): the states
    far below 1 (conservative) or far above (over-confident), and their share of
    the departure of the per-state means' sum from ``dof``."""
    if not per_state:
        return ""
    names = {k: k.rsplit("_", 1)[0] if k.endswith(("_deg", "_degps", "_Nms", "_Nm"))
             else k for k in per_state}
    total = float(sum(per_state.values()))
    if total <= dof:
        picked = {k: v for k, v in per_state.items() if v < quiet}
        share = sum(1.0 - v for v in picked.values()) / max(dof - total, 1e-300)
        how, side = f"far below 1 (under {quiet:g}), their σ far larger than their errors", \
            "shortfall"
    else:
        picked = {k: v for k, v in per_state.items() if v > loud}
        share = sum(v - 1.0 for v in picked.values()) / (total - dof)
        how, side = f"far above 1 (over {loud:g}), their errors larger than their σ", "excess"
    if not picked:
        return ""
    listed = ", ".join(f"{names[k]} {v:.2g}" for k, v in sorted(picked.items(),
                                                                key=lambda kv: kv[1]))
    return (f"Per state, mean (e/σ)² (expected 1 each; summary.json): {listed} are {how}; "
            f"they make {100 * share:.0f}% of the {side} of the per-state sum "
            f"({total:.2f}) from {dof}.")


def verdict_text(real: dict | None, linear: dict | None, per_state: dict | None = None) -> str:
    """The verdict box: a headline (the real run's verdict, or the twin's when there
    is no real NEES), a line of numbers per run (summary.json's full-rate figures
    when given), with both runs whether the twin says the same (then the cause is
    the filter's model, not the linearization), and which states cause it."""
    head = real or linear
    if head is None:
        return "no NEES samples"
    whose = "real run" if real is not None else "linear twin"
    lines = [f"Verdict ({whose}): {head['word'].upper()}: {head['why']}."]
    for name, v in (("real", real), ("linear twin", linear)):
        if v is None:
            continue
        where = ("" if v["below"] is None else
                 f"{100 * v['below']:.0f}% below, {100 * v['above']:.0f}% above")
        if v.get("full_rate"):
            src = "; full-rate, summary.json"
            where = f"; drawn rows: {where}" if where else ""
        else:
            src, where = "; drawn rows", f"; {where}"
        lines.append(f"{name}: per-sample NEES inside its 95% bounds "
                     f"{100 * v['inside']:.0f}% of the time (95% expected{where}); "
                     f"mean {v['mean']:.2f} against the expected {v['dof']}{src}.")
    if real is not None and linear is not None:
        same = abs(real["mean"] - linear["mean"]) <= 0.05 * linear["mean"]
        lines.append("The linear twin gives the same: the cause is the filter's model and "
                     "tuning, not the linearization." if same else
                     "The linear twin differs: the linearization accounts for the difference.")
    states = per_state_text(per_state, head["dof"])
    if states:
        lines.append(textwrap.fill(states, 150))
    return "\n".join(lines)


def _log_axis(ax, bottom: float, top: float) -> None:
    ax.set_yscale("log")
    ax.set_ylim(bottom, top)
    ax.yaxis.set_major_locator(LogLocator(base=10.0, numticks=12))
    ax.yaxis.set_minor_locator(NullLocator())   # decades only: faster and less clutter
    ax.grid(alpha=0.3, which="major")


def _below_note(ax, y, bottom: float) -> str:
    """Per-sample χ² draws near zero are many decades down; say how many are below
    the axis rather than stretching it."""
    y = finite(y)
    share = float(np.mean(y < bottom)) if y.size else 0.0
    return f"; {100 * share:.1f}% of samples below the axis" if share > 0 else ""


# The twin's NEES nearly equals the real one: drawn after it, dashed and narrower,
# so both show where they coincide.
_NEES_STYLE = {"real": dict(lw=2.4, ls="-", zorder=4), "linear": dict(lw=1.2, ls=(0, (4, 2)),
                                                                       zorder=5)}


def _nees_panel(ax, t_s, nees: dict, dof: int, bounds, win_s: float,
                summary: dict | None) -> None:
    lo, hi = (float(v) for v in bounds)
    wlabel = f"{win_s / 60:g}-min mean"
    values = []
    for key in ("real", "linear"):
        if nees.get(key) is None:
            continue
        y = f64(nees[key])
        # NEES may be stored on a stride: its samples, and the breaks between them.
        ok = np.isfinite(y) | np.isnan(t_s)
        t_k, y_k = t_s[ok] / 3600.0, y[ok]
        values.append(y_k[np.isfinite(y_k)])
        color = _NEES_COLORS[key]
        ax.plot(*stride(t_k, y_k), ".", ms=1.0, color=color, alpha=0.3, zorder=2)
        dot_handle(ax, color, f"NEES {_NEES_NAMES[key]}, per sample")
        peak = nees.get(f"{key}_max")
        if peak is not None:   # decimated rows: the largest full-rate NEES of each row
            y_max = f64(peak)
            # The twin's under the real one: where they coincide the real shows.
            ax.plot(*minmax_line(t_s / 3600.0, y_max), color=color, lw=0.6, alpha=0.6,
                    zorder=2 if key == "real" else 1.5,
                    label=f"NEES {_NEES_NAMES[key]}, full-rate max per row")
            values.append(y_max[np.isfinite(y_max)])
        mean = running_mean(y_k, window(t_s[ok], win_s))
        ax.plot(*every(t_k, mean, 4000), color=color, **_NEES_STYLE[key],
                label=f"NEES {_NEES_NAMES[key]}, {wlabel}"
                + (" (dashed, over the real)" if key == "linear" else ""))
    ax.axhline(dof, color="k", lw=0.9, zorder=3, label="expected value")
    ax.axhline(lo, color="k", lw=0.9, ls="--", zorder=3, label="per-sample χ² 95% bounds")
    ax.axhline(hi, color="k", lw=0.9, ls="--", zorder=3)
    allv = np.concatenate(values) if values else np.empty(0)
    pos = allv[allv > 0]
    bottom = min(lo / 10.0, pct(pos, 1, lo / 10.0))
    top = max(hi * 3.0, 2.0 * pct(pos, 100, hi))
    # Room above the data for the verdict box.
    _log_axis(ax, bottom, top * 20.0)
    v = {k: summary_verdict(summary, k, dof, bounds, nees_verdict(nees.get(k), dof, bounds))
         if nees.get(k) is not None else None for k in ("real", "linear")}
    per_state = (summary or {}).get("nees_mean_per_state")
    ax.text(0.005, 0.97, verdict_text(v["real"], v["linear"], per_state), transform=ax.transAxes,
            va="top", fontsize=8, zorder=10,
            bbox=dict(boxstyle="round", fc="w", ec="0.5", alpha=0.92))
    ax.set_ylabel(f"NEES ({dof} states,\ndimensionless)")
    ax.set_title(f"NEES = (x̂ − x)ᵀ P⁻¹ (x̂ − x); bounds [{lo:.3g}, {hi:.3g}]"
                 f"{_below_note(ax, allv, bottom)}", loc="left", fontsize=9)


def _explain_dss(ax, t_h, rm, dss, note: str) -> None:
    """The note on why yaw NIS is small in DSS periods, written in the first long
    yaw gap after the first DSS period (the panel has no data there; the longest gap
    if none follows) with an arrow to that period's lowest mean."""
    a, b = runs_of(dss)[0]
    k = a + int(np.nanargmin(rm[a:b + 1])) if np.isfinite(rm[a:b + 1]).any() else a
    gaps = runs_of(~np.isfinite(rm))
    after = [g for g in gaps if g[0] >= b and t_h[g[1]] - t_h[g[0]] >= 2.0]
    g0, g1 = after[0] if after else max(gaps, key=lambda r: r[1] - r[0]) if gaps else (b, b)
    ax.annotate(note, xy=(t_h[k], rm[k] if np.isfinite(rm[k]) else 1.0), xycoords="data",
                xytext=(t_h[g0] + 0.01 * (t_h[-1] - t_h[0]), 0.25),
                textcoords=("data", "axes fraction"), ha="left", va="center", fontsize=8,
                zorder=10,
                bbox=dict(boxstyle="round", fc="w", ec="0.5", alpha=0.92),
                arrowprops=dict(arrowstyle="->", color="k", lw=0.8))


def _nis_panel(ax, t_s, name: str, y, bounds, win: int, wlabel: str, dss, dss_note) -> None:
    lo, hi = (float(v) for v in bounds)
    t_h = t_s / 3600.0
    y = f64(y)
    ax.plot(*stride(t_h, y), ".", ms=1.0, color="C1", alpha=0.35, zorder=2)
    dot_handle(ax, "C1", "NIS per sample")
    rm = running_mean(y, win)
    ax.plot(*every(t_h, rm, 4000), color="C4", lw=1.4, zorder=4, label=f"NIS {wlabel}")
    ax.axhline(1.0, color="k", lw=0.9, zorder=3, label="expected value")
    ax.axhline(lo, color="k", lw=0.9, ls="--", zorder=3, label="per-sample χ² 95% bounds")
    ax.axhline(hi, color="k", lw=0.9, ls="--", zorder=3)
    fin = np.isfinite(y)
    n_eff = int(np.median(np.convolve(fin, np.ones(win), mode="valid"))) \
        if y.size >= win else 0
    if n_eff > 1:
        d = 1.96 * np.sqrt(2.0 / n_eff)
        ax.axhspan(max(1 - d, 1e-12), 1 + d, color="C4", alpha=0.3, lw=0, zorder=1,
                   label=f"NIS {wlabel}: 95% range if white (N = {n_eff})")
    # The axis holds the running mean everywhere (the down-weighted DSS periods
    # included) and the bounds; per-sample draws far below are counted, not drawn.
    bottom = min(lo / 10.0, 0.3 * pct(rm[rm > 0], 0, lo / 10.0))
    top = max(hi * 3.0, 2.0 * pct(y, 100, hi))
    _log_axis(ax, bottom, top)
    vals = y[fin]
    stats = (f"{100 * np.mean((vals >= lo) & (vals <= hi)):.1f}% in the 95% bounds, mean "
             f"{np.mean(vals):.2f}" if vals.size else "no updates")
    ax.set_title(f"NIS, {name} measurement: ν²/S, expected 1, bounds [{lo:.2g}, {hi:.3g}]. "
                 f"{stats}{_below_note(ax, y, bottom)}",
                 loc="left", fontsize=9)
    if name == "yaw" and dss is not None and np.any(dss) and dss_note:
        _explain_dss(ax, t_h, rm, dss, dss_note)
    ax.set_ylabel(f"NIS {name}\n(dimensionless)")


def plot_consistency(t_s, gap, nees: dict | None, nees_dof: int, nees_bounds, nis: dict,
                     nis_bounds, title: str, dss=None, dss_note: str | None = None,
                     mean_window_s: float = 600.0, *, summary: dict | None = None,
                     warnings=None, min_gap_s: float = 0.0,
                     gap_labels: tuple[str, str] | None = None):
    """Filter consistency: NEES of each run given (``nees`` = {"real", "linear"},
    NaN where not computed) with a verdict box, and the NIS of each measurement,
    against per-sample χ² 95% bounds, with running means; log y.  ``dss`` marks
    the samples whose yaw came from the deliberately down-weighted DSS (shaded,
    and ``dss_note`` says why yaw NIS is small there).  Without NEES (no truth)
    the figure holds the NIS panels only.  ``summary`` (summary.json's dict) gives
    the verdict's numbers, full-rate, and the states that cause it
    (``nees_mean_per_state``); ``warnings`` (messages) are written under the figure;
    yaw outages of at least ``min_gap_s`` and shorter ones are shaded apart, with
    ``gap_labels``."""
    t_s = f64(t_s)
    t_h = t_s / 3600.0
    gap = np.asarray(gap, dtype=bool)
    has_nees = nees is not None and any(nees.get(k) is not None for k in ("real", "linear"))
    nis_names = [n for n in ("roll", "yaw", "h") if n in nis] + \
        [n for n in nis if n not in ("roll", "yaw", "h")]
    heights = ([3.6] if has_nees else []) + [2.6] * len(nis_names)
    fig, axes = panel_figure(heights, warnings, 1.0)
    dss = None if dss is None else np.asarray(dss, dtype=bool)
    labels = gap_labels or (decor_gap_labels(min_gap_s) if min_gap_s > 0
                            else (GAP_LABEL, GAP_LABEL))
    for ax in axes:
        shade_gaps(ax, t_s, t_h, gap, min_gap_s, labels)
        if dss is not None:
            shade_mask(ax, t_h, dss, "DSS yaw, deliberately down-weighted by the filter",
                       color=DSS_COLOR, alpha=0.45)
    if has_nees:
        _nees_panel(axes[0], t_s, nees, nees_dof, nees_bounds, mean_window_s, summary)
    win = window(t_s, mean_window_s)
    wlabel = f"{mean_window_s / 60:g}-min mean"
    for ax, name in zip(axes[int(has_nees):], nis_names, strict=True):
        _nis_panel(ax, t_s, name, nis[name], nis_bounds, win, wlabel, dss, dss_note)
    time_axis(axes[-1], t_h)
    figure_legend(fig, axes, ncol=3)
    what = "NEES, NIS" if has_nees else "NIS; no truth given, so no NEES"
    fig.suptitle(f"Filter consistency ({what}) — {title}")
    return fig
