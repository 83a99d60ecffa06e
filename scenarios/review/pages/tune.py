"""The page of a `dynprop tune` directory (RUN_DIR/tune/): the tuned process noise
with its σ and status, the scenario's noise and the tuned noise compared (NIS,
whiteness, σ_yaw), the optimizer, then tune.md (docs/outputs.md, "Tune"; what
each figure means: docs/tune.md).
"""

from __future__ import annotations

from .. import page_parts
from .. import traces as tr
from ..cells import Table, cell, text
from ..page_parts import finite, points_figure, record_table, verdict
from ..render import Page, Section
from ..run_figures import Plot
from ..source import Source

TUNE = "tune.json"
FIELDS = ("status", "value", "sigma", "sigma_ln", "limit_95", "limit_side", "start", "applied",
          "scenario_allowed", "tied")
OWN = ("estimated", "before", "after", "tuned_process_noise", "scenario_process_noise")
KINDS = ("roll", "yaw", "h")


def verdicts(t: dict) -> list:
    """The optimizer's convergence (``optimizer.converged``) and, for the scenario's
    noise and the tuned noise, every kind's mean NIS inside its χ² 95% bounds
    (``before``/``after`` ``nis.<kind>.inside``)."""
    opt = t.get("optimizer") or {}
    out = [verdict("Optimizer", opt.get("converged"), [
        text("maximum likelihood found: converged "),
        cell(opt.get("converged"), TUNE, "optimizer.converged"), text(" after "),
        cell(opt.get("iterations"), TUNE, "optimizer.iterations"), text(" iterations; ln L "),
        cell((t.get("loglik") or {}).get("start"), TUNE, "loglik.start"), text(" → "),
        cell((t.get("loglik") or {}).get("tuned"), TUNE, "loglik.tuned")])]
    for side, label in (("after", "NIS, tuned noise"), ("before", "NIS, scenario's noise")):
        nis = (t.get(side) or {}).get("nis") or {}
        flags = [nis[k].get("inside") for k in KINDS if k in nis]
        ok = None if not flags or any(f is None for f in flags) else all(flags)
        parts = [text("mean NIS of each kind of update inside its χ²₁ 95% bounds: ")]
        for m, k in enumerate(k for k in KINDS if k in nis):
            n, key = nis[k], f"{side}.nis.{k}"
            b = n.get("bounds") or [None, None]
            parts += [text(f"{'; ' if m else ''}{k} "), cell(n.get("mean"), TUNE, f"{key}.mean",
                                                             css="" if n.get("inside")
                                                             else "failed"),
                      text(" in ["), cell(b[0], TUNE, f"{key}.bounds[0]"), text(", "),
                      cell(b[1], TUNE, f"{key}.bounds[1]"), text("]")]
        out.append(verdict(label, ok, parts))
    return out


def estimated_table(t: dict) -> Table:
    rows = []
    for name, e in (t.get("estimated") or {}).items():
        k = f"estimated.{name}"
        row = [text(name)]
        for f in FIELDS:
            css = "failed" if f == "status" and e.get(f) == "not determined" else ""
            row.append(cell(e.get(f), TUNE, f"{k}.{f}", css=css) if f in e else text("—"))
        b = e.get("bounds") or [None, None]
        row += [cell(b[0], TUNE, f"{k}.bounds[0]"), cell(b[1], TUNE, f"{k}.bounds[1]")]
        rows.append(row)
    cols = ["parameter", "status", "estimate", "1σ", "1σ of ln θ", "95% limit", "side",
            "scenario", "applied", "scenario allowed", "tied", "bound low", "bound high"]
    return Table("tune-estimated", cols, rows, "The tuned process noise (tune.json estimated; "
                 "units (N m)² s for q_x, q_z, q_w, (N m)²/s for q_px … q_cz)")


def before_after_table(t: dict) -> Table:
    """Every figure of ``before`` beside the same key of ``after``."""
    rows = page_parts.before_after_rows(t.get("before") or {}, t.get("after") or {}, TUNE)
    return Table("tune-before-after", ["", "scenario's noise", "tuned noise", "unit"], rows,
                 "The filter with the scenario's noise and with the tuned noise (tune.json "
                 "before, after)")


def noise_table(t: dict) -> Table:
    scen, tuned = t.get("scenario_process_noise") or {}, t.get("tuned_process_noise") or {}
    rows = []
    for k in list(scen) + [k for k in tuned if k not in scen]:
        a, b = scen.get(k), tuned.get(k)
        rows.append([text(k), cell(a, TUNE, f"scenario_process_noise.{k}") if k in scen
                     else text("—"),
                     cell(b, TUNE, f"tuned_process_noise.{k}") if k in tuned else text("—"),
                     cell(b / a if finite(a) and finite(b) and a else None)])
    return Table("tune-noise", ["key", "scenario", "tuned (--tuned-from)", "ratio (here)"], rows,
                 "estimator.process_noise, the scenario's and as the filter is given it")


def noise_figure(t: dict) -> Plot:
    """Per parameter on a log scale: the scenario's value, the value applied, the
    estimate ±1σ where determined, and the 95% limit where one rules the
    scenario's value out."""
    est = t.get("estimated") or {}
    names = list(est)
    groups = [{"panel": 0, "name": "scenario", "x": names, "y": [est[n].get("start")
                                                                for n in names],
               "err": None, "color": tr.COLORS["sigma"], "symbol": "circle-open", "size": 12},
              {"panel": 0, "name": "applied (tuned)", "x": names,
               "y": [est[n].get("applied") for n in names], "err": None,
               "color": tr.COLORS["linear"], "symbol": "diamond", "size": 9}]
    det = [n for n in names if finite(est[n].get("value")) and finite(est[n].get("sigma"))]
    if det:
        v = [est[n]["value"] for n in det]
        s = [est[n]["sigma"] for n in det]
        # A log axis has no place for value − σ ≤ 0: the bar stops just above zero.
        groups.append({"panel": 0, "name": "estimate ±1σ", "x": det, "y": v, "err": s,
                       "err_minus": [min(a, 0.999 * b) for a, b in zip(s, v, strict=True)],
                       "color": tr.COLORS["real"], "size": 7})
    for side, symbol in (("upper", "triangle-down"), ("lower", "triangle-up")):
        lim = [n for n in names if est[n].get("limit_side") == side
               and finite(est[n].get("limit_95"))]
        if lim:
            groups.append({"panel": 0, "name": f"95% {side} limit", "x": lim,
                           "y": [est[n]["limit_95"] for n in lim], "err": None,
                           "color": tr.COLORS["paper"], "symbol": symbol, "size": 10})
    fig = points_figure(groups, [{"title": "process noise (log)", "x_title": "parameter"}],
                        height=380, log=(0,))
    caption = ("The scenario's value (open circle), the value the tuned filter is given "
               "(diamond), the maximum-likelihood estimate ±1σ where determined, and the "
               "one-sided 95% limit (triangles) where the likelihood rules the scenario's value "
               "out. Units (N m)² s for q_x, q_z, q_w; (N m)²/s for the torque states.")
    return Plot("tune-noise", "Process noise: scenario and tuned", caption, fig,
                time_axis=False)


def check_figure(t: dict) -> Plot:
    """Mean NIS per kind before and after with its bounds; σ_yaw of the periodic
    covariance before and after against the paper's 0.040°."""
    groups = []
    for side, name, color in (("before", "scenario's noise", tr.COLORS["sigma"]),
                              ("after", "tuned noise", tr.COLORS["real"])):
        nis = (t.get(side) or {}).get("nis") or {}
        kinds = [k for k in KINDS if k in nis]
        groups.append({"panel": 0, "name": name, "x": kinds,
                       "y": [nis[k].get("mean") for k in kinds], "err": None, "color": color,
                       "group": side})
        sy = (t.get(side) or {}).get("sigma_yaw_deg") or {}
        groups.append({"panel": 1, "name": name, "x": list(sy), "y": list(sy.values()),
                       "err": None, "color": color, "group": side, "show": False})
    nis = (t.get("after") or {}).get("nis") or {}
    kinds = [k for k in KINDS if k in nis and nis[k].get("bounds")]
    if kinds:
        b = [nis[k]["bounds"] for k in kinds]
        groups.append({"panel": 0, "name": "χ²₁ 95% bounds", "x": kinds,
                       "y": [(lo + hi) / 2 for lo, hi in b], "err": [(hi - lo) / 2 for lo, hi in b],
                       "color": tr.COLORS["paper"], "symbol": "line-ew", "size": 14})
    fig = points_figure(groups, [{"title": "mean NIS", "x_title": "update"},
                                 {"title": "σ_yaw (°)", "x_title": "periodic covariance"}])
    paper = t.get("paper_sigma_yaw_deg")
    if finite(paper):
        fig["layout"]["shapes"] = [{"type": "line", "xref": "x2 domain", "x0": 0, "x1": 1,
                                    "yref": "y2", "y0": paper, "y1": paper,
                                    "line": {"color": tr.COLORS["paper"], "dash": "dot"}}]
    caption = ("Left: the mean NIS of each kind of update with the scenario's noise and the "
               "tuned noise, red its χ²₁ 95% bounds for that many updates. Right: σ_yaw of "
               "the periodic covariance (Eq. 55, at the gap end, its largest), red dotted "
               f"the paper's {paper}° (Eq. 56).")
    return Plot("tune-check", "The scenario's noise against the tuned noise", caption, fig,
                time_axis=False)


def build(src: Source, command: str | None, requirement_deg: float | None = None) -> Page:
    t = src.record
    tel = t.get("telemetry") or {}
    intro = ("The process noise that maximizes the likelihood of the filter's innovations "
             "over the telemetry, and the filter with it (docs/tune.md).")
    sections = [Section("verdict", "Verdict", intro, verdicts(t), [estimated_table(t)])]
    sections.append(Section("figures", "Figures", plots=[noise_figure(t), check_figure(t)]))
    tables = [before_after_table(t), noise_table(t),
              record_table("tune-record", t, TUNE, "tune.json, the rest: the telemetry, the "
                           "method, the likelihood and the optimizer", skip=OWN)]
    sections.append(Section("tables", "Tables", tables=tables))
    sections += page_parts.as_written(src, "tune.md")
    return page_parts.page(src, command, "tune", f"{t.get('scenario')}: dynprop tune",
                           f"{tel.get('span_h')} h of {tel.get('file')}; "
                           f"{t.get('command') or ''}",
                           sections, page_parts.run_dir_of(src, tel.get("run_dir")))
