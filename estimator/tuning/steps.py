"""The compiled steps of the likelihood (``likelihood``): the paper filter's step with
ln L's sums carried along (``likelihood_step``), and with forward sensitivities along
chosen directions of θ and the Fisher information (``score_step``; its reference,
CasADi's differentiation of the whole step, ``score_step_ad``), each one CasADi
function built once and rolled out by ``rollout``."""

from __future__ import annotations

from functools import lru_cache

import casadi as ca
import numpy as np

from ..kalman.steps import (
    MEAS_STATES,
    N_UT,
    _pack_sym,
    _sparse_sym,
    _symmetric,
    _unpack_sym,
    propagation,
    sequential_update,
)
from ..linear.model import N_STATES

N_BASE = N_STATES + N_UT          # x and packed P
N_ACC = 6                         # Σ ln S and Σ ν²/S per measurement kind
N_DIR = N_UT + 2    # a direction's parameters: U_v (45), its q_w and roll-factor rates


def _params_sym(n_q: int, roll: bool):
    """Φ (81), Γ (81), Q_d(θ) (45), the unit extra noise Q_e (45), U_j (45 each, which
    only the score step reads), the q_w map [q_w fixed, coefficients (n_q)], then θ
    (n_q + roll)."""
    n2 = N_STATES**2
    n_theta = n_q + int(roll)
    p = ca.SX.sym("p", 2 * n2 + 2 * N_UT + n_q * N_UT + 1 + n_q + n_theta)
    i = 2 * n2
    phi, gam = _sparse_sym(p[:n2]), _sparse_sym(p[n2:i])
    qfix, qe = _unpack_sym(p[i:i + N_UT]), _unpack_sym(p[i + N_UT:i + 2 * N_UT])
    i += 2 * N_UT
    units = [_unpack_sym(p[i + j * N_UT:i + (j + 1) * N_UT]) for j in range(n_q)]
    i += n_q * N_UT
    qw_fixed, qw_coef = p[i], p[i + 1:i + 1 + n_q]
    theta = p[i + 1 + n_q:]
    return p, phi, gam, qfix, qe, units, qw_fixed, qw_coef, theta


def _step_expressions(n_q: int, roll: bool, trace: list | None = None,
                      qd_of_theta: bool = False):
    """The symbols and expressions of one filter step as a function of θ; with
    ``trace``, also the parameters' pieces and each update's P and K (for
    ``score_step``); ``qd_of_theta`` forms Q_d from θ inside the step (the passed Q_d
    is then Q_fixed), for differentiating the step as a whole (``score_step_ad``)."""
    s = ca.SX.sym("s", N_BASE)
    z, m = ca.SX.sym("z", 3), ca.SX.sym("m", 3)
    r, u, e = ca.SX.sym("r", 3), ca.SX.sym("u", N_STATES), ca.SX.sym("e")
    p, phi, gam, qfix, qe, units, qw_fixed, qw_coef, theta = _params_sym(n_q, roll)
    # Q_d(θ) = Q_fixed + Σ θ_j U_j is formed once per pass, outside (``Likelihood._p``):
    # in the step it would cost 2·45·n operations every sample.
    qd = qfix
    if qd_of_theta:   # symbolic in θ, for differentiating the step as a whole
        qd = qd + sum((theta[j] * units[j] for j in range(n_q)), ca.SX(N_STATES, N_STATES))
    # A bridged dropout's wheel noise (``kalman.ExtraNoise``): the input e is the
    # bridge's measured q_w, of which the filter's own q_w already carries a part.
    q_w = qw_fixed
    for j in range(n_q):
        q_w = q_w + qw_coef[j] * theta[j]
    e_eff = ca.fmax(e - q_w, 0)
    r_eff = ca.vertcat(r[0] * theta[n_q], r[1], r[2]) if roll else r
    x, P = s[:N_STATES], _unpack_sym(s[N_STATES:])
    updates: list = []
    x, P, nus, ss = sequential_update(x, P, z, m, r_eff, updates)
    x_next, P_next = propagation(x, P, u, e_eff, phi, gam, qd, qe)
    if trace is not None:
        trace += [updates, phi, qe, units, qw_coef, q_w, e]
    return (s, z, m, r, u, e, p, theta), ca.vertcat(x_next, _pack_sym(P_next)), nus, ss


def _accumulated(acc, m, nus, ss):
    return acc + ca.vertcat(*(m[i] * ca.log(ss[i]) for i in range(3)),
                            *(m[i] * nus[i] ** 2 / ss[i] for i in range(3)))


@lru_cache(maxsize=4)
def likelihood_step(n_q: int, roll: bool) -> ca.Function:
    """``(s, z, m, r, u, e, p) -> (s_next, aux)``: the filter's step (the same
    expressions as ``kalman.steps.filter_step``) with s = [x⁻, P⁻ (45), Σ m ln S (3),
    Σ m ν²/S (3)] and aux = [ν (3), S (3)]; e is the step's raw bridge noise."""
    (s0, z, m, r, u, e, p, _), base_next, nus, ss = _step_expressions(n_q, roll)
    acc = ca.SX.sym("acc", N_ACC)
    s = ca.vertcat(s0, acc)
    out = ca.cse(ca.vertcat(base_next, _accumulated(acc, m, nus, ss), *nus, *ss))
    n_s = N_BASE + N_ACC
    return ca.Function(f"dynprop_ll{n_q}{'r' if roll else ''}", [s, z, m, r, u, e, p],
                       [out[:n_s], out[n_s:]], ["s", "z", "m", "r", "u", "e", "p"],
                       ["s_next", "aux"])


def n_fisher(n: int) -> int:
    return n * (n + 1) // 2


def _sym_update(dP, K, w) -> ca.SX:
    """dP − K wᵀ − w Kᵀ on the upper triangle only, mirrored."""
    out = ca.SX(N_STATES, N_STATES)
    for a, b in zip(*np.triu_indices(N_STATES), strict=True):
        out[a, b] = dP[a, b] - K[a] * w[b] - w[a] * K[b]
        out[b, a] = out[a, b]
    return out


def _fisher_terms(m, nu, S, dnu, dS, n):
    """The score and information increments of one scalar update: ℓ = −½ m (ln S + ν²/S),
    ∂ℓ = −½ m (∂S (1/S − ν²/S²) + 2ν ∂ν/S), and m (½ ∂S ∂Sᵀ/S² + ∂ν ∂νᵀ/S) as its
    upper triangle, row-major."""
    g = [-0.5 * m * (dS[j] * (1 / S - nu**2 / S**2) + dnu[j] * (2 * nu / S)) for j in range(n)]
    f = [m * (0.5 * dS[a] * dS[b] / S**2 + dnu[a] * dnu[b] / S)
         for a, b in zip(*np.triu_indices(n), strict=True)]
    return g, f


@lru_cache(maxsize=16)
def score_step(n_q: int, roll: bool, k: int) -> ca.Function:
    """``likelihood_step`` carrying the sensitivities along k directions v of θ too:
    s = [x, P (45), the six sums, ∂[x, P]/∂v (54·k, column by direction), the score
    ∂ln L/∂v (k), the Fisher information's upper triangle (k(k+1)/2, row-major)];
    aux = [ν (3), S (3)].  The parameter vector is ``likelihood_step``'s followed, per
    direction, by U_v = Σ v_j U_j (45), ∂q_w/∂v and ∂θ_R/∂v: with the unit vectors as
    directions, the gradient and information of every parameter; with a few, those
    of a few, at the cost of a few (``Likelihood.score``).

    The sensitivity recursion is derived by hand at the optimal gain, where the
    Joseph form's gain terms drop out: for a scalar update with a = P gᵀ,
    K = m a/S, ∂a = ∂P gᵀ, ∂S = ∂a_i + ∂r, ∂ν = −∂x_i, ∂K = m (∂a − K ∂S)/S,

        ∂x⁺ = ∂x + ∂K ν + K ∂ν,   ∂P⁺ = ∂P − ∂a Kᵀ − K ∂aᵀ + ∂S K Kᵀ,

    then ∂x⁻ = Φ ∂x⁺ and ∂P⁻ = Φ ∂P⁺ Φᵀ + U_v + ∂e_eff Q_e (the bridge noise less
    q_w, ``_step_expressions``).  Half the operations of differentiating the Joseph
    form itself (``score_step_ad``, which the tests hold it to)."""
    trace: list = []
    (s0, z, m, r, u, e, p0, theta), base_next, nus, ss = _step_expressions(n_q, roll, trace)
    updates, phi, qe, _, _, q_w, e_raw = trace
    dirs = ca.SX.sym("dirs", N_DIR * k)
    p = ca.vertcat(p0, dirs)
    units = [_unpack_sym(dirs[v * N_DIR:v * N_DIR + N_UT]) for v in range(k)]
    dqw = [dirs[v * N_DIR + N_UT] for v in range(k)]
    droll = [dirs[v * N_DIR + N_UT + 1] for v in range(k)]
    acc = ca.SX.sym("acc", N_ACC)
    D = ca.SX.sym("D", N_BASE, k)
    g = ca.SX.sym("g", k)
    fisher = ca.SX.sym("F", n_fisher(k))
    dxs = [D[:N_STATES, j] for j in range(k)]
    dPs = [_unpack_sym(D[N_STATES:, j]) for j in range(k)]
    g_next = [g[j] for j in range(k)]
    f_next = [fisher[i] for i in range(n_fisher(k))]
    for i, (idx, (_, K)) in enumerate(zip(MEAS_STATES, updates, strict=True)):
        S, nu = ss[i], nus[i]
        dnu, dS = [], []
        for j in range(k):
            da = dPs[j][:, idx]
            # The roll variance is r·θ_R: a direction that moves θ_R moves S by r.
            dSj = da[idx] + (r[0] * droll[j] if roll and i == 0 else 0)
            dnu_j = -dxs[j][idx]
            dK = m[i] * (da - K * dSj) / S
            dxs[j] = dxs[j] + dK * nu + K * dnu_j
            # −∂a Kᵀ − K ∂aᵀ + ∂S K Kᵀ = −w Kᵀ − K wᵀ with w = ∂a − ½ ∂S K.
            w = da - (0.5 * dSj) * K
            dPs[j] = _sym_update(dPs[j], K, w)
            dnu.append(dnu_j)
            dS.append(dSj)
        gi, fi = _fisher_terms(m[i], nu, S, dnu, dS, k)
        g_next = [a + b for a, b in zip(g_next, gi, strict=True)]
        f_next = [a + b for a, b in zip(f_next, fi, strict=True)]
    # e_eff = max(e − q_w, 0): where the bridge noise exceeds q_w it falls as q_w rises.
    bridged = e_raw > q_w
    D_next = [ca.vertcat(phi @ dxs[j], _pack_sym(_symmetric(
        phi @ dPs[j] @ phi.T + units[j] - (bridged * dqw[j]) * qe))) for j in range(k)]
    s = ca.vertcat(s0, acc, ca.vec(D), g, fisher)
    out = ca.cse(ca.vertcat(base_next, _accumulated(acc, m, nus, ss), *D_next, *g_next,
                            *f_next, *nus, *ss))
    n_s = s.numel()
    return ca.Function(f"dynprop_score{n_q}{'r' if roll else ''}_{k}",
                       [s, z, m, r, u, e, p], [out[:n_s], out[n_s:]],
                       ["s", "z", "m", "r", "u", "e", "p"], ["s_next", "aux"])


@lru_cache(maxsize=4)
def score_step_ad(n_q: int, roll: bool) -> ca.Function:
    """``score_step`` for every parameter (the unit directions) by CasADi's forward mode
    (``jtimes``) through the step's own expressions, Joseph form and all, Q_d formed
    from θ inside: the tests' reference for the derived recursion.  Its parameter
    vector is ``likelihood_step``'s with Q_fixed in Q_d's place."""
    (s0, z, m, r, u, e, p, theta), base_next, nus, ss = _step_expressions(
        n_q, roll, qd_of_theta=True)
    n = n_q + int(roll)
    acc = ca.SX.sym("acc", N_ACC)
    D = ca.SX.sym("D", N_BASE, n)
    g = ca.SX.sym("g", n)
    fisher = ca.SX.sym("F", n_fisher(n))
    wrt = ca.vertcat(s0, theta)
    seeds = ca.vertcat(D, ca.SX.eye(n))
    exprs = ca.vertcat(base_next, *nus, *ss)
    d = ca.jtimes(exprs, wrt, seeds)               # (54 + 6, n): forward mode
    D_next, dnu, dS = d[:N_BASE, :], d[N_BASE:N_BASE + 3, :], d[N_BASE + 3:, :]
    g_next, f_next = g, fisher
    iu = np.triu_indices(n)
    for i in range(3):
        S, nu = ss[i], nus[i]
        # ∂ℓ/∂θ of ℓ = −½(ln S + ν²/S), and the expected information of (ν, S).
        g_next = g_next - 0.5 * m[i] * (dS[i, :].T * (1 / S - nu**2 / S**2)
                                        + dnu[i, :].T * (2 * nu / S))
        outer = 0.5 * dS[i, :].T @ dS[i, :] / S**2 + dnu[i, :].T @ dnu[i, :] / S
        f_next = f_next + m[i] * ca.vertcat(*(outer[a, b] for a, b in zip(*iu, strict=True)))
    s = ca.vertcat(s0, acc, ca.vec(D), g, fisher)
    out = ca.cse(ca.vertcat(base_next, _accumulated(acc, m, nus, ss), ca.vec(D_next), g_next,
                            f_next, *nus, *ss))
    n_s = s.numel()
    return ca.Function(f"dynprop_score_ad{n_q}{'r' if roll else ''}", [s, z, m, r, u, e, p],
                       [out[:n_s], out[n_s:]], ["s", "z", "m", "r", "u", "e", "p"],
                       ["s_next", "aux"])
