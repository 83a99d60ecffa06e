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

from ..linear.model import ModelParams, input_vector
from ..linear.noise import PAPER_SENSORS, SensorSpecs, roll_variance, tach_variance, yaw_variance
from .filter import Measurements
from .savgol import savgol_derivative


def yaw_momentum(wheel_speeds_radps: np.ndarray, yaw_factors: np.ndarray) -> np.ndarray:
    """h = Σ k_i Ω_i (N m s) from wheel speeds (N, n) and k_i = I_w,i a_i·ẑ (Eq. 2);
    with k_i = I_w,i a_i·ŷ, the pitch momentum H of Eq. 1 likewise."""
    return np.asarray(wheel_speeds_radps) @ np.asarray(yaw_factors, dtype=float)


def quantisation_inflation(noise: float, quantum: float, samples: float) -> float:
    """Factor on a reading's variance noise² + quantum²/12 when its quantisation
    error stays correlated over ``samples`` samples: treating correlated samples as
    independent makes a filter over-confident, so the quantisation share counts
    once per correlation time, (noise² + q²/12 · samples)/(noise² + q²/12)."""
    quant = quantum**2 / 12
    return (noise**2 + quant * samples) / (noise**2 + quant)


def wheel_torque(h_Nms: np.ndarray, dt_s: float, window_s: float = 20.0) -> np.ndarray:
    """N_w* = ḣ by a Savitzky–Golay derivative (quadratic, ``window_s`` wide).

    Missing samples (NaN: a telemetry dropout) are bridged by a straight line
    between the samples either side, so across a dropout N_w* is the mean wheel
    torque Δh/Δt over it: the torque that carries the propagated h from the last
    tachometer reading to the next.  The first and last samples must be present."""
    h_Nms = np.asarray(h_Nms, dtype=float)
    missing = ~np.isfinite(h_Nms)
    if missing.any():
        k = np.arange(len(h_Nms))
        h_Nms = np.interp(k, k[~missing], h_Nms[~missing])
    n = len(h_Nms)
    window = int(round(window_s / dt_s)) | 1  # odd
    if n < 5:
        return np.zeros(n)
    window = min(window, n if n % 2 else n - 1)
    return savgol_derivative(h_Nms, window, min(2, window - 1), dt_s)


MIN_WINDOWS = 100  # bridges of a length measured on the file, for its mean square


def _bridge_q(h: np.ndarray, steps: int, dt_s: float, var_h: float) -> float | None:
    """q_w ((N m)² s) of a random walk whose Brownian bridge over ``steps`` samples
    matches the file: the mean square of h at the bridge's middle less the straight
    line between its ends, over every such window with all three samples present,
    less the tachometer noise in those three.  None if there are too few windows."""
    m = steps // 2
    w = m / steps
    a, mid, b = h[:-steps], h[m:len(h) - steps + m], h[steps:]
    d = mid - ((1.0 - w) * a + w * b)
    d = d[np.isfinite(d)]
    if d.size < MIN_WINDOWS:
        return None
    excess = float(np.mean(d * d)) - var_h * (1.0 + (1.0 - w) ** 2 + w**2)
    return max(excess, 0.0) / (steps * dt_s * w * (1.0 - w))


def dropout_wheel_noise(h_Nms: np.ndarray, dt_s: float, var_h: float) -> np.ndarray | None:
    """Per-step wheel-torque noise q_w for the steps a dropout bridges, or None if
    every tachometer sample is present.

    Across a dropout N_w* is the mean torque Δh/Δt (``wheel_torque``); the true
    torque wanders about it (the control works the wheels at the nutation period).
    Its effect is modelled as the paper's wheel-torque noise q_w on the bridged
    steps, sized from the telemetry itself: for a bridge of L steps, q_w is the one
    whose Brownian bridge has the variance that straight-line bridges of L steps
    leave at their middle, measured wherever the file has the three samples
    (``_bridge_q``; lengths with too few windows take the longest measured one's q,
    a random walk's extrapolation).  The filtered σ_h then grows over the dropout
    as q_w·t, which covers the bridge's error (q_w·t·(1 − t/T) at time t of T)."""
    h = np.asarray(h_Nms, dtype=float)
    missing = ~np.isfinite(h)
    if not missing.any():
        return None
    edges = np.flatnonzero(np.diff(np.r_[0, missing.astype(int), 0]))
    starts, ends = edges[::2] - 1, edges[1::2]  # last present before, first after
    lengths = ends - starts
    per_step = np.zeros(len(h))
    q_of: dict[int, float] = {}
    fallback = None
    for steps in sorted(set(lengths.tolist())):
        q = _bridge_q(h, steps, dt_s, var_h)
        if q is None:
            q = fallback if fallback is not None else 0.0
        else:
            fallback = q
        q_of[steps] = q
    for a, b in zip(starts, ends, strict=True):
        per_step[a:b] = q_of[int(b - a)]
    return per_step


@dataclass(frozen=True)
class FilterInputs:
    measurements: Measurements
    u: np.ndarray          # (N, 9), Eq. 12a; its h column is the modelled N_w*
    # q_w ((N m)² s) on each step a telemetry dropout bridges, zero elsewhere; or None
    wheel_noise: np.ndarray | None = None


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
    # A missing roll or wheel speed (NaN: a dropout) means no update at that sample;
    # h needs every wheel.  The ends must be present to bridge the wheel torque.
    h = yaw_momentum(speeds, k)
    if not (np.isfinite(h[0]) and np.isfinite(h[-1])):
        raise ValueError("the wheel speeds of the first and last samples must be present")
    if yaw_sigma_rad is None:  # a file without per-sample σ: the Sun sensor's spec
        var_yaw = yaw_variance(sensors)
    else:
        var_yaw = np.where(np.isfinite(yaw), np.asarray(yaw_sigma_rad, dtype=float) ** 2, 1.0)
    meas = Measurements(roll, yaw, h, roll_variance(sensors), var_yaw,
                        float(np.sum(k**2)) * tach_variance(sensors))
    nw = wheel_torque(h, dt_s, nw_window_s)
    u = input_vector(params, Nx_model_Nm, Nz_model_Nm, nw) * np.ones((len(roll), 1))
    return FilterInputs(meas, u, dropout_wheel_noise(h, dt_s, float(meas.var_h)))


# --- Telemetry at any cadence (``steps``): each sample at its own time --------------

def cadence(t_s) -> float:
    """A file's own cadence: its median step (s)."""
    return float(np.median(np.diff(np.asarray(t_s, dtype=float))))


def _uniform(t: np.ndarray, dt: float, origin: float | None = None) -> np.ndarray:
    """Times origin + k·dt covering [t[0], t[-1]] (origin: t[0] when None).  A stretch
    of a longer record passes the record's origin, so its points are the record's."""
    if origin is None:
        return t[0] + dt * np.arange(int(np.floor((t[-1] - t[0]) / dt + 1e-9)) + 1)
    k0 = int(np.ceil((t[0] - origin) / dt - 1e-9))
    k1 = int(np.floor((t[-1] - origin) / dt + 1e-9))
    return origin + dt * np.arange(k0, k1 + 1)


def wheel_torque_at(t_s, h_Nms, window_s: float = 20.0, cadence_s: float | None = None,
                    origin_s: float | None = None) -> np.ndarray:
    """N_w* held over each step [t_k, t_{k+1}] of samples at any times: the mean of
    ḣ over the step, the constant input that carries h across it (Eq. 31 holds ū
    over the step).  ḣ is ``wheel_torque``'s Savitzky–Golay derivative of h
    resampled linearly onto the file's own cadence (``cadence``), so across a gap it
    is the bridge's Δh/Δt, as on the grid; its running integral, read at the sample
    times, gives each step's mean.  The last sample gets the step before it.  A
    stretch of a longer record (a streamed window) passes the record's cadence and
    first time (``cadence_s``, ``origin_s``), so it resamples onto the record's points."""
    t = np.asarray(t_s, dtype=float)
    h = np.asarray(h_Nms, dtype=float)
    ok = np.isfinite(h)
    if not (ok[0] and ok[-1]):
        raise ValueError("the wheel speeds of the first and last samples must be present")
    dt = cadence(t) if cadence_s is None else cadence_s
    grid = _uniform(t, dt, origin_s)
    rate = wheel_torque(np.interp(grid, t[ok], h[ok]), dt, window_s)
    integral = np.r_[0.0, np.cumsum(0.5 * (rate[1:] + rate[:-1]) * dt)]
    # The integral at the samples (the last ones may lie past the grid's end by < dt).
    H = np.interp(t, grid, integral, right=np.nan)
    past = np.isnan(H)
    H[past] = integral[-1] + rate[-1] * (t[past] - grid[-1])
    nw = np.diff(H) / np.diff(t)
    return np.r_[nw, nw[-1]]


def dropout_wheel_noise_at(t_s, h_Nms, var_h: float, gap_factor: float = 1.5,
                           cadence_s: float | None = None, origin_s: float | None = None
                           ) -> np.ndarray | None:
    """``dropout_wheel_noise`` for samples at any times: per-step q_w ((N m)² s) on each
    step longer than ``gap_factor`` × the file's cadence (a dropout, or a missing
    tachometer reading inside one), None if there is none.  A bridge of duration T
    takes the q_w that straight-line bridges of T leave at their middle, measured on
    the file resampled to its cadence at the nearest sample (not interpolated, which
    would average the tachometer noise away): a jitter of tens of ms moves a bridge
    of minutes by nothing that matters.  ``cadence_s``, ``origin_s``: as
    ``wheel_torque_at``'s."""
    t = np.asarray(t_s, dtype=float)
    h = np.asarray(h_Nms, dtype=float)
    ok = np.isfinite(h)
    dt = cadence(t) if cadence_s is None else cadence_s
    tk, hk = t[ok], h[ok]
    span = np.diff(tk)
    gaps = span > gap_factor * dt
    if not gaps.any():
        return None
    grid = _uniform(t, dt, origin_s)
    j = np.clip(np.searchsorted(tk, grid), 1, len(tk) - 1)
    j = np.where(grid - tk[j - 1] < tk[j] - grid, j - 1, j)
    near = np.where(np.abs(tk[j] - grid) <= 0.5 * dt, hk[j], np.nan)
    lengths = np.rint(span[gaps] / dt).astype(np.int64)
    q_of, fallback = {}, None
    for steps in sorted(set(lengths.tolist())):
        q = _bridge_q(near, steps, dt, var_h) if steps < len(near) else None
        if q is None:
            q = fallback if fallback is not None else 0.0
        else:
            fallback = q
        q_of[steps] = q
    # Each bridged tachometer span's q_w on every filter step inside it.
    per_step = np.zeros(len(t))
    idx = np.flatnonzero(ok)
    for k, steps in zip(np.flatnonzero(gaps), lengths, strict=True):
        per_step[idx[k]:idx[k + 1]] = q_of[int(steps)]
    return per_step


def prepare_at_times(params: ModelParams, t_s, roll_rad, yaw_rad, wheel_speeds_radps,
                     yaw_factors, sensors: SensorSpecs = PAPER_SENSORS, yaw_sigma_rad=None,
                     Nx_model_Nm=0.0, Nz_model_Nm=0.0, nw_window_s: float = 20.0,
                     cadence_s: float | None = None, origin_s: float | None = None
                     ) -> FilterInputs:
    """``prepare`` for samples at their own times ``t_s`` (any cadence, jitter, gaps):
    the same measurements, with N_w* each step's mean (``wheel_torque_at``) and the
    dropout noise per step (``dropout_wheel_noise_at``); ``cadence_s``, ``origin_s``
    those of the record a stretch ``t_s`` is of (``wheel_torque_at``)."""
    t = np.asarray(t_s, dtype=float)
    dt = cadence(t) if cadence_s is None else cadence_s
    base = prepare(params, dt, roll_rad, yaw_rad, wheel_speeds_radps, yaw_factors,
                   sensors, yaw_sigma_rad, Nx_model_Nm, Nz_model_Nm, nw_window_s)
    meas = base.measurements
    nw = wheel_torque_at(t, meas.h_Nms, nw_window_s, dt, origin_s)
    u = input_vector(params, Nx_model_Nm, Nz_model_Nm, nw) * np.ones((len(t), 1))
    return FilterInputs(meas, u, dropout_wheel_noise_at(t, meas.h_Nms, float(meas.var_h),
                                                        cadence_s=dt, origin_s=origin_s))


def earth_pitch(pitch_rad, dt_s: float, window_s: float = 20.0) -> np.ndarray:
    """The Earth sensor's pitch and pitch rate (N, 2), smoothed by the quadratic
    Savitzky–Golay fit ``wheel_torque`` uses: the nonlinear batch's pitch, which it
    takes from the sensor rather than propagating (``batch.steps``).  Missing samples
    are bridged by a straight line."""
    p = np.asarray(pitch_rad, dtype=float)
    ok = np.isfinite(p)
    if not ok.any():
        raise ValueError("no Earth-sensor pitch")
    if not ok.all():
        k = np.arange(len(p))
        p = np.interp(k, k[ok], p[ok])
    n = len(p)
    window = min(int(round(window_s / dt_s)) | 1, n if n % 2 else n - 1)
    if window < 3:
        return np.column_stack([p, np.zeros(n)])
    return np.column_stack([savgol_derivative(p, window, 2, dt_s, deriv=0),
                            savgol_derivative(p, window, 2, dt_s, deriv=1)])
