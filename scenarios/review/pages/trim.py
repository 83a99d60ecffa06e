"""The page of a `dynprop trim` directory (RUN_DIR/trim/): κ̂ ± σ, the tab
recommendation, the truth comparison when the run had a truth, the out-of-phase
check and --verify's before and after, then trim.md (docs/outputs.md, "Trim").

trim.json holds no arrays, so its figure is κ̂ and the fitted constant torques
with their ±3σ beside the truth, and the tab now, recommended and (with a truth)
at full trim.
"""

from __future__ import annotations

from .. import traces as tr
from ..cells import Table, cell, text
from ..page_parts import (
    as_written,
    before_after_rows,
    finite,
    page,
    points_figure,
    record_table,
    run_dir_of,
    verdict,
)
from ..render import Page, Section
from ..run_figures import Plot
from ..source import Source

TRIM = "trim.json"
# trim.json's keys shown in tables of their own.
OWN = ("kappa_Nm", "kappa_sigma_Nm", "constant_torque_Nm", "constant_torque_sigma_Nm",
       "recommendation", "truth", "out_of_phase", "verify")


def verdicts(t: dict) -> list:
    """The tab (κ̂ within ±3σ of 0: no move, trim.json ``recommendation.move``), κ̂
    against the true κ (within 3σ, ``truth.error_over_sigma``; "not tested" without
    a truth) and the out-of-phase check (``out_of_phase.consistent``)."""
    rec = t.get("recommendation") or {}
    move = rec.get("move")
    parts = [text("κ̂ "), cell(t.get("kappa_Nm"), TRIM, "kappa_Nm", "N m"), text(" ± "),
             cell(t.get("kappa_sigma_Nm"), TRIM, "kappa_sigma_Nm", "N m"), text(" (1σ, at 1 AU): ")]
    if move:
        parts += [text("move the tab from "), cell(rec.get("trim_tab_deg"), TRIM,
                                                   "recommendation.trim_tab_deg", "°"),
                  text(" to "), cell(rec.get("trim_tab_deg_new"), TRIM,
                                     "recommendation.trim_tab_deg_new", "°"),
                  text(" ± "), cell(rec.get("sigma_deg"), TRIM, "recommendation.sigma_deg", "°"),
                  text(", leaving about "), cell(rec.get("residual_after_Nm"), TRIM,
                                                 "recommendation.residual_after_Nm", "N m"),
                  text(" (1σ)")]
    elif move is not None:
        parts += [text("within 3σ of zero: leave the tab at "),
                  cell(rec.get("trim_tab_deg"), TRIM, "recommendation.trim_tab_deg", "°")]
    out = [verdict("Tab at trim", None if move is None else not move,
                   [text("met when κ̂ is within ±3σ of 0 (no move); ")] + parts)]
    truth = t.get("truth")
    if truth:
        z = truth.get("error_over_sigma")
        out.append(verdict("κ̂ against the truth", abs(z) <= 3 if finite(z) else None, [
            text("true κ "), cell(truth.get("kappa_Nm"), TRIM, "truth.kappa_Nm", "N m"),
            text("; (κ̂ − κ)/σ = "), cell(z, TRIM, "truth.error_over_sigma"),
            text(", within ±3 to be met")]))
    else:
        out.append(verdict("κ̂ against the truth", None,
                           [text("not tested: the run has no truth.csv")]))
    oop = t.get("out_of_phase") or {}
    out.append(verdict("Out-of-phase torque", oop.get("consistent"), [
        text("the orbit-rate torque out of phase with the Sun: amplitude "),
        cell(oop.get("amplitude_Nm"), TRIM, "out_of_phase.amplitude_Nm", "N m"),
        text(", χ²(1) = "), cell(oop.get("chi2_1dof"), TRIM, "out_of_phase.chi2_1dof"),
        text(" (consistent with none at χ² ≤ 6.63, the 99% point: the solar model fits)")]))
    return out


def estimate_table(t: dict) -> Table:
    rows = [[text("κ (solar, at 1 AU)"), cell(t.get("kappa_Nm"), TRIM, "kappa_Nm"),
             cell(t.get("kappa_sigma_Nm"), TRIM, "kappa_sigma_Nm"),
             cell(3 * t["kappa_sigma_Nm"] if finite(t.get("kappa_sigma_Nm")) else None)]]
    for axis, v in (t.get("constant_torque_Nm") or {}).items():
        s = (t.get("constant_torque_sigma_Nm") or {}).get(axis)
        rows.append([text(f"constant {axis} torque"),
                     cell(v, TRIM, f"constant_torque_Nm.{axis}"),
                     cell(s, TRIM, f"constant_torque_sigma_Nm.{axis}"),
                     cell(3 * s if finite(s) else None)])
    return Table("trim-estimate", ["torque", "estimate (N m)", "1σ (N m)", "3σ (here)"], rows,
                 "What the batch estimated (trim.json)")


def verify_table(t: dict) -> Table | None:
    v = t.get("verify")
    if not v:
        return None
    rows = before_after_rows(v.get("before") or {}, v.get("after") or {}, TRIM, "verify.")
    if "residual_fall" in v:
        rows.append([text("residual_fall (true κ before / after)"),
                     cell(v["residual_fall"], TRIM, "verify.residual_fall"), text(""), text("")])
    return Table("trim-verify", ["", "before the move", "after", "unit"], rows,
                 "--verify: the run again with the tab moved (trim.json verify)")


def figure(t: dict) -> Plot:
    """κ̂ and the constant torques ±3σ with the true κ; the tab now, recommended ±3σ
    and the truth's full-trim tab."""
    rec, truth = t.get("recommendation") or {}, t.get("truth") or {}
    names = ["κ (solar)"] + [f"constant {a}" for a in (t.get("constant_torque_Nm") or {})]
    values = [t.get("kappa_Nm")] + list((t.get("constant_torque_Nm") or {}).values())
    sig = [t.get("kappa_sigma_Nm")] + [(t.get("constant_torque_sigma_Nm") or {}).get(a)
                                       for a in (t.get("constant_torque_Nm") or {})]
    groups = [{"panel": 0, "name": "estimate ±3σ", "x": names, "y": values,
               "err": [3 * s if finite(s) else None for s in sig], "color": tr.COLORS["real"]}]
    if finite(truth.get("kappa_Nm")):
        groups.append({"panel": 0, "name": "truth", "x": names[:1], "y": [truth["kappa_Nm"]],
                       "err": None, "color": tr.COLORS["paper"], "symbol": "x"})
        if finite(truth.get("kappa_after_Nm")):
            groups.append({"panel": 0, "name": "true κ after the move", "x": names[:1],
                           "y": [truth["kappa_after_Nm"]], "err": None,
                           "color": tr.COLORS["ekf"], "symbol": "diamond"})
    groups.append({"panel": 1, "name": "tab now", "x": ["now"], "y": [rec.get("trim_tab_deg")],
                   "err": None, "color": tr.COLORS["sigma"], "group": "tab", "show": False})
    groups.append({"panel": 1, "name": "recommended ±3σ", "x": ["recommended"],
                   "y": [rec.get("trim_tab_deg_new")],
                   "err": [3 * rec["sigma_deg"] if finite(rec.get("sigma_deg")) else None],
                   "color": tr.COLORS["real"], "group": "estimate ±3σ", "show": False})
    if finite(truth.get("full_trim_tab_deg")):
        groups.append({"panel": 1, "name": "true full trim", "x": ["true full trim"],
                       "y": [truth["full_trim_tab_deg"]], "err": None,
                       "color": tr.COLORS["paper"], "symbol": "x", "group": "truth",
                       "show": False})
    fig = points_figure(groups, [{"title": "torque (N m)"}, {"title": "trim tab (°)"}])
    caption = ("Left: κ̂ (the solar torque at 1 AU) and the fitted constant roll and yaw "
               "torques with ±3σ, the true κ (×) when the run has a truth. Right: the tab now, "
               "the recommended tab ±3σ and the truth's full-trim tab.")
    return Plot("trim", "κ̂ and the tab", caption, fig, time_axis=False)


def build(src: Source, command: str | None, requirement_deg: float | None = None) -> Page:
    t = src.record
    intro = "The solar-torque coefficient κ fitted over the run's telemetry, and the trim " \
        "tab it asks for (docs/trim.md)."
    sections = [Section("verdict", "Verdict", intro, verdicts(t), [estimate_table(t)])]
    sections.append(Section("figure", "Figure", plots=[figure(t)]))
    tables = [record_table("trim-recommendation", t.get("recommendation") or {}, TRIM,
                           "The recommendation (trim.json recommendation)",
                           prefix="recommendation")]
    if t.get("truth"):
        tables.append(record_table("trim-truth", t["truth"], TRIM, "Against the truth "
                                   "(trim.json truth)", prefix="truth"))
    tables.append(record_table("trim-out-of-phase", t.get("out_of_phase") or {}, TRIM,
                               "The out-of-phase check (trim.json out_of_phase)",
                               prefix="out_of_phase"))
    verify = verify_table(t)
    if verify is not None:
        tables.append(verify)
    tables.append(record_table("trim-record", t, TRIM, "trim.json, the rest: the batch, its "
                               "tuning, what it assumes and estimates", skip=OWN))
    sections.append(Section("tables", "Tables", tables=tables))
    sections += as_written(src, "trim.md")
    b = t.get("batch") or {}
    return page(src, command, "trim", f"{t.get('scenario')}: dynprop trim",
                f"batch {b.get('from_s')} … {b.get('to_s')} s ({b.get('duration_h')} h), "
                f"{src.path}", sections, run_dir_of(src))
