"""The runs behind the linearization report: the error sweep (Sections 2 and 3) and
the per-effect error budget (Section 2).

Every run reuses the one compiled truth step and the compiled linear rollouts;
only parameters and inputs change between runs.  Each run is reduced to scalars
and |divergence| envelopes as soon as it finishes, so memory stays at one run.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from dynprop.eom.linear import eq5_inertia
from dynprop.estimator.kalman.consistency import chi2_bounds, fraction_inside, nees
from dynprop.estimator.kalman.filter import unpack
from dynprop.estimator.linear.model import N_STATES, R, Y

from ..config import build
from ..config.schema import Scenario
from ..config.sections import Solar
from ..files.checks import nees_check
from ..run.ekf import run_ekf
from ..run.simulate import simulate
from ..run.statistics import nees_series
from ..run.whole import run_scenario
from ..samples import sun_gaps
from .propagation import (
    DEG,
    SWEEP_DEG,
    Change,
    divergence,
    envelope,
    gap_yaw_errors,
    linear_models,
    model_inputs,
    model_state,
    sweep_changes,
    variant,
)

KINDS = ("attitude", "rate")


@dataclass
class SweepOutput:
    cases: list[dict]          # one per (kind, δ), δ = 0 first: the JSON part
    envelopes: dict            # (kind, δ) -> {"t_s", "eq11_yaw", "eq11_roll", ...}
    gap: tuple[int, int] | None
    thresholds: dict


def _gap(tel, s: Scenario):
    present = tel.yaw_head >= 0
    gaps = sun_gaps(present, s.sample_interval_s, s.estimator.sun_gap_min_h)
    return present, [(int(a), int(b)) for a, b in gaps]


def _ekf(v: Scenario, runs):
    """The extended Kalman filter on the case's own (nonlinear-truth) telemetry."""
    tel = runs.sim.telemetry
    head = np.where(tel.yaw_head >= 0, tel.yaw_head, np.nan)
    return run_ekf(v, tel.roll_rad, tel.pitch_rad, tel.yaw_rad, tel.wheel_speeds_radps,
                   tel.yaw_sigma_rad, head)


def _estimation(runs, present, gaps, ekf=None) -> dict:
    """Filter on nonlinear and on linear telemetry, and the EKF on the nonlinear:
    yaw at the gap ends and NEES over the second half of the run (after the
    start-up transient)."""
    ends = [b for _, b in gaps if b < len(present)]
    err = runs.real.x - runs.truth_model
    err_lin = runs.linear.x - runs.twin_model
    idx, n_real, n_lin = nees_series(runs)
    late = idx >= len(present) // 2
    bounds = chi2_bounds(N_STATES, 1)
    mean_real, mean_lin = float(np.mean(n_real[late])), float(np.mean(n_lin[late]))
    out = {
        "yaw_error_gap_end_real_deg": [float(err[b, Y] / DEG) for b in ends],
        "yaw_error_gap_end_linear_deg": [float(err_lin[b, Y] / DEG) for b in ends],
        "yaw_sigma_gap_end_deg": [float(runs.real.sigma[b, Y] / DEG) for b in ends],
        "yaw_rms_real_deg": float(np.sqrt(np.mean(err[:, Y] ** 2)) / DEG),
        "yaw_rms_linear_deg": float(np.sqrt(np.mean(err_lin[:, Y] ** 2)) / DEG),
        "nees_mean_real": mean_real,
        "nees_mean_linear": mean_lin,
        "nees_inside_95_real": fraction_inside(n_real[late], bounds),
        "nees_inside_95_linear": fraction_inside(n_lin[late], bounds),
        # None (not tested) without a gap end: never a vacuous True.
        "within_3sigma_at_gap_ends": _within(err, runs.real.sigma, ends),
        "nees_verdict_real": nees_check(mean_real, bounds, None)["verdict"],
        "nees_verdict_linear": nees_check(mean_lin, bounds, None)["verdict"],
    }
    if ekf is not None:
        err_e = ekf.x - runs.truth_model
        n_e = nees(ekf.x[idx], unpack(ekf.P_packed[idx]), runs.truth_model[idx])
        out.update({
            "yaw_error_gap_end_ekf_deg": [float(err_e[b, Y] / DEG) for b in ends],
            "yaw_sigma_gap_end_ekf_deg": [float(ekf.sigma[b, Y] / DEG) for b in ends],
            "nees_mean_ekf": float(np.mean(n_e[late])),
            "nees_verdict_ekf": nees_check(float(np.mean(n_e[late])), bounds, None)["verdict"],
            "ekf_within_3sigma_at_gap_ends": _within(err_e, ekf.sigma, ends)})
    return out


def _within(err, sigma, ends) -> bool | None:
    """Every gap-end yaw error within 3σ; None when there is no gap end to judge."""
    if not ends:
        return None
    return bool(all(abs(err[b, Y]) <= 3 * sigma[b, Y] for b in ends))


def run_sweep(s: Scenario, progress=None) -> SweepOutput:
    """δ = 0 and the attitude and rate sweeps, each a full `dynprop run` (no smoother)."""
    params, _ = build.estimator_model(s)
    wn, dt = params.omega_n_radps, s.sample_interval_s
    models = linear_models(s)
    cases, envs, gap, thresholds = [], {}, None, {}
    plan = [("none", 0.0)] + [(k, d) for k in KINDS for d in SWEEP_DEG]
    for kind, delta in plan:
        changes = [] if kind == "none" else sweep_changes(s, kind, delta, wn)
        v = variant(s, changes)
        runs = run_scenario(v, smooth=False)
        truth = runs.sim.truth
        present, gaps = _gap(runs.sim.telemetry, v)
        if kind == "none":
            complete = [g for g in gaps if g[1] < len(present)]
            gap = complete[0] if complete else None
            thresholds = _thresholds(s, runs, complete)
            # The pitch loop's wheel-speed (H) variation, for the eigenfrequency table.
            thresholds["H_ptp_Nms"] = float(np.ptp(truth.H_Nms))
        x5, u = model_state(truth, wn), model_inputs(truth, dt)
        div, env = {}, {"t_s": truth.t_s[::64]}
        for name, m in models.items():
            e = divergence(x5, u, m)
            d = {"max_roll_deg": float(np.abs(e[:, 0]).max() / DEG),
                 "max_yaw_deg": float(np.abs(e[:, 2]).max() / DEG),
                 "max_h_Nms": float(np.abs(e[:, 4]).max())}
            if gap is not None:
                eg = divergence(x5, u, m, *gap)
                d["gap_yaw_deg"] = float(eg[-1, 2] / DEG)
            div[name] = d
            env[f"{name}_roll"] = envelope(e[:, 0] / DEG)
            env[f"{name}_yaw"] = envelope(e[:, 2] / DEG)
        env["t_s"] = truth.t_s[::64][:len(env["eq11_yaw"])]
        cases.append({"kind": kind, "delta_deg": delta, "overrides": changes,
                      "divergence": div,
                      "estimation": _estimation(runs, present, gaps, _ekf(v, runs))})
        envs[(kind, delta)] = env
        del runs, truth
        if progress:
            progress()
    return SweepOutput(cases, envs, gap, thresholds)


def _thresholds(s: Scenario, runs, gaps) -> dict:
    """10 % of the filter's steady-state σ (roll: median over the second half of the
    δ = 0 run; yaw: at its last Sun-gap end, the yaw σ's daily maximum), and the Earth
    sensor's 1σ noise."""
    n = len(runs.real.sigma)
    roll_sigma = float(np.median(runs.real.sigma[n // 2:, R]) / DEG)
    ends = [b for _, b in gaps]
    yaw_sigma = float(runs.real.sigma[ends[-1], Y] / DEG) if ends else \
        float(np.max(runs.real.sigma[n // 2:, Y]) / DEG)
    where = ("at the last Sun-gap end of the δ = 0 run" if ends else
             "the largest over the second half of the δ = 0 run, which has no Sun-gap end")
    return {"roll_sigma_deg": roll_sigma, "yaw_sigma_deg": yaw_sigma, "yaw_sigma_from": where,
            "ten_percent_roll_sigma_deg": 0.1 * roll_sigma,
            "ten_percent_yaw_sigma_deg": 0.1 * yaw_sigma,
            "earth_sensor_noise_deg": float(s.sensors.earth.noise_deg)}


def crossing(deltas, values, level: float) -> float | None:
    """The error size at which ``values`` (increasing with ``deltas``) first exceeds
    ``level``, interpolated on log–log axes; 0.0 if already above at the smallest δ,
    None if never reached."""
    d, v = np.asarray(deltas, float), np.asarray(values, float)
    above = np.flatnonzero(v > level)
    if above.size == 0:
        return None
    k = above[0]
    if k == 0:
        return 0.0
    x0, x1, y0, y1 = np.log(d[k - 1]), np.log(d[k]), np.log(v[k - 1]), np.log(v[k])
    return float(np.exp(x0 + (np.log(level) - y0) * (x1 - x0) / (y1 - y0)))


def threshold_table(out: SweepOutput, model: str = "eq11") -> list[dict]:
    rows = []
    levels = {"10% of filter sigma": ("ten_percent_roll_sigma_deg", "ten_percent_yaw_sigma_deg"),
              "Earth-sensor noise": ("earth_sensor_noise_deg", "earth_sensor_noise_deg")}
    for kind in KINDS:
        cs = [c for c in out.cases if c["kind"] == kind]
        deltas = [c["delta_deg"] for c in cs]
        for axis, key, li in (("roll", "max_roll_deg", 0), ("yaw", "max_yaw_deg", 1)):
            vals = [c["divergence"][model][key] for c in cs]
            for label, keys in levels.items():
                level = out.thresholds[keys[li]]
                rows.append({"sweep": kind, "axis": axis, "threshold": label,
                             "level_deg": level, "delta_star_deg": crossing(deltas, vals, level)})
    return rows


# --- error budget --------------------------------------------------------------------

def _diag(a, b, c) -> list[list[float]]:
    return [[a, 0.0, 0.0], [0.0, b, 0.0], [0.0, 0.0, c]]


def budget_plan(s: Scenario) -> tuple[list[Change], list[dict]]:
    """The ideal configuration (every assumption of Eq. 11 true) and one row per
    effect, each as changes to the scenario; ``in_scenario`` says whether the
    scenario as configured has the effect."""
    J = np.asarray(s.spacecraft.inertia_kgm2, float)
    Ix, Iy, Iz = np.diag(J)
    I_ = eq5_inertia(Ix, Iz)
    # The ideal flies the scenario schema's default tab (GOES-Next's, 1e-6 N m residual).
    sol, default_trim = s.environment.solar, Solar.model_fields["trim_tab_deg"].default
    ctrl = s.control
    # The pitch loop stays on: without it any pitch torque (products of inertia, the
    # solar torque off the orbit plane) runs pitch away by tens of degrees in a day.
    # Without ripple it holds H constant to ~1e-5 relative.
    ideal = [("spacecraft.inertia_kgm2", _diag(I_, I_, I_)), ("environment.ripple.enabled", False),
             ("control.magnetic_unloading", False), ("environment.shadow_model", "none"),
             ("environment.solar.trim_tab_deg", default_trim)]
    products = np.abs(J[~np.eye(3, dtype=bool)]).max() > 0
    kappa = sol.untrimmed_torque_Nm - sol.tab_effectiveness_Nm_per_deg * sol.trim_tab_deg
    kappa_default = sol.untrimmed_torque_Nm - sol.tab_effectiveness_Nm_per_deg * default_trim
    rows = [
        ("unequal_IxIz", "I_x ≠ I_z as given (Eq. 5)", [("spacecraft.inertia_kgm2",
                                                          _diag(Ix, I_, Iz))], Ix != Iz),
        ("Iy", "I_y ≠ I as given (Eq. 6)", [("spacecraft.inertia_kgm2", _diag(I_, Iy, I_))],
         Iy != I_),
        ("products_plus30", "products of inertia +30 kg m²",
         [("spacecraft.inertia_kgm2", (np.full((3, 3), -30.0) + np.diag([I_ + 30] * 3)).tolist())],
         bool(products)),
        ("products_minus30", "products of inertia −30 kg m²",
         [("spacecraft.inertia_kgm2", (np.full((3, 3), 30.0) + np.diag([I_ - 30] * 3)).tolist())],
         bool(products)),
        ("H_variation", "H variations (the pitch loop against wheel ripple)",
         [("environment.ripple.enabled", True)],
         ctrl.enabled and ctrl.pitch_loop and s.environment.ripple.enabled),
        ("untrimmed_solar", "untrimmed solar torque (tab 0°)",
         [("environment.solar.trim_tab_deg", 0.0)], sol.enabled and kappa > 1.5 * kappa_default),
        ("magnetic_control", "magnetic control dipoles (unloading torquers)",
         [("control.magnetic_unloading", True)], ctrl.enabled and ctrl.magnetic_unloading),
        ("eclipse", "eclipse (solar torque off in shadow)",
         [("environment.shadow_model", s.environment.shadow_model
           if s.environment.shadow_model != "none" else "conical")],
         s.environment.shadow_model != "none"),
    ]
    return ideal, [{"key": k, "label": lab, "changes": ch, "in_scenario": bool(flag)}
                   for k, lab, ch, flag in rows]


def run_budget(s: Scenario, gap: tuple[int, int], extra_deg: float = 1.0, progress=None
               ) -> dict:
    """Yaw error of Eq. 11 across the first Sun gap, per effect, at the scenario's
    initial state and with ``extra_deg`` of attitude error added (the sweep's
    changes).  Contribution = row − ideal; total = the scenario as configured."""
    params, _ = build.estimator_model(s)
    ideal, rows = budget_plan(s)
    columns = {"initial": [], f"plus_{extra_deg:g}deg": sweep_changes(
        s, "attitude", extra_deg, params.omega_n_radps, pitch=False)}

    def measure(changes):
        v = variant(s, changes)
        sim = simulate(v)
        if progress:
            progress()
        out = gap_yaw_errors(v, sim.truth, gap)
        out["H_ptp_Nms"] = float(np.ptp(sim.truth.H_Nms))
        return out

    out = {"gap_h": [gap[0] * s.sample_interval_s / 3600, gap[1] * s.sample_interval_s / 3600],
           "ideal_overrides": ideal, "rows": [], "columns": list(columns)}
    base = {c: measure(ideal + ch) for c, ch in columns.items()}
    total = {c: measure(ch) for c, ch in columns.items()}
    for r in rows:
        vals = {c: measure(ideal + r["changes"] + ch) for c, ch in columns.items()}
        r = dict(r)
        r["H_ptp_Nms"] = {c: vals[c].pop("H_ptp_Nms") for c in columns}
        r["contribution"] = {c: {k: vals[c][k] - base[c][k] for k in base[c]
                                 if k != "H_ptp_Nms"} for c in columns}
        out["rows"].append(r)
    out["ideal"] = base
    out["total"] = total
    out["sum_in_scenario"] = {
        c: {k: base[c][k] + sum(r["contribution"][c][k] for r in out["rows"]
                                if r["in_scenario"] and r["key"] != "products_minus30")
            for k in base[c] if k != "H_ptp_Nms"} for c in columns}
    return out
