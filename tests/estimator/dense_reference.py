"""Reference filters written from the textbook in plain numpy, for the tests to hold
the compiled ones to, sharing none of their code: the Kalman filter on the paper's
nine states (``kalman_reference``, given the test's own Φ, Γ, Q_d), its likelihood
(``reference_loglik``), and the filter and RTS smoother on the state with sensor-bias
states (``estimator.augmented``: ``reference_filter``, ``reference_smoother``) with
its own prior, augmented F, Q and their discretisation, its own measurement rows.

From the package it takes only inputs: the paper's F (``model.dynamics_matrix``,
Eq. 11b), the noise intensities (``ProcessNoise``'s numbers) and the bias model's
parameters (``BiasModel``'s names, prior σ0 and walk densities q_b).  The rest is
written out here:

* the prior: the paper's nine as given, each bias zero mean with variance σ0², no
  correlation with the attitude;
* F_a = blockdiag(F, 0) (each bias constant between noise) and
  Q_a = blockdiag(Q (Eq. 34, typed from the paper), diag(q_b)) (a random walk of
  density q_b, zero for a random constant);
* Φ = expm(F_a Δt), Γ = ∫₀^Δt expm(F_a s) ds (Eq. 31 with ū held over the step, from
  the expm of [[F_a, I], [0, 0]]) and Q_d by Van Loan's method (Eq. 32);
* the rows (Eq. 26 with the biases): the Earth sensor reads r + b_earth_roll, a yaw
  sample of head 0 (DSS), 1 (CASS1) or 2 (CASS2) reads y + that head's bias (y alone
  where the head has no bias state), the tachometers read h;
* sequential scalar updates (Eqs. 36-38, Joseph form) in the order roll, yaw, h, a
  present measurement with ν²/S > γ left out when gating; then x⁻ = Φx⁺ + Γū,
  P⁻ = ΦP⁺Φᵀ + Q_d (+ scale_k Q_d(q_w = 1) on a step with extra wheel-torque noise);
* the Rauch-Tung-Striebel smoother over the filter's posteriors.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import scipy.linalg as sl

# The installed name, not the tests' short alias: benchmarks/run.py imports this module too.
from dynprop.estimator.linear.model import ProcessNoise, dynamics_matrix

N9 = 9
ROLL_STATE, YAW_STATE, H_STATE = 0, 2, 4        # r, y, h in Eq. 10's order
ROLL_BIAS = "earth_roll"
HEAD_BIAS = {0: "dss_yaw", 1: "cass1_yaw", 2: "cass2_yaw"}   # sun_head code -> bias


def eq34_noise_density(p, q: ProcessNoise) -> np.ndarray:
    """Q of Eq. 34 (9×9), typed from the paper."""
    H = p.H_Nms
    Q = np.zeros((N9, N9))
    Q[1, 1] = q.q_x / H**2
    Q[3, 3] = (q.q_z + q.q_w) / H**2
    Q[3, 4] = Q[4, 3] = -q.q_w / H
    Q[4, 4] = q.q_w
    Q[5:, 5:] = np.diag([q.q_px, q.q_pz, q.q_cx, q.q_cz])
    return Q


def _names(bias) -> tuple[str, ...]:
    return () if bias is None else tuple(bias.names)


def prior(x0, P0, bias) -> tuple[np.ndarray, np.ndarray]:
    """[x0, 0], blockdiag(P0, diag(σ0²))."""
    nb = len(_names(bias))
    s0 = np.asarray(bias.sigma0_rad if nb else (), dtype=float)
    P = np.zeros((N9 + nb, N9 + nb))
    P[:N9, :N9] = P0
    P[N9:, N9:] = np.diag(s0 * s0)
    return np.r_[np.asarray(x0, dtype=float), np.zeros(nb)], P


def discretization(p, q: ProcessNoise, bias, dt: float) -> SimpleNamespace:
    """Φ, Γ (n×9: ū drives the paper's states only) and Q_d of the augmented model
    over dt, and Q_e: Q_d of the wheel-torque noise alone (q_w = 1), for extra noise."""
    names = _names(bias)
    nb = len(names)
    n = N9 + nb
    F = np.zeros((n, n))
    F[:N9, :N9] = dynamics_matrix(p)
    walk = np.asarray(bias.walk_rad2ps if nb else (), dtype=float)

    def van_loan(Q):
        M = sl.expm(np.block([[-F, Q], [np.zeros((n, n)), F.T]]) * dt)   # Van Loan (1978)
        Qd = M[n:, n:].T @ M[:n, n:]
        return 0.5 * (Qd + Qd.T)

    Q = np.zeros((n, n))
    Q[:N9, :N9] = eq34_noise_density(p, q)
    Q[N9:, N9:] = np.diag(walk)
    Qe = np.zeros((n, n))
    Qe[:N9, :N9] = eq34_noise_density(p, ProcessNoise(q_x=0.0, q_z=0.0, q_w=1.0))
    gam = sl.expm(np.block([[F, np.eye(n)], [np.zeros((n, 2 * n))]]) * dt)[:n, n:]
    return SimpleNamespace(Phi=sl.expm(F * dt), Gamma=gam[:, :N9], Qd=van_loan(Q),
                           Qe=van_loan(Qe))


def row(bias, kind: str, head=None) -> np.ndarray:
    """The measurement row of 'roll', 'yaw' (of sun head ``head``) or 'h'."""
    names = _names(bias)
    g = np.zeros(N9 + len(names))
    if kind == "roll":
        g[ROLL_STATE] = 1.0
        if ROLL_BIAS in names:
            g[N9 + names.index(ROLL_BIAS)] = 1.0
    elif kind == "yaw":
        g[YAW_STATE] = 1.0
        if head is not None and HEAD_BIAS[head] in names:
            g[N9 + names.index(HEAD_BIAS[head])] = 1.0
    else:
        g[H_STATE] = 1.0
    return g


def _inputs(u, n_steps):
    return np.zeros((n_steps, N9)) if u is None else np.asarray(u, dtype=float)


def _scale(extra_scale, n_steps):
    return np.zeros(n_steps) if extra_scale is None else np.asarray(extra_scale, float)


def filter_loop(z, r, d, x, P, rows, u=None, extra_scale=None, gate=None) -> SimpleNamespace:
    """The textbook filter, one numpy step at a time: for each sample the scalar
    Joseph updates (Eqs. 36-38) in the order roll, yaw, h, a present measurement whose
    ν²/S exceeds ``gate`` left out; then x⁻ = Φx⁺ + Γū, P⁻ = ΦP⁺Φᵀ + Q_d (+ scale_k
    Q_e).  ``d``: Φ, Γ, Q_d (and Q_e with ``extra_scale``); ``rows(k, i)``: the
    measurement row of kind i (0 roll, 1 yaw, 2 h) at sample k.  The a-posteriori x,
    P, the innovations ν and their variances S (NaN where absent), ``rejected`` (N, 3)
    and the prior after the last step (x_next, P_next)."""
    z = np.asarray(z, dtype=float)
    n_steps = len(z)
    r = np.broadcast_to(np.asarray(r, dtype=float), z.shape)
    u, scale = _inputs(u, n_steps), _scale(extra_scale, n_steps)
    x, P = np.array(x, dtype=float), np.array(P, dtype=float)
    n = len(x)
    out = SimpleNamespace(x=np.empty((n_steps, n)), P=np.empty((n_steps, n, n)),
                          nu=np.full((n_steps, 3), np.nan), S=np.full((n_steps, 3), np.nan),
                          rejected=np.zeros((n_steps, 3), bool))
    eye = np.eye(n)
    for k in range(n_steps):
        for i in range(3):
            if np.isnan(z[k, i]):
                continue
            g = rows(k, i)
            S = g @ P @ g + r[k, i]
            nu = z[k, i] - g @ x
            out.nu[k, i], out.S[k, i] = nu, S
            if gate is not None and nu * nu / S > gate:
                out.rejected[k, i] = True
                continue
            K = P @ g / S
            x = x + K * nu
            IKG = eye - np.outer(K, g)
            P = IKG @ P @ IKG.T + r[k, i] * np.outer(K, K)
        out.x[k], out.P[k] = x, P
        x = d.Phi @ x + d.Gamma @ u[k]
        P = d.Phi @ P @ d.Phi.T + d.Qd + (scale[k] * d.Qe if scale[k] else 0.0)
    out.x_next, out.P_next = x, P
    return out


def reference_filter(z, r, dt, p, q, bias, x0, P0, u=None, sun_head=None, gate=None,
                     extra_scale=None) -> SimpleNamespace:
    """``filter_loop`` on the augmented model: its own prior, discretisation and rows.
    z (N, 3): roll, yaw, h (NaN where absent); r: their variances ((3,) or (N, 3));
    x0, P0 the paper's nine; u (N, 9) the inputs ū of Eq. 12a; ``sun_head`` (N,) the
    head of each yaw sample; ``extra_scale`` (N,) the q_w added on each step."""
    kinds = ("roll", "yaw", "h")

    def rows(k, i):
        head = int(sun_head[k]) if i == 1 and sun_head is not None else None
        return row(bias, kinds[i], head)

    return filter_loop(z, r, discretization(p, q, bias, dt), *prior(x0, P0, bias), rows,
                       u, extra_scale, gate)


def kalman_reference(z, r, d, x0, P0, u=None, extra_scale=None) -> SimpleNamespace:
    """``filter_loop`` on the paper's nine states with the discretisation ``d`` given
    (Φ, Γ, Q_d and Q_e: the test's own expm and Van Loan)."""
    return filter_loop(z, r, d, x0, P0, lambda k, i: row(None, ("roll", "yaw", "h")[i]), u,
                       extra_scale)


def reference_loglik(z, r, Phi, Gamma, Qd, x0, P0, u=None, extra_Qd=None) -> float:
    """ln L = −½ Σ (ln 2πS + ν²/S) over every scalar update of the filter in plain
    numpy, with the textbook (non-Joseph) update P − K Pᵢ, symmetrised, and
    ``extra_Qd`` (N, 9, 9) added per step."""
    z = np.asarray(z, dtype=float)
    n_steps = len(z)
    r = np.broadcast_to(np.asarray(r, dtype=float), z.shape)
    u = _inputs(u, n_steps)
    x, P = np.array(x0, dtype=float), np.array(P0, dtype=float)
    total = 0.0
    for k in range(n_steps):
        for i, idx in enumerate((ROLL_STATE, YAW_STATE, H_STATE)):
            if np.isnan(z[k, i]):
                continue
            S = P[idx, idx] + r[k, i]
            nu = z[k, i] - x[idx]
            total += np.log(2 * np.pi * S) + nu * nu / S
            K = P[:, idx] / S
            x = x + K * nu
            P = P - np.outer(K, P[idx])
            P = 0.5 * (P + P.T)
        x = Phi @ x + Gamma @ u[k]
        P = Phi @ P @ Phi.T + Qd + (0.0 if extra_Qd is None else extra_Qd[k])
    return -0.5 * total


def reference_smoother(filtered, dt, p, q, bias, u=None, extra_scale=None
                       ) -> SimpleNamespace:
    """Rauch-Tung-Striebel over ``reference_filter``'s posteriors: with the prediction
    P⁻ = ΦP_kΦᵀ + Q_d (+ scale_k Q_e) and C = P_kΦᵀ(P⁻)⁻¹,
    x_k|N = x_k + C(x_k+1|N − Φx_k − Γū_k), P_k|N = P_k + C(P_k+1|N − P⁻)Cᵀ."""
    xs, Ps = filtered.x, filtered.P
    n_steps = len(xs)
    u, scale = _inputs(u, n_steps), _scale(extra_scale, n_steps)
    d = discretization(p, q, bias, dt)
    x_s, P_s = xs.copy(), Ps.copy()
    for k in range(n_steps - 2, -1, -1):
        P_pred = d.Phi @ Ps[k] @ d.Phi.T + d.Qd + scale[k] * d.Qe
        C = np.linalg.solve(P_pred, d.Phi @ Ps[k]).T
        x_s[k] = xs[k] + C @ (x_s[k + 1] - d.Phi @ xs[k] - d.Gamma @ u[k])
        P_s[k] = Ps[k] + C @ (P_s[k + 1] - P_pred) @ C.T
    return SimpleNamespace(x=x_s, P=P_s)
