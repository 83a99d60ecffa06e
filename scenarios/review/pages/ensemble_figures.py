"""The interactive figures of a Monte Carlo set's page, from montecarlo.npz (the
ensemble series `dynprop montecarlo` draws its PNGs from), montecarlo.json and the
case records (docs/outputs.md, "Monte Carlo set").

montecarlo.npz: ``t_s`` (the 60 s grid), ``rms`` and ``sigma_rms`` (G, 9): the
ensemble RMS of the errors and the RMS over the runs of the filter's σ,
``mean_err`` (G, 9), ``nees_avg`` (G,) with ``nees_bounds`` (χ²(9N)/N, 95%),
``nsq`` (G, 9): (e/σ)² averaged over the runs, with ``nsq_bounds`` (χ²(N)/N),
``gaps_h`` (the median Sun gaps); with the twin ``rms_linear`` and
``nees_avg_linear``, with the EKF ``rms_ekf`` and ``nees_avg_ekf``.
"""

from __future__ import annotations

import numpy as np

from .. import traces as tr
from ..page_parts import PALETTE, spread_band, vline
from ..run_figures import Plot

STATES = ("roll", "roll rate", "yaw", "yaw rate", "h", "N_px", "N_pz", "N_cx", "N_cz")
PANELS = ((0, "roll", "deg"), (2, "yaw", "deg"), (4, "h", "N m s"))
OTHERS = (("linear", "linear twin", tr.COLORS["linear"]), ("ekf", "EKF", tr.COLORS["ekf"]))


def time_axis(npz: dict, converged_h: float | None) -> tuple:
    """x in axis units, its title, and the shading: median Sun gaps and the start of
    the NEES test (``converged_after_h``, dotted)."""
    t = np.asarray(npz["t_s"], dtype=float)
    scale, unit = tr.time_unit(float(t[-1] - t[0]) if len(t) else 0.0)
    gaps = [(a * 3600 / scale, b * 3600 / scale)
            for a, b in np.reshape(npz.get("gaps_h", np.zeros((0, 2))), (-1, 2))]
    shapes = tr.shades(gaps, "sun_gap")
    if converged_h is not None:
        shapes.append(vline(converged_h * 3600 / scale))
    legend = [tr.legend_only("Sun gap (median over the runs)", tr.SHADES["sun_gap"])] \
        if gaps else []
    return t / scale, f"time since epoch ({unit})", shapes, legend, scale


def errors(npz: dict, runs: int, eq55_deg: float | None, converged_h: float | None) -> Plot:
    """±3 × the ensemble RMS error (shaded) against ±3 × the RMS of the filter's σ
    (dashed), the ensemble mean error, for roll, yaw and h: the paper's accuracy
    claim over N runs (the filter's σ should cover the errors' spread, not more)."""
    x, title, shapes, legend, scale = time_axis(npz, converged_h)
    data, panels = list(legend), []
    # The initial scales from the NEES test's start (the dispersed initial errors
    # before it would flatten the rest), or from the first hour in a shorter set.
    span_h = float(x[-1] - x[0]) * scale / 3600 if len(x) else 0.0
    skip = 3600.0 * (converged_h if converged_h and converged_h < span_h else 1.0)
    for i, (k, name, unit) in enumerate(PANELS):
        y, first = tr.axis(i), i == 0
        rms, sig = npz["rms"][:, k], npz["sigma_rms"][:, k]
        panels.append({"title": f"{name} error ({unit})",
                       "range": tr.robust_range([3 * rms, 3 * sig], x, skip, scale)})
        data += spread_band(x, 3 * rms, f"±3 × ensemble RMS error ({runs} runs)",
                            tr.COLORS["band"], y, group="rms", show=first)
        data += tr.sigma_band(x, sig, y, "±3 × RMS of the filter's σ", group="sigma",
                              show=first)
        data += tr.series(x, npz["mean_err"][:, k], "ensemble mean error", tr.COLORS["truth"],
                          y, group="mean", show=first)
        for key, label, color in OTHERS:
            if f"rms_{key}" in npz:
                data += tr.sigma_band(x, npz[f"rms_{key}"][:, k], y,
                                      f"±3 × ensemble RMS, {label}", color, "dot",
                                      group=key, show=first)
        if k == 2 and eq55_deg:
            shapes += [tr.hline(s * 3 * eq55_deg, y, tr.COLORS["paper"]) for s in (1, -1)]
    caption = ("Shaded: ±3 × the ensemble RMS of the error (estimate − truth) over the "
               "runs; dashed: ±3 × the RMS over the runs of the filter's own σ; black: the "
               "ensemble mean error (a bias shows here). "
               + (f"Red dotted: ±3σ_yaw of Eq. 55 ({eq55_deg:.4f}°). " if eq55_deg else "")
               + "Grey dotted: the start of the NEES test (montecarlo.converged_after_h); "
               "the initial scales leave out the time before it.")
    layout = tr.stacked_layout(panels, title, 210, shapes, (float(x[0]), float(x[-1])))
    return Plot("mc-errors", "Ensemble errors against the filter's σ", caption,
                {"data": data, "layout": layout})


def nees(npz: dict, record: dict, converged_h: float | None) -> Plot:
    """The averaged NEES with its χ²(9N)/N 95% bounds and expected value 9, then each
    state's (e/σ)² averaged over the runs with χ²(N)/N's: which states make the NEES
    what it is."""
    x, title, shapes, legend, scale = time_axis(npz, converged_h)
    data = list(legend)
    lo, hi = (float(b) for b in npz["nees_bounds"])
    data += tr.series(x, npz["nees_avg"], "averaged NEES", tr.COLORS["truth"], "y")
    for key, label, color in OTHERS:
        if f"nees_avg_{key}" in npz:
            data += tr.series(x, npz[f"nees_avg_{key}"], f"averaged NEES, {label}", color, "y")
    shapes += [tr.hline(b, "y", tr.COLORS["paper"], "dash") for b in (lo, hi)]
    shapes.append(tr.hline(float((record.get("nees") or {}).get("dof") or 9), "y",
                           tr.COLORS["sigma"], "dot"))
    for k, name in enumerate(STATES):
        data += tr.series(x, npz["nsq"][:, k], name, PALETTE[k], "y2")
    shapes += [tr.hline(float(b), "y2", tr.COLORS["paper"], "dash") for b in npz["nsq_bounds"]]
    panels = [{"title": "averaged NEES (9 states)"}, {"title": "(e/σ)² averaged over runs"}]
    layout = tr.stacked_layout(panels, title, 280, shapes, (float(x[0]), float(x[-1])))
    for k in ("yaxis", "yaxis2"):
        layout[k]["type"] = "log"
    caption = (f"Top: the NEES averaged over the runs, red dashed its 95% bounds "
               f"[{lo:.3g}, {hi:.3g}] (χ²(9N)/N), grey dotted its expected value. Bottom: "
               "each state's (error/σ)² averaged over the runs, red dashed one state's 95% "
               "bounds (χ²(N)/N). Log scales; grey dotted vertical: the start of the test.")
    return Plot("mc-nees", "Consistency: averaged NEES", caption,
                {"data": data, "layout": layout})


def _jitter(n: int, width: float) -> np.ndarray:
    """Deterministic spread within a column (as plots/montecarlo.py): the same set
    gives the same page."""
    return ((np.arange(n) * 0.6180339887) % 1.0 - 0.5) * width


def _keep(z: np.ndarray) -> np.ndarray:
    """Indices of the cases drawn: all of them up to ``tr.MAX_POINTS``; beyond, the
    300 largest |e/σ| (the cases a reviewer looks for) and evenly spaced ranks of
    the rest (the distribution's shape)."""
    n = len(z)
    if n <= tr.MAX_POINTS:
        return np.arange(n)
    order = np.argsort(np.abs(z))
    ranks = np.round(np.linspace(0, n - 301, tr.MAX_POINTS - 300)).astype(int)
    return np.unique(np.concatenate([order[ranks], order[-300:]]))


def gap_end_strip(cases: list[dict], gaps: list[dict]) -> Plot | None:
    """Each case's yaw error at each Sun-gap end over its own filter σ, one column
    per gap end and one dot per case (hover: which case), with the ±1, 2, 3 levels a
    consistent filter puts 68, 95 and 99.7% of its cases inside."""
    if not gaps:
        return None
    series = (("", "nonlinear truth", tr.COLORS["real"], ""),
              ("_linear", "linear twin", tr.COLORS["linear"], ""),
              ("_ekf", "EKF", tr.COLORS["ekf"], "_ekf"))
    present = [s for s in series if any(f"yaw_error{s[0]}_at_gap_end_deg" in c for c in cases)]
    width = 0.5 / max(1, len(present))
    data, thinned, ticks = [], False, []
    for j, g in enumerate(gaps):
        ticks.append(f"gap {g.get('gap', j + 1)} end"
                     + (f", {g['end_h_median']:.1f} h" if "end_h_median" in g else ""))
        for m, (err, label, color, sig) in enumerate(present):
            rows = [(c["case"], c[f"yaw_error{err}_at_gap_end_deg"][j],
                     c[f"yaw_sigma{sig}_at_gap_end_deg"][j]) for c in cases
                    if len(c.get(f"yaw_error{err}_at_gap_end_deg") or []) > j
                    and len(c.get(f"yaw_sigma{sig}_at_gap_end_deg") or []) > j]
            if not rows:
                continue
            k, e, s = (np.array(v, dtype=float) for v in zip(*rows, strict=True))
            z = e / s
            keep = _keep(z)
            thinned |= len(keep) < len(z)
            xpos = j + (m - (len(present) - 1) / 2) * width + _jitter(len(keep), 0.8 * width)
            trace = tr.line(xpos, z[keep], label, color, mode="markers", group=label,
                            show=j == 0)
            trace["marker"]["size"] = 7 if len(keep) <= 200 else 4
            trace["text"] = [f"case {int(a)}: e = {b:.4g}°, σ = {c:.4g}°"
                             for a, b, c in zip(k[keep], e[keep], s[keep], strict=True)]
            trace["hovertemplate"] = "%{text}<br>e/σ = %{y:.3f}<extra>" + label + "</extra>"
            data.append(trace)
    if not data:
        return None
    shapes = [tr.hline(s * k, "y", tr.COLORS["sigma"], d)
              for k, d in ((1, "solid"), (2, "dash"), (3, "dot")) for s in (1, -1)]
    layout = {"height": 420, "margin": {"l": 80, "r": 20, "t": 30, "b": 60},
              "template": "plotly_white", "hovermode": "closest", "shapes": shapes,
              "legend": {"orientation": "h", "y": 1.0, "yanchor": "bottom"},
              "xaxis": {"tickmode": "array", "tickvals": list(range(len(gaps))),
                        "ticktext": ticks, "range": [-0.5, len(gaps) - 0.5],
                        "zeroline": False},
              "yaxis": {"title": {"text": "yaw error / its filter σ"}, "zeroline": True}}
    caption = ("One dot per case (hover for which, its error and σ); grey lines at ±1σ "
               "(solid), ±2σ (dashed), ±3σ (dotted), where a consistent filter puts 68%, "
               "95% and 99.7% of its cases.")
    if thinned:
        caption += (f" Beyond {tr.MAX_POINTS} cases a column shows the 300 largest |e/σ| and "
                    "evenly spaced ranks of the rest.")
    return Plot("mc-gap-ends", "Yaw at the Sun-gap ends, case by case", caption,
                {"data": data, "layout": layout}, time_axis=False)
