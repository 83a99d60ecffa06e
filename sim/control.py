"""Attitude control: a pitch loop and a roll/yaw loop (sampled, zero-order hold).

The controller runs once per step from the state at the start of the step and
holds its commands over the step, as a flight computer does.  It sees roll,
pitch, body rates and the wheel speeds, but not yaw: like the GOES-Next
momentum-bias design, yaw is controlled only through roll/yaw coupling.

* Pitch: a PD law on pitch commands the common-mode wheel momentum rate,
  ``Ḣ_cmd = I_y (ω_p² θ + 2 ζ ω_p θ̇)``, so that ``I_y θ̈ ≈ −Ḣ`` (Eq. 3b) closes
  with bandwidth ω_p.
* Roll/yaw through the wheels: ``ḣ_cmd = N_w = H (k_r φ + k_ṙ φ̇) + k_h h``.
* Roll/yaw through magnetic torquers: momentum unloading with the cross-product
  law ``m = B × T_des / |B|²``, ``T_des = −k_m h ẑ``, each axis saturated.

The default gains put the closed-loop nutation time constant near 16 min and the
slow orbit-rate (yaw) mode near 4 h on the GOES-Next defaults (eigenvalues of the
nonlinear step's Jacobian, checked by the tests).  Only an external torque can
damp the orbit-rate mode: the total inertial momentum is conserved and the wheels
store only pitch and yaw momentum, so with magnetic unloading off that mode is
neutral (a physical limit of wheel-only momentum-bias control, also tested).
Each loop can be switched off on its own.

* Momentum direction through magnetic torquers (issue 45; off by default): the
  unloading law above holds only h.  With ``momentum_direction_gain_per_s`` k_d > 0 the
  torquers also steer the whole momentum, ``T_des += −k_d C_BR P H_R``, where H_R is
  the total angular momentum (body and wheels) in the orbit frame and P keeps its
  roll and yaw components, the part off the orbit normal.  In the orbit frame
  ``Ḣ_R = T_R − ω_RN × H_R`` with ω_RN = −ω0 ŷ, so those two components obey
  ``Ḣx = Tx + ω0 Hz``, ``Ḣz = Tz − ω0 Hx``: a neutral pair at ±iω0, fixed in inertial
  space, which only an external torque moves (the wheels store y and z only).  The
  law puts that pair at ``−k_d ± iω0`` (less the part of P H along the field, which
  m × B cannot give: ``docs/conventions.md``).  The controller uses the attitude and
  wheel speeds; on the spacecraft the yaw comes from the Sun sensors and the ground,
  and the loop, with a time constant of a day, does not see a 0.04° yaw error.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np
from dynprop.eom.gyrostat import euler312, torquer_dipole, total_momentum, unloading_dipole


@dataclass(frozen=True)
class Control:
    enabled: bool = True
    pitch_loop: bool = True
    roll_yaw_loop: bool = True
    pitch_bandwidth_radps: float = 0.02
    pitch_damping: float = 0.7
    roll_gain_per_s: float = 0.01          # k_r
    roll_rate_gain: float = 1.8            # k_ṙ (dimensionless)
    yaw_momentum_gain_per_s: float = -0.01  # k_h
    magnetic_unloading: bool = True
    unloading_gain_per_s: float = 3e-4     # k_m
    torquer_max_Am2: float = 10.0
    momentum_direction_gain_per_s: float = 0.0  # k_d (0: off)
    # After a wheel switch (``sim.events``): the yaw demand flies on the spacecraft's
    # standby yaw wheel (``wheel_allocation``).
    yaw_on_standby_wheel: bool = False

    def __post_init__(self) -> None:
        for name, value in self.__dict__.items():
            if not isinstance(value, bool) and not np.isfinite(value):
                raise ValueError(f"control {name} must be finite")
        if self.pitch_bandwidth_radps < 0 or self.pitch_damping < 0:
            raise ValueError("pitch bandwidth and damping must be non-negative")
        if self.torquer_max_Am2 < 0:
            raise ValueError("torquer saturation must be non-negative")
        if self.momentum_direction_gain_per_s < 0:
            raise ValueError("momentum direction gain must be non-negative")


def wheel_allocation(axes: np.ndarray, standby: int | None = None,
                     switched: bool = False) -> np.ndarray:
    """Map a desired wheel-momentum rate (Ḣ_y, ḣ_z) to motor torques, (n × 2).

    Motor torques change the wheel momentum by Σ u_i a_i; the pseudo-inverse of
    the y–z rows of the axis matrix spreads the demand evenly over the wheels.

    With a ``standby`` yaw wheel (axis ±z, ``Spacecraft.standby_wheel``) the others fly
    both demands and the standby wheel none: it idles.  ``switched`` (after a wheel
    switch) gives it the yaw demand, ḣ/a_z, and leaves the others only the pitch
    demand with no yaw part: for the canted V pair, equal torques (the common mode),
    so their differential, their share of h, stays where the switch found it.
    """
    m = np.asarray(axes, dtype=float).T[1:3, :]
    if standby is None:
        if switched:
            raise ValueError("a wheel switch needs a standby yaw wheel")
        return np.linalg.pinv(m)
    flying = [i for i in range(m.shape[1]) if i != standby]
    out = np.zeros((m.shape[1], 2))
    pinv = np.linalg.pinv(m[:, flying])
    out[flying, 0] = pinv[:, 0]
    if switched:
        out[standby, 1] = 1.0 / m[1, standby]
    else:
        out[flying, 1] = pinv[:, 1]
    return out


def control_law(c_br, w_br, wheel_speeds, field_r, prm, w_bn=None):
    """Symbolic control commands (motor torques u, torquer dipole m) at step start.

    ``prm`` is the unpacked parameter dict of ``sim.step``; with ``w_bn`` (ω_BN, body)
    and the managed step's ``dir_gain``, the torquers also steer the momentum's
    direction (the module doc).
    """
    _, roll, pitch = euler312(c_br)
    h = ca.dot(prm["A"][2, :].T, prm["Iw"] * wheel_speeds)
    on = prm["ctrl_on"]
    pitch_demand = prm["pitch_kp"] * pitch + prm["pitch_kd"] * w_br[1]
    yaw_demand = prm["H_nom"] * (prm["roll_kp"] * roll + prm["roll_kd"] * w_br[0]) \
        + prm["h_gain"] * h
    u = on * (prm["alloc"] @ ca.vertcat(pitch_demand, yaw_demand))

    field_b = c_br @ field_r
    if w_bn is None:
        return u, on * unloading_dipole(field_b, h, prm["mtq_gain"], prm["mtq_max"])
    h_r = c_br.T @ total_momentum(w_bn, wheel_speeds, prm["J"], prm["Iw"], prm["A"])
    t_des = ca.vertcat(0, 0, -prm["mtq_gain"] * h) \
        - prm["dir_gain"] * (c_br @ ca.vertcat(h_r[0], 0, h_r[2]))
    return u, on * torquer_dipole(field_b, t_des, prm["mtq_max"])
