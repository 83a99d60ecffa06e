"""The pitch filter and smoother on the model of Eq. 3b (``model``): pitch, pitch rate
and a constant pitch torque, driven by the signed wheel momentum rate Ḣ.

Filter.  Per sample: a scalar Joseph update with the Earth-sensor pitch (NaN: none),
then x⁻ = Φx⁺ + ΓḢ_k, P⁻ = ΦP⁺Φᵀ + Q_d over the interval after the sample (``kalman``'s
order), one CasADi step compiled with its C loop (``rollout``), Φ, Γ, Q_d read per step.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import casadi as ca
import numpy as np
from dynprop.rollout.chunks import ChunkedRollout

from ..linear.steps import step_intervals
from .model import PitchDiscretization, PitchNoise, discretize

_IU = np.triu_indices(3)        # packed upper triangle: 00 01 02 11 12 22


def pack(P: np.ndarray) -> np.ndarray:
    return P[..., _IU[0], _IU[1]]


def unpack(p: np.ndarray) -> np.ndarray:
    p = np.asarray(p)
    P = np.zeros(p.shape[:-1] + (3, 3))
    P[..., _IU[0], _IU[1]] = p
    P[..., _IU[1], _IU[0]] = p
    return P


def _sym(p) -> ca.SX:
    P = ca.SX(3, 3)
    for n, (i, j) in enumerate(zip(*_IU, strict=True)):
        P[i, j] = P[j, i] = p[n]
    return P


def _psym(P) -> ca.SX:
    return ca.vertcat(*(P[i, j] for i, j in zip(*_IU, strict=True)))


def _step_params():
    """Φ rows 0–1 (6), Γ[0:2] (2), Q_d packed (6): Φ's last row is (0, 0, 1), Γ[2] = 0."""
    prm = ca.SX.sym("prm", 14)
    Phi = ca.vertcat(ca.reshape(prm[:6], 3, 2).T, ca.horzcat(0, 0, 1))
    return prm, Phi, ca.vertcat(prm[6], prm[7], 0), _sym(prm[8:])


def _param_rows(d: PitchDiscretization) -> np.ndarray:
    return np.concatenate([d.Phi[..., :2, :].reshape(d.dt.shape + (6,)),
                           d.Gamma[..., :2], pack(d.Qd)], axis=-1)


@lru_cache(maxsize=1)
def filter_step() -> ca.Function:
    """``(s, z, m, r, u, prm, unused) -> (s_next, aux)``: s = [x⁻, P⁻ packed] at t_k,
    m = 1 with a measurement z (z = 0, m = 0 without: K = 0 leaves x, P bit for bit),
    aux = [x⁺, P⁺ packed, ν, S]."""
    s, z, m, r, u = (ca.SX.sym(n, w) for n, w in (("s", 9), ("z", 1), ("m", 1), ("r", 1),
                                                   ("u", 1)))
    prm, Phi, Gam, Qd = _step_params()
    x, P = s[:3], _sym(s[3:])
    S = P[0, 0] + r
    K = m * P[:, 0] / S
    nu = z - x[0]
    ikg = ca.SX.eye(3) - ca.horzcat(K, ca.SX(3, 2))
    P = _sym(_psym(ikg @ P @ ikg.T + r * (K @ K.T)))          # Joseph form
    x = x + K * nu
    xn, Pn = Phi @ x + Gam * u, Phi @ P @ Phi.T + Qd
    out = ca.cse(ca.vertcat(xn, _psym(Pn), x, _psym(P), nu, S))
    return ca.Function("dynprop_pitch_kf", [s, z, m, r, u, prm, ca.SX.sym("unused")],
                       [out[:9], out[9:]])


@lru_cache(maxsize=1)
def smoother_step() -> ca.Function:
    """Backward RTS step ``(s, x⁺_k, P⁺_k, u_k, prm_k, unused) -> (s_prev, aux)`` with
    s = [x^s_{k+1}, P^s_{k+1} packed]; aux = [x^s_k, P^s_k packed]."""
    s, xk, pk, u = ca.SX.sym("s", 9), ca.SX.sym("x", 3), ca.SX.sym("P", 6), ca.SX.sym("u")
    prm, Phi, Gam, Qd = _step_params()
    Pk = _sym(pk)
    x_pred, P_pred = Phi @ xk + Gam * u, _sym(_psym(Phi @ Pk @ Phi.T + Qd))
    Cg = ca.solve(P_pred, Phi @ Pk).T
    xs = xk + Cg @ (s[:3] - x_pred)
    Ps = Pk + Cg @ (_sym(s[3:]) - P_pred) @ Cg.T
    out = ca.cse(ca.vertcat(xs, _psym(Ps)))
    return ca.Function("dynprop_pitch_rts", [s, xk, pk, u, prm, ca.SX.sym("unused")],
                       [out, out])


@lru_cache(maxsize=4)
def _engine(kind: str, backend: str | None) -> ChunkedRollout:
    return ChunkedRollout({"filter": filter_step, "smoother": smoother_step}[kind](),
                          4096, 256, backend)


@dataclass(frozen=True)
class PitchResult:
    """A-posteriori x (N, 3) = [θ rad, θ̇ rad/s, N_y N m] and packed P (N, 6) at each
    sample; innovations ν, their variances S and NIS ν²/S (NaN where no measurement);
    the prior after the last step; the per-step parameter rows (for the smoother)."""

    x: np.ndarray
    P_packed: np.ndarray
    innovations: np.ndarray
    innovation_var: np.ndarray
    nis: np.ndarray
    x_next: np.ndarray
    P_next: np.ndarray
    rows: np.ndarray
    u: np.ndarray
    backend: str

    @property
    def P(self) -> np.ndarray:
        return unpack(self.P_packed)

    @property
    def sigma(self) -> np.ndarray:
        return np.sqrt(self.P_packed[:, [0, 3, 5]])


def _rows(params, noise, dt_or_times, n: int, steps=None) -> np.ndarray:
    """Per-step parameter rows (n, 14): a stride-0 view for one fixed Δt, else each
    distinct interval after sample k (``steps.step_intervals``, or ``steps`` when
    given) evaluated once."""
    if steps is not None:
        distinct, index = np.unique(np.asarray(steps, dtype=float), return_inverse=True)
        return _param_rows(discretize(params, noise, distinct))[index]
    if np.ndim(dt_or_times) == 0:
        return np.broadcast_to(_param_rows(discretize(params, noise, float(dt_or_times))),
                               (n, 14))
    t = np.asarray(dt_or_times, dtype=float)
    if t.shape != (n,):
        raise ValueError(f"times must be ({n},), one per sample")
    distinct, index = np.unique(step_intervals(t), return_inverse=True)
    return _param_rows(discretize(params, noise, distinct))[index]


def pitch_filter(z, u, dt_or_times, params, noise: PitchNoise, x0, P0, R,
                 backend: str | None = None, steps=None) -> PitchResult:
    """Kalman filter over a record: Earth-sensor pitch ``z`` (rad, NaN where missing),
    Ḣ ``u`` (N m, rate of the signed H; scalar or (N,)), a fixed Δt (s) or the sample
    times (N,), the prior x0, P0 at the first sample and the pitch variance R (rad²,
    scalar or (N,)).  ``steps`` (N,): the interval after each sample, when the record
    is a stretch of a longer one (its last step reaches the next stretch)."""
    z = np.asarray(z, dtype=float)
    n = len(z)
    u = np.broadcast_to(np.asarray(u, dtype=float), (n,))
    r = np.broadcast_to(np.asarray(R, dtype=float), (n,))
    present = np.isfinite(z)
    if not np.all(np.isfinite(u)) or np.any(~(r[present] > 0) | ~np.isfinite(r[present])):
        raise ValueError("Ḣ must be finite, R positive and finite where z is present")
    x0, P0 = np.asarray(x0, dtype=float), np.asarray(P0, dtype=float)
    if x0.shape != (3,) or P0.shape != (3, 3):
        raise ValueError("x0 must have 3 elements and P0 be 3×3")
    rows = _rows(params, noise, dt_or_times, n, steps)
    engine = _engine("filter", backend)
    s0 = np.concatenate([x0, pack(0.5 * (P0 + P0.T))])
    inputs = [np.where(present, z, 0.0), present.astype(float), np.where(present, r, 1.0),
              u, rows]
    last, aux = engine.run_final(s0, inputs, np.zeros(1))
    nu, S = aux[:, 9], aux[:, 10]
    nu[~present] = np.nan
    S[~present] = np.nan
    return PitchResult(aux[:, :3], aux[:, 3:9], nu, S, nu * nu / S, last[:3],
                       unpack(last[3:]), rows, u, engine.backend)


def rts_smoother(res: PitchResult, backend: str | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Rauch–Tung–Striebel smoothed x (N, 3) and packed P (N, 6) of a filter run."""
    n = len(res.x)
    if n < 2:
        return res.x.copy(), res.P_packed.copy()
    rev = slice(n - 2, None, -1)
    engine = _engine("smoother", backend)
    s0 = np.concatenate([res.x[-1], res.P_packed[-1]])
    _, aux = engine.run_final(s0, [res.x[rev], res.P_packed[rev], res.u[rev], res.rows[rev]],
                              np.zeros(1))
    out = np.vstack([aux[::-1], s0[None, :]])
    return out[:, :3], out[:, 3:]
