"""comparison.npz: the series every run figure is drawn from, float32 (drawing only).

The figures (``figures.run``) read nothing else besides scenario.yaml, so
``dynprop plot`` redraws exactly what ``run`` (or ``estimate``) drew, and which
figures exist follows from which keys are here (``figures.run.figure_set``).

Keys (time first, N samples; state columns in ``estimator.linear.model`` order, in
display units: deg, deg/s, N m s, N m; written only when their inputs exist):

- always: ``t_s`` (s, float64), ``yaw_present`` (1 where a Sun-sensor yaw is
  used), ``x_real`` and ``sigma`` (N, 9) the filter's estimate and 1σ,
  ``nis_real`` (N, 3) roll, yaw, h NIS (NaN where no update);
- with a truth: ``truth_model`` (N, 9) the truth in the model's states,
  ``err_real`` (N, 9) = x_real − truth_model, ``nees_real`` (N) NEES (NaN between
  the samples it is computed on), ``err_smoothed`` (N, 9) with a smoother,
  ``true_euler_deg`` (N, 3) yaw, roll, pitch (deg);
- with a linear twin: ``err_linear`` (N, 9), ``nees_linear`` (N), and with a truth
  too ``err_real_minus_linear`` (N, 3) roll (deg), yaw (deg), h (N m s) real −
  linearized error, differenced in float64 before the float32 rounding (for h
  the difference, ~1e-13 N m s, is below the float32 resolution of the errors);
- with the pitch filter (``run.pitch``): ``x_pitch`` and ``sigma_pitch`` (N, 3) its
  estimate and 1σ (pitch deg, pitch rate deg/s, N_y N m), ``nis_pitch`` (N); with a
  truth ``err_pitch`` (N, 3) and ``nees_pitch`` (N, 3-state NEES, NaN between its
  samples, which are the 9-state NEES's);
- with the telemetry: ``tel_roll_deg``, ``tel_pitch_deg``, ``tel_yaw_deg`` (deg,
  NaN where absent), ``tel_yaw_sigma_deg`` (deg, a-priori 1σ of the ground yaw),
  ``tel_sun_head`` (0 dss, 1 cass1, 2 cass2, NaN none), ``tel_wheelK_rpm`` (rpm).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from dynprop.estimator.kalman.consistency import nis
from dynprop.estimator.linear.model import H_WHEEL, R, Y

from ..units import RAD2DEG
from .columns import PITCH_FACTORS, display_factors

#: telemetry.csv columns the telemetry figure draws (besides every wheelK_rpm).
TELEMETRY_COLUMNS = ("roll_deg", "pitch_deg", "yaw_deg", "yaw_sigma_deg", "sun_head")
DIFF_STATES = (R, Y, H_WHEEL)   # columns of err_real_minus_linear: roll, yaw, h


def _telemetry_arrays(telemetry: dict, n: int) -> dict[str, np.ndarray]:
    names = [c for c in TELEMETRY_COLUMNS if c in telemetry] + \
        sorted((c for c in telemetry if c.startswith("wheel") and c.endswith("_rpm")),
               key=lambda c: int(c[5:-4]) if c[5:-4].isdigit() else 0)
    out = {}
    for c in names:
        values = np.asarray(telemetry[c], dtype=float)
        if values.shape != (n,):
            raise ValueError(f"telemetry column {c} has {values.shape} values; the run has {n}")
        out[f"tel_{c}"] = values
    return out


@dataclass(frozen=True)
class PitchRows:
    """The pitch filter on the rows: x, σ (N, 3, rad, rad/s, N m), innovations and
    their variances; with a truth, its pitch states (N, 3) and the 3-state NEES at the
    NEES indices of ``comparison_arrays``'s ``nees_data``."""

    x: np.ndarray
    sigma: np.ndarray
    innovations: np.ndarray
    innovation_var: np.ndarray
    truth: np.ndarray | None = None
    nees: np.ndarray | None = None


@dataclass(frozen=True)
class ComparisonInputs:
    """What comparison.npz is drawn from, on its rows (model coordinates, rad): the
    paper filter's history ``real`` (x, sigma, innovations, innovation_var) and the
    ω_n of its model always; the truth in the model's states, the smoothed estimate,
    the twin's filter estimate with the twin's states, the true 3-1-2 angles (yaw,
    roll, pitch) and the filters beside the paper's (by name: x, sigma) each when
    the run has them."""

    omega_n: float
    real: object
    truth_model: np.ndarray | None = None
    smoothed_x: np.ndarray | None = None
    linear_x: np.ndarray | None = None
    twin_model: np.ndarray | None = None
    true_euler_rad: np.ndarray | None = None
    filters: dict = field(default_factory=dict)
    pitch: PitchRows | None = None


def comparison_arrays(c: ComparisonInputs, t_s, yaw_present, nees_data,
                      telemetry: dict | None = None) -> dict[str, np.ndarray]:
    """Everything the run figures need, full resolution, float32 (drawing only).
    ``nees_data`` = (indices, real NEES or None, linear NEES or None).
    ``telemetry``: the telemetry.csv columns on the filter's samples (as read back),
    or None."""
    f = display_factors(c.omega_n)
    n = len(t_s)
    real = c.real
    out = {"t_s": np.asarray(t_s, dtype=float),
           "yaw_present": np.asarray(yaw_present, dtype=np.float32),
           "x_real": real.x * f, "sigma": real.sigma * np.abs(f),
           "nis_real": nis(real.innovations, real.innovation_var)}
    truth = c.truth_model is not None
    twin = c.linear_x is not None and c.twin_model is not None
    if truth:
        err = real.x - c.truth_model
        out.update(truth_model=c.truth_model * f, err_real=err * f)
        if c.smoothed_x is not None:
            out["err_smoothed"] = (c.smoothed_x - c.truth_model) * f
        for name, res in c.filters.items():
            # A filter besides the paper's (estimator.filters), on the same telemetry.
            out[f"err_{name}"] = (res.x - c.truth_model) * f
            out[f"sigma_{name}"] = res.sigma * np.abs(f)
    if twin:
        err_lin = c.linear_x - c.twin_model
        out["err_linear"] = err_lin * f
        if truth:
            cols = list(DIFF_STATES)
            out["err_real_minus_linear"] = (err - err_lin)[:, cols] * f[cols]
    idx, nees_real, nees_lin = nees_data
    for key, values in (("nees_real", nees_real), ("nees_linear", nees_lin)):
        if values is not None:
            series = np.full(n, np.nan)
            series[idx] = values
            out[key] = series
    if c.pitch is not None:
        p = c.pitch
        out.update(x_pitch=p.x * PITCH_FACTORS, sigma_pitch=p.sigma * PITCH_FACTORS,
                   nis_pitch=p.innovations**2 / p.innovation_var)
        if p.truth is not None:
            out["err_pitch"] = (p.x - p.truth) * PITCH_FACTORS
        if p.nees is not None:
            series = np.full(n, np.nan)
            series[idx] = p.nees
            out["nees_pitch"] = series
    if c.true_euler_rad is not None:
        out["true_euler_deg"] = c.true_euler_rad * RAD2DEG  # yaw, roll, pitch
    if telemetry is not None:
        out.update(_telemetry_arrays(telemetry, n))
    return {k: (v if k == "t_s" else np.asarray(v, dtype=np.float32)) for k, v in out.items()}
