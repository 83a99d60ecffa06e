"""What `run` and `estimate` print: the verdicts of summary.json's ``checks``, a
line per filter, then one line per warning.  Reads the summary only, so the console
and the file agree."""

from __future__ import annotations


def _gap_ends(summary: dict) -> str:
    errs, sigs = summary["yaw_error_at_gap_end_deg"], summary["yaw_sigma_at_gap_end_deg"]
    check = summary["checks"]["gap_end_yaw_within_3sigma"]
    if check["passed"] is None:
        return f"Sun-gap-end yaw {check['detail']}"
    verdict = "all within 3 sigma" if check["passed"] else "NOT all within 3 sigma"
    if len(errs) <= 6:
        # (None: `estimate --truth` had no truth row near that end.)
        ends = ", ".join("not tested" if e is None else f"{e:+.4f}" for e in errs)
        sig = ", ".join(f"{e:.4f}" for e in sigs)
        return f"at Sun-gap ends {ends} deg (filter sigma {sig}): {verdict}"
    # A season of gap ends: the worst one, and where the rest are (daily.csv).
    return f"{check['detail']} (daily.csv)"


def _real_minus_linear(summary: dict) -> str:
    check = summary["checks"]["real_minus_linear"]
    if check["passed"] is None:
        return f"real - linearized {check['detail']}"
    yaw = summary["nonlinear_vs_linear"]["yaw_deg"]
    ok = "below" if check["passed"] else "ABOVE"
    return (f"real - linearized yaw max {yaw['max_abs_difference']:.2g} deg, {ok} "
            f"{check['limit_deg']:.2g} (10% of sigma)")


def _nees(check: dict) -> str:
    if check["passed"] is None:
        return f"NEES {check['detail']}"
    return check["detail"].split(": ")[0] + f": {check['verdict']}"


def _ekf_line(summary: dict) -> list[str]:
    e = summary.get("ekf")
    if e is None or e["yaw_error_rms_deg"] is None:
        return []
    c = summary["checks"]
    return [f"EKF: yaw error RMS {e['yaw_error_rms_deg']:.4f} deg; "
            + _gap_ends({**e, "checks": {"gap_end_yaw_within_3sigma":
                                         c["ekf_gap_end_yaw_within_3sigma"]}})
            + "; " + _nees(c["ekf_nees"])]


def estimate_lines(name: str, summary: dict, step_s: float, seconds: float) -> list[str]:
    """The console report of `estimate`: what was filtered, then the verdicts as
    `run` gives them (errors only with a truth, at the rows it has), then warnings."""
    tel = summary["telemetry"]
    gaps = tel.get("cadence_note") or (
        f"{tel['missing_steps']} without a row, {tel['dropouts']} dropouts, longest "
        f"{tel['longest_dropout_s']:g} s")
    if tel.get("on_filter_grid", True):
        lines = [f"{name}: filtered {tel['rows']} telemetry rows on {tel['filter_steps']} "
                 f"steps of {step_s:g} s ({gaps}) in {seconds:.1f} s"]
    else:
        lines = [f"{name}: filtered {tel['rows']} telemetry rows, each at its own time "
                 f"({tel['dropouts']} dropouts, longest {tel['longest_dropout_s']:g} s; "
                 f"{tel['cadence_note']}) in {seconds:.1f} s"]
    eq55 = f"Eq. 55: {summary['analytic_sigma_yaw_deg']:.4f} deg"
    sigmas = summary["yaw_sigma_at_gap_end_deg"]
    if summary["yaw_error_rms_deg"] is None:
        at_ends = (f"filter yaw sigma at Sun-gap ends {', '.join(f'{e:.4f}' for e in sigmas)}"
                   f" deg" if sigmas else
                   "no Sun-gap end in the telemetry: gap-end yaw not tested")
        lines.append(f"{at_ends}; {eq55}; no --truth, so no errors")
    else:
        cadence = tel["compared_cadence_s"]
        every = "" if cadence is None else f", every {cadence:g} s"
        lines.append(f"errors on the {tel['compared_rows']} samples the truth has a row "
                     f"for{every}: yaw error RMS {summary['yaw_error_rms_deg']:.4f} deg; "
                     f"{_gap_ends(summary)}; {_nees(summary['checks']['nees'])}; {eq55}")
        judged = [t for t in tel.get("gap_end_compared_at_s") or () if t is not None]
        if judged and tel["compared_rows"] < tel["filter_steps"]:
            # A truth coarser than the telemetry: say which sample each end was judged at.
            lines.append("the truth is coarser than the telemetry: Sun-gap ends judged at "
                         "the last truth row inside each gap, t = "
                         + ", ".join(f"{t:.3f}" for t in judged) + " s (docs/outputs.md)")
        lines += _ekf_line(summary)
    lines += _pitch_line(summary)
    lines += _bias_and_gate(summary)
    lines += [f"warning: {w['message']}" for w in summary["warnings"]]
    return lines


def _pitch_line(summary: dict) -> list[str]:
    """The pitch filter's line (Eq. 3b), when it ran."""
    p = summary.get("pitch")
    if not p or p["sigma_pitch_mean_after_1h_deg"] is None:
        return []
    sigma = f"σ {p['sigma_pitch_mean_after_1h_deg']:.4f} deg"
    if p["sigma_pitch_steady_state_deg"] is not None:
        sigma += f" (its model's steady state {p['sigma_pitch_steady_state_deg']:.4f})"
    if p["pitch_error_rms_after_1h_deg"] is None:
        return [f"pitch filter (Eq. 3b): {sigma}; no truth, so no errors"]
    parts = [f"pitch filter (Eq. 3b): error RMS {p['pitch_error_rms_after_1h_deg']:.4f} deg",
             sigma, f"{100 * p['pitch_within_3sigma_fraction_after_1h']:.2f}% within 3σ"]
    if p["nees_mean_after_1h"] is not None:
        lo, hi = p["nees_bounds_95"]
        parts.append(f"mean NEES {p['nees_mean_after_1h']:.2f} (3 states; 95% bounds "
                     f"{lo:.2f}–{hi:.2f})")
    return ["; ".join(parts) + " (after the first hour)"]


def _bias_and_gate(summary: dict) -> list[str]:
    """A line for the bias states and one for the gate, when the run had them."""
    lines = []
    biases = summary.get("bias_states")
    if biases:
        parts = []
        for name, b in biases.items():
            truth = "" if b["truth_deg"] is None else f" (truth {b['truth_deg']:.4f})"
            parts.append(f"{name} {b['estimate_deg']:.4f} ± {b['sigma_deg']:.4f}{truth}")
        lines.append("bias states, deg: " + "; ".join(parts))
    gate = summary.get("outliers")
    if gate:
        r = gate["rejected"]
        heads = ", ".join(f"{k} {v}" for k, v in gate["rejected_yaw_by_head"].items())
        lines.append(f"outlier gate χ² > {gate['gate_chi2']:g}: rejected roll {r['roll']}, "
                     f"yaw {r['yaw']} ({heads}), h {r['h']}")
    return lines


def run_lines(name: str, summary: dict, seconds: float) -> list[str]:
    """The console report of a run: its headline, then its warnings."""
    parts = [f"yaw error RMS {summary['yaw_error_rms_deg']:.4f} deg", _gap_ends(summary),
             _real_minus_linear(summary), _nees(summary["checks"]["nees"]),
             f"Eq. 55: {summary['analytic_sigma_yaw_deg']:.4f} deg", f"{seconds:.1f} s"]
    lines = [f"{name}: " + "; ".join(parts)] + _ekf_line(summary) + _pitch_line(summary) \
        + _bias_and_gate(summary)
    lines += [f"warning: {w['message']}" for w in summary["warnings"]]
    return lines
