"""comparison.npz: the series every run figure is drawn from, float32 (drawing only).

The figures (``scenarios.plotting``) read nothing else besides scenario.yaml and
summary.json, so ``dynprop plot`` redraws exactly what ``run`` drew."""

from __future__ import annotations

import numpy as np

from estimator.consistency import nis

from .outputs import RAD2DEG, display_factors


def comparison_arrays(runs, t_s, yaw_present, nees_data) -> dict[str, np.ndarray]:
    """Everything the run figures need, full resolution, float32 (drawing only)."""
    f = display_factors(runs.params.omega_n_radps)
    idx, real, lin = nees_data
    n_real = np.full(len(t_s), np.nan)
    n_lin = np.full(len(t_s), np.nan)
    n_real[idx], n_lin[idx] = real, lin
    out = {
        "t_s": t_s, "yaw_present": yaw_present.astype(np.float32),
        "err_real": (runs.real.x - runs.truth_model) * f,
        "err_linear": (runs.linear.x - runs.twin_model) * f,
        "err_smoothed": (runs.smoothed.x - runs.truth_model) * f,
        "sigma": runs.real.sigma * np.abs(f),
        "x_real": runs.real.x * f, "truth_model": runs.truth_model * f,
        "nees_real": n_real, "nees_linear": n_lin,
        "nis_real": nis(runs.real.innovations, runs.real.innovation_var),
        "true_euler_deg": runs.sim.truth.euler_rad * RAD2DEG,  # yaw, roll, pitch
    }
    return {k: (v if k == "t_s" else np.asarray(v, dtype=np.float32)) for k, v in out.items()}
