"""Symbolic gyrostat dynamics and attitude kinematics (CasADi SX), docs/conventions.md.

The torque laws at the end (gravity gradient, solar imbalance, magnetic dipole and
the torquers' unloading law) take CasADi symbols, as the truth's step and the EKF
build them, and numpy arrays of 3-vectors (rows), as the ground rebuilds the known
torques from telemetry (``scenarios.trim``): one formula for both, so the ground's
torques are the truth's.

Two forms of the same Euler equation are provided, because the wheels can be
driven two ways:

* ``body_accel_from_wheel_accel``: the textbook gyrostat equation with the wheel
  accelerations Ω̇ prescribed,
  ``J ω̇ + Σ I_w Ω̇_i a_i = −ω × H + N``.  Its body-y and body-z wheel terms are
  exactly Ḣ and ḣ, so with Ω̇ as the input it is the form the paper's Eqs. 3a–3c
  (and Eq. 4, ḣ = N_w) linearise.  The Jacobian checks use it.
* ``motor_torque_rates``: what the simulator integrates, with motor torques
  ``u_i = I_w (Ω̇_i + a_i·ω̇)`` as inputs.  Eliminating Ω̇ gives
  ``(J − Σ I_w a_i a_iᵀ) ω̇ = −ω × H + N − Σ u_i a_i``.

J is the locked-wheel inertia of the whole spacecraft and Ω_i are speeds
relative to the body; H = Jω + Σ I_w Ω_i a_i is then the total angular momentum.
"""

from __future__ import annotations

import casadi as ca
import numpy as np


def skew(v):
    """``[v×]`` for a 3-vector SX/MX."""
    return ca.vertcat(ca.horzcat(0, -v[2], v[1]),
                      ca.horzcat(v[2], 0, -v[0]),
                      ca.horzcat(-v[1], v[0], 0))


def dcm_from_quat(q):
    """Frame rotation ``A(q)`` for a scalar-last quaternion (as in ``sim.frames``)."""
    qv, q4 = q[0:3], q[3]
    return (q4**2 - ca.dot(qv, qv)) * ca.DM.eye(3) + 2 * (qv @ qv.T) - 2 * q4 * skew(qv)


def quat_rate(q, w_br):
    """Kinematics ``q̇ = ½ Ξ(q) ω`` (Markley & Crassidis Eq. 3.20), ω = ω_BR in body axes."""
    qv, q4 = q[0:3], q[3]
    xi = ca.vertcat(q4 * ca.DM.eye(3) + skew(qv), -qv.T)
    return 0.5 * (xi @ w_br)


def total_momentum(w, wheel_speeds, J, Iw, A):
    """H = J ω + Σ I_w Ω_i a_i (body axes).  ``A`` holds the spin axes as columns (3×n)."""
    return J @ w + A @ (Iw * wheel_speeds)


def body_accel_from_wheel_accel(w, wheel_speeds, wheel_accels, n_ext, J, Iw, A):
    """ω̇ from ``J ω̇ = −ω × H + N − Σ I_w Ω̇_i a_i`` (prescribed wheel accelerations)."""
    h_tot = total_momentum(w, wheel_speeds, J, Iw, A)
    rhs = -ca.cross(w, h_tot) + n_ext - A @ (Iw * wheel_accels)
    return ca.solve(J, rhs)


def motor_torque_rates(w, wheel_speeds, u, n_ext, J, Js_inv, Iw, A):
    """(ω̇, Ω̇) for motor torques u.  ``Js_inv = (J − Σ I_w a aᵀ)⁻¹`` is precomputed
    numerically because it is constant for a run and a symbolic 3×3 solve in the
    inner loop would only cost time."""
    h_tot = total_momentum(w, wheel_speeds, J, Iw, A)
    w_dot = Js_inv @ (-ca.cross(w, h_tot) + n_ext - A @ u)
    wheel_accels = u / Iw - A.T @ w_dot
    return w_dot, wheel_accels


def euler312(c):
    """(yaw, roll, pitch) from C_BR, computed as ``sim.frames.euler312_from_dcm``:
    ψ from row 1, then roll and pitch from ``M = C R3(ψ)ᵀ = R2(θ) R1(φ)``, whose
    cos ψ, sin ψ come from row 1 without trigonometry.  Exact to round-off near
    and at gimbal lock (there ψ = 0 and θ carries ψ ± θ)."""
    rho = ca.hypot(c[1, 0], c[1, 1])
    at_lock = rho == 0
    cy = ca.if_else(at_lock, 1.0, c[1, 1] / ca.if_else(at_lock, 1.0, rho))
    sy = ca.if_else(at_lock, 0.0, -c[1, 0] / ca.if_else(at_lock, 1.0, rho))
    yaw = ca.atan2(-c[1, 0], c[1, 1])
    roll = ca.atan2(c[1, 2], rho)
    pitch = ca.atan2(c[2, 0] * cy + c[2, 1] * sy, c[0, 0] * cy + c[0, 1] * sy)
    return yaw, roll, pitch


def euler312_rates(roll, pitch, wx, wy, wz):
    """(ψ̇, φ̇, θ̇) from ω_BR = (wx, wy, wz) in body axes for C_BR = R2(θ)R1(φ)R3(ψ),
    the inverse of ω = (cθ φ̇ − sθ cφ ψ̇, θ̇ + sφ ψ̇, sθ φ̇ + cθ cφ ψ̇): CasADi symbols
    (the EKF's paper coordinates) or numpy arrays (the truth's, ``sim.frames``)."""
    cos, sin = (np.cos, np.sin) if _numeric(roll) else (ca.cos, ca.sin)
    cth, sth, cph, sph = cos(pitch), sin(pitch), cos(roll), sin(roll)
    roll_dot = cth * wx + sth * wz
    yaw_dot = (-sth * wx + cth * wz) / cph
    pitch_dot = wy - sph * yaw_dot
    return yaw_dot, roll_dot, pitch_dot


def dcm_from_euler312(yaw, roll, pitch):
    """``C_BR = R2(pitch) R1(roll) R3(yaw)``, symbolic (as ``sim.frames``)."""
    cy, sy = ca.cos(yaw), ca.sin(yaw)
    cr, sr = ca.cos(roll), ca.sin(roll)
    cp, sp = ca.cos(pitch), ca.sin(pitch)
    r3 = ca.vertcat(ca.horzcat(cy, sy, 0), ca.horzcat(-sy, cy, 0), ca.horzcat(0, 0, 1))
    r1 = ca.vertcat(ca.horzcat(1, 0, 0), ca.horzcat(0, cr, sr), ca.horzcat(0, -sr, cr))
    r2 = ca.vertcat(ca.horzcat(cp, 0, -sp), ca.horzcat(0, 1, 0), ca.horzcat(sp, 0, cp))
    return r2 @ r1 @ r3


def rot_about_y(angle):
    """Active rotation by +angle about y: how an inertially fixed vector moves in the
    orbit frame, which itself turns at −ω0 about y_R (docs/conventions.md)."""
    return rot_about_y_cs(ca.cos(angle), ca.sin(angle))


def rot_about_y_cs(c, s):
    """``rot_about_y`` from a precomputed cosine and sine."""
    return ca.vertcat(ca.horzcat(c, 0, s), ca.horzcat(0, 1, 0), ca.horzcat(-s, 0, c))


def _numeric(*values) -> bool:
    return all(isinstance(v, np.ndarray) for v in values)


def _cross(a, b):
    """a × b: numpy rows of 3-vectors (broadcast), or CasADi 3-vectors."""
    return np.cross(a, b) if _numeric(a, b) else ca.cross(a, b)


def _times(M, v):
    """M v: for numpy rows of 3-vectors, each row times Mᵀ."""
    return v @ np.asarray(M).T if _numeric(v) else M @ v


def gravity_gradient_torque(nadir_b, J, coef):
    """``3μ/R³ · n̂ × J n̂`` with n̂ the nadir (z_R, the third column of C_BR) in body
    axes; ``coef`` = 3μ/R³ = 3ω0²."""
    return coef * _cross(nadir_b, _times(J, nadir_b))


def solar_torque(sun_b, coef, lever_axis):
    """Array–sail imbalance torque ``κ · d̂ × ŝ`` (paper Section 2.2).

    d̂ is the array-to-sail centre-of-pressure direction (≈ pitch axis) and ŝ the
    spacecraft-to-Sun unit vector, both in body axes.  ``coef`` = κ already scaled by
    the shadow factor and (1 AU / r)² (numpy: a column, one per row of ``sun_b``);
    the sign of κ sets the torque's phase.
    """
    return coef * _cross(lever_axis, sun_b)


def offset_torque(sun_b, coef, lever_axis):
    """The solar array's offset torque ``κ_o ŝ⊥``, ŝ⊥ = ŝ − (d̂·ŝ) d̂: the Sun direction in
    the plane normal to the lever axis d̂ (``sim.environment.SolarTorque``).  ``coef`` is
    κ_o scaled as ``solar_torque``'s.  Perpendicular to the tab's d̂ × ŝ, in the same
    plane."""
    if _numeric(sun_b):
        d = np.asarray(lever_axis, dtype=float)
        return coef * (sun_b - (sun_b @ d)[..., None] * d)
    return coef * (sun_b - ca.dot(lever_axis, sun_b) * lever_axis)


def magnetic_torque(dipole_b, field_b):
    """``m × B``, both in body axes (B is constant in the orbit frame at GEO)."""
    return _cross(dipole_b, field_b)


def torquer_dipole(field_b, t_des, m_max, floor: float = 1e-30):
    """The cross-product law ``m = B × T_des / |B|²`` for any desired torque (symbolic),
    each axis saturated at ±``m_max``: m × B is then T_des less its part along B."""
    m = _cross(field_b, t_des) / (ca.dot(field_b, field_b) + floor)
    return ca.fmin(ca.fmax(m, -m_max), m_max)


def unloading_dipole(field_b, h, gain, m_max, floor: float = 1e-30):
    """The torquers' momentum-unloading law: the dipole ``m = B × T_des / |B|²`` for
    the desired torque ``T_des = −k_m h ẑ``, each axis saturated at ±``m_max``.
    ``floor`` keeps m finite (and zero) if the field is ever zero.  numpy: h a
    vector of samples and B one field for all of them."""
    if _numeric(h):
        t_des = np.zeros((len(h), 3))
        t_des[:, 2] = -gain * h
        m = _cross(field_b, t_des) / (field_b @ field_b + floor)
        return np.clip(m, -m_max, m_max)
    t_des = ca.vertcat(0, 0, -gain * h)
    m = _cross(field_b, t_des) / (ca.dot(field_b, field_b) + floor)
    return ca.fmin(ca.fmax(m, -m_max), m_max)
