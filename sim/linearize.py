"""Linearise the truth model's Euler equation about Earth pointing (paper Section 3).

The paper writes the attitude dynamics as second-order equations in the 3-1-2
angles (Eqs. 3a–3c).  To compare coefficient by coefficient, this module builds
the angular accelerations (ψ̈, φ̈, θ̈) from the *same* symbolic gyrostat
equation and torque laws the simulator integrates (``eom.gyrostat``), with the
attitude and rates expressed in Euler angles, and differentiates them with
CasADi.

The wheel inputs are the wheel-momentum rates (Ḣ, ḣ): the paper's N_w is ḣ by
its Eq. 4, and Ḣ appears in Eq. 3b.  The torques N exclude gravity gradient,
which the paper keeps on the left-hand side.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np
from dynprop.eom import gyrostat as dyn
from dynprop.eom.linear import eq3_coefficients, jacobian_of

from .frames import GeoOrbit
from .spacecraft import Spacecraft


@dataclass(frozen=True)
class EulerLinearization:
    """Jacobians of (ψ̈, φ̈, θ̈) at the nominal state.

    Columns of ``wrt_state``: ψ, φ, θ, ψ̇, φ̇, θ̇, h.  Columns of ``wrt_input``:
    N_x, N_y, N_z, Ḣ, ḣ.  Rows: ψ̈, φ̈, θ̈.  Units SI (the layout of ``eom.linear``).
    """

    wrt_state: np.ndarray
    wrt_input: np.ndarray
    H_Nms: float
    omega0_radps: float


def euler_angle_accelerations(spacecraft: Spacecraft, orbit: GeoOrbit,
                              gravity_gradient: bool = True) -> ca.Function:
    """CasADi function ``(angles, rates, h, H, N, Hdot, hdot) -> (ψ̈, φ̈, θ̈)``.

    Angles and rates are ordered (ψ, φ, θ).  The wheel speeds are recovered from
    (H, h), so the spacecraft must have wheels spanning the y–z plane; two wheels
    give an exact inverse, more use the minimum-norm one.
    """
    ang = ca.SX.sym("ang", 3)
    rate = ca.SX.sym("rate", 3)
    h = ca.SX.sym("h")
    H = ca.SX.sym("H")
    n_ext = ca.SX.sym("N", 3)
    H_dot = ca.SX.sym("Hdot")
    h_dot = ca.SX.sym("hdot")
    J = ca.DM(spacecraft.J)
    Iw = ca.DM(spacecraft.wheel_inertias)
    A = ca.DM(spacecraft.wheel_axes.T)
    w0 = orbit.rate_radps
    # Wheel speeds and accelerations that give the requested y/z wheel momentum.
    to_wheels = ca.DM(np.linalg.pinv(spacecraft.wheel_axes.T[1:3, :] * spacecraft.wheel_inertias))
    wheel_speeds = to_wheels @ ca.vertcat(H, h)
    wheel_accels = to_wheels @ ca.vertcat(H_dot, h_dot)

    yaw, roll, pitch = ang[0], ang[1], ang[2]
    c_br = dyn.dcm_from_euler312(yaw, roll, pitch)
    w_rn = ca.vertcat(0, -w0, 0)
    # ω_BR from 3-1-2 rates: yaw about R's z, roll about the once-rotated x, pitch about body y.
    w_br = (dyn.dcm_from_euler312(0, roll, pitch) @ ca.vertcat(0, 0, rate[0])
            + dyn.dcm_from_euler312(0, 0, pitch) @ ca.vertcat(rate[1], 0, 0)
            + ca.vertcat(0, rate[2], 0))
    w_bn = w_br + c_br @ w_rn
    torque = n_ext
    if gravity_gradient:
        torque = torque + dyn.gravity_gradient_torque(c_br[:, 2], J, 3.0 * w0**2)
    w_bn_dot = dyn.body_accel_from_wheel_accel(w_bn, wheel_speeds, wheel_accels, torque,
                                               J, Iw, A)
    # d/dt(C_BR ω_RN) = −[ω_BR×] C_BR ω_RN for a constant ω_RN in R.
    w_br_dot = w_bn_dot + ca.cross(w_br, c_br @ w_rn)
    M = ca.jacobian(w_br, rate)
    m_dot_rate = ca.jtimes(w_br, ang, rate)
    accel = ca.solve(M, w_br_dot - m_dot_rate)
    return ca.Function("euler_accel", [ang, rate, h, H, n_ext, H_dot, h_dot], [accel],
                       ["ang", "rate", "h", "H", "N", "Hdot", "hdot"], ["accel"])


def linearize_about_nominal(spacecraft: Spacecraft, orbit: GeoOrbit) -> EulerLinearization:
    """CasADi Jacobian of the nonlinear model at zero attitude, zero relative rate,
    h = 0 and the spacecraft's nominal (signed) H."""
    f = euler_angle_accelerations(spacecraft, orbit)
    ang, rate = ca.MX.sym("a", 3), ca.MX.sym("r", 3)
    h, n_ext, H_dot, h_dot = ca.MX.sym("h"), ca.MX.sym("N", 3), ca.MX.sym("Hd"), ca.MX.sym("hd")
    H = float(spacecraft.pitch_bias_Nms())
    acc = f(ang, rate, h, H, n_ext, H_dot, h_dot)
    jac = ca.Function("euler_jacobian", [ang, rate, h, n_ext, H_dot, h_dot],
                      [ca.jacobian(acc, ca.vertcat(ang, rate, h)),
                       ca.jacobian(acc, ca.vertcat(n_ext, H_dot, h_dot))])
    zero3 = np.zeros(3)
    a_x, a_u = jac(zero3, zero3, 0.0, zero3, 0.0, 0.0)
    return EulerLinearization(np.array(a_x), np.array(a_u), H, orbit.rate_radps)


def paper_eq3_coefficients(spacecraft: Spacecraft, orbit: GeoOrbit) -> EulerLinearization:
    """The same Jacobians written from the paper's Eqs. 3a–3c (signed H, diagonal J,
    ``eom.linear``)."""
    Ix, Iy, Iz = np.diag(spacecraft.J)
    H = float(spacecraft.pitch_bias_Nms())
    w0 = orbit.rate_radps
    x, u = jacobian_of(eq3_coefficients(Ix, Iy, Iz, H, w0))
    return EulerLinearization(x, u, H, w0)
