"""The page of a Monte Carlo set (`dynprop montecarlo`): the set's verdicts, the
ensemble figures, montecarlo.json's every figure and one row per case
(docs/outputs.md, "Monte Carlo set").

The verdicts judge what montecarlo.json holds, never anything recomputed from the
cases: the averaged-NEES test (``nees``: "not tested" when its figures are null,
no grid point after ``converged_after_h``), the gap-end yaw against each case's
filter σ (``gap_end_yaw[j].fraction_within``), against the paper's Eq. 56 and
against the requirement.
"""

from __future__ import annotations

import numpy as np
from dynprop.estimator.analysis.covariance import PAPER_SIGMA_YAW_DEG
from scipy.stats import binom

from ...montecarlo.stats import nees_inside_needed
from ..cells import Table, cell, text
from ..page_parts import finite, page, record_table, verdict
from ..render import Page, Section
from ..run_page import requirement_of
from ..source import Source, read_json
from . import ensemble_figures as figs

MC = "montecarlo.json"
NPZ = "montecarlo.npz"
# A consistent filter leaves ±3σ with this probability (two-sided Gaussian).
P_BEYOND_3SIGMA = 0.0026997960632601866
# Too many beyond ±3σ: fewer than this chance with a consistent filter.
TAIL = 0.025
# A case record's figures in the case table, after its gap ends.
CASE_FIGURES = ("roll_error_rms_deg", "yaw_error_rms_deg", "h_error_rms_Nms",
                "yaw_error_max_abs_deg", "nees_mean")
# montecarlo.json's keys with tables of their own.
OWN_TABLES = ("nees", "gap_end_yaw", "rms_after_convergence", "dispersions", "ekf")


def nees_verdict(mc: dict):
    """Met when the averaged NEES after convergence is inside its 95% bounds 95% of
    the time, less three binomial standard deviations of sampling scatter (the
    allowance montecarlo's own diagnosis makes, its "consistent within sampling
    scatter": ``montecarlo.stats.nees_inside_needed``)."""
    n = mc.get("nees") or {}
    frac = n.get("fraction_after_convergence")
    label = "Averaged NEES"
    if not frac or n.get("mean_after_convergence") is None:
        why = [cell(n["diagnosis"], MC, "nees.diagnosis")] if n.get("diagnosis") else \
            [text("no NEES figures in montecarlo.json")]
        # The diagnosis of an untested set says so itself ("not tested (…)").
        head = [] if str(n.get("diagnosis")).startswith("not tested") else [text("not tested: ")]
        return verdict(label, None, head + why)
    points = n.get("points_after_convergence") or 0
    need = nees_inside_needed(points)
    lo, hi = n["bounds_95"]
    parts = [text("inside its χ²(9N)/N 95% bounds ["), cell(lo, MC, "nees.bounds_95[0]"),
             text(", "), cell(hi, MC, "nees.bounds_95[1]"), text("] a fraction "),
             cell(frac["inside"], MC, "nees.fraction_after_convergence.inside"),
             text(" of the "), cell(points, MC, "nees.points_after_convergence"),
             text(" grid points from "), cell(mc.get("converged_after_h"), MC,
                                                "converged_after_h", "h"),
             text(" (needed: "), cell(need), text("); mean "),
             cell(n["mean_after_convergence"], MC, "nees.mean_after_convergence"),
             text(". "), cell(n.get("diagnosis"), MC, "nees.diagnosis")]
    return verdict(label, frac["inside"] >= need, parts)


def filter_verdict(gaps: list[dict], label: str, prefix: str):
    """Met unless some gap end has more cases beyond ±3σ of their own filter σ than
    a consistent filter gives with probability ``TAIL`` (binomial, p = 0.27%)."""
    judged = [(j, g) for j, g in enumerate(gaps) if (g.get("fraction_within") or {})
              .get("3sigma") is not None and g.get("n")]
    if not judged:
        return verdict(label, None, [text("not tested: no Sun-gap end in the runs")])
    parts, ok = [text("cases whose gap-end yaw error is beyond ±3σ of their own filter σ: ")], True
    for m, (j, g) in enumerate(judged):
        beyond = round((1 - g["fraction_within"]["3sigma"]) * g["n"])
        tail = float(binom.sf(beyond - 1, g["n"], P_BEYOND_3SIGMA))   # P(X ≥ beyond)
        ok &= tail >= TAIL
        parts += [text(f"{'; ' if m else ''}gap {g.get('gap', j + 1)}: "), cell(beyond),
                  text(" of "), cell(g["n"], MC, f"{prefix}gap_end_yaw[{j}].n"),
                  text(" (fraction within "),
                  cell(g["fraction_within"]["3sigma"], MC,
                       f"{prefix}gap_end_yaw[{j}].fraction_within.3sigma"),
                  text("; a consistent filter has as many or more with chance "), cell(tail),
                  text(")")]
    parts.append(text(f". Not met when that chance is under {TAIL:.1%}."))
    return verdict(label, ok, parts)


def _worst_quantile(gaps: list[dict]) -> tuple[int, float] | None:
    q = [(j, (g.get("abs_quantile_deg") or {}).get("3sigma")) for j, g in enumerate(gaps)]
    q = [(j, v) for j, v in q if finite(v)]
    return max(q, key=lambda p: p[1]) if q else None


def paper_verdict(gaps: list[dict]):
    """Eq. 56's σ_yaw = 0.040° after the gap: the 99.7% quantile of |e| (where a
    Gaussian puts 3σ) within 3 × 0.040° at every gap end."""
    limit = 3 * PAPER_SIGMA_YAW_DEG
    head = text(f"the 99.7% quantile of |gap-end yaw error| within 3 × {PAPER_SIGMA_YAW_DEG:.3f}°"
                f" = {limit:.3f}° (Eq. 56): ")
    worst = _worst_quantile(gaps)
    if worst is None:
        return verdict("Paper, Eq. 56", None, [head, text("not tested: no Sun-gap end")])
    j, v = worst
    parts = [head, text(f"worst, gap {gaps[j].get('gap', j + 1)}: "),
             cell(v, MC, f"gap_end_yaw[{j}].abs_quantile_deg.3sigma", "°")]
    if ((gaps[j].get("abs_quantile_ci95_deg") or {}).get("3sigma") or [0, 0])[1] is None:
        parts.append(text(" (too few cases to bound it above: a sample quantile, not a σ)"))
    return verdict("Paper, Eq. 56", v <= limit, parts)


def requirement_verdict(mc: dict, requirement: float | None):
    """3 × the ensemble RMS yaw error after convergence and every gap end's 99.7%
    |e| quantile within the requirement (a 3σ bound, as on the run page)."""
    label = "Requirement (3σ)"
    if requirement is None:
        return verdict(label, None, [text(
            "not tested: no requirement set (report.yaw_requirement_deg in the scenario, or "
            "`dynprop report DIR --yaw-requirement-deg X`)")])
    parts, ok = [text(f"requirement {requirement:g}°: ")], None
    rms = ((mc.get("rms_after_convergence") or {}).get("yaw_deg") or {}).get("ensemble_rms")
    if finite(rms):
        ok = 3 * rms <= requirement
        parts += [text("3 × ensemble RMS yaw error after convergence 3 × "),
                  cell(rms, MC, "rms_after_convergence.yaw_deg.ensemble_rms", "°"),
                  text(" = "), cell(3 * rms, unit="°")]
    worst = _worst_quantile(mc.get("gap_end_yaw") or [])
    if worst is not None:
        j, v = worst
        ok = (ok is not False) and v <= requirement
        parts += [text("; worst gap-end 99.7% |e| quantile "),
                  cell(v, MC, f"gap_end_yaw[{j}].abs_quantile_deg.3sigma", "°")]
    if ok is None:
        parts.append(text("not tested: no ensemble yaw error after convergence"))
    return verdict(label, ok, parts)


def gap_table(mc: dict) -> Table:
    """Per gap end and estimator: montecarlo.json's ``gap_end_yaw`` statistics (the
    twin's under each gap's ``linear``, the EKF's under ``ekf.gap_end_yaw``)."""
    rows = []
    for j, k, name, g in _gap_rows(mc):
        q, w = g.get("abs_quantile_deg") or {}, g.get("fraction_within") or {}
        end = (mc["gap_end_yaw"][j] if j < len(mc["gap_end_yaw"]) else {}).get("end_h_median")
        rows.append([text(str(g.get("gap", j + 1))), text(name),
                     cell(end, MC, f"gap_end_yaw[{j}].end_h_median") if end is not None
                     else text("—"),
                     cell(g.get("n"), MC, f"{k}.n"),
                     *[cell(g.get(f), MC, f"{k}.{f}") for f in ("mean_deg", "std_deg",
                                                                "rms_deg")],
                     *[cell(q.get(s), MC, f"{k}.abs_quantile_deg.{s}")
                       for s in ("1sigma", "2sigma", "3sigma")],
                     cell(g.get("predicted_sigma_deg"), MC, f"{k}.predicted_sigma_deg"),
                     *[cell(w.get(s), MC, f"{k}.fraction_within.{s}")
                       for s in ("1sigma", "2sigma", "3sigma")]])
    cols = ["gap", "estimator", "end (h, median)", "n", "mean (°)", "std (°)", "RMS (°)",
            "|e| 68.3% q. (°)", "95.4% q. (°)", "99.7% q. (°)", "filter σ, RMS (°)",
            "within 1σ", "within 2σ", "within 3σ"]
    return Table("mc-gap-ends", cols, rows, "Yaw at the Sun-gap ends over the cases "
                 "(montecarlo.json gap_end_yaw: the |e| quantiles are sample quantiles, "
                 "not σ; 'within' are fractions of the cases)")


def _gap_rows(mc: dict) -> list[tuple[int, str, str, dict]]:
    """(gap index, key path, estimator, statistics), gap by gap."""
    out = []
    ekf = (mc.get("ekf") or {}).get("gap_end_yaw") or []
    for j, g in enumerate(mc.get("gap_end_yaw") or []):
        out.append((j, f"gap_end_yaw[{j}]", "filter", g))
        if g.get("linear"):
            out.append((j, f"gap_end_yaw[{j}].linear", "linear twin", g["linear"]))
        if j < len(ekf):
            out.append((j, f"ekf.gap_end_yaw[{j}]", "EKF", ekf[j]))
    return out


def quantile_table(mc: dict) -> Table:
    rows = []
    for j, g in enumerate(mc.get("gap_end_yaw") or []):
        k = f"gap_end_yaw[{j}]"
        for s, level in (g.get("abs_quantile_level") or {}).items():
            lo, hi = ((g.get("abs_quantile_ci95_deg") or {}).get(s) or [None, None])
            rows.append([text(str(g.get("gap", j + 1))),
                         cell(level, MC, f"{k}.abs_quantile_level.{s}"),
                         cell(g["abs_quantile_deg"][s], MC, f"{k}.abs_quantile_deg.{s}"),
                         cell(lo, MC, f"{k}.abs_quantile_ci95_deg.{s}[0]"),
                         cell(hi, MC, f"{k}.abs_quantile_ci95_deg.{s}[1]") if hi is not None
                         else text("open: too few cases")])
    return Table("mc-quantiles", ["gap", "level", "|e| quantile (°)", "95% interval from (°)",
                                  "to (°)"], rows, "The |e| quantiles' distribution-free 95% "
                 "intervals (montecarlo.json abs_quantile_ci95_deg)")


def rms_table(mc: dict) -> Table:
    rows = []
    for prefix, name, branch in (("", "filter", mc), ("ekf.", "EKF", mc.get("ekf") or {})):
        for state, r in (branch.get("rms_after_convergence") or {}).items():
            k = f"{prefix}rms_after_convergence.{state}"
            e, s = r.get("ensemble_rms"), r.get("filter_sigma_rms")
            rows.append([text(state), text(name), cell(e, MC, f"{k}.ensemble_rms"),
                         cell(s, MC, f"{k}.filter_sigma_rms"),
                         cell(e / s if finite(e) and finite(s) and s else None)])
    return Table("mc-rms", ["state", "estimator", "ensemble RMS error", "RMS of the filter σ",
                            "ratio (here)"], rows, "After convergence: the errors' spread "
                 "against the filter's σ (montecarlo.json rms_after_convergence)")


def nees_state_table(mc: dict) -> Table:
    n = mc.get("nees") or {}
    means = n.get("per_state_mean_after_convergence") or {}
    test = n.get("per_state_test_95") or {}
    rows = [[text(s), cell(v, MC, f"nees.per_state_mean_after_convergence.{s}"),
             cell(test[s], MC, f"nees.per_state_test_95.{s}", css="failed"
                  if test[s] == "above" else "") if s in test else text("not tested")]
            for s, v in means.items()]
    return Table("mc-nees-states", ["state", "mean (e/σ)² after convergence",
                                    "against the 95% bounds"], rows,
                 "Per state (montecarlo.json nees.per_state_*; the bounds are in the NEES "
                 "table under Tables)")


def load_cases(src: Source, runs: int) -> list[tuple[str, dict]]:
    """The set's case records (cases/case-NNNNN.json), those of its ``runs_requested``
    only: a directory rerun with fewer runs keeps the others' files."""
    out = []
    for p in sorted((src.path / "cases").glob("case-*.json")):
        rec = read_json(p, ("case", "status"))
        if isinstance(rec["case"], int) and rec["case"] < runs:
            out.append((f"cases/{p.name}", rec))
    return out


def case_table(cases: list[tuple[str, dict]], n_gaps: int) -> Table:
    rows = []
    for name, c in cases:
        ok = c["status"] == "ok"
        row = [cell(c["case"], name, "case"),
               cell(c["status"], name, "status", css="" if ok else "failed"),
               cell(c.get("epoch_utc"), name, "epoch_utc")]
        for j in range(n_gaps):
            e, s = _at(c, "yaw_error_at_gap_end_deg", j), _at(c, "yaw_sigma_at_gap_end_deg", j)
            end = _at(c, "gap_end_h", j)
            z = e / s if finite(e) and finite(s) and s else None
            row += [cell(end, name, f"gap_end_h[{j}]") if end is not None else text("—"),
                    cell(e, name, f"yaw_error_at_gap_end_deg[{j}]") if e is not None
                    else text("—"),
                    cell(s, name, f"yaw_sigma_at_gap_end_deg[{j}]") if s is not None
                    else text("—"),
                    cell(z, css="failed" if z is not None and abs(z) > 3 else "")]
        row += [cell(c[k], name, k) if k in c else text("—") for k in CASE_FIGURES]
        row.append(cell(c.get("error"), name, "error") if not ok else text(""))
        rows.append(row)
    cols = ["case", "status", "epoch (UTC)"]
    for j in range(n_gaps):
        cols += [f"gap {j + 1} end (h)", "yaw error (°)", "filter σ (°)", "e/σ (here)"]
    cols += ["roll RMS (°)", "yaw RMS (°)", "h RMS (N m s)", "max |yaw| (°)", "NEES mean",
             "error"]
    return Table("mc-cases", cols, rows, "One row per case (cases/case-NNNNN.json; e/σ worked "
                 "out here from its yaw_sigma_at_gap_end_deg, red beyond 3)")


def _at(c: dict, key: str, j: int):
    v = c.get(key) or []
    return v[j] if j < len(v) else None


def dispersion_table(mc: dict) -> Table:
    """montecarlo.json ``dispersions``.  Its keys are scenario key paths, dots and
    all (``spacecraft.inertia_kgm2``), which a cell's key path cannot name: the
    values are shown without a source rather than with a key that leads nowhere."""
    rows = []
    for key, d in (mc.get("dispersions") or {}).items():
        rows.append([text(key), text(str(d.get("distribution")))]
                    + [cell(d[f]) if f in d else text("") for f in ("mean", "sigma", "low",
                                                                     "high")])
    return Table("mc-dispersions", ["scenario key", "distribution", "mean", "σ", "low", "high"],
                 rows, "What was dispersed (montecarlo.json dispersions, about the nominal "
                 "scenario's value)")


def build(src: Source, command: str | None, requirement_deg: float | None = None) -> Page:
    mc, scenario = src.record, src.scenario or {}
    with np.load(src.path / NPZ) as z:
        npz = {k: z[k] for k in z.files}
    cases = load_cases(src, mc["runs_requested"])
    gaps = mc.get("gap_end_yaw") or []
    conv = mc.get("converged_after_h")
    verdicts = [nees_verdict(mc), filter_verdict(gaps, "Filter σ", "")]
    if (mc.get("ekf") or {}).get("gap_end_yaw"):
        verdicts.append(filter_verdict(mc["ekf"]["gap_end_yaw"], "EKF σ", "ekf."))
    verdicts += [paper_verdict(gaps),
                 requirement_verdict(mc, requirement_of(scenario, requirement_deg))]
    intro = (f"{mc.get('runs_ok')} of {mc.get('runs_requested')} runs finished "
             f"({mc.get('runs_failed')} failed, {mc.get('runs_missing')} missing). Is the "
             "filter consistent over the runs (averaged NEES), does each case's σ cover its "
             "gap-end yaw error, and how do the errors compare with the paper's 0.040° and "
             "the requirement?")
    sections = [Section("verdict", "Verdict", intro, verdicts, [gap_table(mc)] if gaps else [])]
    ok_cases = [c for _, c in cases if c["status"] == "ok"]
    if "t_s" in npz and len(npz["t_s"]):
        sections.append(Section("errors", "Errors", plots=[
            figs.errors(npz, mc.get("runs_ok"), mc.get("analytic_sigma_yaw_deg"), conv)],
            after=[rms_table(mc)]))
        sections.append(Section("consistency", "Consistency", plots=[figs.nees(npz, mc, conv)],
                                after=[nees_state_table(mc)]))
    strip = figs.gap_end_strip(ok_cases, gaps)
    if gaps:
        sections.append(Section("gap-ends", "Gap ends", plots=[strip] if strip else [],
                                after=[quantile_table(mc)]))
    n_gaps = max((len(c.get("yaw_error_at_gap_end_deg") or []) for c in ok_cases), default=0)
    sections.append(Section("cases", "Cases", f"Rerun case K alone: {mc.get('reproduce_case')}",
                            tables=[case_table(cases, n_gaps)]))
    tables = [record_table("mc-record", mc, MC, "montecarlo.json, the other figures",
                           skip=OWN_TABLES),
              record_table("mc-nees", mc.get("nees") or {}, MC, "montecarlo.json nees, the "
                           "averaged-NEES test", skip=("per_state_mean_after_convergence",
                                                       "per_state_test_95"), prefix="nees"),
              dispersion_table(mc)]
    if mc.get("ekf"):
        tables.insert(2, record_table("mc-ekf", mc["ekf"], MC, "montecarlo.json ekf, the "
                                      "EKF's NEES", skip=("gap_end_yaw",
                                                          "rms_after_convergence"),
                                      prefix="ekf"))
    sections.append(Section("tables", "Tables", tables=tables))
    return page(src, command, "montecarlo", f"{mc.get('scenario')}: dynprop montecarlo",
                f"seed {mc.get('seed')}, {mc.get('runs_ok')} of {mc.get('runs_requested')} "
                f"runs, {mc.get('grid_s') or 0:.4g} s grid, NEES from {conv} h, "
                f"dynprop {mc.get('dynprop_version')}", sections)
