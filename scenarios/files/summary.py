"""What `dynprop run` and `dynprop estimate` write: estimate.csv, summary.json and
comparison.npz (the full-resolution series the figures are drawn from)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from dynprop.estimator.consistency import chi2_bounds, fraction_inside, nees, nis
from dynprop.estimator.covariance import approx_yaw_variance
from dynprop.estimator.kalman import unpack
from dynprop.estimator.model import N_STATES, R, Y

from .. import __version__
from ..config.schema import Scenario

RAD2DEG = 180.0 / np.pi
# Estimate columns: state name with its unit, and the factor from model units
# (ṙ/ω_n and ẏ/ω_n are written as rates in deg/s).
STATE_COLUMNS = ("roll_deg", "roll_rate_degps", "yaw_deg", "yaw_rate_degps", "h_Nms",
                 "N_px_Nm", "N_pz_Nm", "N_cx_Nm", "N_cz_Nm")


def display_factors(omega_n: float) -> np.ndarray:
    return np.array([RAD2DEG, RAD2DEG * omega_n, RAD2DEG, RAD2DEG * omega_n, 1, 1, 1, 1, 1])


def estimate_columns(t_s, x, sigma, omega_n: float) -> dict[str, np.ndarray]:
    f = display_factors(omega_n)
    cols = {"t_s": t_s}
    for k, name in enumerate(STATE_COLUMNS):
        cols[name] = x[:, k] * f[k]
    for k, name in enumerate(STATE_COLUMNS):
        cols[f"sigma_{name}"] = sigma[:, k] * abs(f[k])
    return cols


def sun_gaps(yaw_present: np.ndarray, dt_s: float, min_hours: float) -> list[tuple[int, int]]:
    """(first missing, first present again) index pairs of yaw outages ≥ ``min_hours``;
    a gap still open at the end of the run has end = N."""
    missing = ~np.asarray(yaw_present, dtype=bool)
    edges = np.flatnonzero(np.diff(np.r_[0, missing.astype(int), 0]))
    pairs = list(zip(edges[::2], edges[1::2], strict=True))
    return [(a, b) for a, b in pairs if (b - a) * dt_s >= min_hours * 3600]


NEES_STRIDE = 10  # NEES on every 10th sample (5 s apart): plenty for means and figures


def nees_series(runs) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """Sample indices and NEES of the real and linear runs, unpacking only the
    covariances used; None for a run that has no truth (``estimate`` without
    ``--truth``) or no linear twin (``estimate``)."""
    idx = np.arange(0, len(runs.real.x), NEES_STRIDE)
    real = lin = None
    if runs.truth_model is not None:
        real = nees(runs.real.x[idx], unpack(runs.real.P_packed[idx]), runs.truth_model[idx])
    if runs.linear is not None:
        lin = nees(runs.linear.x[idx], unpack(runs.linear.P_packed[idx]), runs.twin_model[idx])
    return idx, real, lin


def _rms(a) -> float:
    return float(np.sqrt(np.nanmean(np.square(a))))


def _mean_or_none(a) -> float | None:
    """Mean of the finite values, or None (JSON null) when there are none, e.g. the
    yaw NIS of a run that never sees the Sun."""
    a = np.asarray(a, dtype=float)
    a = a[np.isfinite(a)]
    return float(a.mean()) if a.size else None


def eq55_sigma_yaw_deg(s: Scenario, params) -> float:
    """The paper's steady-state yaw σ, √(q/(ω0 H²)) (Eq. 55), with q the mean of the
    scenario's roll and yaw torque noise, in degrees."""
    q = 0.5 * (s.estimator.process_noise.q_x + s.estimator.process_noise.q_z)
    return float(np.sqrt(approx_yaw_variance(q, params.H_Nms, params.omega0_radps))) * RAD2DEG


def _per_state(values) -> dict[str, float]:
    # Keyed by estimate.csv's column names, as montecarlo.json's per-state figures.
    return {name: float(v) for name, v in zip(STATE_COLUMNS, values, strict=True)}


def _nis_means(result) -> dict[str, float | None]:
    return {m: _mean_or_none(nis(result.innovations[:, i], result.innovation_var[:, i]))
            for i, m in enumerate(("roll", "yaw", "h"))}


def _comparison(err, err_lin) -> dict:
    return {name: {"rms_real": _rms(err[:, k]) * f, "rms_linear": _rms(err_lin[:, k]) * f,
                   "rms_difference": _rms(err[:, k] - err_lin[:, k]) * f,
                   "max_abs_difference": float(np.max(np.abs(err[:, k] - err_lin[:, k])) * f)}
            for name, k, f in (("roll_deg", R, RAD2DEG), ("yaw_deg", Y, RAD2DEG),
                               ("h_Nms", 4, 1.0))}


def summarize(s: Scenario, runs, t_s, yaw_present, nees_data) -> dict:
    """summary.json: the figures of the run, every key documented in docs/outputs.md.
    A figure that needs the truth (``estimate`` without ``--truth``) or the linear
    twin (``estimate``) is null, so every summary has the same keys.  No wall-clock
    time: the same scenario and seed must give the same bytes."""
    truth, twin = runs.truth_model is not None, runs.linear is not None
    err = runs.real.x - runs.truth_model if truth else None
    err_lin = runs.linear.x - runs.twin_model if twin else None
    sig = runs.real.sigma
    gaps = sun_gaps(yaw_present, s.sample_interval_s, s.estimator.sun_gap_min_h)
    ends = [b for _, b in gaps if b < len(t_s)]
    _, n_real, n_lin = nees_data
    nees_b = chi2_bounds(N_STATES, 1)

    def when(ok, value):
        return value() if ok else None

    f = {
        "yaw_rms": when(truth, lambda: _rms(err[:, Y]) * RAD2DEG),
        "per_state": when(truth, lambda: np.mean(
            (err / np.maximum(sig, 1e-300))[::NEES_STRIDE] ** 2, axis=0)),
        "yaw_rms_linear": when(twin, lambda: _rms(err_lin[:, Y]) * RAD2DEG),
        "roll_rms": when(truth, lambda: _rms(err[:, R]) * RAD2DEG),
        "h_rms": when(truth, lambda: _rms(err[:, 4])),
        "yaw_rms_smoothed": when(
            truth and runs.smoothed is not None,
            lambda: _rms(runs.smoothed.x[:, Y] - runs.truth_model[:, Y]) * RAD2DEG),
        "gaps": gaps,
        "end_err": when(truth, lambda: [float(err[b, Y] * RAD2DEG) for b in ends]),
        "end_err_linear": when(twin, lambda: [float(err_lin[b, Y] * RAD2DEG) for b in ends]),
        "end_sigma": [float(sig[b, Y] * RAD2DEG) for b in ends],
        "ends_within": when(truth, lambda: bool(all(abs(err[b, Y]) <= 3 * sig[b, Y]
                                                    for b in ends))),
        "comparison": when(truth and twin, lambda: _comparison(err, err_lin)),
        "nees_mean": when(truth, lambda: float(np.mean(n_real))),
        "nees_mean_linear": when(twin, lambda: float(np.mean(n_lin))),
        "nees_inside": when(truth, lambda: fraction_inside(n_real, nees_b)),
        "nees_inside_linear": when(twin, lambda: fraction_inside(n_lin, nees_b)),
        "nis": _nis_means(runs.real),
        "nis_linear": when(twin, lambda: _nis_means(runs.linear)),
    }
    return assemble_summary(s, runs.params, runs.real.backend, truth, twin, f)


def assemble_summary(s: Scenario, params, backend: str, truth: bool, twin: bool, f: dict
                     ) -> dict:
    """summary.json's dict from the run's figures ``f`` (``summarize`` computes them
    from whole arrays, ``accumulate.RunFigures`` window by window): one key order,
    one set of keys, whichever computed them."""
    dt = s.sample_interval_s
    eq55 = eq55_sigma_yaw_deg(s, params)
    nees_b = chi2_bounds(N_STATES, 1)
    end_sigma = f["end_sigma"]
    return {
        "scenario": s.name, "seed": s.seed, "epoch_utc": s.epoch_utc,
        "duration_s": s.duration_s, "dynprop_version": __version__,
        "backend": backend, "filters": ["paper"], "linear_twin": twin, "truth": truth,
        "yaw_error_rms_deg": f["yaw_rms"],
        "nees_mean_per_state": None if f["per_state"] is None else _per_state(f["per_state"]),
        "yaw_error_rms_linear_deg": f["yaw_rms_linear"],
        "roll_error_rms_deg": f["roll_rms"],
        "h_error_rms_Nms": f["h_rms"],
        "yaw_error_rms_smoothed_deg": f["yaw_rms_smoothed"],
        "sun_gaps_h": [[a * dt / 3600, b * dt / 3600] for a, b in f["gaps"]],
        "yaw_error_at_gap_end_deg": f["end_err"],
        "yaw_error_linear_at_gap_end_deg": f["end_err_linear"],
        "yaw_sigma_at_gap_end_deg": end_sigma,
        "yaw_within_3sigma_at_gap_ends": f["ends_within"],
        "analytic_sigma_yaw_deg": eq55,
        "last_gap_end_sigma_over_eq55": (float(end_sigma[-1] / eq55) if end_sigma else None),
        "nonlinear_vs_linear": f["comparison"],
        "nees_mean": f["nees_mean"],
        "nees_mean_linear": f["nees_mean_linear"],
        "nees_dof": N_STATES, "nees_bounds_95_per_sample": nees_b,
        "nees_fraction_inside_95": f["nees_inside"],
        "nees_fraction_inside_95_linear": f["nees_inside_linear"],
        "nis_mean": f["nis"],
        "nis_mean_linear": f["nis_linear"],
        "nis_bounds_95_per_sample": chi2_bounds(1, 1),
    }


def write_summary(path: Path, summary: dict) -> None:
    path.write_text(json.dumps(summary, indent=2, allow_nan=False) + "\n")
