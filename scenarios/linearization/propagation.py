"""Section 2 of the linearization report: nonlinear against linear propagation.

The nonlinear truth and a linear model start from the same deviation and are
driven by the same torques: the true external roll and yaw torques (gravity
gradient excluded, the models carry it in F) and the true wheel-momentum rate
N_w = ḣ.  Their difference, linear minus nonlinear, is the *divergence*.  Two
linear models are propagated:

- ``eq11``: the paper's model (Eq. 11c and the h column of Eq. 11d), the one
  the filter uses;
- ``jacobian``: the CasADi Jacobian of the truth at the nominal state, in the
  same units.  Its divergence is the pure second-order remainder, so it must
  grow as the square of the initial error; any first-order part of the eq11
  divergence is the price of the paper's approximations (Eqs. 5 and 6).

Scenario variants are expressed as ``--set`` style (key, value) pairs, so every
row of the report names the overrides that reproduce it.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any

import numpy as np
from dynprop.eom.linear import model_matrices
from dynprop.estimator.linear import model as em
from dynprop.estimator.linear.propagate import propagate_lti, zoh
from dynprop.estimator.linear.transition import discretize
from dynprop.sim.frames import euler312_rates
from dynprop.sim.linearize import linearize_about_nominal

from ..bridge.coordinates import external_torque, model_attitude, step_rates
from ..config import build
from ..config.loader import validate
from ..config.schema import Scenario
from ..units import DEG
from .coefficients import eq11_matrices

SWEEP_DEG = (0.01, 0.1, 1.0, 3.0, 10.0)
ENVELOPE = 64  # samples per bin of the |divergence| envelopes kept for the figures

Change = tuple[str, Any]


def variant(s: Scenario, changes: list[Change]) -> Scenario:
    """The scenario with dotted-key changes applied and validated like ``--set``."""
    raw = s.model_dump(mode="json")
    for key, value in changes:
        node = raw
        *parents, last = key.split(".")
        for k in parents:
            node = node[k]
        node[last] = value
    return validate(raw)


def set_flags(changes: list[Change]) -> str:
    """The changes as ``--set`` options (values in YAML flow syntax)."""
    return " ".join(f"--set {k}={json.dumps(v, separators=(',', ':'))}" for k, v in changes)


def sweep_changes(s: Scenario, kind: str, delta_deg: float, omega_n: float,
                  pitch: bool = True) -> list[Change]:
    """Initial roll and yaw errors of δ (``attitude``), or initial roll and yaw rates
    δ·|ω_n| (``rate``): a rate error ω starts a nutation cone of half-angle ≈ ω/|ω_n|,
    so both sweeps span the same 0.01°–10° of attitude excursion.  (10 °/s itself would
    tumble the spacecraft: the body momentum would be 5 times H.)  The filter's initial
    σ is widened to cover the error, so that the filter's consistency measures the
    model, not a prior that excludes the truth.  Pitch gets the same error unless
    ``pitch`` is false: its coupling into roll and yaw is second order (Eq. 3b)."""
    i, sig = s.initial_state, s.estimator.initial_sigma
    if kind == "attitude":
        return [("initial_state.roll_deg", i.roll_deg + delta_deg),
                ("initial_state.pitch_deg", i.pitch_deg + delta_deg * pitch),
                ("initial_state.yaw_deg", i.yaw_deg + delta_deg),
                ("estimator.initial_sigma.roll_deg", max(sig.roll_deg, delta_deg)),
                ("estimator.initial_sigma.yaw_deg", max(sig.yaw_deg, delta_deg))]
    if kind == "rate":
        rate = delta_deg * abs(omega_n)
        w = list(i.rate_wrt_orbit_degps)
        return [("initial_state.rate_wrt_orbit_degps",
                 [w[0] + rate, w[1] + rate * pitch, w[2] + rate]),
                ("estimator.initial_sigma.roll_rate_degps", max(sig.roll_rate_degps, rate)),
                ("estimator.initial_sigma.yaw_rate_degps", max(sig.yaw_rate_degps, rate))]
    raise ValueError(f"unknown sweep kind {kind!r}")


@dataclass(frozen=True)
class LinearModel:
    """A discretized 5-state roll/yaw/h model: x_{k+1} = Φ x_k + Γ [N_x, N_z, N_w]_k."""

    name: str
    F: np.ndarray
    G: np.ndarray
    Phi: np.ndarray
    Gamma: np.ndarray


def linear_models(s: Scenario, names=("eq11", "jacobian")) -> dict[str, LinearModel]:
    """The paper's Eq. 11 model and the exact Jacobian, for this scenario's spacecraft."""
    params, _ = build.estimator_model(s)
    wn, dt = params.omega_n_radps, s.sample_interval_s
    mats = {"eq11": eq11_matrices(params.omega0_radps, wn, params.H_Nms)}
    if "jacobian" in names:
        lin = linearize_about_nominal(build.build_spacecraft(s), build.orbit(s))
        mats["jacobian"] = model_matrices(lin.wrt_state, lin.wrt_input, wn)
    return {k: LinearModel(k, F, G, *zoh(F, G, dt)) for k, (F, G) in mats.items()}


def model_state(truth, omega_n: float) -> np.ndarray:
    """The truth as [r, ṙ/ω_n, y, ẏ/ω_n, h] (N, 5), Euler rates from ω_BR."""
    return model_attitude(truth, euler312_rates(truth.euler_rad, truth.w_br_radps), omega_n)


def model_inputs(truth, dt: float) -> np.ndarray:
    """[N_x, N_z, N_w] (N, 3): true external body torques and N_w averaged over each
    step (exact for h under a zero-order hold)."""
    ext = external_torque(truth)
    return np.column_stack([ext[:, 0], ext[:, 2], step_rates(truth.h_Nms, dt)])


def divergence(x_truth: np.ndarray, u: np.ndarray, m: LinearModel, start: int = 0,
               stop: int | None = None) -> np.ndarray:
    """Linear minus nonlinear (N', 5) from ``start`` to ``stop`` (inclusive), the
    linear model started on the truth at ``start``."""
    stop = len(x_truth) - 1 if stop is None else stop
    lin = propagate_lti(m.Phi, m.Gamma, x_truth[start], u[start:stop + 1])
    return lin - x_truth[start:stop + 1]


def envelope(a: np.ndarray, block: int = ENVELOPE) -> np.ndarray:
    """max |a| over consecutive blocks (keeps nutation peaks that decimation would drop)."""
    n = len(a) // block * block
    env = np.abs(a[:n]).reshape(-1, block).max(axis=1)
    return np.append(env, np.abs(a[n:]).max()) if n < len(a) else env


def gap_yaw_errors(s: Scenario, truth, gap: tuple[int, int]) -> dict[str, float]:
    """Yaw error (deg) of Eq. 11 propagated across the Sun gap from the truth at its
    start: with the true torques (``dynamics``), and with the paper's torque model
    instead (``torque_model``: N* plus the constant + ω0-sinusoid states fitted over
    the run, Eqs. 9 and 18; the fit's residual is what the model cannot represent)."""
    a, b = gap
    params, noise = build.estimator_model(s)
    dt, wn = s.sample_interval_s, params.omega_n_radps
    x5, u = model_state(truth, wn), model_inputs(truth, dt)
    eq11 = linear_models(s, ("eq11",))["eq11"]
    dyn = divergence(x5, u, eq11, a, b)[-1]
    mt = s.estimator.model_torques
    states, _, _ = em.project_torques(truth.t_s, u[:, 0] - mt.roll_Nm, u[:, 1] - mt.yaw_Nm,
                                   params.omega0_radps)
    disc = discretize(params, noise, dt)
    x0 = np.concatenate([x5[a], states[a]])
    uu = em.input_vector(params, mt.roll_Nm, mt.yaw_Nm, u[a:b + 1, 2])
    tq = propagate_lti(disc.Phi, disc.Gamma, x0, uu)[-1, :5] - x5[b]
    return {"dynamics_deg": float(dyn[2] / DEG), "torque_model_deg": float(tq[2] / DEG),
            "dynamics_roll_deg": float(dyn[0] / DEG),
            "torque_model_roll_deg": float(tq[0] / DEG)}
