"""comparison.npz: the series every run figure is drawn from, float32 (drawing only).

The figures (``scenarios.plotting``) read nothing else besides scenario.yaml and
summary.json, so ``dynprop plot`` redraws exactly what ``run`` drew."""

from __future__ import annotations

import numpy as np

from estimator.consistency import nis

from .outputs import RAD2DEG, display_factors


def comparison_arrays(runs, t_s, yaw_present, nees_data) -> dict[str, np.ndarray]:
    """Everything the run figures need, full resolution, float32 (drawing only).
    Keys that need the truth (``runs.truth_model``, ``runs.sim``) or the linear twin
    (``runs.linear``) are left out when those are None (``dynprop estimate``)."""
    f = display_factors(runs.params.omega_n_radps)
    idx, real, lin = nees_data
    out = {"t_s": t_s, "yaw_present": yaw_present.astype(np.float32),
           "sigma": runs.real.sigma * np.abs(f), "x_real": runs.real.x * f,
           "nis_real": nis(runs.real.innovations, runs.real.innovation_var)}

    def every_tenth(values):
        full = np.full(len(t_s), np.nan)
        full[idx] = values
        return full

    if runs.truth_model is not None:
        out.update(err_real=(runs.real.x - runs.truth_model) * f,
                   truth_model=runs.truth_model * f, nees_real=every_tenth(real))
        if runs.smoothed is not None:
            out["err_smoothed"] = (runs.smoothed.x - runs.truth_model) * f
    if runs.linear is not None:
        out.update(err_linear=(runs.linear.x - runs.twin_model) * f,
                   nees_linear=every_tenth(lin))
    if runs.sim is not None:
        out["true_euler_deg"] = runs.sim.truth.euler_rad * RAD2DEG  # yaw, roll, pitch
    return {k: (v if k == "t_s" else np.asarray(v, dtype=np.float32)) for k, v in out.items()}
