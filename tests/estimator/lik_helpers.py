"""Telemetry drawn from the paper filter's own linear model, for the likelihood and
noise-tuning tests (test_likelihood.py, test_tune_fit.py): the truth steps as
x_{k+1} = Φ x_k + Γ u_k + w_k with w_k ~ N(0, Q_d(θ) + e'_k Q_d(q_w = 1)), the
measurements are roll, yaw and h with the stated variances, so the filter's
likelihood is exactly the model's and its maximum is a consistent estimate of θ."""

from __future__ import annotations

import numpy as np

from estimator.kalman.filter import Measurements
from estimator.linear.model import H_WHEEL, N_STATES, ModelParams, ProcessNoise, R, Y
from estimator.linear.transition import discretize

DT = 0.512
# GOES-Next numbers from the paper (Section 2, Eq. 1), typed here independently.
H = -0.1082 * 2 * 5485 * 2 * np.pi / 60 * np.cos(np.deg2rad(1.656))
PARAMS = ModelParams(3364.376, 954.936, 3461.393, H, np.sqrt(3.986004418e14 / 42164170.0**3))
R_ROLL, R_YAW, R_H = 3.3e-8, (0.04 * np.pi / 180) ** 2, 1.5e-7
P0 = np.diag([1e-6, 1e-6, 1e-4, 1e-6, 1e-4, 1e-12, 1e-12, 1e-12, 1e-12])
NOISE_KEYS = ("q_x", "q_z", "q_w", "q_px", "q_pz", "q_cx", "q_cz")


def noise_at(groups: dict, fixed: ProcessNoise, theta) -> ProcessNoise:
    """The ProcessNoise that θ sets (each group's keys times their factors, the
    rest held at ``fixed``), written out here rather than taken from NoiseModel."""
    values = {k: getattr(fixed, k) for k in NOISE_KEYS}
    for t, group in zip(theta, groups.values(), strict=False):
        for k, c in group.items():
            values[k] = c * float(t)
    return ProcessNoise(**values)


def unit_wheel_Qd(dt: float = DT) -> np.ndarray:
    """Q_d of q_w = 1 (N m)² s alone: what a bridged dropout adds per unit."""
    return discretize(PARAMS, ProcessNoise(q_x=0.0, q_z=0.0, q_w=1.0), dt).Qd


def noise_sqrt(Q: np.ndarray) -> np.ndarray:
    """A square root L (L Lᵀ = Q) of a positive semi-definite Q whose states have mixed
    units (rad² next to (N m)²): the eigen-decomposition is taken in units of each
    state's own √Q_ii, where it is well conditioned; zero rows stay zero."""
    d = np.sqrt(np.clip(np.diag(Q), 0.0, None))
    s = np.where(d > 0, d, 1.0)
    w, V = np.linalg.eigh(Q / np.outer(s, s))
    return s[:, None] * (V * np.sqrt(np.clip(w, 0.0, None)))


def simulate(q: ProcessNoise, n: int, rng, *, u=None, extra=None, x0=None,
             var_yaw=R_YAW) -> tuple[np.ndarray, np.ndarray]:
    """The truth x (n, 9) and measurements z (n, 3: roll, yaw, h) of the linear model,
    x_0 ~ N(x0, P0); ``extra`` (n,) adds extra[k]·Q_d(q_w = 1) to step k → k+1 (the
    bridged dropout), ``var_yaw`` may vary per sample."""
    disc = discretize(PARAMS, q, DT)
    L = noise_sqrt(disc.Qd)
    Lw = noise_sqrt(unit_wheel_Qd())
    u = np.zeros((n, N_STATES)) if u is None else np.asarray(u, float)
    e = np.zeros(n) if extra is None else np.asarray(extra, float)
    drive = (rng.standard_normal((n, N_STATES)) @ L.T + u @ disc.Gamma.T
             + np.sqrt(e)[:, None] * (rng.standard_normal((n, N_STATES)) @ Lw.T))
    x = (np.zeros(N_STATES) if x0 is None else np.asarray(x0, float)) \
        + noise_sqrt(P0) @ rng.standard_normal(N_STATES)
    xs = np.empty((n, N_STATES))
    PhiT = np.ascontiguousarray(disc.Phi.T)
    for k in range(n):
        xs[k] = x
        x = x @ PhiT + drive[k]
    sd = np.column_stack(np.broadcast_arrays(np.sqrt(R_ROLL), np.sqrt(var_yaw), np.sqrt(R_H)))
    sd = np.broadcast_to(sd, (n, 3))
    z = xs[:, [R, Y, H_WHEEL]] + sd * rng.standard_normal((n, 3))
    return xs, z


def simulate_many(q: ProcessNoise, n: int, m: int, rng) -> np.ndarray:
    """Measurements z (m, n, 3) of m independent records of the model (no inputs, no
    extra noise, x_0 ~ N(0, P0)), stepped together."""
    disc = discretize(PARAMS, q, DT)
    L = noise_sqrt(disc.Qd)
    x = rng.standard_normal((m, N_STATES)) @ noise_sqrt(P0).T
    PhiT = np.ascontiguousarray(disc.Phi.T)
    xs = np.empty((n, m, N_STATES))
    for k in range(n):
        xs[k] = x
        x = x @ PhiT + rng.standard_normal((m, N_STATES)) @ L.T
    z = xs[..., [R, Y, H_WHEEL]] + np.sqrt([R_ROLL, R_YAW, R_H]) * rng.standard_normal((n, m, 3))
    return z.transpose(1, 0, 2)


def measurements(z: np.ndarray, var_roll=R_ROLL, var_yaw=R_YAW) -> Measurements:
    return Measurements(z[:, 0], z[:, 1], z[:, 2], var_roll, var_yaw, R_H)
