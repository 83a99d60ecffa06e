"""The interactive figures of a `run` or `estimate` page, from comparison.npz (the
arrays the PNG figures are drawn from), summary.json and daily.csv.

Every time figure has one x axis under its stacked panels, and the page links the
x axes of all of them (render's script), so zooming one zooms all: the error
panels, consistency, torques and telemetry stay on the same span.  Sun gaps,
shorter yaw outages, telemetry gaps and eclipses are shaded behind every panel, in
the PNG figures' colours (``figures.marks``).  The arrays come cut at the
telemetry gaps (``figures.marks.Cut``): nothing is drawn across one.  Screened
values are ticked at the top of the error panels.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from dynprop.estimator.linear import model as em

from ..figures.marks import Cut
from . import events as ev
from . import traces as tr

# comparison.npz's columns: the model's state indices (estimator.linear.model), as
# figures.run's COLUMNS.
STATE = {"roll": em.R, "yaw": em.Y, "h": em.H_WHEEL, "N_px": em.NPX, "N_pz": em.NPZ,
         "N_cx": em.NCX, "N_cz": em.NCZ}
UNITS = {"roll": "deg", "yaw": "deg", "h": "N m s"}
TORQUES = ("N_px", "N_pz", "N_cx", "N_cz")
TORQUE_MEANING = {"N_px": "periodic roll (x)", "N_pz": "periodic yaw (z)",
                  "N_cx": "constant roll (x)", "N_cz": "constant yaw (z)"}


@dataclass(frozen=True)
class Plot:
    id: str
    title: str
    caption: str
    figure: dict
    time_axis: bool = True


@dataclass(frozen=True)
class Axis:
    """The run's time axis: rows in axis units and the shading behind every panel."""
    x: np.ndarray
    title: str
    shapes: list
    legend: list
    scale: float                  # seconds per axis unit
    range: tuple[float, float]    # the run's span, in axis units


# The filter's start-up, left out of the initial y scales: its prior σ would
# flatten everything after it (the autoscale button shows it).
STARTUP_S = 3600.0

def time_axis(c: Cut, summary: dict, duration_s: float, eclipse: list[tuple[float, float]],
              min_gap_h: float, events=()) -> Axis:
    """Rows in hours (days beyond three days); shading for the Sun gaps summary.json
    lists, the shorter yaw outages (runs of three days or less: beyond, a year's 700
    noon outages would bury the gaps), the telemetry gaps and the eclipses
    (truth.csv's ``eclipse``, in seconds); and the scheduled ``events``
    (``review.events``: summary.json's, in the rows' seconds), when any."""
    scale, unit = tr.time_unit(duration_s)
    x = c["t_s"] / scale
    gaps = [(a * 3600 / scale, b * 3600 / scale) for a, b in summary.get("sun_gaps_h") or []]
    shapes = tr.shades(gaps, "sun_gap")
    legend = [tr.legend_only(f"Sun gap (≥ {min_gap_h:g} h without yaw)",
                             tr.SHADES["sun_gap"])] if gaps else []
    if duration_s <= 3 * 86400.0 and "yaw_present" in c:
        # Judged on every row, then cut: an outage running through a telemetry gap is one.
        short = [s for s in tr.spans(x, c.rows(c.source["yaw_present"] < 0.5))
                 if (s[1] - s[0]) * scale < min_gap_h * 3600]
        shapes += tr.shades(short, "outage")
        if short:
            legend.append(tr.legend_only("shorter yaw outage (noon, dropouts)",
                                         tr.SHADES["outage"]))
    holes = [(a / scale, b / scale) for a, b in c.gaps_s]
    shapes += tr.shades(holes, "telemetry_gap")
    if holes:
        legend.append(tr.legend_only("telemetry gap (no rows: nothing drawn across it)",
                                     tr.SHADES["telemetry_gap"]))
    ecl = [(a / scale, b / scale) for a, b in eclipse]
    shapes += tr.shades(ecl, "eclipse")
    if ecl:
        legend.append(tr.legend_only("eclipse", tr.SHADES["eclipse"]))
    shapes += ev.shapes(events, scale)
    legend += ev.legend(events)
    return Axis(x, f"time since epoch ({unit})", shapes, legend, scale,
                (float(x[0]), float(x[-1])) if len(x) else (0.0, 1.0))


def _layout(panels: list[dict], ax: Axis, per_panel: int = 210, shapes=None) -> dict:
    return tr.stacked_layout(panels, ax.title, per_panel,
                             list(ax.shapes) if shapes is None else shapes, ax.range)


def _range(ax: Axis, *values):
    return tr.robust_range(list(values), ax.x, STARTUP_S, ax.scale)


def _extremes(c: dict, key: str, col: int) -> tuple:
    lo, hi = c.get(f"{key}_min"), c.get(f"{key}_max")
    if lo is None or hi is None:
        return None, None
    return lo[:, col], hi[:, col]


def errors(c: dict, ax: Axis, eq55_deg: float | None) -> Plot:
    """Yaw, roll and h errors with the filter's ±3σ (the linearized error and the EKF
    beside them when the run has them), the pitch filter's error, then real −
    linearized on its own scale."""
    if "err_real" not in c:
        return estimates(c, ax)
    data, panels, shapes = list(ax.legend), [], list(ax.shapes)
    for n in ("yaw", "roll", "h"):
        if not np.isfinite(c["err_real"][:, STATE[n]]).any():
            continue    # a truth without that state (an AEM: the attitude only)
        y, col, first = tr.axis(len(panels)), STATE[n], not panels
        panels.append({"title": f"{n} error ({UNITS[n]})", "range": _range(
            ax, 3 * c["sigma"][:, col], c["err_real"][:, col],
            *(c[k][:, col] for k in ("err_linear", "err_ekf") if k in c))})
        data += tr.sigma_band(ax.x, c["sigma"][:, col], y, group="sigma", show=first)
        # The EKF, then the linearized error, under the real one: the real error is
        # what the page is about, and the others differ from it by little.
        if "err_ekf" in c:
            data += tr.series(ax.x, c["err_ekf"][:, col], "EKF error", tr.COLORS["ekf"], y,
                              group="ekf", show=first, outline=True)
            if "sigma_ekf" in c:
                data += tr.sigma_band(ax.x, c["sigma_ekf"][:, col], y, "EKF ±3σ",
                                      tr.COLORS["ekf"], "dot", group="ekf_sigma", show=first)
        if "err_linear" in c:
            data += tr.series(ax.x, c["err_linear"][:, col], "linearized error (linear twin)",
                              tr.COLORS["linear"], y, group="linear", show=first, outline=True)
        lo, hi = _extremes(c, "err_real", col)
        data += tr.series(ax.x, c["err_real"][:, col], "real error (filter on the truth)",
                          tr.COLORS["real"], y, lo, hi, group="real", show=first)
        if n == "yaw" and eq55_deg is not None:
            shapes += [tr.hline(s * 3 * eq55_deg, y, tr.COLORS["paper"]) for s in (1, -1)]
    if "err_pitch" in c:
        # The pitch filter's (Eq. 3b): a filter of its own, no twin or EKF beside it.
        y = tr.axis(len(panels))
        panels.append({"title": "pitch error (deg)", "range": _range(
            ax, 3 * c["sigma_pitch"][:, 0], c["err_pitch"][:, 0])})
        data += tr.sigma_band(ax.x, c["sigma_pitch"][:, 0], y, group="sigma", show=False)
        lo, hi = _extremes(c, "err_pitch", 0)
        data += tr.series(ax.x, c["err_pitch"][:, 0], "real error (filter on the truth)",
                          tr.COLORS["real"], y, lo, hi, group="real", show=False)
    if "err_real_minus_linear" in c:
        y = tr.axis(len(panels))
        panels.append({"title": "real − linearized (deg)"})
        for j, n, color in ((1, "yaw", tr.COLORS["teal"]), (0, "roll", tr.COLORS["smoothed"])):
            lo, hi = _extremes(c, "err_real_minus_linear", j)
            data += tr.series(ax.x, c["err_real_minus_linear"][:, j],
                              f"{n}: real − linearized", color, y, lo, hi)
    layout = _layout(panels, ax, shapes=shapes)
    data += _screened(c, ax, layout, sum(1 for p in panels if "real −" not in p["title"]))
    caption = ("Estimate − truth with the filter's ±3σ; the linearized error is the same "
               "filter on the linear model's telemetry, against the linear model. "
               + ("Pitch is its own 3-state filter's (Eq. 3b). " if "err_pitch" in c else "")
               + (f"Red dotted: ±3σ_yaw of Eq. 55 ({eq55_deg:.4f}°). " if eq55_deg else "")
               + "The first hour (the filter's start-up) is left out of the initial scales. "
               "Drag to zoom (every time figure follows), double-click to reset.")
    return Plot("errors", "Errors against the truth", caption, {"data": data, "layout": layout})


def estimates(c: dict, ax: Axis) -> Plot:
    """No truth (`estimate` without --truth): the estimates with their ±3σ."""
    data, panels = list(ax.legend), []
    for i, n in enumerate(("yaw", "roll", "h")):
        y, col = tr.axis(i), STATE[n]
        est, s = c["x_real"][:, col], 3 * c["sigma"][:, col]
        panels.append({"title": f"{n} ({UNITS[n]})", "range": _range(ax, est + s, est - s)})
        data += tr.series(ax.x, est + s, "estimate ± 3σ", tr.COLORS["sigma"], y,
                          group="sig", show=i == 0, outline=True)
        data += tr.series(ax.x, est - s, "estimate ± 3σ", tr.COLORS["sigma"], y,
                          group="sig", show=False, outline=True)
        data += tr.series(ax.x, est, "estimate", tr.COLORS["real"], y, group="est",
                          show=i == 0)
    layout = _layout(panels, ax)
    data += _screened(c, ax, layout, len(panels))
    return Plot("errors", "Estimates (no truth)", "The filter's estimates and their ±3σ.",
                {"data": data, "layout": layout})


def _screened(c, ax: Axis, layout: dict, n_panels: int) -> list[dict]:
    """Ticks at the top of each of the first ``n_panels`` panels at the times of the
    screened values (comparison.npz's ``screened_t_s``; none when absent): on a
    hidden 0–1 axis over each panel, added to ``layout``.  Beyond ``MAX_POINTS``
    the times are rounded to the page's resolution first."""
    t = np.asarray(c.get("screened_t_s", []), dtype=float) / ax.scale
    t = t[np.isfinite(t)]
    if not t.size or not n_panels:
        return []
    if t.size > tr.MAX_POINTS:
        res = (ax.range[1] - ax.range[0]) / tr.MAX_POINTS or 1.0
        t = np.unique(np.round(t / res)) * res
    first = sum(1 for k in layout if k.startswith("yaxis")) + 1
    color = tr.SHADES["screened"]
    out = []
    for k in range(n_panels):
        key = first + k
        layout[f"yaxis{key}"] = {"overlaying": tr.axis(k), "anchor": "x", "range": [0, 1],
                                 "visible": False, "fixedrange": True}
        out.append({"type": "scatter", "mode": "markers", "name": "screened value (a dropout)",
                    "x": tr.typed(t), "y": tr.typed(np.full(t.size, 0.97)),
                    "yaxis": f"y{key}", "legendgroup": "screened", "showlegend": k == 0,
                    "marker": {"symbol": "line-ns-open", "size": 10, "color": color,
                               "line": {"width": 1.5, "color": color}},
                    "hovertemplate": "screened value<extra></extra>"})
    return out


def consistency(c: dict, ax: Axis, summary: dict) -> Plot | None:
    """NEES (every 10th sample) with χ²(9)'s 95% per-sample band, NIS of each update
    with χ²(1)'s."""
    if "nis_real" not in c:
        return None
    data, panels, shapes = list(ax.legend), [], list(ax.shapes)
    nees_b = summary.get("nees_bounds_95_per_sample")
    nis_b = summary.get("nis_bounds_95_per_sample")
    # An attitude-only truth (an AEM) gives no NEES: all NaN, no panel.
    if "nees_real" in c and np.isfinite(c["nees_real"]).any():
        panels.append({"title": "NEES (9 states)"})
        # The linearized NEES first, as outlines: the real one over it is the verdict.
        for key, name, color in (("linear", "NEES, linearized", tr.COLORS["linear"]),
                                 ("real", "NEES, real", tr.COLORS["real"])):
            if f"nees_{key}" not in c:
                continue
            v = c[f"nees_{key}"]
            ok = np.isfinite(v) | np.isnan(ax.x)   # its samples, and the breaks between
            hi = c.get(f"nees_{key}_max")
            data += tr.series(ax.x[ok], v[ok], name, color, "y",
                              None if hi is None else v[ok], None if hi is None else hi[ok],
                              outline=key == "linear")
        if nees_b:
            shapes += [tr.hline(b, "y", tr.COLORS["paper"], "dash") for b in nees_b]
    base = len(panels)
    for j, m in enumerate(("roll", "yaw", "h")):
        v = c["nis_real"][:, j]
        if not np.isfinite(v).any():
            continue
        ok = np.isfinite(v) | np.isnan(ax.x)   # binned, a band: the breaks cut it
        y = tr.axis(len(panels))
        panels.append({"title": f"NIS {m}"})
        data += tr.series(ax.x[ok], v[ok], f"NIS {m}", tr.COLORS["real"], y,
                          group="nis", show=len(panels) == base + 1, mode="markers")
        if nis_b:
            shapes += [tr.hline(b, y, tr.COLORS["paper"], "dash") for b in nis_b]
    if not panels:
        return None
    layout = _layout(panels, ax, 190, shapes)
    for i, k in enumerate(sorted((k for k in layout if k.startswith("yaxis")),
                                 key=lambda k: int(k[5:] or 1))):
        # Decades only (minor labels crowd), over what the bounds are about: an
        # update's NIS reaches 1e-12 where its residual is tiny; autoscale shows it.
        nees = i == 0 and "nees_real" in c
        layout[k].update(type="log", dtick=1, range=[-2, 2] if nees else [-5, 1.5])
    caption = ("Normalized estimation error squared (every 10th sample) and normalized "
               "innovation squared per update, on log scales; red dashed: the χ² 2.5% and "
               "97.5% points for one sample (9 and 1 degrees of freedom).")
    return Plot("consistency", "Consistency: NEES and NIS", caption,
                {"data": data, "layout": layout})


def torques(c: dict, ax: Axis) -> Plot:
    data, panels = list(ax.legend), []
    for i, n in enumerate(TORQUES):
        y, col = tr.axis(i), STATE[n]
        s = 3 * c["sigma"][:, col]
        truth = c["truth_model"][:, col] if "truth_model" in c else None
        panels.append({"title": f"{n} (N m)", "range": _range(
            ax, c["x_real"][:, col] + s, c["x_real"][:, col] - s, truth)})
        data += tr.series(ax.x, c["x_real"][:, col], "estimate", tr.COLORS["real"], y,
                          group="est", show=i == 0)
        data += tr.series(ax.x, c["x_real"][:, col] + s, "estimate ± 3σ", tr.COLORS["sigma"],
                          y, group="sig", show=i == 0)
        data += tr.series(ax.x, c["x_real"][:, col] - s, "estimate ± 3σ", tr.COLORS["sigma"],
                          y, group="sig", show=False)
        if "truth_model" in c:
            data += tr.series(ax.x, c["truth_model"][:, col], "truth (model coordinates)",
                              tr.COLORS["truth"], y, group="truth", show=i == 0)
    caption = ("The torque states (Eq. 34): " + ", ".join(f"{k} {v}" for k, v in
                                                          TORQUE_MEANING.items())
               + "; the truth's torques expressed in the filter's coordinates.")
    return Plot("torques", "Torques: estimates against the truth", caption,
                {"data": data, "layout": _layout(panels, ax, 170)})


def telemetry(c: dict, ax: Axis) -> Plot | None:
    if "tel_yaw_deg" not in c:
        return None
    data, panels = list(ax.legend), []
    truth = c.get("true_euler_deg")
    for i, (n, col) in enumerate((("roll", 1), ("pitch", 2), ("yaw", 0))):
        y = tr.axis(i)
        panels.append({"title": f"{n} (deg)"})
        data += tr.series(ax.x, c[f"tel_{n}_deg"], "measured", tr.COLORS["real"], y,
                          group="meas", show=i == 0, mode="markers")
        if truth is not None:
            data += tr.series(ax.x, truth[:, col], "truth", tr.COLORS["truth"], y,
                              group="truth", show=i == 0)
    wheels = sorted(k for k in c if k.startswith("tel_wheel") and k.endswith("_rpm"))
    if wheels:
        y = tr.axis(len(panels))
        panels.append({"title": "wheel speed (rpm)"})
        for k, color in zip(wheels, (tr.COLORS["real"], tr.COLORS["linear"],
                                     tr.COLORS["ekf"], tr.COLORS["smoothed"]), strict=False):
            data += tr.series(ax.x, c[k], k[4:-4], color, y)
    caption = ("The telemetry at the stored rows: Earth-sensor roll and pitch, the ground "
               "yaw from the Sun sensors (absent in the gaps) and the tachometers.")
    return Plot("telemetry", "Telemetry overview", caption,
                {"data": data, "layout": _layout(panels, ax, 170)})


def season(daily: dict, events=(), t0_s: float = 0.0) -> Plot | None:
    """A long run's days (daily.csv): the gap-end yaw error with the filter's ±3σ and
    Eq. 55's, the daily yaw RMS real and linearized, and the eclipse minutes; the
    scheduled ``events`` marked (day k holds t in [t0_s + k, t0_s + k + 1) days, drawn
    over k ± 0.5: an event falls inside its own day's width)."""
    day = np.asarray(daily.get("day", []), dtype=float)
    if len(day) < 3:
        return None
    data, panels = ev.legend(events), []
    panels.append({"title": "gap-end yaw error (deg)"})
    e, s = daily["gap_end_yaw_error_deg"], daily["gap_end_yaw_sigma_deg"]
    data.append(tr.line(day, e, "gap-end yaw error", tr.COLORS["real"], mode="markers"))
    data += tr.sigma_band(day, s, "y")
    data += tr.sigma_band(day, daily["eq55_sigma_yaw_deg"], "y", "±3σ_yaw, Eq. 55",
                          tr.COLORS["paper"], "dot")
    panels.append({"title": "daily yaw RMS (deg)"})
    data.append(tr.line(day, daily["yaw_error_rms_deg"], "yaw RMS, real", tr.COLORS["real"],
                        "y2"))
    if "yaw_error_rms_linear_deg" in daily:
        data.append(tr.line(day, daily["yaw_error_rms_linear_deg"], "yaw RMS, linearized",
                            tr.COLORS["linear"], "y2", dash="dash"))
    panels.append({"title": "eclipse (min)"})
    data.append(tr.line(day, daily["eclipse_min"], "eclipse minutes", tr.COLORS["truth"],
                        "y3"))
    caption = "One point per day of the run (daily.csv, every figure at the full sample rate)."
    return Plot("season", "The run's days", caption,
                {"data": data, "layout": tr.stacked_layout(
                    panels, "day of the run", 200, ev.shapes(events, 86400.0, t0_s + 43200.0),
                    x_range=(day[0] - 0.5, day[-1] + 0.5))},
                time_axis=False)
