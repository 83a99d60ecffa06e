"""Ground-side preprocessing: telemetry arrays to filter measurements and inputs.

Works on plain arrays (any telemetry source, simulated or read from CSV):

* roll from the Earth sensor, yaw from the Sun-sensor solution where present,
  h from the tachometers, h = Σ k_i Ω_i with k_i = I_w,i a_i·ẑ (Eq. 2 for the
  two canted wheels, k = ±I_w sin c);
* the modelled wheel torque N_w* = ḣ, from a Savitzky–Golay derivative of the
  tachometer h: a local quadratic fit over ``nw_window_s`` (20 s by default).
  Differencing samples would amplify the tachometer noise (1.5e-5 N m s per
  sample) into ~3e-5 N m; the 20 s fit brings it to ~4e-7 N m with a spectral
  density ~1e-12 (N m)² s, negligible beside q = 5.4e-7 (Eq. 45), while keeping
  the control's torque changes over tens of seconds;
* modelled environment torques N_x*, N_z* as given (the scenario's estimator model);
* variances: roll σ² + q²/12 (Eq. 47), h Σ k_i² R_tach (Eqs. 46, 48), and yaw the
  per-sample a-priori variance of the ground solution when provided.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.signal import savgol_filter

from .covariance import SensorSpecs, roll_variance, tach_variance, yaw_variance
from .kalman import Measurements
from .model import ModelParams, input_vector

PAPER_SENSORS = SensorSpecs()  # Sections 2.1 and 2.3


def yaw_momentum(wheel_speeds_radps: np.ndarray, yaw_factors: np.ndarray) -> np.ndarray:
    """h = Σ k_i Ω_i (N m s) from wheel speeds (N, n) and k_i = I_w,i a_i·ẑ."""
    return np.asarray(wheel_speeds_radps) @ np.asarray(yaw_factors, dtype=float)


def wheel_torque(h_Nms: np.ndarray, dt_s: float, window_s: float = 20.0) -> np.ndarray:
    """N_w* = ḣ by a Savitzky–Golay derivative (quadratic, ``window_s`` wide)."""
    n = len(h_Nms)
    window = int(round(window_s / dt_s)) | 1  # odd
    if n < 5:
        return np.zeros(n)
    window = min(window, n if n % 2 else n - 1)
    return savgol_filter(np.asarray(h_Nms, dtype=float), window, min(2, window - 1), deriv=1,
                         delta=dt_s, mode="interp")


@dataclass(frozen=True)
class FilterInputs:
    measurements: Measurements
    u: np.ndarray          # (N, 9), Eq. 12a; its h column is the modelled N_w*


def prepare(params: ModelParams, dt_s: float, roll_rad, yaw_rad, wheel_speeds_radps,
            yaw_factors, sensors: SensorSpecs = PAPER_SENSORS, yaw_sigma_rad=None,
            Nx_model_Nm=0.0, Nz_model_Nm=0.0, nw_window_s: float = 20.0) -> FilterInputs:
    """Measurements and inputs for ``kalman_filter`` from telemetry arrays."""
    roll = np.asarray(roll_rad, dtype=float)
    yaw = np.asarray(yaw_rad, dtype=float)
    speeds = np.asarray(wheel_speeds_radps, dtype=float)
    k = np.asarray(yaw_factors, dtype=float)
    if speeds.ndim != 2 or speeds.shape != (len(roll), len(k)):
        raise ValueError(f"wheel speeds must be (N, {len(k)}) for N = {len(roll)} samples")
    if not (np.all(np.isfinite(roll)) and np.all(np.isfinite(speeds))):
        raise ValueError("roll and wheel speeds must be present at every sample")
    h = yaw_momentum(speeds, k)
    if yaw_sigma_rad is None:  # a file without per-sample σ: the Sun sensor's spec
        var_yaw = yaw_variance(sensors)
    else:
        var_yaw = np.where(np.isfinite(yaw), np.asarray(yaw_sigma_rad, dtype=float) ** 2, 1.0)
    meas = Measurements(roll, yaw, h, roll_variance(sensors), var_yaw,
                        float(np.sum(k**2)) * tach_variance(sensors))
    nw = wheel_torque(h, dt_s, nw_window_s)
    u = input_vector(params, Nx_model_Nm, Nz_model_Nm, nw) * np.ones((len(roll), 1))
    return FilterInputs(meas, u)
