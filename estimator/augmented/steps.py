"""The compiled steps of the filter with sensor-bias states and outlier gating
(``augmented``): the paper's step (``kalman.steps``) on the state [x (Eq. 10), b],
b the chosen sensor biases, each one CasADi function built once per bias set and
gating choice and rolled out by ``rollout``.

The biases are constant or random walks, so Φ_a = blockdiag(Φ, I), Γ_a = [Γ; 0] and
Q_d,a = blockdiag(Q_d, diag(q_b Δt)) (Eqs. 31–32 with the bias block appended): the
parameter vector is the paper step's (Φ, Γ, Q_d, Q_e) with q_b Δt and the gate γ
after it, and ``diagcat`` keeps Φ's structural zeros (Eq. 15) and the identity's, so
the products skip them as the paper's step does.
"""

from __future__ import annotations

from functools import lru_cache

import casadi as ca
import numpy as np
from dynprop.rollout.chunks import ChunkedRollout

from ..kalman.steps import N_UT, _cholesky_solve, _sparse_sym, _unpack_sym
from ..linear.model import H_WHEEL, N_STATES, R, Y
from .model import YAW_HEADS

N_MEAS = 3                                          # roll, yaw, h
_N_BASE_P = 2 * N_STATES**2 + 2 * N_UT              # Φ, Γ, Q_d, Q_e of the paper's step


def n_packed(n: int) -> int:
    return n * (n + 1) // 2


def _triu(n: int) -> tuple[np.ndarray, np.ndarray]:
    return np.triu_indices(n)


def _unpack_n(p, n: int) -> ca.SX:
    P = ca.SX(n, n)
    for k, (i, j) in enumerate(zip(*_triu(n), strict=True)):
        P[i, j] = p[k]
        P[j, i] = p[k]
    return P


def _pack_n(P) -> ca.SX:
    return ca.vertcat(*(P[i, j] for i, j in zip(*_triu(P.size1()), strict=True)))


def _symmetric(P) -> ca.SX:
    """P rebuilt from its upper triangle: the lower half's expressions are dropped,
    which halves the work of every update and propagation (as in ``kalman.steps``)."""
    return _unpack_n(_pack_n(P), P.size1())


def yaw_bias_columns(names: tuple[str, ...]) -> list[int]:
    """State indices of the yaw-bias states, in ``names`` order (the selector's order)."""
    return [N_STATES + i for i, name in enumerate(names) if name in YAW_HEADS]


def _params_sym(nb: int, gating: bool):
    """The paper step's Φ (81), Γ (81), Q_d (45) and unit extra noise Q_e (45), then
    each bias's q_b Δt (nb) and, when gating, γ: laid out by ``augmented_params``."""
    p = ca.SX.sym("p", _N_BASE_P + nb + int(gating))
    n2 = N_STATES**2
    phi = ca.diagcat(_sparse_sym(p[:n2]), ca.SX.eye(nb))
    gam = ca.vertcat(_sparse_sym(p[n2:2 * n2]), ca.SX(nb, N_STATES))
    walk = p[_N_BASE_P:_N_BASE_P + nb]
    qd = ca.diagcat(_unpack_sym(p[2 * n2:2 * n2 + N_UT]),
                    *(ca.SX(walk[j]) for j in range(nb)))
    qe = ca.diagcat(_unpack_sym(p[2 * n2 + N_UT:_N_BASE_P]), ca.SX(nb, nb))
    gamma = p[-1] if gating else None
    return p, phi, gam, qd, qe, gamma


def measurement_rows_sym(names: tuple[str, ...], sel) -> list[ca.SX]:
    """G rows (Eq. 26 with the biases): roll e_r (+ e_earth_roll), yaw e_y + Σ sel_j
    e_{b_j} over the yaw-bias states (the one-hot ``sel`` picks the sample's head;
    all zero for a head without a bias state), h e_h."""
    n = N_STATES + len(names)
    rows = []
    for idx in (R, Y, H_WHEEL):
        G = ca.SX(1, n)
        G[idx] = 1.0
        rows.append(G)
    if "earth_roll" in names:
        rows[0][N_STATES + names.index("earth_roll")] = 1.0
    for j, col in enumerate(yaw_bias_columns(names)):
        rows[1][col] = sel[j]
    return rows


def gated_update(x, P, z, m, r, rows, gamma=None):
    """Sequential scalar updates of roll, yaw and h (Eqs. 36–38), each in Joseph form
    (Eq. 37), as ``kalman.steps.sequential_update`` with rows of up to three nonzeros.
    With ``gamma`` a present measurement with ν²/S > γ is rejected: its gain is zeroed
    by a 0/1 factor, so the Joseph form leaves P unchanged bit for bit (no branch), and
    S is the one at that point of the sequence.  Returns x, P, ν, S and the 0/1
    rejection of each measurement."""
    n = P.size1()
    eye = ca.SX.eye(n)
    nus, ss, rej = [], [], []
    for i, G in enumerate(rows):
        PG = P @ G.T
        S = G @ PG + r[i]
        nu = z[i] - G @ x
        # m = 0 (absent; z = 0 there, NaN never enters) zeroes the gain as in the paper's
        # step; the gate multiplies in its own 0/1, a comparison that codegen emits as
        # a branch-free (a <= b).
        g = m[i] if gamma is None else m[i] * (nu * nu <= gamma * S)
        K = g * PG / S
        ikg = eye - K @ G
        P = _symmetric(ikg @ P @ ikg.T + r[i] * (K @ K.T))  # Joseph form, Eq. 37
        x = x + K * nu
        nus.append(nu)
        ss.append(S)
        rej.append(ca.SX(0) if gamma is None else m[i] - g)
    return x, P, nus, ss, rej


def propagation(x, P, u, e, phi, gam, qd, qe):
    """x⁻ = Φ_a x⁺ + Γ_a ū, P⁻ = Φ_a P⁺ Φ_aᵀ + Q_d,a + e·Q_e,a (Eqs. 31–32)."""
    return phi @ x + gam @ u, _symmetric(phi @ P @ phi.T + qd + e * qe)


def _sizes(names):
    nb = len(names)
    n = N_STATES + nb
    return nb, n, n_packed(n), len(yaw_bias_columns(names))


@lru_cache(maxsize=8)
def filter_step(names: tuple[str, ...], gating: bool) -> ca.Function:
    """``(s, z, m, r, u, e[, sel], p) -> (s_next, aux)`` with s = [x⁻ (n), P⁻ packed] at
    t_k; z, m, r, u, e as in ``kalman.steps.filter_step``; sel the one-hot head of the
    sample's yaw over the yaw-bias states (an input only when there are some); aux =
    [x⁺ (n), ν (3), S (3), rejected (3), P⁺ packed]: P last, so that a caller keeps
    every other column at every sample and P on chosen ones (``augmented._roll``)."""
    nb, n, nt, ny = _sizes(names)
    s = ca.SX.sym("s", n + nt)
    z, m, r = ca.SX.sym("z", N_MEAS), ca.SX.sym("m", N_MEAS), ca.SX.sym("r", N_MEAS)
    u, e = ca.SX.sym("u", N_STATES), ca.SX.sym("e")
    sel = ca.SX.sym("sel", ny)
    p, phi, gam, qd, qe, gamma = _params_sym(nb, gating)
    x, P = s[:n], _unpack_n(s[n:], n)
    x, P, nus, ss, rej = gated_update(x, P, z, m, r, measurement_rows_sym(names, sel), gamma)
    x_next, P_next = propagation(x, P, u, e, phi, gam, qd, qe)
    out = ca.cse(ca.vertcat(x_next, _pack_n(P_next), x, *nus, *ss, *rej, _pack_n(P)))
    ins, labels = [s, z, m, r, u, e], ["s", "z", "m", "r", "u", "e"]
    if ny:
        ins, labels = ins + [sel], labels + ["sel"]
    return ca.Function(f"dynprop_akf_{_tag(names)}{'_g' if gating else ''}",
                       [*ins, p], [out[:n + nt], out[n + nt:]],
                       [*labels, "p"], ["s_next", "aux"])


def _smoother_pieces(names):
    nb, n, nt, _ = _sizes(names)
    xk, pk = ca.SX.sym("x", n), ca.SX.sym("P", nt)
    u, e = ca.SX.sym("u", N_STATES), ca.SX.sym("e")
    p, phi, gam, qd, qe, _ = _params_sym(nb, False)
    Pk = _unpack_n(pk, n)
    x_pred = phi @ xk + gam @ u
    P_pred = _symmetric(phi @ Pk @ phi.T + qd + e * qe)
    return n, nt, xk, pk, u, e, p, phi, Pk, x_pred, P_pred


@lru_cache(maxsize=8)
def smoother_step(names: tuple[str, ...]) -> ca.Function:
    """Backward RTS step ``(s, x⁺_k, P⁺_k, u_k, e_k, p) -> (s_prev, aux)`` with
    s = [x^s_{k+1}, P^s_{k+1}], aux = [x^s_k, P^s_k]; C = P⁺_k Φ_aᵀ P⁻¹_pred from a
    Cholesky solve (P_pred is symmetric positive definite: every bias has a prior
    σ > 0).  The gate needs no part here: the filter's posteriors already hold it."""
    n, nt, xk, pk, u, e, p, phi, Pk, x_pred, P_pred = _smoother_pieces(names)
    s = ca.SX.sym("s", n + nt)
    xs1, Ps1 = s[:n], _unpack_n(s[n:], n)
    C = _cholesky_solve(P_pred, phi @ Pk).T
    xs = xk + C @ (xs1 - x_pred)
    Ps = Pk + C @ (Ps1 - P_pred) @ C.T
    out = ca.cse(ca.vertcat(xs, _pack_n(Ps)))
    return ca.Function(f"dynprop_arts_{_tag(names)}", [s, xk, pk, u, e, p], [out, out],
                       ["s", "x", "P", "u", "e", "p"], ["s_prev", "aux"])


@lru_cache(maxsize=8)
def smoother_x_step(names: tuple[str, ...]) -> ca.Function:
    """The RTS step for the smoothed state alone (``kalman.steps.smoother_x_step``):
    x^s_k = x⁺_k + P⁺_k Φ_aᵀ P⁻¹_pred (x^s_{k+1} − x⁻_{k+1}), one right-hand side."""
    n, _, xk, pk, u, e, p, phi, Pk, x_pred, P_pred = _smoother_pieces(names)
    s = ca.SX.sym("s", n)
    out = ca.cse(xk + Pk @ (phi.T @ _cholesky_solve(P_pred, s - x_pred)))
    return ca.Function(f"dynprop_arts_x_{_tag(names)}", [s, xk, pk, u, e, p],
                       [out, out], ["s", "x", "P", "u", "e", "p"], ["s_prev", "aux"])


_TAGS = {"earth_roll": "r", "dss_yaw": "d", "cass1_yaw": "c1", "cass2_yaw": "c2"}


def _tag(names) -> str:
    """A step's name suffix, one per bias set (the compiled cache tells them apart by
    their source too)."""
    return "".join(_TAGS[name] for name in names) or "none"


@lru_cache(maxsize=16)
def engine(kind: str, names: tuple[str, ...], gating: bool, chunk: int,
           backend: str | None) -> ChunkedRollout:
    """The rollout of one step kind ('filter', 'smoother', 'smoother_x'), compiled
    once per bias set (and gating, for the filter)."""
    if kind == "filter":
        step = filter_step(names, gating)
    else:
        step = {"smoother": smoother_step, "smoother_x": smoother_x_step}[kind](names)
    return ChunkedRollout(step, chunk, 256, backend)
