"""The verdicts of a run or an estimate, and the warnings they raise: summary.json's
``checks`` and ``warnings`` (docs/outputs.md).

A verdict is computed from at least one sample of what it judges, or it is
"not tested" with the reason: ``passed`` is then None (JSON null), never True.

The limits are stated, with where they come from:

- The linear range.  `dynprop linearization goes_next_equinox` (validation §4)
  found Eq. 11 propagated beside the nonlinear truth accurate to 10% of the
  filter's σ_yaw up to 0.19° of attitude error, and the paper's filter on the
  nonlinear telemetry consistent at every Sun-gap end up to 3° (attitude and
  nutation cone alike), but not at 10°.  A truth that goes further than 0.19°
  from the nominal attitude is outside the range where the linearization was
  checked accurate; further than 3°, outside where the filter was found to work.
- Real − linearized.  The difference between the filter's errors on the
  nonlinear truth and on the linear twin is what the linearization costs; above
  10% of σ_yaw (Eq. 55, the scenario's) it is no longer negligible beside the
  filter's own accuracy (the same 10% the linearization report uses).
- NEES.  The mean of the 9-state NEES after the first hour (the start-up
  transient left out, as ``studies.ekf_crossover`` does) against the 95% bounds of
  one sample, χ²(9).  A time average of a consistent filter's NEES scatters less about
  9 than one sample does, however correlated the samples, so outside those bounds
  is a real departure and inside is no evidence either way (as the Monte Carlo
  per-state test, ``montecarlo.stats.per_state_test``).
"""

from __future__ import annotations

import numpy as np

LINEAR_MODEL_RANGE_DEG = 0.19
FILTER_TESTED_RANGE_DEG = 3.0
REAL_MINUS_LINEAR_FRACTION = 0.1
# A state whose mean (e/σ)² is below this is named as making the filter conservative.
QUIET_STATE = 0.2

_SOURCE = "`dynprop linearization goes_next_equinox`, docs/validation.md §4"


def _check(passed, detail: str, **values) -> dict:
    return {"passed": passed, "detail": detail, **values}


def _not_tested(why: str, **values) -> dict:
    return _check(None, f"not tested ({why})", **values)


def gap_end_check(errors, sigmas) -> dict:
    """Gap-end yaw against the filter's 3σ (``errors`` None: no truth)."""
    if errors is None:
        return _not_tested("no truth to compare with")
    if not errors:
        return _not_tested("no Sun-gap end in the run")
    # A null error: `estimate --truth` had no truth row near that end to judge it by.
    judged = [(e, s) for e, s in zip(errors, sigmas, strict=True) if e is not None]
    if not judged:
        return _not_tested("no truth row close enough to any Sun-gap end")
    ratios = [e / s for e, s in judged]
    worst = max(range(len(ratios)), key=lambda i: abs(ratios[i]))
    inside = sum(abs(r) <= 3 for r in ratios)
    skipped = len(errors) - len(judged)
    return _check(inside == len(ratios),
                  f"{inside} of {len(ratios)} Sun-gap ends within 3σ"
                  + (f" ({skipped} not tested: no truth row near them)" if skipped else "")
                  + f", worst {judged[worst][0]:+.4f}° = {ratios[worst]:+.2f}σ",
                  ends=len(ratios), worst_over_sigma=ratios[worst])


def nees_check(mean, bounds, per_state: dict | None, who: str = "the filter",
               why_not: str = "no truth to compare with", after: str = "",
               states: int = 9) -> dict:
    """Mean NEES against the one-sample 95% bounds (module doc).  Outside them the
    filter is conservative or overconfident; inside, the test does not reject it,
    which is no proof of consistency: ``passed`` true, verdict "not rejected"."""
    if mean is None:
        return _not_tested(why_not, verdict="not tested")
    lo, hi = bounds
    head = f"mean NEES{after} {mean:.2f} (expected {states}; 95% bounds {lo:.2f}–{hi:.2f})"
    states = per_state or {}
    if mean > hi:
        loud = ", ".join(f"{k} {v:.2g}" for k, v in states.items() if v > 1)
        return _check(False, f"{head}: {who} is overconfident, its errors larger than its σ"
                      + (f" (mean (e/σ)² above 1: {loud})" if loud else ""),
                      verdict="overconfident")
    if mean < lo:
        quiet = ", ".join(f"{k} {v:.2g}" for k, v in states.items() if v < QUIET_STATE)
        return _check(False, f"{head}: {who} is conservative, its σ larger than its errors"
                      + (f" (mean (e/σ)² below {QUIET_STATE:g}: {quiet})" if quiet else ""),
                      verdict="conservative")
    return _check(True, f"{head}: not rejected (inside the bounds; no proof of "
                  "consistency)", verdict="not rejected")


def settled_nees_check(figures: dict, bounds, per_state: dict | None,
                       who: str = "the filter") -> dict:
    """``nees_check`` of a filter's NEES after the first hour (``figures``: summary.json
    or its section of another filter), not tested without truth or that hour."""
    why = ("the run is shorter than its first hour, the start-up the check leaves out"
           if figures["nees_mean"] is not None else
           "the truth holds the attitude only: an AEM has no rates, momentum or torques"
           if figures.get("yaw_error_rms_deg") is not None else "no truth to compare with")
    return nees_check(figures.get("nees_mean_after_1h"), bounds, per_state, who=who,
                      why_not=why, after=" after the first hour")


def linear_range_check(max_deg: dict | None, at_h: dict | None) -> dict:
    """How far the truth went from the nominal attitude (``max_deg``, roll and yaw,
    reached at ``at_h``), against the linear range."""
    if max_deg is None:
        return _not_tested("no truth")
    axis = max(("roll", "yaw"), key=lambda k: max_deg[k])
    top, t_h = max_deg[axis], at_h[axis]
    where = f"truth max |{axis}| {top:.3g}° at {_when(t_h)}"
    values = {"limit_deg": LINEAR_MODEL_RANGE_DEG, "filter_tested_deg": FILTER_TESTED_RANGE_DEG,
              "truth_max_abs_deg": top}
    if top > FILTER_TESTED_RANGE_DEG:
        return _check(False, f"{where}: beyond the {FILTER_TESTED_RANGE_DEG:g}° up to which "
                      f"the paper's filter was found consistent ({_SOURCE}); the "
                      "linearization is not checked here", **values)
    if top > LINEAR_MODEL_RANGE_DEG:
        return _check(False, f"{where}: beyond the {LINEAR_MODEL_RANGE_DEG:g}° up to which "
                      f"Eq. 11 was found accurate to 10% of σ_yaw ({_SOURCE}; the filter "
                      f"was found consistent up to {FILTER_TESTED_RANGE_DEG:g}°)", **values)
    return _check(True, f"{where}: inside the {LINEAR_MODEL_RANGE_DEG:g}° where Eq. 11 was "
                  "found accurate to 10% of σ_yaw", **values)


def real_minus_linear_check(comparison: dict | None, sigma_deg: float,
                            sigma_source: str = "Eq. 55") -> dict:
    """The largest |real − linearized| yaw error against a fraction of σ_yaw
    (``sigma_source`` says which σ: the filter's own at the Sun-gap ends, or Eq. 55's
    for a run without one)."""
    limit = REAL_MINUS_LINEAR_FRACTION * sigma_deg
    if comparison is None:
        return _not_tested("needs the truth and the linear twin", limit_deg=limit)
    v = comparison["yaw_deg"]["max_abs_difference"]
    rms = comparison["yaw_deg"]["rms_difference"]
    text = (f"real − linearized yaw up to {v:.2g}° (RMS {rms:.2g}°) against "
            f"{100 * REAL_MINUS_LINEAR_FRACTION:g}% of σ_yaw ({sigma_source}: "
            f"{sigma_deg:.4f}°), {limit:.2g}°")
    if v > limit:
        return _check(False, text + ": the nonlinear truth, not only the filter's model, "
                      "sets part of the error here", limit_deg=limit, value_deg=v)
    return _check(True, text, limit_deg=limit, value_deg=v)


def judged_sigma(summary: dict) -> tuple[float, str]:
    """The σ_yaw the real − linearized check judges against: the smallest of the
    filter's own σ at the Sun-gap ends (the strictest), else Eq. 55's.  The filter's σ
    is the one its errors are read against; Eq. 55's assumes the paper's sensors and the
    scenario's q, and after `dynprop tune` moved q it can be far from the filter's."""
    ends = [v for v in summary.get("yaw_sigma_at_gap_end_deg") or () if v is not None]
    if ends:
        return float(min(ends)), "the filter's smallest at a Sun-gap end"
    return summary["analytic_sigma_yaw_deg"], "Eq. 55"


def _when(t_h: float) -> str:
    return f"{t_h:.1f} h" if t_h < 72 else f"day {t_h / 24:.1f}"


# A mean NIS this far from 1 (either way) over a whole file is no statistical wobble:
# the measurement's σ in the scenario is off by more than √10 ≈ 3.2, as a unit or a
# sensor's noise entered wrong makes it.  The bundled runs' means lie within 0.53–6.0.
NIS_FAR = 10.0


def nis_check(nis: dict | None) -> dict:
    """Each measurement's mean NIS over the file against [1/NIS_FAR, NIS_FAR]."""
    means = {k: v for k, v in (nis or {}).items() if v is not None}
    if not means:
        return _not_tested("no measurement update")
    far = {k: v for k, v in means.items() if not 1 / NIS_FAR <= v <= NIS_FAR}
    worst = max(means, key=lambda k: abs(np.log(max(means[k], 1e-300))))
    numbers = {"means": means, "worst": worst, "worst_mean": means[worst]}
    text = ", ".join(f"{k} {v:.3g}" for k, v in means.items())
    if far:
        named = ", ".join(f"{k} {v:.2g}" for k, v in far.items())
        return _check(False, f"mean NIS {named}, expected near 1 (within {1 / NIS_FAR:g}–"
                      f"{NIS_FAR:g}): the measurement's σ in the scenario is far from its "
                      "scatter in the data; likely causes: the file's unit (--unit), or the "
                      "sensor's noise or quantum in the scenario (sensors.earth, "
                      "sensors.sun, sensors.tachometer)", **numbers)
    return _check(True, f"mean NIS {text}, within {1 / NIS_FAR:g}–{NIS_FAR:g} of 1",
                  **numbers)


def pitch_nees_check(pitch: dict | None) -> dict:
    """The pitch filter's mean NEES after the first hour against χ²(3)'s one-sample 95%
    bounds (as the 9-state one, module doc)."""
    if not isinstance(pitch, dict):
        return _not_tested("no pitch filter (the telemetry has no pitch_deg)",
                           verdict="not tested")
    if pitch.get("nees_mean_after_1h") is None and pitch.get("nees_mean") is not None:
        return _not_tested("the run is shorter than its first hour, the start-up the "
                           "check leaves out", verdict="not tested")
    mean = pitch.get("nees_mean_after_1h")
    return nees_check(mean, pitch["nees_bounds_95"], None, who="the pitch filter",
                      after=" after the first hour", states=3) | {
        "nees_mean_after_1h": mean, "bounds": list(pitch["nees_bounds_95"])}


def run_checks(summary: dict) -> dict:
    """The ``checks`` section from a summary's figures."""
    per_state = summary.get("nees_mean_per_state")
    checks = {
        "gap_end_yaw_within_3sigma": gap_end_check(summary["yaw_error_at_gap_end_deg"],
                                                   summary["yaw_sigma_at_gap_end_deg"]),
        "nees": settled_nees_check(summary, summary["nees_bounds_95_per_sample"], per_state),
        "linear_range": linear_range_check(summary.get("truth_max_abs_deg"),
                                           summary.get("truth_max_abs_at_h")),
        "real_minus_linear": real_minus_linear_check(summary["nonlinear_vs_linear"],
                                                     *judged_sigma(summary)),
        "nis": nis_check(summary.get("nis_mean")),
    }
    if "pitch" in summary:
        checks["pitch_nees"] = pitch_nees_check(summary["pitch"])
    return checks


def other_filter_checks(name: str, section: dict, bounds) -> dict:
    """The gap-end and NEES verdicts of a filter beside the paper's (its summary
    section, e.g. ``ekf``), keyed ``<name>_…``."""
    who = f"the {name.upper()}"
    return {f"{name}_gap_end_yaw_within_3sigma": gap_end_check(
                section["yaw_error_at_gap_end_deg"], section["yaw_sigma_at_gap_end_deg"]),
            f"{name}_nees": settled_nees_check(section, bounds, None, who=who)}


def warnings_of(checks: dict) -> list[dict]:
    """One warning per failed check, ``check`` naming it, ``message`` saying what and
    why.  An untested check is no warning: its own detail says why it is untested."""
    return [{"check": name, "message": c["detail"]}
            for name, c in checks.items() if c["passed"] is False]


def add_checks(summary: dict) -> dict:
    """``summary`` with ``checks`` and ``warnings`` (the paper's filter's, then each
    other filter's in ``filters``)."""
    # Last in the file, however often added: one key order for every summary.
    summary.pop("checks", None)
    summary.pop("warnings", None)
    checks = run_checks(summary)
    for name in summary.get("filters", ()):
        if name != "paper" and isinstance(summary.get(name), dict):
            checks.update(other_filter_checks(name, summary[name],
                                              summary["nees_bounds_95_per_sample"]))
    summary["checks"] = checks
    summary["warnings"] = warnings_of(checks) + telemetry_warnings(summary)
    return summary


def telemetry_warnings(summary: dict) -> list[str]:
    """A line per telemetry gap longer than ``estimator.max_gap_s`` (`estimate`'s
    telemetry section): accepted, and worth knowing, since the covariance grows
    across it."""
    from .screen import screen_warnings
    tel = summary.get("telemetry")
    gaps = tel.get("gaps_over_max_gap_h") if isinstance(tel, dict) else None
    screened = screen_warnings(tel.get("screened")) if isinstance(tel, dict) else []
    return screened + [{"check": "telemetry_gaps",
             "message": f"telemetry gap of {length:.3g} h from {start:.3g} h is longer than "
             "estimator.max_gap_s: no measurement across it, the covariance grows with the "
             "process noise"} for start, length in gaps or ()]
