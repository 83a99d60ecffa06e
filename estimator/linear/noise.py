"""The paper's measurement and process noise from the sensors' specifications
(Section 6, Eqs. 44–48, 51): the roll, yaw and tachometer variances with their
quantisation, h's variance through the wheels' cant, and the torque and ripple
densities q and q_w.  These are the filter's R and q as the paper sets them; the
covariance analyses (``analysis.covariance``) and the ground preprocessing
(``kalman.preprocess``) both read them here.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

SIDEREAL_DAY_S = 86164.0905
RPM = 2 * np.pi / 60


@dataclass(frozen=True)
class SensorSpecs:
    """Sections 2.1 and 2.3; yaw is the DSS's (the paper gives the filter none; errata 7)."""

    dt_s: float = 0.512
    tach_quantum_rpm: float = 0.0163
    tach_noise_3sigma_rpm: float = 0.0978
    roll_noise_deg: float = 0.01
    roll_quantum_deg: float = 0.01
    yaw_noise_deg: float = 0.0042
    yaw_quantum_deg: float = 0.125
    wheel_inertia_kgm2: float = 0.1082
    cant_deg: float = 1.656
    # Σ k_i² with h = Σ k_i Ω_i (k_i = I_w,i a_i·ẑ); None means the two canted wheels,
    # 2 (I_w sin c)².  The backup configuration's yaw reaction wheel needs its own.
    h_factor_sq_sum: float | None = None


PAPER_SENSORS = SensorSpecs()   # Sections 2.1 and 2.3


def quantized_variance(sigma: float, quantum: float) -> float:
    """σ² + quantum²/12: noise plus uniform quantisation error (Eqs. 46–47)."""
    return sigma**2 + quantum**2 / 12.0


def tach_variance(s: SensorSpecs = SensorSpecs()) -> float:
    """R_tach of Eq. 46, (rad/s)², per wheel."""
    return quantized_variance(s.tach_noise_3sigma_rpm / 3.0, s.tach_quantum_rpm) * RPM**2


def roll_variance(s: SensorSpecs = SensorSpecs()) -> float:
    """R_roll of Eq. 47, rad²."""
    return quantized_variance(s.roll_noise_deg, s.roll_quantum_deg) * (np.pi / 180) ** 2


def yaw_variance(s: SensorSpecs = SensorSpecs()) -> float:
    """Sun-sensor yaw variance, rad² (the rule of Eq. 47)."""
    return quantized_variance(s.yaw_noise_deg, s.yaw_quantum_deg) * (np.pi / 180) ** 2


def h_variance(s: SensorSpecs = SensorSpecs()) -> float:
    """Variance of h = Σ k_i Ω_i from the tachometers, (N m s)²: Σ k_i² R_tach, which for
    the two canted wheels of Eq. 2 is 2 (I_w sin c)² R_tach."""
    k2 = s.h_factor_sq_sum
    if k2 is None:
        k2 = 2.0 * (s.wheel_inertia_kgm2 * np.sin(np.deg2rad(s.cant_deg))) ** 2
    return k2 * tach_variance(s)


def combined_variance(H_Nms: float, s: SensorSpecs = SensorSpecs()) -> float:
    """R_k of Eq. 48: the variance of the measured x̃1 = r + h/H."""
    return roll_variance(s) + h_variance(s) / H_Nms**2


def continuous_R(H_Nms: float, s: SensorSpecs = SensorSpecs()) -> float:
    """R = R_k Δt of Eq. 51, rad² s."""
    return combined_variance(H_Nms, s) * s.dt_s


def torque_noise_density(torque_Nm: float = 5e-6, correlation_s: float = SIDEREAL_DAY_S / 4):
    """q of Eq. 45: mean-square torque error × correlation time (a quarter orbit)."""
    return torque_Nm**2 * correlation_s


def ripple_noise_density(psd_per_hz: float = 6e-7, cant_deg: float = 1.656,
                         paper: bool = False) -> float:
    """q_w of Eq. 44 for two wheels of one-sided ripple PSD G (N m)²/Hz.

    ``paper=True``: the printed expression 2 sin²c G/2π (1.595e-10, printed
    1.3e-10).  Default: the white-noise intensity of Eq. 35, 2 sin²c G/2 (5.0e-10),
    as the truth model uses (docs/paper-errata.md entry 6).
    """
    return 2 * np.sin(np.deg2rad(cant_deg)) ** 2 * psd_per_hz / (2 * np.pi if paper else 2.0)
