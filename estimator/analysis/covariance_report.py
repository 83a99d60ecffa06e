"""`dynprop covariance`: the steady-state yaw σ of Section 6 by every method
(``covariance``), side by side with the paper's 0.040° (Eq. 56)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..linear.model import ModelParams, ProcessNoise
from ..linear.noise import (
    PAPER_SENSORS,
    SensorSpecs,
    combined_variance,
    continuous_R,
    h_variance,
    roll_variance,
    tach_variance,
    yaw_variance,
)
from . import covariance as cov

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
    "gap_end_white": "9-state, yaw white at the DSS spec: gap end",
}


def _entry(P2=None, p22=None) -> dict:
    p11, p12, p22 = (None, None, p22) if P2 is None else (P2[0, 0], P2[0, 1], P2[1, 1])
    return {"p11": p11 and float(p11), "p12": p12 and float(p12), "p22": float(p22),
            "sigma_yaw_deg": float(np.rad2deg(np.sqrt(p22)))}


def filter_yaw_specs(sensors: SensorSpecs, yaw_inflation: float) -> SensorSpecs:
    """``sensors`` with the yaw variance the run's filter gives a DSS reading: the
    spec's noise² + quantum²/12 times ``yaw_inflation`` (its quantisation error counted
    once per correlation time, ``preprocess.quantisation_inflation``), carried as an
    equivalent white noise with no quantum, so that every analysis reads it through
    ``yaw_variance`` unchanged."""
    sigma_deg = float(np.rad2deg(np.sqrt(yaw_variance(sensors) * yaw_inflation)))
    return replace(sensors, yaw_noise_deg=sigma_deg, yaw_quantum_deg=0.0)


def covariance_report(p: ModelParams, noise: ProcessNoise, sensors: SensorSpecs = PAPER_SENSORS,
                      *, gap_s: float = 28800.0, period_s: float = 86400.0,
                      yaw_inflation: float = 1.0, yaw_correlation_s: float | None = None
                      ) -> dict:
    """σ_yaw by every method (p11, p12, p22 of x̃ = [r + h/H, y], rad²), with the inputs.

    The 2-state methods use q = (q_x + q_z)/2 (the paper takes them equal).  The
    9-state rows take yaw every sample outside the gap with the DSS variance of
    ``sensors`` times ``yaw_inflation``, the factor by which a run's filter
    down-weights a DSS yaw (its quantisation error counted once per
    ``yaw_correlation_s``); ``gap_end_white`` is the same gap end with the spec's
    variance taken as white (1: Section 6 as printed, and the two coincide).
    """
    H, w0 = p.H_Nms, p.omega0_radps
    q = 0.5 * (noise.q_x + noise.q_z)
    Rc = continuous_R(H, sensors)
    p11, p22, p12 = cov.closed_form_steady_state(q, H, w0, Rc)
    dare = cov.roll_tach_steady_state(p, noise, sensors)
    filter_specs = filter_yaw_specs(sensors, yaw_inflation)
    gap = cov.periodic_gap_covariance(p, noise, filter_specs, gap_s=gap_s, period_s=period_s)
    white = gap if yaw_inflation == 1.0 else \
        cov.periodic_gap_covariance(p, noise, sensors, gap_s=gap_s, period_s=period_s)
    methods = {
        "eq54": _entry(np.array([[p11, p12], [p12, p22]])),
        "eq55": _entry(p22=cov.approx_yaw_variance(q, H, w0)),
        "care": _entry(cov.care_steady_state(w0, H, Rc, noise.q_x, noise.q_z)),
        "care_qw": _entry(cov.care_steady_state(w0, H, Rc, noise.q_x, noise.q_z, noise.q_w)),
        "dare_prior": _entry(cov.reduced(dare["P_prior"], p)),
        "dare_post": _entry(cov.reduced(dare["P_post"], p)),
        "gap_end": _entry(cov.reduced(gap.P_gap_end, p)),
        "gap_max": _entry(p22=gap.sigma_yaw_rad.max() ** 2),
        "gap_min": _entry(p22=gap.sigma_yaw_rad.min() ** 2),
        "gap_end_white": _entry(cov.reduced(white.P_gap_end, p)),
    }
    inputs = {"H_Nms": H, "omega0_radps": w0, "q": q, "q_w": noise.q_w, "dt_s": sensors.dt_s,
              "R_tach": tach_variance(sensors), "R_roll": roll_variance(sensors),
              "R_h": h_variance(sensors), "R_yaw": yaw_variance(filter_specs), "R": Rc,
              "R_yaw_white": yaw_variance(sensors), "yaw_inflation": yaw_inflation,
              "yaw_noise_deg": sensors.yaw_noise_deg,
              "yaw_quantum_deg": sensors.yaw_quantum_deg,
              "R_k": combined_variance(H, sensors), "q_ratio": q / (w0**2 * H**2 * Rc),
              "alpha": cov.alpha(q, H, w0, Rc), "gap_s": gap_s, "period_s": period_s}
    return {"inputs": {k: float(v) for k, v in inputs.items()}, "methods": methods,
            "yaw_correlation_s": yaw_correlation_s,
            "gap": {"days_to_converge": gap.days,
                    "max_at_s": float(gap.times_s[np.argmax(gap.sigma_yaw_rad)] % period_s)},
            "paper_sigma_yaw_deg": cov.PAPER_SIGMA_YAW_DEG}


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
        *_yaw_lines(report), "",
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


def _yaw_lines(report: dict) -> list[str]:
    """What the 9-state rows assume about yaw, a line each: the sensor, its weight,
    when it reads, and what a run does that this analysis leaves out."""
    i, corr = report["inputs"], report.get("yaw_correlation_s")
    white_sigma = np.rad2deg(np.sqrt(i["R_yaw_white"]))
    lines = [
        "Yaw measurement of the 9-state rows (Eqs. 49-55 have none):",
        f"  DSS noise {i['yaw_noise_deg']:g} deg, quantum {i['yaw_quantum_deg']:g} deg: "
        f"{white_sigma:.4f} deg a sample if white (R_yaw = {i['R_yaw_white']:.2e} rad^2)"]
    if i["yaw_inflation"] != 1.0:
        when = "" if corr is None else f" per {corr:g} s\n  (estimator.dss_error_correlation_s)"
        lines += (f"  weighed as a run's filter weighs it, its quantisation error counted once"
                  f"{when}: R_yaw x {i['yaw_inflation']:.4g} = {i['R_yaw']:.2e} rad^2 "
                  f"({np.rad2deg(np.sqrt(i['R_yaw'])):.3f} deg a sample)").splitlines()
    else:
        lines.append("  taken as white, as Section 6 does (a run's filter counts its "
                     "quantisation error once per correlation time)")
    lines += [
        f"  every {i['dt_s']:g} s but for {i['gap_s'] / 3600:g} h of every "
        f"{i['period_s'] / 3600:g} h (the paper's gap; a run reports its own);",
        f"  the covariance is periodic within {report['gap']['days_to_converge']} days",
        "  left out: a run's CASS yaw (about 1 deg, more off boresight) outside the DSS's "
        "hours,",
        "  and each yaw sigma over the sine of the Sun's angle from the yaw axis"]
    return lines
