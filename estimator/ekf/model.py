"""The extended Kalman filter's process and measurement models (CasADi SX).

The physics the paper linearises, kept nonlinear: the rigid gyrostat with its full
(locked-wheel) inertia J, the wheel momentum (0, H, h) of two canted wheels in body
axes, the gravity gradient 3ω0² n̂ × J n̂, and unknown roll/yaw torques modelled as
the paper does, a constant N_c plus N_p turning at the orbit rate (Eqs. 9, 18),
driven by white noise.  Attitude is a scalar-last quaternion q_BR (orbit frame R to
body B), so nothing is singular at any attitude; its error is the small rotation
δθ with A(q) = A(δq(δθ)) A(q̂) (the multiplicative EKF, Markley & Crassidis §6.2).

Nominal state X (12):  q_BR (4), ω_BR (3, rad/s, body), h (N m s), N_px, N_pz,
N_cx, N_cz (N m).  Error state δx (11):  δθ (3), δω (3), δh, δN (4).
Inputs u (5):  H and Ḣ (the pitch wheels' momentum and its rate, from the
tachometers, Eq. 1), N_w* (= ḣ, the paper's wheel-torque input), N_x*, N_z* (the
modelled roll and yaw torques of Eq. 9).
Measurements (4):  roll, pitch (Earth sensor), yaw (ground solution): the 3-1-2
Euler angles of C_BR; and h (tachometers, Eq. 2).

The equations are ``eom.gyrostat``'s, which the truth integrates too.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
from dynprop.eom.gyrostat import (
    dcm_from_quat,
    euler312,
    euler312_rates,
    gravity_gradient_torque,
    quat_rate,
)

NX, NE, NU, NZ = 12, 11, 5, 4
Q, W, HW, NP, NC = slice(0, 4), slice(4, 7), 7, slice(8, 10), slice(10, 12)
MEAS_NAMES = ("roll", "pitch", "yaw", "h")
ANGLE_MEAS = (0, 1, 2)
# The process noise's intensities, in this order ((N m)² s, then (N m)²/s).
NOISE_NAMES = ("q_x", "q_y", "q_z", "q_w", "q_px", "q_pz", "q_cx", "q_cz")
# J and J⁻¹ (column-major; J⁻¹ computed once in numpy, not symbolically at every
# evaluation of the dynamics), ω0, Δt, the noise intensities.
N_PARAMS = 9 + 9 + 2 + len(NOISE_NAMES)
DT_INDEX = 19   # where Δt sits in the parameter vector (``pack_params``)


def unpack_params(p):
    return (ca.reshape(p[0:9], 3, 3), p[18], p[19], p[20:20 + len(NOISE_NAMES)])


def inverse_inertia(p):
    return ca.reshape(p[9:18], 3, 3)


def pack_params(J_kgm2, omega0_radps: float, dt_s: float, noise: dict[str, float]
                ) -> np.ndarray:
    J = np.asarray(J_kgm2, dtype=float)
    return np.concatenate([J.ravel(order="F"), np.linalg.inv(J).ravel(order="F"),
                           [omega0_radps, dt_s], [float(noise[k]) for k in NOISE_NAMES]])


def quat_mult(q, p):
    """q ⊗ p with A(q ⊗ p) = A(q) A(p) (scalar last; Markley & Crassidis Eq. 2.82b)."""
    qv, q4, pv, p4 = q[0:3], q[3], p[0:3], p[3]
    return ca.vertcat(q4 * pv + p4 * qv - ca.cross(qv, pv), q4 * p4 - ca.dot(qv, pv))


def inject(X, dx):
    """X̂ ⊕ δx: the attitude error multiplies (δq = [δθ/2, 1], normalised), the rest adds."""
    dq = ca.vertcat(0.5 * dx[0:3], 1.0)
    q = quat_mult(dq / ca.norm_2(dq), X[Q])
    return ca.vertcat(q, X[4:] + dx[3:])


def extract(X_ref, X):
    """δx with X = X_ref ⊕ δx (to first order for δθ: twice the Gibbs vector)."""
    qref = X_ref[Q]
    dq = quat_mult(X[Q], ca.vertcat(-qref[0:3], qref[3]))
    return ca.vertcat(2.0 * dq[0:3] / dq[3], X[4:] - X_ref[4:])


def derivative(X, u, p):
    """Ẋ of the nominal state (module doc)."""
    J, w0, _, _ = unpack_params(p)
    q, w_br, h = X[Q], X[W], X[HW]
    npx, npz, ncx, ncz = X[8], X[9], X[10], X[11]
    H, Hdot, Nw, Nx, Nz = u[0], u[1], u[2], u[3], u[4]
    C = dcm_from_quat(q)
    # The orbit frame turns at −ω0 about y_R (docs/conventions.md).
    w_rn = C @ ca.vertcat(0, -w0, 0)
    w = w_br + w_rn
    h_w = ca.vertcat(0, H, h)
    n = C[:, 2]                                    # nadir in body axes
    torque = (gravity_gradient_torque(n, J, 3 * w0**2)
              + ca.vertcat(Nx + npx + ncx, 0, Nz + npz + ncz)
              - ca.cross(w, J @ w + h_w) - ca.vertcat(0, Hdot, Nw))
    w_dot = inverse_inertia(p) @ torque
    # d/dt (C ω_RN^R) = −ω_BR × C ω_RN^R, so ω̇_BR = ω̇_BN + ω_BR × ω_RN^B.
    w_br_dot = w_dot + ca.cross(w_br, w_rn)
    return ca.vertcat(quat_rate(q, w_br), w_br_dot, Nw, w0 * npz, -w0 * npx, 0, 0)


def rk4(X, u, p):
    """One RK4 step of Δt with u held; the quaternion renormalised."""
    dt = unpack_params(p)[2]
    k1 = derivative(X, u, p)
    k2 = derivative(X + 0.5 * dt * k1, u, p)
    k3 = derivative(X + 0.5 * dt * k2, u, p)
    k4 = derivative(X + dt * k3, u, p)
    Xn = X + dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
    return ca.vertcat(Xn[Q] / ca.norm_2(Xn[Q]), Xn[4:])


def measure(X):
    """[roll, pitch, yaw, h] of the state."""
    yaw, roll, pitch = euler312(dcm_from_quat(X[Q]))
    return ca.vertcat(roll, pitch, yaw, X[HW])


def paper_coordinates(X, p, omega_n_radps):
    """The state in the paper's coordinates (Eq. 10): roll, φ̇/ω_n, yaw, ψ̇/ω_n, h and
    the torque states, with the Euler rates of ω_BR (``eom.gyrostat.euler312_rates``)."""
    yaw, roll, pitch = euler312(dcm_from_quat(X[Q]))
    w = X[W]
    yaw_dot, roll_dot, _ = euler312_rates(roll, pitch, w[0], w[1], w[2])
    return ca.vertcat(roll, roll_dot / omega_n_radps, yaw, yaw_dot / omega_n_radps, X[HW],
                      X[8:12])


def noise_map(p):
    """G (11×8): how the white noises of NOISE_NAMES enter δẋ."""
    Jinv = inverse_inertia(p)
    G = ca.SX(NE, len(NOISE_NAMES))
    G[3:6, 0] = Jinv[:, 0]
    G[3:6, 1] = Jinv[:, 1]
    G[3:6, 2] = Jinv[:, 2]
    G[3:6, 3] = -Jinv[:, 2]      # the wheel-torque error: −w_w on the body, +w_w on h
    G[6, 3] = 1.0
    for k in range(4):
        G[7 + k, 4 + k] = 1.0
    return G


def _conj(q):
    return ca.vertcat(-q[0:3], q[3])


def error_rate_matrix(X, u, p):
    """F (11×11): δẋ = F δx at X, the Jacobian at δx = 0 of d/dt (X̂ ⊕ δx ⊖ X̂) with
    both states moving by ``derivative``.  For the attitude, δq = q ⊗ q̂⁻¹ and
    δθ = 2 δq_v/δq_4, so δθ̇ = 2 (δq̇_v δq_4 − δq_v δq̇_4)/δq_4² (to first order
    −ω̂_BR × δθ + δω, Markley & Crassidis Eq. 6.60, but taken exactly here)."""
    dx = ca.SX.sym("dx", NE)
    Xd = inject(X, dx)
    f, fh = derivative(Xd, u, p), derivative(X, u, p)
    q, qh = Xd[Q], X[Q]
    dq = quat_mult(q, _conj(qh))
    dq_dot = quat_mult(f[Q], _conj(qh)) + quat_mult(q, _conj(fh[Q]))
    dtheta_dot = 2 * (dq_dot[0:3] * dq[3] - dq[0:3] * dq_dot[3]) / dq[3] ** 2
    rate = ca.vertcat(dtheta_dot, f[4:] - fh[4:])
    return ca.substitute(ca.jacobian(rate, dx), dx, ca.DM.zeros(NE))


def transition(X, u, p):
    """Φ ≈ exp(F Δt) with F at the step's midpoint, to third order in F Δt:
    ‖F Δt‖ ≈ |ω_n| Δt = 0.019, so the series leaves out ~5e-9 of Φ, and the midpoint
    makes the change of F over the step a third-order term too (at the step's start
    it would be ½ Ḟ Δt², 4e-6 at 0.06°/s of nutation).  One derivative's Jacobian
    rather than RK4's four."""
    dt = unpack_params(p)[2]
    Xm = X + 0.5 * dt * derivative(X, u, p)
    Xm = ca.vertcat(Xm[Q] / ca.norm_2(Xm[Q]), Xm[4:])
    A = error_rate_matrix(Xm, u, p) * dt
    A2 = A @ A
    return ca.SX.eye(NE) + A + A2 / 2 + (A2 @ A) / 6


def rk4_transition(X, u, p):
    """Φ of the RK4 step itself, ∂(rk4(X ⊕ δx) ⊖ rk4(X))/∂δx at 0: the reference
    ``transition`` is checked against (tests)."""
    dx = ca.SX.sym("dx", NE)
    return ca.substitute(ca.jacobian(extract(rk4(X, u, p), rk4(inject(X, dx), u, p)), dx),
                         dx, ca.DM.zeros(NE))


def error_jacobians():
    """CasADi functions of the nominal state at δx = 0: Φ (11×11) over one step, the
    measurement rows H (4×11), and T (9×11), the paper coordinates' Jacobian."""
    X, dx = ca.SX.sym("X", NX), ca.SX.sym("dx", NE)
    u, p, wn = ca.SX.sym("u", NU), ca.SX.sym("p", N_PARAMS), ca.SX.sym("wn")
    Xd = inject(X, dx)

    def at_zero(expr):
        return ca.substitute(ca.jacobian(expr, dx), dx, ca.DM.zeros(NE))

    return (ca.Function("ekf_phi", [X, u, p], [transition(X, u, p)]),
            ca.Function("ekf_h", [X], [at_zero(measure(Xd))]),
            ca.Function("ekf_t", [X, p, wn], [at_zero(paper_coordinates(Xd, p, wn))]))
