"""The extended Kalman filter on the full nonlinear model (``ekf.model``), beside the
paper's linear one (``kalman``): the same telemetry, the same compiled
rollout, results in the paper's coordinates so every comparison applies to both.

Each step, at t_k: sequential scalar updates of roll, pitch, yaw and h, all
linearised at the prior (so the order does not matter: the batch update, one
scalar at a time), in Joseph form, the angle innovations wrapped to ±π; the
correction is then applied to the nominal state (the quaternion multiplicatively,
``ekf.model.inject``).  Then RK4 propagation of the nominal state over Δt with the
inputs held, and P⁻ = Φ P⁺ Φᵀ + Q_d with Φ the error-state Jacobian of that very
RK4 step and Q_d = ½(Φ G Q Gᵀ Φᵀ + G Q Gᵀ) Δt (trapezoid: Δt = 0.512 s is 1/340 of
the nutation period).  The error state is reset to zero after each update; the
reset's Jacobian, I − ½[δθ×], is dropped, as is usual for small corrections.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import casadi as ca
import numpy as np
from dynprop.rollout.chunks import ChunkedRollout

from ..kalman.filter import N_UT, FilterResult
from ..kalman.maneuver import Maneuver, filter_segments
from ..linear.steps import per_step, roll_blocks, step_params, substeps
from . import model as m

_IU = np.triu_indices(m.NE)
N_UT_E = len(_IU[0])   # 66
_IU9 = np.triu_indices(9)


def _unpack_sym(p, n, iu) -> ca.SX:
    P = ca.SX(n, n)
    for k, (i, j) in enumerate(zip(*iu, strict=True)):
        P[i, j] = p[k]
        P[j, i] = p[k]
    return P


def _pack_sym(P, iu) -> ca.SX:
    return ca.vertcat(*(P[i, j] for i, j in zip(*iu, strict=True)))


def unpack_e(p: np.ndarray) -> np.ndarray:
    """(..., 66) -> symmetric (..., 11, 11)."""
    p = np.asarray(p)
    P = np.zeros(p.shape[:-1] + (m.NE, m.NE))
    P[..., _IU[0], _IU[1]] = p
    P[..., _IU[1], _IU[0]] = p
    return P


def _symmetric(P):
    return _unpack_sym(_pack_sym(P, _IU), m.NE, _IU)


def _wrap(a):
    return ca.atan2(ca.sin(a), ca.cos(a))


ITERATIONS = 2   # of the measurement update: 10° → ~1° → ~0.01°, the noise level


@lru_cache(maxsize=4)
def ekf_step(iterations: int = ITERATIONS) -> ca.Function:
    """``(s, z, mask, r, u, p) -> (s_next, aux)`` with s = [X̂⁻ (12), P⁻ (66)], p =
    [model parameters (``ekf.model.pack_params``), ω_n]; aux = [x (9) and P (45) in
    the paper's coordinates, ν (4), S (4), X̂⁺ (12)] after the update."""
    s = ca.SX.sym("s", m.NX + N_UT_E)
    z, mask, r = ca.SX.sym("z", m.NZ), ca.SX.sym("m", m.NZ), ca.SX.sym("r", m.NZ)
    u, p = ca.SX.sym("u", m.NU), ca.SX.sym("p", m.N_PARAMS + 1)
    pm, wn = p[:m.N_PARAMS], p[m.N_PARAMS]
    phi_f, h_f, t_f = m.error_jacobians()
    nus, ss = [], []
    X_prior, P_prior = s[:m.NX], _unpack_sym(s[m.NX:], m.NE, _IU)
    X = X_prior
    for it in range(iterations):
        # Gauss–Newton on the update (iterated EKF): linearise at the current iterate
        # X, where the prior's mean sits at d (X_prior = X ⊕ d).
        Hm, zhat = h_f(X), m.measure(X)
        dx = m.extract(X, X_prior) if it else ca.SX.zeros(m.NE)
        P = P_prior
        for i in range(m.NZ):
            G = Hm[i, :]
            a = P @ G.T
            S = G @ a + r[i]
            K = mask[i] * a / S
            resid = z[i] - zhat[i]
            if i in m.ANGLE_MEAS:
                resid = _wrap(resid)
            nu = resid - G @ dx
            # Joseph form (I − KG) P (I − KG)ᵀ + r K Kᵀ, expanded: with a dense row G
            # it is rank-one terms, O(n²) instead of O(n³).
            P = _symmetric(P - K @ a.T - a @ K.T + S * (K @ K.T))
            dx = dx + K * nu
            if it == 0:   # the innovations of the prior, for NIS
                nus.append(resid)
                ss.append(S)
        X = m.inject(X, dx)
    Xp = X
    T = t_f(Xp, pm, wn)
    x9 = m.paper_coordinates(Xp, pm, wn)
    P9 = T @ P @ T.T
    Phi = phi_f(Xp, u, pm)
    Gn = m.noise_map(pm)
    _, _, dt, q = m.unpack_params(pm)
    half_gqg = 0.5 * dt * (Gn @ ca.diag(q) @ Gn.T)
    X_next = m.rk4(Xp, u, pm)
    # Φ P Φᵀ + Q_d with Q_d = ½Δt (Φ GQGᵀ Φᵀ + GQGᵀ): one congruence, not two.
    P_next = _symmetric(Phi @ (P + half_gqg) @ Phi.T + half_gqg)
    out = ca.cse(ca.vertcat(X_next, _pack_sym(P_next, _IU), x9, _pack_sym(P9, _IU9),
                            *nus, *ss, Xp))
    n_s = m.NX + N_UT_E
    return ca.Function("dynprop_ekf", [s, z, mask, r, u, p], [out[:n_s], out[n_s:]],
                       ["s", "z", "m", "r", "u", "p"], ["s_next", "aux"])


@lru_cache(maxsize=4)
def _engine(chunk: int, backend: str | None, iterations: int = ITERATIONS) -> ChunkedRollout:
    return ChunkedRollout(ekf_step(iterations), chunk, 256, backend)


@dataclass(frozen=True)
class EkfInputs:
    """Per sample: measurements z (N, 4: roll, pitch, yaw in rad, h in N m s; NaN
    where missing), their variances r (N, 4), and the inputs u (N, 5: H, Ḣ, N_w*,
    N_x*, N_z*)."""

    z: np.ndarray
    r: np.ndarray
    u: np.ndarray
    # The response to a thruster-firing flag (``kalman.maneuver``; its states
    # ``ROLL_YAW`` of the error state, its prior the EKF's), None without one.
    maneuver: Maneuver | None = None

    def cut(self, rows) -> EkfInputs:
        return EkfInputs(self.z[rows], self.r[rows], self.u[rows],
                         None if self.maneuver is None else self.maneuver.cut(rows))


# The error states a maneuver reset returns to the prior: δθ_x, δθ_z, δω_x, δω_z (roll,
# yaw and their rates, the paper's attitude block); pitch, which the thruster's roll
# and yaw torques do not move, is left alone, as the wheel momentum and torque states.
ROLL_YAW = (0, 2, 3, 5)


def inflated_params(params: np.ndarray, noise) -> np.ndarray:
    """The parameter vector with the maneuver's white torque (``Maneuver.noise``)
    added to q_x and q_z."""
    p = np.array(params, dtype=float, copy=True)
    base = m.N_PARAMS - len(m.NOISE_NAMES)
    p[base + m.NOISE_NAMES.index("q_x")] += noise.q_x
    p[base + m.NOISE_NAMES.index("q_z")] += noise.q_z
    return p


@dataclass(frozen=True)
class EkfResult(FilterResult):
    """``FilterResult`` in the paper's coordinates (x, P_packed: roll, ṙ/ω_n, yaw,
    ẏ/ω_n, h, torque states; innovations and their variances in the order roll,
    pitch, yaw, h), plus the nominal state history X (N, 12: q_BR, ω_BR, h, N)."""

    X: np.ndarray | None = None


def initial_state(x0_paper: np.ndarray, P0_paper: np.ndarray, pitch_sigma_rad: float,
                  pitch_rate_sigma_radps: float, omega_n_radps: float
                  ) -> tuple[np.ndarray, np.ndarray]:
    """The EKF's prior from the paper filter's (Eq. 10 coordinates, diagonal P0):
    attitude from roll and yaw (pitch 0), body rates from the scaled Euler rates (at
    small angles ω_BR ≈ (φ̇, θ̇, ψ̇)), and pitch's σ given separately."""
    x0 = np.asarray(x0_paper, dtype=float)
    sig = np.sqrt(np.diag(P0_paper))
    roll, yaw = x0[0], x0[2]
    cr, sr, cy, sy = np.cos(roll / 2), np.sin(roll / 2), np.cos(yaw / 2), np.sin(yaw / 2)
    # q for R1(roll) R3(yaw) (scalar last, A(q1 ⊗ q2) = A(q1) A(q2)).
    q = np.array([sr * cy, sr * sy, cr * sy, cr * cy])
    X0 = np.concatenate([q, [x0[1] * omega_n_radps, 0.0, x0[3] * omega_n_radps], x0[4:]])
    d = np.concatenate([[sig[0], pitch_sigma_rad, sig[2]],
                        [sig[1] * abs(omega_n_radps), pitch_rate_sigma_radps,
                         sig[3] * abs(omega_n_radps)], sig[4:]])
    return X0, np.diag(d**2)


def ekf_filter(inputs: EkfInputs, params: np.ndarray, omega_n_radps: float,
               X0: np.ndarray, P0: np.ndarray, backend: str | None = None,
               chunk: int = 4096, rows=None, keep_nominal: bool = False,
               iterations: int = ITERATIONS, dt_s: np.ndarray | None = None) -> EkfResult:
    """Run the EKF over every sample (``rows``: keep only those samples' history).
    ``params`` from ``ekf.model.pack_params``; with ``dt_s`` (the interval after each
    sample, ``steps.step_intervals``) each step propagates over its own Δt instead of
    the one in ``params`` (``_ekf_per_step``).  ``inputs.maneuver``: the filter runs
    segment by segment, each flagged step with the inflated noise, the roll and yaw
    block of P reset where the response says (``kalman.maneuver``)."""
    mv = inputs.maneuver
    if mv is not None and mv.active:
        def run(seg, inflated, X, P, seg_rows, _):
            return ekf_filter(EkfInputs(inputs.z[seg], inputs.r[seg], inputs.u[seg]),
                              inflated_params(params, mv.noise) if inflated else params,
                              omega_n_radps, X, P, backend, chunk, seg_rows, keep_nominal,
                              iterations, None if dt_s is None else np.asarray(dt_s)[seg])
        return filter_segments(mv, run, X0, P0, rows, None,
                               ("x", "P_packed", "innovations", "innovation_var", "X"))
    z, r, u = (np.asarray(a, dtype=float) for a in (inputs.z, inputs.r, inputs.u))
    n = len(z)
    if z.shape != (n, m.NZ) or r.shape != (n, m.NZ) or u.shape != (n, m.NU):
        raise ValueError("z and r must be (N, 4) and u (N, 5)")
    present = np.isfinite(z)
    if np.any(~(np.isfinite(r) & (r > 0)) & present):
        raise ValueError("measurement variances must be positive where a value is present")
    if not np.all(np.isfinite(u)):
        raise ValueError("the inputs u must be finite")
    if dt_s is not None:
        return _ekf_per_step(inputs, params, omega_n_radps, X0, P0, backend, chunk, rows,
                             keep_nominal, iterations, np.asarray(dt_s, dtype=float))
    engine = _engine(chunk, backend, iterations)
    P0 = np.asarray(P0, dtype=float)
    s0 = np.concatenate([np.asarray(X0, dtype=float), 0.5 * (P0 + P0.T)[_IU]])
    p = np.concatenate([np.asarray(params, dtype=float), [omega_n_radps]])
    ins = [np.where(present, z, 0.0), present.astype(float), np.where(present, r, 1.0), u]
    rows = None if rows is None else np.asarray(rows, dtype=np.int64)
    last, aux = engine.run_kept(s0, ins, p, rows)
    if rows is not None:
        present = present[rows]
    return _result(last, aux, present, engine.backend, keep_nominal)


def _result(last, aux, present, backend: str, keep_nominal: bool) -> EkfResult:
    """The EKF's history from its rollout's final state and kept aux rows (ν and S
    blanked where a measurement was absent)."""
    o = 9 + N_UT
    nu, S = aux[:, o:o + m.NZ].copy(), aux[:, o + m.NZ:o + 2 * m.NZ].copy()
    nu[~present], S[~present] = np.nan, np.nan
    return EkfResult(aux[:, :9], aux[:, 9:o], nu, S, last[:m.NX], unpack_e(last[m.NX:]),
                     backend, aux[:, o + 2 * m.NZ:] if keep_nominal else None)



def _ekf_per_step(inputs: EkfInputs, params, omega_n_radps, X0, P0, backend, chunk, rows,
                  keep_nominal, iterations, dt_s) -> EkfResult:
    """``ekf_filter`` with each sample's own interval ``dt_s``.  The EKF integrates its
    nonlinear model with one RK4 step per interval, which is accurate only over a small
    part of the nutation period (the ~0.5 s the filter is designed for), so an interval
    longer than the nominal one in ``params`` is cut into equal sub-steps no longer than
    it, without measurements, the sample's inputs held over them: a three-hour gap is
    ~21,000 sub-steps, and the history keeps the samples themselves."""
    z = np.asarray(inputs.z, dtype=float)
    n = len(z)
    if dt_s.shape != (n,) or not np.all(np.isfinite(dt_s) & (dt_s > 0)):
        raise ValueError(f"dt_s must hold {n} positive intervals")
    nominal = float(params[m.DT_INDEX])
    src, first, h = substeps(dt_s, nominal)     # first: each sample's own sub-step
    fresh = np.zeros(len(src), dtype=bool)
    fresh[first] = True
    zz = np.where(fresh[:, None], z[src], np.nan)
    expanded = EkfInputs(zz, np.asarray(inputs.r, dtype=float)[src],
                         np.asarray(inputs.u, dtype=float)[src])
    keep = first if rows is None else first[np.asarray(rows, dtype=np.int64)]
    params_of = step_params(np.concatenate([np.asarray(params, dtype=float),
                                            [omega_n_radps]]), m.DT_INDEX, h)

    z2, r2, u2 = expanded.z, expanded.r, expanded.u
    present = np.isfinite(z2)
    P0 = np.asarray(P0, dtype=float)
    s0 = np.concatenate([np.asarray(X0, dtype=float), 0.5 * (P0 + P0.T)[_IU]])
    ins = [np.where(present, z2, 0.0), present.astype(float), np.where(present, r2, 1.0), u2]
    engine = _engine_per_step(chunk, backend, iterations)
    last, _, aux = roll_blocks(engine, s0, ins, len(src), params_of, np.arange(0), keep,
                               np.arange(engine.n_aux))
    return _result(last, aux, present[keep], engine.backend, keep_nominal)


@lru_cache(maxsize=4)
def _engine_per_step(chunk: int, backend: str | None, iterations: int = ITERATIONS
                     ) -> ChunkedRollout:
    return ChunkedRollout(per_step(ekf_step(iterations)), chunk, 256, backend)
