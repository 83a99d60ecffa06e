"""`dynprop covariance`: the steady-state yaw σ of Section 6 by every method
(``covariance``), side by side with the paper's 0.040° (Eq. 56)."""

from __future__ import annotations

import numpy as np

from .covariance import (
    PAPER_SIGMA_YAW_DEG,
    SensorSpecs,
    alpha,
    approx_yaw_variance,
    care_steady_state,
    closed_form_steady_state,
    combined_variance,
    continuous_R,
    h_variance,
    periodic_gap_covariance,
    reduced,
    roll_tach_steady_state,
    roll_variance,
    tach_variance,
    yaw_variance,
)
from .model import ModelParams, ProcessNoise

PAPER_SENSORS = SensorSpecs()   # Sections 2.1 and 2.3

METHODS = {
    "eq54": "Eq. 54 closed form",
    "eq55": "Eq. 55 approximation q/(w0 H^2)",
    "care": "Eq. 49 steady state (solve_continuous_are)",
    "care_qw": "Eq. 49 with q + q_w/2",
    "dare_prior": "5-state roll+h filter, a priori (DARE)",
    "dare_post": "5-state roll+h filter, a posteriori",
    "gap_end": "9-state, daily yaw gap: at the gap end",
    "gap_max": "9-state, daily yaw gap: daily maximum",
    "gap_min": "9-state, daily yaw gap: daily minimum",
}


def _entry(P2=None, p22=None) -> dict:
    p11, p12, p22 = (None, None, p22) if P2 is None else (P2[0, 0], P2[0, 1], P2[1, 1])
    return {"p11": p11 and float(p11), "p12": p12 and float(p12), "p22": float(p22),
            "sigma_yaw_deg": float(np.rad2deg(np.sqrt(p22)))}


def covariance_report(p: ModelParams, noise: ProcessNoise, sensors: SensorSpecs = PAPER_SENSORS,
                      *, gap_s: float = 28800.0, period_s: float = 86400.0) -> dict:
    """σ_yaw by every method (p11, p12, p22 of x̃ = [r + h/H, y], rad²), with the inputs.

    The 2-state methods use q = (q_x + q_z)/2 (the paper takes them equal).
    """
    H, w0 = p.H_Nms, p.omega0_radps
    q = 0.5 * (noise.q_x + noise.q_z)
    Rc = continuous_R(H, sensors)
    p11, p22, p12 = closed_form_steady_state(q, H, w0, Rc)
    dare = roll_tach_steady_state(p, noise, sensors)
    gap = periodic_gap_covariance(p, noise, sensors, gap_s=gap_s, period_s=period_s)
    methods = {
        "eq54": _entry(np.array([[p11, p12], [p12, p22]])),
        "eq55": _entry(p22=approx_yaw_variance(q, H, w0)),
        "care": _entry(care_steady_state(w0, H, Rc, noise.q_x, noise.q_z)),
        "care_qw": _entry(care_steady_state(w0, H, Rc, noise.q_x, noise.q_z, noise.q_w)),
        "dare_prior": _entry(reduced(dare["P_prior"], p)),
        "dare_post": _entry(reduced(dare["P_post"], p)),
        "gap_end": _entry(reduced(gap.P_gap_end, p)),
        "gap_max": _entry(p22=gap.sigma_yaw_rad.max() ** 2),
        "gap_min": _entry(p22=gap.sigma_yaw_rad.min() ** 2),
    }
    inputs = {"H_Nms": H, "omega0_radps": w0, "q": q, "q_w": noise.q_w, "dt_s": sensors.dt_s,
              "R_tach": tach_variance(sensors), "R_roll": roll_variance(sensors),
              "R_h": h_variance(sensors), "R_yaw": yaw_variance(sensors), "R": Rc,
              "R_k": combined_variance(H, sensors), "q_ratio": q / (w0**2 * H**2 * Rc),
              "alpha": alpha(q, H, w0, Rc), "gap_s": gap_s, "period_s": period_s}
    return {"inputs": {k: float(v) for k, v in inputs.items()}, "methods": methods,
            "gap": {"days_to_converge": gap.days,
                    "max_at_s": float(gap.times_s[np.argmax(gap.sigma_yaw_rad)] % period_s)},
            "paper_sigma_yaw_deg": PAPER_SIGMA_YAW_DEG}


def format_covariance_report(report: dict) -> str:
    """The text of ``dynprop covariance``."""
    i = report["inputs"]
    lines = [
        "Steady-state yaw accuracy (Section 6)",
        f"H = {i['H_Nms']:.3f} N m s, w0 = {i['omega0_radps']:.5e} rad/s, "
        f"q = {i['q']:.3e} (N m)^2 s (Eq. 45), q_w = {i['q_w']:.2e} (N m)^2 s",
        f"R_tach = {i['R_tach']:.3e} (rad/s)^2 (Eq. 46), R_roll = {i['R_roll']:.3e} rad^2 "
        f"(Eq. 47), R_k = {i['R_k']:.4e} rad^2 (Eq. 48)",
        f"R = R_k dt = {i['R']:.3e} rad^2 s (Eq. 51), q/(w0^2 H^2 R) = {i['q_ratio']:.3e}, "
        f"alpha = {i['alpha']:.2f} (Eq. 54d)",
        f"9-state filter: yaw (R_yaw = {i['R_yaw']:.2e} rad^2) except {i['gap_s'] / 3600:g} h "
        f"of every {i['period_s'] / 3600:g} h; periodic within {report['gap']['days_to_converge']}"
        " days", "",
        f"{'method':<44}{'p11 rad^2':>11}{'p12 rad^2':>11}{'p22 rad^2':>11}{'sigma_yaw':>11}",
    ]
    lines.append("-" * len(lines[-1]))
    for key, label in METHODS.items():
        m = report["methods"][key]
        cells = "".join(f"{'-':>11}" if m[c] is None else f"{m[c]:>11.3e}"
                        for c in ("p11", "p12", "p22"))
        lines.append(f"{label:<44}{cells}{m['sigma_yaw_deg']:>10.4f}°")
    lines.append(f"{'paper (Eq. 56)':<77}{report['paper_sigma_yaw_deg']:>10.3f}°")
    return "\n".join(lines)
