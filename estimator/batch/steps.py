"""The compiled passes of the batch least-squares estimator (``batch``): each one CasADi
step rolled out by ``rollout`` over a span's samples, so a day of 0.512 s data is a
C loop, with no Python per sample.

Linear (the paper's model, Eqs. 11–12, 31): the state at sample k is
x_k = Ψ_k x_0 + d_k, with Ψ_{k+1} = Φ Ψ_k (Ψ_0 = I) and d_{k+1} = Φ d_k + Γ ū_k
(d_0 = 0).  The pass carries Ψ_k and d_k and sums the normal equations of the
measurements z_k = G x_k + v (Eq. 26): Λ = Σ Ψᵀ Gᵀ R⁻¹ G Ψ, b = Σ Ψᵀ Gᵀ R⁻¹ (z − G d),
c = Σ (z − G d)ᵀ R⁻¹ (z − G d).

Nonlinear (the EKF's process model, ``ekf.model``): the state X_k (12) is rolled
out by RK4, and its sensitivity Ψ_k = ∂X_k/∂(x_0, c) (12 × m) by forward-mode
derivatives of that very step (``ca.jtimes``): the Gauss–Newton Jacobian of the
rollout itself, not of an approximation.  x_0 is the paper's nine states at the
epoch (``from_paper``); c are consider parameters (inertia and cant), at zero.
Pitch is not solved for: it decouples (Eq. 3b) and, propagated open loop over
hours, drifts by degrees (a double integrator of the small error in the measured
Ḣ), so after every step the state's pitch and pitch rate are set to the Earth
sensor's (smoothed) values, roll, yaw and their rates kept (``slave_pitch``).
"""

from __future__ import annotations

from functools import lru_cache

import casadi as ca
import numpy as np
from dynprop.eom.gyrostat import dcm_from_quat, euler312, euler312_rates

from ..ekf import model as m
from ..ekf.filter import _pack_sym as _pack_sym_iu
from ..ekf.filter import _unpack_sym as _unpack_sym_iu
from ..kalman.steps import _IU, MEAS_STATES, N_UT, PHI_PATTERN, _pack_sym, _sparse_sym
from ..linear.model import N_STATES

# Consider parameters of the nonlinear model: the inertia's six entries (kg m²),
# then the wheels' cant (rad), which scales the tachometers' H, Ḣ (cos) and h, N_w*
# (sin).
CONSIDER_NONLINEAR = ("Ixx", "Iyy", "Izz", "Ixy", "Ixz", "Iyz", "cant")
N_C = len(CONSIDER_NONLINEAR)
# Batch parameters: the EKF's (``ekf.model.pack_params``), then tan and cot of the
# nominal cant (the consider cant's first-order scale factors).
N_PB = m.N_PARAMS + 2


# --- linear -----------------------------------------------------------------------

def _psi_sym(flat) -> ca.SX:
    """Ψ_k from its column-major entries: Φ's structure (Eq. 15) is closed under
    products, so Ψ = Φ^k has it too and its structural zeros are skipped."""
    return _sparse_sym(flat)


@lru_cache(maxsize=2)
def linear_step() -> ca.Function:
    """``(s, z, mask, r, u, p) -> (s_next, aux)`` with s = [Ψ (81, column-major), d (9),
    Λ (45, ``kalman.steps.pack``), b (9), c (1)], z, mask, r the roll, yaw, h
    measurements as the filter takes them, u = ū_k (Eq. 12a) and p the filter's
    parameter vector (``kalman.steps.pack_params``: Φ, Γ, Q_d, unused here);
    aux = d at the sample (G d, the zero-state prediction of roll, yaw, h)."""
    n2 = N_STATES**2
    s = ca.SX.sym("s", n2 + N_STATES + N_UT + N_STATES + 1)
    z, mask, r = ca.SX.sym("z", 3), ca.SX.sym("m", 3), ca.SX.sym("r", 3)
    u = ca.SX.sym("u", N_STATES)
    p = ca.SX.sym("p", 2 * n2 + 2 * N_UT)
    phi, gam = _sparse_sym(p[:n2]), _sparse_sym(p[n2:2 * n2])
    Psi = _psi_sym(s[:n2])
    d = s[n2:n2 + N_STATES]
    o = n2 + N_STATES
    Lam = _unpack_sym_iu(s[o:o + N_UT], N_STATES, _IU)
    b = s[o + N_UT:o + N_UT + N_STATES]
    c = s[-1]
    for i, idx in enumerate(MEAS_STATES):
        g = Psi[idx, :]
        e = z[i] - d[idx]
        w = mask[i] / r[i]
        Lam = Lam + w * (g.T @ g)
        b = b + w * e * g.T
        c = c + w * e * e
    Psi_n = phi @ Psi
    d_n = phi @ d + gam @ u
    flat = ca.vertcat(*(Psi_n[i, j] if PHI_PATTERN[i, j] else ca.SX(0)
                        for j in range(N_STATES) for i in range(N_STATES)))
    s_next = ca.cse(ca.vertcat(flat, d_n, _pack_sym(Lam), b, c))
    aux = ca.vertcat(*(d[idx] for idx in MEAS_STATES))
    return ca.Function("dynprop_batch_lin", [s, z, mask, r, u, p], [s_next, aux],
                       ["s", "z", "m", "r", "u", "p"], ["s_next", "aux"])


# --- nonlinear --------------------------------------------------------------------

def _axis_quat(axis: int, angle):
    v = [0, 0, 0]
    v[axis] = ca.sin(angle / 2)
    return ca.vertcat(*v, ca.cos(angle / 2))


def from_euler(yaw, roll, pitch, yaw_dot, roll_dot, pitch_dot, rest) -> ca.SX:
    """X (12) from 3-1-2 angles, their rates and [h, N_px, N_pz, N_cx, N_cz]: q_BR for
    C_BR = R2(θ) R1(φ) R3(ψ) and ω_BR = (cθ φ̇ − sθ cφ ψ̇, θ̇ + sφ ψ̇, sθ φ̇ + cθ cφ ψ̇)
    (the inverse of ``eom.gyrostat.euler312_rates``)."""
    q = m.quat_mult(_axis_quat(1, pitch), m.quat_mult(_axis_quat(0, roll),
                                                      _axis_quat(2, yaw)))
    cth, sth, cph, sph = ca.cos(pitch), ca.sin(pitch), ca.cos(roll), ca.sin(roll)
    w = ca.vertcat(cth * roll_dot - sth * cph * yaw_dot, pitch_dot + sph * yaw_dot,
                   sth * roll_dot + cth * cph * yaw_dot)
    return ca.vertcat(q, w, rest)


def from_paper(x9, pitch, pitch_dot, omega_n):
    """X from the paper's nine states (Eq. 10: roll, ṙ/ω_n, yaw, ẏ/ω_n, h, torques)
    and the pitch and its rate (the Earth sensor's)."""
    return from_euler(x9[2], x9[0], pitch, x9[3] * omega_n, x9[1] * omega_n, pitch_dot,
                      x9[4:9])


def slave_pitch(X, pitch, pitch_dot):
    """X with its pitch and pitch rate replaced, its yaw, roll, their rates, h and
    torques kept (module doc)."""
    yaw, roll, th = euler312(dcm_from_quat(X[m.Q]))
    w = X[m.W]
    yaw_dot, roll_dot, _ = euler312_rates(roll, th, w[0], w[1], w[2])
    return from_euler(yaw, roll, pitch, yaw_dot, roll_dot, pitch_dot, X[7:])


def _with_consider(p, u, c):
    """The model's parameters and inputs with the consider parameters c applied to
    first order (exact derivatives at c = 0, where they are the nominal ones): J + δJ
    with J⁻¹ − J⁻¹ δJ J⁻¹, and the cant's scale on H, Ḣ (cos) and on N_w* (sin)."""
    J = ca.reshape(p[0:9], 3, 3)
    Jinv = ca.reshape(p[9:18], 3, 3)
    dJ = ca.vertcat(ca.horzcat(c[0], c[3], c[4]), ca.horzcat(c[3], c[1], c[5]),
                    ca.horzcat(c[4], c[5], c[2]))
    tan_c, cot_c = p[m.N_PARAMS], p[m.N_PARAMS + 1]
    pm = ca.vertcat(ca.reshape(J + dJ, 9, 1), ca.reshape(Jinv - Jinv @ dJ @ Jinv, 9, 1),
                    p[18:m.N_PARAMS])
    cos_scale, sin_scale = 1 - tan_c * c[6], 1 + cot_c * c[6]
    ue = ca.vertcat(u[0] * cos_scale, u[1] * cos_scale, u[2] * sin_scale, u[3], u[4])
    return pm, ue, sin_scale


def _wrap(a):
    return ca.atan2(ca.sin(a), ca.cos(a))


def model_step(X, u, pitch_next, p, c):
    """One RK4 step (``ekf.model.rk4``) with the consider parameters applied, then
    pitch slaved to the Earth sensor's at the step's end."""
    pm, ue, _ = _with_consider(p, u, c)
    Xn = m.rk4(X, ue, pm)
    return slave_pitch(Xn, pitch_next[0], pitch_next[1])


def predicted(X, p, c):
    """Roll, yaw (3-1-2) and the tachometers' h as the telemetry gives it (scaled by
    sin(cant_nominal)/sin(cant), the consider cant)."""
    _, _, sin_scale = _with_consider(p, ca.SX.zeros(5), c)
    z = m.measure(X)
    return ca.vertcat(z[0], z[2], z[3] / sin_scale)


@lru_cache(maxsize=4)
def nonlinear_step(n_consider: int, with_paper: bool) -> ca.Function:
    """``(s, z, mask, r, u, pitch, p) -> (s_next, aux)``: the Gauss–Newton pass at one
    sample.  s = [X (12), Ψ (12·k, column-major, k = 9 + ``n_consider``), Λ (packed
    k × k), b (k), c (1)]; z, mask, r as the filter's (roll, yaw, h); u the EKF's
    inputs (H, Ḣ, N_w*, N_x*, N_z*); pitch = (θ, θ̇) at the step's end; p the batch
    parameters (``N_PB``, with ω_n last).  aux = the residuals (3, wrapped), and with
    ``with_paper`` the paper-coordinate state (9) and its sensitivity ∂x/∂(x_0, c)
    (9 × k, column-major)."""
    k = N_STATES + n_consider
    iu = np.triu_indices(k)
    nlam = len(iu[0])
    s = ca.SX.sym("s", m.NX + m.NX * k + nlam + k + 1)
    z, mask, r = ca.SX.sym("z", 3), ca.SX.sym("m", 3), ca.SX.sym("r", 3)
    u, pitch = ca.SX.sym("u", m.NU), ca.SX.sym("pitch", 2)
    p = ca.SX.sym("p", N_PB + 1)
    pb, wn = p[:N_PB], p[N_PB]
    c = ca.SX.sym("c", N_C)
    c_used = ca.vertcat(c[:n_consider], ca.SX.zeros(N_C - n_consider)) if n_consider \
        else ca.SX.zeros(N_C)
    X = s[:m.NX]
    Psi = ca.reshape(s[m.NX:m.NX + m.NX * k], m.NX, k)
    o = m.NX + m.NX * k
    Lam = _unpack_sym_iu(s[o:o + nlam], k, iu)
    b, cost = s[o + nlam:o + nlam + k], s[-1]
    # The direct dependence on c, as extra columns: ∂/∂c = [0 | I] in (x_0, c).
    seed_c = ca.horzcat(ca.SX.zeros(n_consider, N_STATES), ca.SX.eye(n_consider)) \
        if n_consider else ca.SX(0, k)
    Xc = ca.vertcat(X, c[:n_consider])
    Psi_c = ca.vertcat(Psi, seed_c)
    zhat = predicted(X, pb, c_used)
    G = ca.jtimes(zhat, Xc, Psi_c)          # 3 × k: ∂ẑ/∂(x_0, c)
    res = []
    for i in range(3):
        e = z[i] - zhat[i]
        if i < 2:
            e = _wrap(e)
        w = mask[i] / r[i]
        g = G[i, :]
        Lam = Lam + w * (g.T @ g)
        b = b + w * e * g.T
        cost = cost + w * e * e
        res.append(mask[i] * e)
    X_next = model_step(X, u, pitch, pb, c_used)
    Psi_next = ca.jtimes(X_next, Xc, Psi_c)
    s_next = ca.vertcat(X_next, ca.reshape(Psi_next, -1, 1), _pack_sym_iu(Lam, iu), b, cost)
    aux = ca.vertcat(*res)
    if with_paper:
        x9 = m.paper_coordinates(X, pb[:m.N_PARAMS], wn)
        T = ca.jtimes(x9, Xc, Psi_c)
        aux = ca.vertcat(aux, x9, ca.reshape(T, -1, 1))
    out = ca.cse(ca.vertcat(s_next, aux))
    n_s = s.size1()
    name = f"dynprop_batch_nl{n_consider}{'p' if with_paper else ''}"
    fn = ca.Function(name, [s, z, mask, r, u, pitch, p, c], [out[:n_s], out[n_s:]])
    # c enters only through its derivative at zero: substitute it away.
    zero_c = ca.DM.zeros(N_C)
    sym = [s, z, mask, r, u, pitch, p]
    return ca.Function(name, sym, fn(*sym, zero_c), ["s", "z", "m", "r", "u", "pitch", "p"],
                       ["s_next", "aux"])


@lru_cache(maxsize=2)
def initial_map() -> ca.Function:
    """``(x9, pitch (2), ω_n) -> (X0, Ψ_0)``: the nominal state at the epoch from the
    paper's nine states and its Jacobian (12 × 9)."""
    x9, pitch, wn = ca.SX.sym("x", N_STATES), ca.SX.sym("pitch", 2), ca.SX.sym("wn")
    X0 = from_paper(x9, pitch[0], pitch[1], wn)
    return ca.Function("batch_x0", [x9, pitch, wn], [X0, ca.jacobian(X0, x9)])


def pack_batch_params(pm: np.ndarray, cant_rad: float, omega_n_radps: float) -> np.ndarray:
    """The nonlinear pass's parameter vector: the EKF's, tan and cot of the cant, ω_n."""
    return np.concatenate([np.asarray(pm, dtype=float),
                           [np.tan(cant_rad), 1.0 / np.tan(cant_rad), omega_n_radps]])
