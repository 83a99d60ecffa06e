"""The verdict at the top of a run's page: the yaw error at the Sun-gap ends judged
three ways (docs/report.md).

1. Against the filter's own σ: summary.json's ``gap_end_yaw_within_3sigma`` check,
   as the run judged it (the page does not judge it again).
2. Against the paper: Eq. 56 predicts σ_yaw = 0.040° after the gap, so each
   gap-end error should lie within 3 × 0.040°.
3. Against the user's requirement ``report.yaw_requirement_deg``, a 3σ bound over
   24 h as GOES states its navigation metrics: met when, for every day of the run,
   three times that day's RMS yaw error (daily.csv, at the full sample rate) is
   within it, and so is every gap-end error.

Each is "met", "not met" or "not tested" (no gap end, no truth, no requirement
set), never "met" with nothing judged.
"""

from __future__ import annotations

import math

from dynprop.estimator.analysis.covariance import PAPER_SIGMA_YAW_DEG

from .cells import Cell, Verdict, cell, text

SUMMARY = "summary.json"


def _status(ok: bool | None) -> str:
    return "not tested" if ok is None else ("met" if ok else "not met")


def _worst_end(summary: dict) -> tuple[int, float] | None:
    """Index and value of the gap-end yaw error of largest magnitude, None without one."""
    ends = [(i, e) for i, e in enumerate(summary.get("yaw_error_at_gap_end_deg") or [])
            if e is not None and math.isfinite(e)]
    return max(ends, key=lambda p: abs(p[1])) if ends else None


def against_filter(summary: dict, label: str = "Filter σ", check: str =
                   "gap_end_yaw_within_3sigma") -> Verdict:
    c = (summary.get("checks") or {}).get(check) or {}
    key = f"checks.{check}"
    parts: list = [text("gap-end yaw error within ±3σ of the filter's own σ: ")]
    if c:
        parts.append(cell(c.get("detail"), SUMMARY, f"{key}.detail"))
    else:
        parts.append(text("not tested (the run has no such check)"))
    return Verdict(label, _status(c.get("passed")), parts)


def against_paper(summary: dict) -> Verdict:
    worst = _worst_end(summary)
    limit = 3 * PAPER_SIGMA_YAW_DEG
    head = text(f"every gap-end |error| within 3 × {PAPER_SIGMA_YAW_DEG:.3f}° = {limit:.3f}° "
                "(Eq. 56's σ_yaw after the gap): ")
    if worst is None:
        return Verdict("Paper, Eq. 56", "not tested",
                       [head, text("not tested (no Sun-gap end judged against a truth)")])
    i, e = worst
    parts: list = [head, text("worst "), cell(e, SUMMARY, f"yaw_error_at_gap_end_deg[{i}]", "°"),
                   text(", the filter's σ there ")]
    sigma = (summary.get("yaw_sigma_at_gap_end_deg") or [None] * (i + 1))[i]
    parts += [cell(sigma, SUMMARY, f"yaw_sigma_at_gap_end_deg[{i}]", "°"),
              text(f" against the paper's {PAPER_SIGMA_YAW_DEG:.3f}°")]
    return Verdict("Paper, Eq. 56", _status(abs(e) <= limit), parts)


def against_requirement(summary: dict, requirement_deg: float | None,
                        daily: list[tuple[int, Cell, float]]) -> Verdict:
    """``daily``: per day, its number, the Cell showing its RMS yaw error and the value
    (deg); empty when the run has no truth."""
    label = "Requirement (3σ over 24 h)"
    if requirement_deg is None:
        return Verdict(label, "not tested", [text(
            "not tested: no requirement set (report.yaw_requirement_deg in the scenario, or "
            "`dynprop report DIR --yaw-requirement-deg X`)")])
    parts: list = [text(f"requirement {requirement_deg:g}°: ")]
    judged = [(d, c, v) for d, c, v in daily if v is not None and math.isfinite(v)]
    worst_end = _worst_end(summary)
    if not judged and worst_end is None:
        return Verdict(label, "not tested", parts + [text("not tested (no yaw error: the "
                                                          "run has no truth)")])
    ok = True
    if judged:
        day, c, v = max(judged, key=lambda p: p[2])
        three = 3 * v
        ok &= three <= requirement_deg
        parts += [text(f"worst day {day}: 3 × RMS yaw error "), c,
                  text(" = "), cell(three, unit="°"),
                  text(" within it" if three <= requirement_deg else " beyond it")]
    if worst_end is not None:
        i, e = worst_end
        ok &= abs(e) <= requirement_deg
        parts += [text("; worst gap-end error "),
                  cell(e, SUMMARY, f"yaw_error_at_gap_end_deg[{i}]", "°"),
                  text(" within it" if abs(e) <= requirement_deg else " beyond it")]
    return Verdict(label, _status(ok), parts)
