"""`dynprop linearization`: assemble the report (report.json, report.md, figures).

report.md is rendered from the same dictionary that is written to report.json,
number by number, so the two cannot disagree.
"""

from __future__ import annotations

import json
from pathlib import Path

from dynprop.estimator.kalman.consistency import chi2_bounds
from dynprop.estimator.linear.model import N_STATES

from .. import __version__
from ..config import build
from ..config.schema import Scenario
from .analysis import KINDS, run_budget, run_sweep, threshold_table
from .coefficients import coefficient_section
from .propagation import SWEEP_DEG, set_flags
from .verdict import g, tested, verdict

FIGURES = ("coefficients.png", "divergence_time.png", "divergence_sweep.png", "budget.png",
           "estimation.png")


def build_report(s: Scenario, command: str, progress=None) -> tuple[dict, dict]:
    """Run everything; returns the report dictionary and the arrays for the figures."""
    sweep = run_sweep(s, progress)
    coeff = coefficient_section(build.build_spacecraft(s), build.orbit(s),
                                sweep.thresholds.get("H_ptp_Nms"))
    budget = run_budget(s, sweep.gap, progress=progress) if sweep.gap else None
    report = {
        "meta": {"scenario": s.name, "seed": s.seed, "epoch_utc": s.epoch_utc,
                 "duration_s": s.duration_s, "sample_interval_s": s.sample_interval_s,
                 "command": command, "dynprop_version": __version__,
                 "sweep_deg": list(SWEEP_DEG)},
        "coefficients": coeff,
        "sweep": {"cases": sweep.cases, "thresholds": sweep.thresholds,
                  "threshold_crossings": threshold_table(sweep),
                  "gap_samples": list(sweep.gap) if sweep.gap else None},
        "budget": budget,
    }
    report["verdict"] = verdict(report)
    return report, {"envelopes": sweep.envelopes}


# --- Markdown -----------------------------------------------------------------------

def _table(header: list[str], rows: list[list[str]]) -> str:
    out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    out += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(out)


def _source(report) -> str:
    m = report["meta"]
    return (f"*Scenario `{m['scenario']}`, seed {m['seed']}, epoch {m['epoch_utc']}, "
            f"{m['duration_s'] / 86400:g} d at {m['sample_interval_s']} s. "
            f"Reproduce: `{m['command']}`.*")


def render_markdown(report: dict) -> str:
    m, c, sw, b = report["meta"], report["coefficients"], report["sweep"], report["budget"]
    src = _source(report)
    i = c["inputs"]
    L = [f"# Linearization validation: {m['scenario']}", "",
         f"dynprop {m['dynprop_version']}. {src}", "", "## Verdict", "", report["verdict"], ""]
    L += ["## 1. Coefficients: the Jacobian against the paper", "",
          f"The CasADi Jacobian of the simulator's own gyrostat at the nominal state "
          f"(I_x = {g(i['Ix_kgm2'], 7)}, I_y = {g(i['Iy_kgm2'], 7)}, I_z = {g(i['Iz_kgm2'], 7)} "
          f"kg m², products {i['products_kgm2']} kg m², H = {g(i['H_Nms'], 7)} N m s signed, "
          f"ω0 = {g(i['omega0_radps'], 7)} rad/s, I = {g(i['I_kgm2'], 7)} kg m², "
          f"ω_n = {g(i['omega_n_radps'], 6)} rad/s, ω0(I_y − I)/H = {g(i['eq6_ratio'])}), "
          "against the unapproximated Eqs. 3a–3c and the approximated Eqs. 7a–7b (Eq. 11c "
          "in model units). Units are SI (1/s², 1/s, 1/(kg m² s), 1/(kg m²)). The last three "
          "columns apply one approximation at a time.", "", src, ""]
    rows = [[r["coefficient"], r["equation"], g(r["jacobian"], 6), g(r["eq3"], 6),
             g(r["rel_jacobian_vs_eq3"]), g(r["eq7"], 6), g(r["rel_eq7_vs_jacobian"]),
             g(r["rel_eq5_only"]), g(r["rel_eq6_only"]), g(r["rel_products"])]
            for r in c["rows"]]
    L += [_table(["coefficient", "Eq.", "Jacobian", "Eq. 3", "rel. Jac−Eq. 3", "Eq. 7/11c",
                  "rel. Eq. 7−Jac", "Eq. 5 only", "Eq. 6 only", "products ±30"], rows), ""]
    L += ["Pitch rows carry Eq. 3b; Eq. 5 is not applied to pitch in the paper, so the "
          "pitch/pitch 'Eq. 5 only' entry shows what it would do (I_x = I_z removes the pitch "
          "gravity-gradient stiffness).", ""]
    o = c["omitted"]
    L += ["Terms the paper sets to zero (largest |Jacobian entry|, SI):", "", src, ""]
    orow = [["as configured"] + [g(o[k]) for k in o]]
    orow += [[f"products {k} kg m²"] + [g(v[kk]) for kk in v]
             for k, v in c["omitted_with_products"].items()]
    L += [_table(["inertia", "pitch → roll/yaw", "roll/yaw → pitch", "other state terms",
                  "other input terms"], orow), ""]
    L += ["Constant H: ∂(accelerations)/∂H is zero at the nominal state (H multiplies rates "
          "and angles), so a varying H is a second-order effect; its first-order trace is "
          "a change of ω_n ∝ H, shown below with the peak-to-peak H of the nominal run "
          f"(ΔH = {g(i['H_range_Nms'])} N m s). Pitch decoupling: exact to first order for a "
          "diagonal tensor (round-off above), broken by products of inertia.", ""]
    L += [f"Model matrix (5×5, model units): max relative difference Jacobian vs Eq. 11 = "
          f"{g(c['model_matrix']['max_rel_difference'])}.", ""]
    L += ["Eigenfrequencies of the roll/yaw block (rad/s) and their relative change against "
          "the Jacobian:", "", src, ""]
    labels = {"jacobian": "Jacobian (exact)", "eq11c": "Eq. 11c (Eqs. 5 + 6)",
              "eq5_only": "Eq. 5 only", "eq6_only": "Eq. 6 only",
              "products_+30": "products +30 kg m²", "products_-30": "products −30 kg m²",
              "H_plus": "H + ΔH", "H_minus": "H − ΔH"}
    erows = [[labels.get(k, k), g(v["omega_slow_radps"], 7), g(v["rel_slow"]),
              g(v["omega_fast_radps"], 7), g(v["rel_fast"])]
             for k, v in c["eigenfrequencies"].items()]
    L += [_table(["model", "ω slow (≈ ω0)", "rel.", "ω fast (≈ |ω_n|)", "rel."], erows), ""]
    L += ["![coefficients](coefficients.png)", ""]

    th = sw["thresholds"]
    L += ["## 2. Propagation: nonlinear against linear", "",
          "The nonlinear truth and a linear model start from the same deviation and are "
          "driven by the same torques: the true external roll/yaw torques and the true "
          "N_w = ḣ. Divergence = linear − nonlinear, maximum over the run. `eq11` is the "
          "filter's model, `jacobian` the exact first-order model. Attitude sweep: roll, "
          "pitch and yaw each start δ off; rate sweep: roll, pitch and yaw rates δ·|ω_n| "
          "(a nutation cone of half-angle δ). Each case is "
          f"`{m['command']}` with the case's overrides; they are in report.json "
          "(`sweep.cases[].overrides`).", "", src, ""]
    drows = []
    for cse in sw["cases"]:
        d = cse["divergence"]
        drows.append([cse["kind"], g(cse["delta_deg"]), g(d["eq11"]["max_roll_deg"]),
                      g(d["eq11"]["max_yaw_deg"]), g(d["eq11"].get("gap_yaw_deg")),
                      g(d["jacobian"]["max_roll_deg"]), g(d["jacobian"]["max_yaw_deg"]),
                      g(d["jacobian"].get("gap_yaw_deg"))])
    L += [_table(["sweep", "δ (deg)", "eq11 roll (deg)", "eq11 yaw (deg)",
                  "eq11 yaw, gap only (deg)", "jacobian roll (deg)", "jacobian yaw (deg)",
                  "jacobian yaw, gap only (deg)"], drows), ""]
    L += [f"Thresholds: filter steady-state σ_roll = {g(th['roll_sigma_deg'])}°, σ_yaw = "
          f"{g(th['yaw_sigma_deg'])}° ({th['yaw_sigma_from']}); Earth-sensor "
          f"noise {g(th['earth_sensor_noise_deg'])}° (1σ). Error size δ* at which the eq11 "
          "divergence first exceeds each (log–log interpolation; — = not within 10°):", "", src, ""]
    trows = [[r["sweep"], r["axis"], r["threshold"], g(r["level_deg"]),
              f"< {SWEEP_DEG[0]:g}" if r["delta_star_deg"] == 0.0 else g(r["delta_star_deg"])]
             for r in sw["threshold_crossings"]]
    L += [_table(["sweep", "axis", "threshold", "level (deg)", "δ* (deg)"], trows), ""]
    L += ["![divergence against time](divergence_time.png)", "",
          "![divergence against initial error](divergence_sweep.png)", ""]
    if b:
        col0, col1 = b["columns"]
        L += ["### Error budget at the end of the Sun gap", "",
              f"Eq. 11 restarted on the truth at the start of the first Sun gap "
              f"({g(b['gap_h'][0], 4)}–{g(b['gap_h'][1], 4)} h) and propagated to its end. "
              "`dynamics`: driven by the true torques; `torque model`: driven by the paper's "
              "torque model instead (N* plus the constant + ω0-sinusoid states of Eqs. 9 and 18 "
              "fitted over the run). The ideal configuration makes every assumption of Eq. 11 "
              f"true: `{set_flags(b['ideal_overrides'])}`. Each row switches one effect on in "
              "it; its contribution is the row's yaw error minus the ideal's. Columns: the "
              f"scenario's initial state (`{col0}`), and with 1° roll and yaw error added "
              f"(`{col1}`).", "", src, ""]
        brows = []
        for r in b["rows"]:
            c0, c1 = r["contribution"][col0], r["contribution"][col1]
            brows.append([r["label"], g(r["in_scenario"]), g(c0["dynamics_deg"]),
                          g(c0["torque_model_deg"]), g(c1["dynamics_deg"]),
                          g(c1["torque_model_deg"]), g(r["H_ptp_Nms"][col0]),
                          f"`{set_flags(r['changes'])}`"])
        for key, label in (("ideal", "ideal configuration (nonlinearity alone)"),
                           ("sum_in_scenario", "ideal + Σ rows in scenario"),
                           ("total", "**total: scenario as configured**")):
            v0, v1 = b[key][col0], b[key][col1]
            brows.append([label, "", g(v0["dynamics_deg"]), g(v0["torque_model_deg"]),
                          g(v1["dynamics_deg"]), g(v1["torque_model_deg"]), "", ""])
        L += [_table(["effect", "in scenario", f"dynamics, {col0} (deg)",
                      f"torque model, {col0} (deg)", f"dynamics, {col1} (deg)",
                      f"torque model, {col1} (deg)", "H p-p (N m s)", "overrides"], brows), ""]
        L += ["![error budget](budget.png)", ""]
    L += ["## 3. Estimation consequence", "",
          "The same filter on telemetry from the nonlinear truth (real) and from the linear "
          "twin (linearized), as in `dynprop run`, for every case of the sweep. NEES over the "
          f"second half of the run (9 states; 95% per-sample χ²(9) bounds "
          f"{g(chi2_bounds(N_STATES, 1)[0])}–{g(chi2_bounds(N_STATES, 1)[1])}; a mean "
          "outside them is a real departure, as summary.json's `checks.nees`: "
          "`overconfident` above, `conservative` below).", "", src, ""]
    erows = []
    for cse in sw["cases"]:
        e = cse["estimation"]
        erows.append([cse["kind"], g(cse["delta_deg"]),
                      ", ".join(g(v) for v in e["yaw_error_gap_end_real_deg"]) or "—",
                      ", ".join(g(v) for v in e["yaw_error_gap_end_linear_deg"]) or "—",
                      ", ".join(g(v) for v in e["yaw_sigma_gap_end_deg"]) or "—",
                      g(e["nees_mean_real"]), g(e["nees_mean_linear"]),
                      tested(e["within_3sigma_at_gap_ends"]), e["nees_verdict_real"],
                      e["nees_verdict_linear"]])
    L += [_table(["sweep", "δ (deg)", "yaw err at gap ends, real (deg)",
                  "linearized (deg)", "filter σ (deg)", "NEES real", "NEES linearized",
                  "real within 3σ", "NEES real, verdict", "NEES linearized, verdict"],
                 erows), ""]
    if not any(c["estimation"]["yaw_error_gap_end_real_deg"] for c in sw["cases"]):
        L += ["Gap-end yaw is not tested: no case of the sweep has a Sun-gap end "
              "(the run is too short to hold one): the last column judges nothing.", ""]
    L += ["![estimation consequence](estimation.png)", ""]
    L += ["### The paper's filter against an extended Kalman filter", "",
          "The EKF (`estimator.filters: [paper, ekf]`, docs/validation.md §8) on the same "
          "nonlinear-truth telemetry: the full gyrostat, quaternion attitude, an iterated "
          "update.  Where the paper's filter leaves 3σ and the EKF does not, the linear "
          "filter is what fails, not the sensors or the tuning.", "", src, ""]
    krows, first_fail = [], None
    for cse in sw["cases"]:
        e = cse["estimation"]
        if "nees_mean_ekf" not in e:
            continue
        ratio = ", ".join(f"{x / sg:+.2f}" for x, sg in zip(e["yaw_error_gap_end_real_deg"],
                                                          e["yaw_sigma_gap_end_deg"],
                                                          strict=True)) or "—"
        ratio_e = ", ".join(f"{x / sg:+.2f}" for x, sg in zip(
            e["yaw_error_gap_end_ekf_deg"], e["yaw_sigma_gap_end_ekf_deg"], strict=True)) or "—"
        krows.append([cse["kind"], g(cse["delta_deg"]), ratio, ratio_e,
                      g(e["nees_mean_real"]), g(e["nees_mean_ekf"]),
                      tested(e["within_3sigma_at_gap_ends"]),
                      tested(e["ekf_within_3sigma_at_gap_ends"]), e["nees_verdict_ekf"]])
        if (first_fail is None and e["within_3sigma_at_gap_ends"] is False
                and e["ekf_within_3sigma_at_gap_ends"] is True):
            first_fail = (cse["kind"], cse["delta_deg"])
    if krows:
        L += [_table(["sweep", "δ (deg)", "gap-end yaw error / σ, paper", "EKF",
                      "NEES paper", "NEES EKF", "paper within 3σ", "EKF within 3σ",
                      "NEES EKF, verdict"],
                     krows), ""]
        untested = all(c["estimation"]["within_3sigma_at_gap_ends"] is None
                       for c in sw["cases"])
        L += [("Not tested: no case has a Sun-gap end to compare the two filters at."
               if untested else
               "The paper's filter first leaves 3σ where the EKF stays inside at the "
               f"{first_fail[0]} sweep's δ = {g(first_fail[1])}°." if first_fail else
               "In no case does the paper's filter leave 3σ while the EKF stays inside."), ""]
    return "\n".join(L)


def write_report(out: Path, report: dict, arrays: dict) -> list[Path]:
    (out / "report.json").write_text(json.dumps(report, indent=1, allow_nan=False) + "\n")
    (out / "report.md").write_text(render_markdown(report))
    return draw_figures(out, report, arrays)


def draw_figures(out: Path, report: dict, arrays: dict) -> list[Path]:
    from ..figures.linearization import draw_report_figures
    return draw_report_figures(out, report, arrays, SWEEP_DEG, KINDS)
