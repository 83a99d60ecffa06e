"""The compiled steps of the paper's filter and the RTS smoother (``kalman``): each
one CasADi function, Φ, Γ and Q_d entering as parameters, with the covariance
packed as its upper triangle and the products skipping Φ's structural zeros
(Eq. 15), built once and rolled out by ``rollout``."""

from __future__ import annotations

from functools import lru_cache

import casadi as ca
import numpy as np
from dynprop.rollout.chunks import ChunkedRollout

from ..linear.model import H_WHEEL, N_STATES, R, Y

MEAS_STATES = (R, Y, H_WHEEL)   # roll, yaw, h: each a unit row of G (Eq. 26)
MEAS_NAMES = ("roll", "yaw", "h")
_IU = np.triu_indices(N_STATES)
N_UT = len(_IU[0])  # 45


def pack(P: np.ndarray) -> np.ndarray:
    """Upper triangle (row-major) of symmetric matrices, (..., 9, 9) -> (..., 45)."""
    return P[..., _IU[0], _IU[1]]


def unpack(p: np.ndarray) -> np.ndarray:
    """Inverse of ``pack``: (..., 45) -> symmetric (..., 9, 9)."""
    p = np.asarray(p)
    P = np.zeros(p.shape[:-1] + (N_STATES, N_STATES))
    P[..., _IU[0], _IU[1]] = p
    P[..., _IU[1], _IU[0]] = p
    return P


def _unpack_sym(p) -> ca.SX:
    P = ca.SX(N_STATES, N_STATES)
    for k, (i, j) in enumerate(zip(*_IU, strict=True)):
        P[i, j] = p[k]
        P[j, i] = p[k]
    return P


def _pack_sym(P) -> ca.SX:
    return ca.vertcat(*(P[i, j] for i, j in zip(*_IU, strict=True)))


# Structural nonzeros of Φ and Γ (Eq. 15): the 4×9 attitude rows, and ψ (Eq. 18):
# h and the constant torques on the diagonal, the periodic pair rotating.
PHI_PATTERN = np.zeros((N_STATES, N_STATES), dtype=bool)
PHI_PATTERN[:4, :] = True
PHI_PATTERN[4, 4] = PHI_PATTERN[7, 7] = PHI_PATTERN[8, 8] = True
PHI_PATTERN[5:7, 5:7] = True


def _sparse_sym(flat) -> ca.SX:
    """A 9×9 SX matrix from column-major entries, zero outside PHI_PATTERN, so
    products skip the structural zeros."""
    M = ca.SX(N_STATES, N_STATES)
    for j in range(N_STATES):
        for i in range(N_STATES):
            if PHI_PATTERN[i, j]:
                M[i, j] = flat[j * N_STATES + i]
    return M


def _params_sym():
    """Φ (81), Γ (81), Q_d (45) and the unit extra noise Q_e (45) as one parameter
    vector."""
    p = ca.SX.sym("p", 2 * N_STATES**2 + 2 * N_UT)
    n2 = N_STATES**2
    return (p, _sparse_sym(p[:n2]), _sparse_sym(p[n2:2 * n2]),
            _unpack_sym(p[2 * n2:2 * n2 + N_UT]), _unpack_sym(p[2 * n2 + N_UT:]))


def _symmetric(P) -> ca.SX:
    """P rebuilt from its upper triangle: the lower half's expressions are dropped,
    which halves the work of every update and propagation."""
    return _unpack_sym(_pack_sym(P))



def pack_params(disc, Qd_unit=None) -> np.ndarray:
    Phi, Gam, Qd = (np.asarray(m, dtype=float) for m in (disc.Phi, disc.Gamma, disc.Qd))
    Qe = np.zeros((N_STATES, N_STATES)) if Qd_unit is None else np.asarray(Qd_unit, float)
    for name, M in (("Phi", Phi), ("Gamma", Gam)):
        off = np.abs(M[~PHI_PATTERN]).max(initial=0.0)
        if off > 1e-12 * np.abs(M).max():
            raise ValueError(f"{name} has entries outside the structure of Eq. 15 ({off:g})")
    return np.concatenate([Phi.ravel(order="F"), Gam.ravel(order="F"), pack(Qd), pack(Qe)])


def sequential_update(x, P, z, m, r, trace: list | None = None):
    """The scalar updates of roll, yaw and h in turn (Eqs. 36–38), each in Joseph form
    (Eq. 37); returns the updated x, P and each measurement's innovation ν and its
    variance S.  Shared by the filter's step and the likelihood's (``tuning.steps``),
    which takes each update's P before it and gain K from ``trace``."""
    eye = ca.SX.eye(N_STATES)
    nus, ss = [], []
    for i, idx in enumerate(MEAS_STATES):
        S = P[idx, idx] + r[i]
        # An absent measurement (m = 0) zeroes the gain, and with K = 0 the Joseph
        # form returns P unchanged bit for bit (I P Iᵀ + r·0): no branches needed.
        K = m[i] * P[:, idx] / S
        nu = z[i] - x[idx]
        if trace is not None:
            trace.append((P, K))
        G = ca.SX(1, N_STATES)
        G[idx] = 1.0
        ikg = eye - K @ G
        P = _symmetric(ikg @ P @ ikg.T + r[i] * (K @ K.T))  # Joseph form, Eq. 37
        x = x + K * nu
        nus.append(nu)
        ss.append(S)
    return x, P, nus, ss


def propagation(x, P, u, e, phi, gam, qd, qe):
    """x⁻ = Φ x⁺ + Γ ū and P⁻ = Φ P⁺ Φᵀ + Q_d + e·Q_e (Eqs. 31–32, ``ExtraNoise``)."""
    # + e·Q_e after + Q_d: with e = 0 it adds (±)0 and changes no bit.
    return phi @ x + gam @ u, _symmetric(phi @ P @ phi.T + qd + e * qe)


@lru_cache(maxsize=2)
def filter_step() -> ca.Function:
    """``(s, z, m, r, u, e, p) -> (s_next, aux)`` with s = [x⁻, P⁻ (45)] at t_k,
    m the 0/1 presence of each measurement (z is 0 where absent: NaN never enters
    the compiled code, and CasADi would fold a ``z == z`` NaN test to true), and
    aux = [x⁺, P⁺ (45), ν (3), S (3)] (the caller blanks ν, S where m = 0), and e the
    step's extra-noise scale (``ExtraNoise``)."""
    s = ca.SX.sym("s", N_STATES + N_UT)
    z, m = ca.SX.sym("z", 3), ca.SX.sym("m", 3)
    r, u, e = ca.SX.sym("r", 3), ca.SX.sym("u", N_STATES), ca.SX.sym("e")
    p, phi, gam, qd, qe = _params_sym()
    x, P = s[:N_STATES], _unpack_sym(s[N_STATES:])
    x, P, nus, ss = sequential_update(x, P, z, m, r)
    x_next, P_next = propagation(x, P, u, e, phi, gam, qd, qe)
    out = ca.cse(ca.vertcat(x_next, _pack_sym(P_next), x, _pack_sym(P), *nus, *ss))
    n_s = N_STATES + N_UT
    return ca.Function("dynprop_kf", [s, z, m, r, u, e, p], [out[:n_s], out[n_s:]],
                       ["s", "z", "m", "r", "u", "e", "p"], ["s_next", "aux"])


def _sum(terms, start):
    for term in terms:
        start = start - term
    return start


def _cholesky_solve(A, B) -> ca.SX:
    """X with A X = B for symmetric positive definite A, by A = L Lᵀ written out
    (A's lower triangle is read), with one division per pivot."""
    n, m = A.size1(), B.size2()
    L = [[None] * n for _ in range(n)]
    inv = [None] * n
    for j in range(n):
        inv[j] = 1.0 / ca.sqrt(_sum((L[j][k] * L[j][k] for k in range(j)), A[j, j]))
        for i in range(j + 1, n):
            L[i][j] = _sum((L[i][k] * L[j][k] for k in range(j)), A[i, j]) * inv[j]
    X = ca.SX(n, m)
    for c in range(m):
        y = [None] * n
        for i in range(n):
            y[i] = _sum((L[i][k] * y[k] for k in range(i)), B[i, c]) * inv[i]
        x = [None] * n
        for i in reversed(range(n)):
            x[i] = _sum((L[k][i] * x[k] for k in range(i + 1, n)), y[i]) * inv[i]
        for i in range(n):
            X[i, c] = x[i]
    return X


@lru_cache(maxsize=2)
def smoother_step() -> ca.Function:
    """Backward RTS step ``(s, x⁺_k, P⁺_k, u_k, e_k, p) -> (s_prev, aux)`` with
    s = [x^s_{k+1}, P^s_{k+1}]; aux = [x^s_k, P^s_k]."""
    s = ca.SX.sym("s", N_STATES + N_UT)
    xk, pk, u = ca.SX.sym("x", N_STATES), ca.SX.sym("P", N_UT), ca.SX.sym("u", N_STATES)
    e = ca.SX.sym("e")
    p, phi, gam, qd, qe = _params_sym()
    Pk = _unpack_sym(pk)
    xs1, Ps1 = s[:N_STATES], _unpack_sym(s[N_STATES:])
    x_pred = phi @ xk + gam @ u
    P_pred = _symmetric(phi @ Pk @ phi.T + qd + e * qe)
    # C = P_k Φᵀ P⁻¹_pred, from a Cholesky solve with the symmetric positive definite
    # P_pred: a third of the operations of CasADi's general (QR) solve, which made the
    # smoother the costliest step of a long run.
    C = _cholesky_solve(P_pred, phi @ Pk).T
    xs = xk + C @ (xs1 - x_pred)
    Ps = Pk + C @ (Ps1 - P_pred) @ C.T
    out = ca.cse(ca.vertcat(xs, _pack_sym(Ps)))
    return ca.Function("dynprop_rts", [s, xk, pk, u, e, p], [out, out],
                       ["s", "x", "P", "u", "e", "p"], ["s_prev", "aux"])


@lru_cache(maxsize=2)
def smoother_x_step() -> ca.Function:
    """The RTS step for the smoothed state alone, ``(s, x⁺_k, P⁺_k, u_k, e_k, p) ->
    (s_prev, aux)`` with s = x^s_{k+1}, aux = x^s_k: x^s_k = x⁺_k + P⁺_k Φᵀ P⁻¹_pred
    (x^s_{k+1} − x⁻_{k+1}), one solve with a single right-hand side and no
    smoothed-covariance recursion (which x^s does not need): a quarter of
    ``smoother_step``'s operations, for runs that report the smoothed estimate only."""
    s = ca.SX.sym("s", N_STATES)
    xk, pk, u = ca.SX.sym("x", N_STATES), ca.SX.sym("P", N_UT), ca.SX.sym("u", N_STATES)
    e = ca.SX.sym("e")
    p, phi, gam, qd, qe = _params_sym()
    Pk = _unpack_sym(pk)
    x_pred = phi @ xk + gam @ u
    P_pred = _symmetric(phi @ Pk @ phi.T + qd + e * qe)
    xs = xk + Pk @ (phi.T @ _cholesky_solve(P_pred, s - x_pred))
    out = ca.cse(xs)
    return ca.Function("dynprop_rts_x", [s, xk, pk, u, e, p], [out, out],
                       ["s", "x", "P", "u", "e", "p"], ["s_prev", "aux"])


@lru_cache(maxsize=6)
def _engine(kind: str, chunk: int, backend: str | None) -> ChunkedRollout:
    base = kind.removesuffix("_per_step")
    step = {"filter": filter_step, "smoother": smoother_step,
            "smoother_x": smoother_x_step}[base]()
    if base != kind:   # each step's own Φ, Γ, Q_d (``steps``: telemetry at any cadence)
        from ..linear.steps import per_step
        step = per_step(step)
    return ChunkedRollout(step, chunk, 256, backend)
