"""The pitch filter's design and inputs (Eq. 3b, ``estimator.pitch``) from a scenario
and its telemetry.

- Model: the nominal diagonal inertias and orbit rate (``build.estimator_model``).
- Noise: the white torque q_w and the torque random walk q_c are the scenario's
  ``estimator.process_noise.q_y`` and ``q_cy``.  The paper has no pitch state; they
  default to roll's q_x and q_cx defaults (the pitch axis sees the same kinds of
  torque: solar, ripple), and are keys of their own so that `dynprop tune`, which
  tunes the roll/yaw filter's q_x, never hands its roll numbers to pitch: a q_x cut
  to 1e-12 made the pitch NEES 2644.
- Prior: zero, with roll's initial σ for pitch, pitch rate and N_y (as the EKF takes
  roll's σ for its pitch).
- Measurement: the Earth sensor's pitch, with the variance of its roll channel
  (``estimator.covariance.roll_variance``: the same sensor, noise and quantum).
- Input: Ḣ of the signed pitch-wheel momentum H = Σ I_w a_i·ŷ Ω_i from the
  tachometers (their common mode), differentiated as the paper filter's ḣ is
  (``estimator.preprocess.wheel_torque``).  A dropout's missing speeds are bridged
  by a straight line (no jump to the nominal H).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from dynprop.estimator.kalman.preprocess import wheel_torque, wheel_torque_at, yaw_momentum
from dynprop.estimator.linear.noise import roll_variance
from dynprop.estimator.pitch.model import PitchNoise

from ..config import build
from ..config.schema import Scenario
from ..units import DEG
from .inputs import join_padded


@dataclass(frozen=True)
class PitchDesign:
    """What ``estimator.pitch.pitch_filter`` needs besides the telemetry."""

    params: object            # estimator.model.ModelParams (its inertias and ω0)
    noise: PitchNoise
    x0: np.ndarray
    P0: np.ndarray
    R: float                  # the Earth sensor's pitch variance, rad²


def pitch_design(s: Scenario) -> PitchDesign:
    params, _ = build.estimator_model(s)
    i, q = s.estimator.initial_sigma, s.estimator.process_noise
    sig = np.array([i.roll_deg * DEG, i.roll_rate_degps * DEG, i.N_cx_Nm])
    return PitchDesign(params, PitchNoise(q_w=q.q_y, q_c=q.q_cy), np.zeros(3),
                       np.diag(sig**2), roll_variance(build.estimator_sensor_specs(s)))


def pitch_wheel_rate(s: Scenario, speeds, t_s=None, record=None) -> np.ndarray:
    """Ḣ (N m) of the signed pitch-wheel momentum from the wheel speeds (N, n; NaN in a
    dropout); ``t_s`` the samples' own times for telemetry off the grid."""
    H = yaw_momentum(speeds, build.build_spacecraft(s).momentum_factors(1))
    window = s.estimator.wheel_torque_window_s
    if t_s is None:
        return wheel_torque(H, s.sample_interval_s, window)
    ok = np.isfinite(H)
    k = np.arange(len(H))
    return wheel_torque_at(t_s, np.interp(k, k[ok], H[ok]), window,
                           *(record if record is not None else ()))


def padded_pitch_wheel_rate(s: Scenario, prev_tail: np.ndarray | None, cur: np.ndarray,
                            nxt: np.ndarray | None, pad: int, t_s=None, record=None
                            ) -> np.ndarray:
    """``pitch_wheel_rate`` of a window's speeds padded with ``pad`` samples of each
    neighbour (``inputs.join_padded``), so that it equals the whole run's; ``t_s`` the
    padded samples' times off the grid (``record``: their file's cadence and first
    time, ``inputs.prepared_inputs``')."""
    joined, sl = join_padded(None if prev_tail is None else (prev_tail,), (cur,),
                             None if nxt is None else (nxt,), pad)
    return pitch_wheel_rate(s, joined[0], t_s, record)[sl]
