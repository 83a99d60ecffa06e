"""The verdict that opens the linearization report: which assumption breaks first.

Budget numbers keep their signs here.  A budget row is the yaw error one effect
adds at the Sun-gap end; the total is the scenario with every effect at once, so a
row can exceed the total in magnitude, or have the other sign, when other effects
(or the effects' interaction) pull the other way.  Dropping the signs would report
"0.0029° of a total 0.00244°" and hide exactly that.
"""

from __future__ import annotations

from dynprop.estimator.kalman.consistency import chi2_bounds
from dynprop.estimator.linear.model import N_STATES

from .analysis import KINDS
from .propagation import SWEEP_DEG

MODELS = {"torque_model_deg": "torque model (Eq. 9)", "dynamics_deg": "dynamics"}
# A term is named as cancelling when it is at least this share of what is cancelled.
NAMED_SHARE = 0.1


def g(v, digits: int = 3) -> str:
    """The one number format of the report's tables and verdict."""
    if v is None:
        return "—"
    if isinstance(v, bool):
        return "yes" if v else "no"
    return f"{v:.{digits}g}"


def signed(v: float, digits: int = 3) -> str:
    """A budget value with its sign always written: +0.000383, −0.0029, 0."""
    if v == 0:
        return "0"
    text = f"{abs(v):.{digits}g}"
    return ("+" if v > 0 else "−") + text


def tested(v) -> str:
    """A verdict's table cell: yes, no, or not tested (None: nothing to judge)."""
    return "not tested" if v is None else g(v)


def first_failure(report, test=lambda e: e["within_3sigma_at_gap_ends"] is False
                  ) -> dict[str, float | None]:
    """Smallest δ per sweep at which the filter on nonlinear telemetry fails ``test``
    (by default: leaves 3σ at a gap end; an untested case is no failure)."""
    out = {}
    for kind in KINDS:
        out[kind] = None
        for c in report["sweep"]["cases"]:
            if c["kind"] == kind and test(c["estimation"]):
                out[kind] = c["delta_deg"]
                break
    return out


def _overconfident(e) -> bool:
    return e.get("nees_verdict_real") == "overconfident"


def estimation_sentences(report) -> list[str]:
    """What the sweep says of the filter: gap-end yaw against 3σ (or that nothing
    tested it), then its NEES against the 95% bounds."""
    cases = report["sweep"]["cases"]
    parts = []
    fail = first_failure(report)
    if all(c["estimation"]["within_3sigma_at_gap_ends"] is None for c in cases):
        parts.append("Gap-end yaw is not tested: no case of the sweep has a Sun-gap end "
                     "(the run is too short).")
    elif any(v is not None for v in fail.values()):
        parts.append("The filter on nonlinear telemetry leaves its 3σ at a Sun-gap end from "
                     + " and ".join(f"δ = {v:g}° ({k})" for k, v in fail.items()
                                    if v is not None)
                     + ", where the linear twin stays consistent: there the linearization, "
                     "not the sensors, limits the estimate.")
    else:
        parts.append("The filter stays within 3σ at every Sun-gap end over the whole sweep.")
    over = first_failure(report, _overconfident)
    hi = chi2_bounds(N_STATES, 1)[1]
    if any(v is not None for v in over.values()):
        parts.append(f"Its NEES (mean over the second half of the run) is above its 95% "
                     f"bound {hi:.3g}, overconfident, from "
                     + " and ".join(f"δ = {v:g}° ({k})" for k, v in over.items()
                                    if v is not None) + ".")
    else:
        parts.append(f"Its NEES stays at or below its 95% bound {hi:.3g} over the whole "
                     "sweep.")
    low = [c for c in cases if c["estimation"].get("nees_verdict_real") == "conservative"]
    if low:
        parts.append(f"In {len(low)} of {len(cases)} cases it is below its lower bound "
                     f"{chi2_bounds(N_STATES, 1)[0]:.3g}: conservative, its σ larger than its "
                     "errors.")
    return parts


def summed_rows(b: dict) -> list[dict]:
    """The rows whose contributions add up, with the ideal, to ``sum_in_scenario``:
    those in the scenario, products of inertia once (the ±30 rows are one effect)."""
    return [r for r in b["rows"] if r["in_scenario"] and r["key"] != "products_minus30"]


def cancellation(b: dict, col: str, key: str, dominant: str | None = None) -> str | None:
    """A clause saying how terms cancel in model ``key`` (torque model or dynamics),
    or None when they do not: the largest row in the scenario is larger in
    magnitude than the total, or has the other sign.  Names the terms of the other
    sign that do it: other rows, the ideal configuration's own nonlinearity, and the
    effects' interaction (total − ideal − Σ rows).  A row already named by the
    sentence before (``dominant``, its key) is "it"."""
    rows = summed_rows(b)
    if not rows:
        return None
    big = max(rows, key=lambda r: abs(r["contribution"][col][key]))
    v, total = big["contribution"][col][key], b["total"][col][key]
    if v == 0 or (abs(v) <= abs(total) and v * total > 0):
        return None
    terms = [(r["label"], r["contribution"][col][key]) for r in rows if r is not big]
    terms += [("the ideal configuration's own nonlinearity", b["ideal"][col][key]),
              ("the effects' interaction", total - b["sum_in_scenario"][col][key])]
    against = sorted((t for t in terms if t[1] * v < 0), key=lambda t: -abs(t[1]))
    named = [t for t in against if abs(t[1]) >= NAMED_SHARE * abs(v - total)] or against[:1]
    who = [f"{label} ({signed(x)}°)" for label, x in named]
    who = ", ".join(who[:-1]) + " and " + who[-1] if len(who) > 1 else "".join(who)
    share = 100 * (v - total) / v
    what = ("more than cancelled: the total has the other sign" if v * total <= 0
            else f"{share:.0f}% of it is cancelled")
    head = ("in the {model}" if big["key"] == dominant else
            "in the {model}, {label} alone gives {v}° against a total of {total}°"
            ).format(model=MODELS[key], label=big["label"], v=signed(v), total=signed(total))
    return f"{head}: {what}" + (f", mainly by {who}" if who else "")


def budget_sentences(b: dict, sigma_yaw_deg: float) -> list[str]:
    """The dominant assumption at the scenario's own state, signed, with any
    cancellation; then the largest effect the scenario does not have."""
    col = b["columns"][0]
    parts = []
    rows = [r for r in b["rows"] if r["in_scenario"]]
    if rows:
        dom = max(rows, key=lambda r: max(abs(r["contribution"][col][k]) for k in MODELS))
        c = dom["contribution"][col]
        key = max(MODELS, key=lambda k: abs(c[k]))
        total = b["total"][col]
        parts.append(
            f"At the scenario's own state the dominant assumption is **{dom['label']}**, "
            f"through the {MODELS[key]}: {signed(c[key])}° of yaw at the Sun-gap end; the "
            f"scenario as configured totals {signed(total['torque_model_deg'])}° (torque "
            f"model) and {signed(total['dynamics_deg'])}° (dynamics), against a filter σ of "
            f"{g(sigma_yaw_deg)}°.")
        other = next(k for k in MODELS if k != key)
        clauses = [x for x in (cancellation(b, col, key, dom["key"]),
                               cancellation(b, col, other, None)) if x]
        if clauses:
            parts.append("Terms cancel " + "; and ".join(clauses) + ".")
    hyp = [r for r in b["rows"] if not r["in_scenario"]]
    if hyp:
        big = max(hyp, key=lambda r: abs(r["contribution"][col]["torque_model_deg"]))
        parts.append(f"Of the effects this scenario does not have, {big['label']} would "
                     f"matter most ({signed(big['contribution'][col]['torque_model_deg'])}°).")
    return parts


def verdict(report) -> str:
    th = {(r["sweep"], r["axis"], r["threshold"]): r["delta_star_deg"]
          for r in report["sweep"]["threshold_crossings"]}
    coeff = report["coefficients"]
    worst = max(coeff["rows"], key=lambda r: r["rel_eq7_vs_jacobian"])
    eig = coeff["eigenfrequencies"]["eq11c"]
    coeff_part = [
        f"Eq. 11's coefficients differ from the exact Jacobian of the nonlinear model by at "
        f"most {100 * worst['rel_eq7_vs_jacobian']:.2g}% ({worst['coefficient']}); Eq. 5 "
        f"(I_x = I_z) causes most of that, while Eq. 6 (dropping ω0(I_y − I)) alone shifts the "
        f"eigenfrequencies, by {100 * eig['rel_slow']:.2g}% (orbit mode) and "
        f"{100 * eig['rel_fast']:.2g}% (nutation).",
    ]
    parts = []
    a = th[("attitude", "yaw", "10% of filter sigma")]
    r = th[("rate", "yaw", "10% of filter sigma")]
    parts.append(
        f"Propagated beside the nonlinear truth, Eq. 11's yaw error exceeds 10% of the filter's "
        f"steady-state σ for initial errors above {_delta_text(a)} (attitude) and "
        f"{_delta_text(r)} (rate, as a nutation cone); below that the first-order model "
        f"is adequate, and its residual grows linearly with the error (coefficient errors), "
        f"then quadratically.")
    parts += estimation_sentences(report)
    b = report["budget"]
    # The dominant assumption first (budget), then error sizes, then the coefficients.
    budget = budget_sentences(b, report["sweep"]["thresholds"]["yaw_sigma_deg"]) if b else []
    return " ".join(budget + parts + coeff_part)


def _delta_text(v) -> str:
    if v is None:
        return f"{SWEEP_DEG[-1]:g}° (never reached)"
    if v == 0.0:
        return f"{SWEEP_DEG[0]:g}° (already at the smallest)"
    return f"{v:.2g}°"
