"""The page of a linearization report (`dynprop linearization`): report.json's
verdict, the coefficients against the paper, the sweep of initial errors, the
error budget at the Sun-gap end, and report.md itself (docs/outputs.md,
"Linearization report"; report.md explains each table).

report.json: ``meta`` (the run), ``coefficients`` (``rows``: the Jacobian against
Eqs. 3 and 7; ``inputs``, ``omitted``, ``model_matrix``, ``eigenfrequencies``),
``sweep`` (``cases``: each initial error's ``divergence`` of Eq. 11 and the exact
Jacobian from the nonlinear truth, and the filter's ``estimation``;
``thresholds``, ``threshold_crossings``), ``budget`` (per effect its yaw at the
gap end, ``initial`` and ``plus_1deg``) and ``verdict`` (a paragraph).
"""

from __future__ import annotations

from .. import traces as tr
from ..cells import Table, cell, text
from ..page_parts import as_written, page, record_table, run_scale, verdict
from ..render import Page, Section
from ..run_figures import Plot
from ..source import Source

REPORT = "report.json"
COEFF = ("jacobian", "eq3", "rel_jacobian_vs_eq3", "eq7", "rel_eq7_vs_jacobian", "rel_eq5_only",
         "rel_eq6_only", "rel_products")
DIVERGENCE = ("max_roll_deg", "max_yaw_deg", "max_h_Nms", "gap_yaw_deg")
BUDGET = ("dynamics_deg", "torque_model_deg", "dynamics_roll_deg", "torque_model_roll_deg")
SCALAR_NAMES = {"yaw_rms_real_deg": "yaw RMS, real (°)", "yaw_rms_linear_deg": "linearized (°)",
                "nees_mean_real": "NEES, real", "nees_mean_linear": "linearized",
                "nees_inside_95_real": "NEES inside 95%, real",
                "nees_inside_95_linear": "linearized",
                "within_3sigma_at_gap_ends": "real within 3σ", "nees_verdict_real":
                "NEES verdict, real", "nees_verdict_linear": "linearized",
                "nees_mean_ekf": "NEES, EKF", "ekf_within_3sigma_at_gap_ends": "EKF within 3σ",
                "nees_verdict_ekf": "NEES verdict, EKF"}
# report.json's NEES verdicts: a mean inside the χ² bounds is the only pass.
NEES_PASS = {"not rejected": True, "conservative": False, "overconfident": False}


def _nominal(report: dict) -> tuple[int, dict] | None:
    """The sweep's case at the scenario's own state (kind "none", δ = 0)."""
    for i, c in enumerate((report.get("sweep") or {}).get("cases") or []):
        if c.get("kind") == "none":
            return i, c
    return None


def verdicts(report: dict) -> list:
    """The filter at the scenario's own state, as report.json judged it: its gap-end
    yaw within 3σ (and the EKF's), its NEES not rejected."""
    nominal = _nominal(report)
    if nominal is None:
        why = [text("not tested: report.json's sweep has no case at the scenario's state")]
        return [verdict("Filter σ", None, why), verdict("NEES", None, why)]
    i, c = nominal
    est, k = c.get("estimation") or {}, f"sweep.cases[{i}].estimation"
    out = []
    for label, flag, err, sig in (
            ("Filter σ", "within_3sigma_at_gap_ends", "yaw_error_gap_end_real_deg",
             "yaw_sigma_gap_end_deg"),
            ("EKF σ", "ekf_within_3sigma_at_gap_ends", "yaw_error_gap_end_ekf_deg",
             "yaw_sigma_gap_end_ekf_deg")):
        if flag not in est and label == "EKF σ":
            continue
        parts = [text("at the scenario's own state (δ = 0), every gap-end yaw error within "
                      "±3σ: ")]
        for j, (e, s) in enumerate(zip(est.get(err) or [], est.get(sig) or [], strict=False)):
            parts += [text(f"{'; ' if j else ''}gap {j + 1} "), cell(e, REPORT, f"{k}.{err}[{j}]",
                                                                      "°"),
                      text(" against σ "), cell(s, REPORT, f"{k}.{sig}[{j}]", "°")]
        out.append(verdict(label, est.get(flag), parts))
    nv = est.get("nees_verdict_real")
    out.append(verdict("NEES", NEES_PASS.get(nv), [
        text("mean NEES over the run's second half at the scenario's state "),
        cell(est.get("nees_mean_real"), REPORT, f"{k}.nees_mean_real"), text(": "),
        cell(nv, REPORT, f"{k}.nees_verdict_real")]))
    return out


def coefficient_table(report: dict) -> Table:
    rows = [[cell(r.get("coefficient"), REPORT, f"coefficients.rows[{i}].coefficient"),
             cell(r.get("equation"), REPORT, f"coefficients.rows[{i}].equation")]
            + [cell(r.get(f), REPORT, f"coefficients.rows[{i}].{f}") for f in COEFF]
            for i, r in enumerate((report.get("coefficients") or {}).get("rows") or [])]
    return Table("lin-coefficients", ["coefficient", "Eq.", "Jacobian", "Eq. 3", "rel. Jac−Eq. 3",
                                      "Eq. 7/11c", "rel. Eq. 7−Jac", "Eq. 5 only", "Eq. 6 only",
                                      "products ±30"], rows,
                 "The Jacobian of the nonlinear model against Eqs. 3 and 7 (SI; the last "
                 "three columns apply one approximation at a time)")


def eigen_table(report: dict) -> Table:
    eig = (report.get("coefficients") or {}).get("eigenfrequencies") or {}
    f = ("omega_slow_radps", "rel_slow", "omega_fast_radps", "rel_fast")
    rows = [[text(name)] + [cell(v.get(x), REPORT, f"coefficients.eigenfrequencies.{name}.{x}")
                            for x in f] for name, v in eig.items()]
    return Table("lin-eigen", ["model", "ω slow (rad/s)", "rel.", "ω fast (rad/s)", "rel."], rows,
                 "Eigenfrequencies of the roll/yaw block, relative to the Jacobian's")


def matrix_table(report: dict) -> Table:
    m = (report.get("coefficients") or {}).get("model_matrix") or {}
    jac, eq11 = m.get("jacobian") or [], m.get("eq11") or []
    rows = [[text(str(i + 1))]
            + [cell(v, REPORT, f"coefficients.model_matrix.jacobian[{i}][{j}]")
               for j, v in enumerate(row)]
            + [cell(v, REPORT, f"coefficients.model_matrix.eq11[{i}][{j}]")
               for j, v in enumerate(eq11[i] if i < len(eq11) else [])]
            for i, row in enumerate(jac)]
    n = len(jac[0]) if jac else 0
    cols = ["row"] + [f"Jacobian [{j + 1}]" for j in range(n)] + [f"Eq. 11 [{j + 1}]"
                                                                  for j in range(n)]
    caption = "The model matrix (model units), Jacobian beside Eq. 11; largest relative " \
        f"difference {m.get('max_rel_difference', float('nan')):.3g} (in the table below)"
    return Table("lin-matrix", cols, rows, caption)


def divergence_table(report: dict) -> Table:
    rows = []
    for i, c in enumerate((report.get("sweep") or {}).get("cases") or []):
        k = f"sweep.cases[{i}]"
        row = [cell(c.get("kind"), REPORT, f"{k}.kind"), cell(c.get("delta_deg"), REPORT,
                                                             f"{k}.delta_deg")]
        for model in ("eq11", "jacobian"):
            d = (c.get("divergence") or {}).get(model) or {}
            row += [cell(d.get(f), REPORT, f"{k}.divergence.{model}.{f}") for f in DIVERGENCE]
        row.append(cell(c.get("overrides"), REPORT, f"{k}.overrides"))
        rows.append(row)
    cols = ["sweep", "δ (°)"] + [f"{m} {q}" for m in ("Eq. 11", "Jacobian")
                                 for q in ("max roll (°)", "max yaw (°)", "max h (N m s)",
                                           "gap yaw (°)")] + ["overrides (scenario key, value)"]
    return Table("lin-divergence", cols, rows, "Propagation: linear − nonlinear from the same "
                 "initial error, maximum over the run (sweep.cases[].divergence)")


def crossing_table(report: dict) -> Table:
    cross = (report.get("sweep") or {}).get("threshold_crossings") or []
    f = ("sweep", "axis", "threshold", "level_deg", "delta_star_deg")
    rows = [[cell(c.get(x), REPORT, f"sweep.threshold_crossings[{i}].{x}") for x in f]
            for i, c in enumerate(cross)]
    return Table("lin-crossings", ["sweep", "axis", "threshold", "level (°)", "δ* (°)"], rows,
                 "Initial error δ* at which Eq. 11's divergence first exceeds each threshold "
                 "(0: beyond it already at the smallest δ; none: not within the sweep)")


def estimation_table(report: dict, ekf: bool) -> Table:
    cases = (report.get("sweep") or {}).get("cases") or []
    n = max((len((c.get("estimation") or {}).get("yaw_sigma_gap_end_deg") or []) for c in cases),
            default=0)
    if ekf:
        lists = ("yaw_error_gap_end_real_deg", "yaw_error_gap_end_ekf_deg",
                 "yaw_sigma_gap_end_ekf_deg")
        scalars = ("nees_mean_ekf", "ekf_within_3sigma_at_gap_ends", "nees_verdict_ekf")
        names = ("paper error", "EKF error", "EKF σ")
    else:
        lists = ("yaw_error_gap_end_real_deg", "yaw_error_gap_end_linear_deg",
                 "yaw_sigma_gap_end_deg")
        scalars = ("yaw_rms_real_deg", "yaw_rms_linear_deg", "nees_mean_real",
                   "nees_mean_linear", "nees_inside_95_real", "nees_inside_95_linear",
                   "within_3sigma_at_gap_ends",
                   "nees_verdict_real", "nees_verdict_linear")
        names = ("error, real", "linearized", "filter σ")
    rows = []
    for i, c in enumerate(cases):
        e, k = c.get("estimation") or {}, f"sweep.cases[{i}].estimation"
        row = [cell(c.get("kind"), REPORT, f"sweep.cases[{i}].kind"),
               cell(c.get("delta_deg"), REPORT, f"sweep.cases[{i}].delta_deg")]
        for f in lists:
            v = e.get(f) or []
            row += [cell(v[j], REPORT, f"{k}.{f}[{j}]") if j < len(v) else text("—")
                    for j in range(n)]
        row += [cell(e[f], REPORT, f"{k}.{f}", css="failed" if e[f] is False else "")
                if f in e else text("—") for f in scalars]
        rows.append(row)
    cols = ["sweep", "δ (°)"] + [f"gap {j + 1} {m} (°)" for m in names for j in range(n)]
    cols += [SCALAR_NAMES.get(f, f) for f in scalars]
    caption = ("The paper's filter against the EKF on the same nonlinear telemetry"
               if ekf else "The filter on nonlinear (real) and linear-twin telemetry, case by "
               "case") + " (sweep.cases[].estimation)"
    return Table("lin-estimation-ekf" if ekf else "lin-estimation", cols, rows, caption)


def budget_table(report: dict) -> Table:
    b = report.get("budget") or {}
    columns = b.get("columns") or []
    rows = []
    for i, r in enumerate(b.get("rows") or []):
        row = [cell(r.get("label"), REPORT, f"budget.rows[{i}].label"),
               cell(r.get("in_scenario"), REPORT, f"budget.rows[{i}].in_scenario")]
        for col in columns:
            c = (r.get("contribution") or {}).get(col) or {}
            row += [cell(c.get(f), REPORT, f"budget.rows[{i}].contribution.{col}.{f}")
                    for f in BUDGET]
        row += [cell((r.get("H_ptp_Nms") or {}).get(col), REPORT,
                     f"budget.rows[{i}].H_ptp_Nms.{col}") for col in columns]
        row += [cell(r.get("key"), REPORT, f"budget.rows[{i}].key"),
                cell(r.get("changes"), REPORT, f"budget.rows[{i}].changes")]
        rows.append(row)
    for key, label in (("ideal", "ideal configuration (nonlinearity alone)"),
                       ("sum_in_scenario", "ideal + Σ rows in scenario"),
                       ("total", "total: the scenario as configured")):
        row = [text(label, "failed" if key == "total" else ""), text("")]
        for col in columns:
            c = (b.get(key) or {}).get(col) or {}
            row += [cell(c[f], REPORT, f"budget.{key}.{col}.{f}") if f in c else text("—")
                    for f in BUDGET]
        row += [cell(((b.get(key) or {}).get(col) or {})["H_ptp_Nms"], REPORT,
                     f"budget.{key}.{col}.H_ptp_Nms")
                if "H_ptp_Nms" in ((b.get(key) or {}).get(col) or {}) else text("—")
                for col in columns] + [text(""), text("")]
        rows.append(row)
    cols = ["effect", "in scenario"] + [f"{q}, {col}" for col in columns
                                        for q in ("yaw dynamics (°)", "yaw torque model (°)",
                                                  "roll dynamics (°)", "roll torque model (°)")]
    cols += [f"H p-p, {col} (N m s)" for col in columns] + ["key", "changes (scenario key, "
                                                               "value)"]
    return Table("lin-budget", cols, rows, "Error budget at the end of the first Sun gap: "
                 "each effect's yaw and roll error against the ideal configuration's (budget)")


def ideal_table(report: dict) -> Table:
    """The ideal configuration every budget row starts from, and the gap it spans."""
    b = report.get("budget") or {}
    rows = [[cell(o[0], REPORT, f"budget.ideal_overrides[{i}][0]"),
             cell(o[1], REPORT, f"budget.ideal_overrides[{i}][1]")]
            for i, o in enumerate(b.get("ideal_overrides") or [])]
    rows += [[text(f"gap_h[{j}] (the Sun gap, h)"), cell(v, REPORT, f"budget.gap_h[{j}]")]
             for j, v in enumerate(b.get("gap_h") or [])]
    rows += [[text(f"columns[{j}]"), cell(v, REPORT, f"budget.columns[{j}]")]
             for j, v in enumerate(b.get("columns") or [])]
    return Table("lin-ideal", ["scenario key", "value"], rows, "The ideal configuration "
                 "(budget.ideal_overrides: every assumption of Eq. 11 true), the gap and the "
                 "columns")


def budget_figure(report: dict) -> Plot | None:
    """Each effect's yaw error at the gap end, dynamics and torque model, at the
    scenario's initial state and with 1° added: which assumption matters."""
    b = report.get("budget") or {}
    rows = b.get("rows") or []
    if not rows:
        return None
    labels = [r["label"] + ("" if r.get("in_scenario") else " (not in scenario)") for r in rows]
    labels += ["ideal (nonlinearity alone)", "total: scenario as configured"]
    data, columns = [], b.get("columns") or []
    for p, col in enumerate(columns):
        for f, name, color in (("dynamics_deg", "dynamics", tr.COLORS["real"]),
                               ("torque_model_deg", "torque model", tr.COLORS["linear"])):
            x = [((r.get("contribution") or {}).get(col) or {}).get(f) for r in rows]
            x += [((b.get(k) or {}).get(col) or {}).get(f) for k in ("ideal", "total")]
            data.append({"type": "bar", "orientation": "h", "y": labels, "x": x,
                         "name": name, "legendgroup": name, "showlegend": p == 0,
                         "marker": {"color": color}, "xaxis": "x" if p == 0 else f"x{p + 1}",
                         "yaxis": "y", "hovertemplate": "%{x:.3g}°<extra>" + name + "</extra>"})
    n = len(columns)
    layout = {"height": 90 + 34 * len(labels), "barmode": "group", "template": "plotly_white",
              "margin": {"l": 330, "r": 20, "t": 40, "b": 50}, "hovermode": "closest",
              "legend": {"orientation": "h", "y": 1.02, "yanchor": "bottom"},
              "yaxis": {"autorange": "reversed", "automargin": True}}
    for p, col in enumerate(columns):
        key = "xaxis" if p == 0 else f"xaxis{p + 1}"
        layout[key] = {"domain": [p / n + (0.04 if p else 0), (p + 1) / n - 0.02],
                       "anchor": "y", "title": {"text": f"yaw at the gap end (°), {col}"},
                       "exponentformat": "power", "zeroline": True}
    caption = ("Eq. 11 restarted on the truth at the first Sun gap's start: each effect's "
               "yaw error at its end with the effect switched on in the ideal configuration, "
               "against that configuration (budget.rows[].contribution); left the scenario's "
               "initial state, right with 1° of roll and yaw error added.")
    return Plot("lin-budget", "Error budget at the Sun-gap end", caption,
                {"data": data, "layout": layout}, time_axis=False)


def sweep_figure(report: dict) -> Plot | None:
    """Against the initial error δ (log–log): Eq. 11's and the Jacobian's largest
    divergence from the nonlinear truth, with the thresholds; below, the filter's
    worst gap-end |error|/σ, real, linearized and EKF, with 3."""
    sweep = report.get("sweep") or {}
    kinds = [k for k in ("attitude", "rate") if any(c.get("kind") == k
                                                    for c in sweep.get("cases") or [])]
    if not kinds:
        return None
    th = sweep.get("thresholds") or {}
    data, shapes, layout = [], [], {}
    for p, kind in enumerate(kinds):
        cases = [c for c in sweep["cases"] if c.get("kind") == kind]
        d = [c["delta_deg"] for c in cases]
        xa, ya, yb = f"x{p + 1 if p else ''}", f"y{2 * p + 1 if p else ''}", f"y{2 * p + 2}"
        for model, dash in (("eq11", None), ("jacobian", "dash")):
            for q, color in (("max_yaw_deg", tr.COLORS["real"]), ("max_roll_deg",
                                                                  tr.COLORS["smoothed"])):
                name = f"{'Eq. 11' if model == 'eq11' else 'Jacobian'}, {q.split('_')[1]}"
                y = [c["divergence"][model][q] for c in cases]
                data.append(_xy(d, y, name, color, xa, ya, dash, p == 0))
        for q, name, color in (("yaw_error_gap_end_real_deg", "filter, real", tr.COLORS["real"]),
                               ("yaw_error_gap_end_linear_deg", "filter, linear twin",
                                tr.COLORS["linear"]),
                               ("yaw_error_gap_end_ekf_deg", "EKF", tr.COLORS["ekf"])):
            sig = "yaw_sigma_gap_end_ekf_deg" if "ekf" in q else "yaw_sigma_gap_end_deg"
            y = [max((abs(e) / s for e, s in zip(c["estimation"].get(q) or [],
                                                 c["estimation"].get(sig) or [], strict=False)
                      if s), default=None) for c in cases]
            if any(v is not None for v in y):
                data.append(_xy(d, y, f"worst gap-end |e|/σ, {name}", color, xa, yb, None,
                                p == 0))
        for level, color in ((th.get("ten_percent_yaw_sigma_deg"), tr.COLORS["real"]),
                             (th.get("ten_percent_roll_sigma_deg"), tr.COLORS["smoothed"]),
                             (th.get("earth_sensor_noise_deg"), tr.COLORS["truth"])):
            if level:
                shapes.append(_hline(level, xa, ya, color))
        shapes.append(_hline(3.0, xa, yb, tr.COLORS["paper"]))
        dom = [p / len(kinds) + (0.05 if p else 0), (p + 1) / len(kinds) - 0.03]
        layout[f"xaxis{p + 1 if p else ''}"] = {
            "domain": dom, "type": "log", "anchor": yb, "title": {"text": f"{kind} δ (°)"}}
        layout[f"yaxis{2 * p + 1 if p else ''}"] = {
            "domain": [0.45, 1.0], "type": "log", "anchor": xa, "exponentformat": "power",
            "title": {"text": "largest divergence (°)" if p == 0 else ""}}
        layout[f"yaxis{2 * p + 2}"] = {
            "domain": [0.0, 0.36], "anchor": xa, "title": {"text": "gap-end |e|/σ"
                                                           if p == 0 else ""}}
    layout.update({"height": 640, "template": "plotly_white", "shapes": shapes,
                   "hovermode": "closest", "margin": {"l": 80, "r": 20, "t": 40, "b": 50},
                   "legend": {"orientation": "h", "y": 1.02, "yanchor": "bottom"}})
    caption = ("Top: linear − nonlinear propagated from the same initial error, its largest "
               "|yaw| and |roll| over the run, for Eq. 11 (solid) and the exact Jacobian "
               "(dashed); dotted: 10% of the filter's σ_yaw (blue) and σ_roll (purple), the "
               "Earth-sensor noise (black) (sweep.thresholds). Bottom: the filter's worst "
               "gap-end |yaw error|/σ; red dotted: 3. The δ = 0 case has no place on a log "
               "axis: it is in the tables.")
    return Plot("lin-sweep", "The sweep: how far the linear model holds", caption,
                {"data": data, "layout": layout}, time_axis=False)


def _xy(x, y, name, color, xa, ya, dash, show) -> dict:
    t = {"type": "scatter", "mode": "lines+markers", "name": name, "x": list(x),
         "y": [None if v is None else float(v) for v in y], "xaxis": xa, "yaxis": ya,
         "line": {"color": color, "width": 1.5}, "marker": {"color": color, "size": 6},
         "legendgroup": name, "showlegend": show,
         "hovertemplate": "δ %{x}°: %{y:.3g}<extra>" + name + "</extra>"}
    if dash:
        t["line"]["dash"] = dash
    return t


def _hline(y: float, xa: str, ya: str, color: str) -> dict:
    """A horizontal line across one panel of a grid (its x axis's domain)."""
    return {"type": "line", "xref": f"{xa} domain", "x0": 0, "x1": 1, "yref": ya, "y0": y,
            "y1": y, "line": {"color": color, "width": 1.2, "dash": "dot"}}


def build(src: Source, command: str | None, requirement_deg: float | None = None) -> Page:
    report = src.record
    meta = report.get("meta") or {}
    intro = str(report.get("verdict") or "").replace("**", "")
    sections = [Section("verdict", "Verdict", intro, verdicts(report))]
    coeff = report.get("coefficients") or {}
    sections.append(Section("coefficients", "Coefficients", tables=[
        coefficient_table(report), eigen_table(report), matrix_table(report),
        record_table("lin-inputs", coeff, REPORT, "The nominal state they are taken at, and "
                     "the terms the paper sets to zero (coefficients)",
                     skip=("rows", "eigenfrequencies", "jacobian", "eq11"),
                     prefix="coefficients")]))
    sweep = [p for p in (sweep_figure(report),) if p is not None]
    sections.append(Section("sweep", "Sweep", plots=sweep, after=[
        divergence_table(report), crossing_table(report),
        record_table("lin-thresholds", report.get("sweep") or {}, REPORT, "Thresholds, and "
                     "the samples where the gaps end (sweep)", skip=("cases",
                                                                    "threshold_crossings"),
                     prefix="sweep"),
        estimation_table(report, False)]
        + ([estimation_table(report, True)] if any(
            "nees_mean_ekf" in (c.get("estimation") or {})
            for c in (report.get("sweep") or {}).get("cases") or []) else [])))
    budget = budget_figure(report)
    sections.append(Section("budget", "Error budget", plots=[budget] if budget else [],
                            after=[budget_table(report), ideal_table(report)]))
    sections.append(Section("meta", "Tables", tables=[record_table(
        "lin-meta", meta, REPORT, "The run (report.json meta)", prefix="meta")]))
    sections += as_written(src, "report.md", "The report as written (its long paragraphs "
                           "wrapped here), with its figures beside it (Files).")
    scen = {"name": meta.get("scenario"), "seed": meta.get("seed"),
            "epoch_utc": meta.get("epoch_utc"), "dynprop_version": meta.get("dynprop_version")}
    return page(src, command, "linearization", f"{meta.get('scenario')}: dynprop linearization",
                run_scale(meta), sections, scenario=scen)
