"""The truth model's RK4 step and its parameter vector (rolled out by ``rollout``).

One symbolic step is built per wheel count and reused for every scenario:
everything that differs between runs (inertia, gains, switches, Δt) enters as a
parameter vector, and everything that varies in time enters as a per-step
exogenous column.  So Monte Carlo sets with dispersed inertia never recompile.

State ``x = [q_BR (4, scalar-last), ω_BN (3, body, rad/s), Ω (n, rad/s)]``.

Time-varying inputs, one mapped input each so numpy arrays reach the compiled
code without an interleaving copy (``input_layout``): ŝ_R (3), the Sun unit
vector in the orbit frame at the start of the step (rotated analytically inside
the step); sun_scale, the shadow factor times (1 AU/r)²; m_prof (3, A m²), a
prescribed control dipole; n_ext (3, N m), any extra body torque; u_wheel (n, N m),
motor torques added to the control's (a momentum dump, a test profile); and
ripple (n, N m), the motor-torque ripple held over the step.  The geomagnetic field is a
parameter: for a geostationary satellite it is constant in the orbit frame.

The *managed* step (``managed=True``) adds two parameters, the array offset's
torque coefficient κ_o and the momentum-direction gain k_d (``sim.control``), and
their terms.  It is built only for runs that use either, so every other run keeps
the step it always had, bit for bit.
"""

from __future__ import annotations

from functools import lru_cache

import casadi as ca
import numpy as np
from dynprop.eom import gyrostat as dyn

from . import geomag
from .control import Control, control_law, wheel_allocation
from .environment import Environment
from .frames import GeoOrbit
from .spacecraft import Spacecraft

MANAGED_PARAMS = (("offset_coef", (1, 1)), ("dir_gain", (1, 1)))


def is_managed(env: Environment, control: Control) -> bool:
    """Whether a run needs the managed step: an array offset torque or the momentum
    direction law."""
    return bool((env.solar.enabled and env.solar.offset_coefficient_Nm != 0)
                or (control.enabled and control.momentum_direction_gain_per_s > 0))


def param_layout(n: int, managed: bool = False) -> tuple[tuple[str, tuple[int, int]], ...]:
    """Names and shapes of the packed parameter vector, in order."""
    return _base_layout(n) + (MANAGED_PARAMS if managed else ())


def _base_layout(n: int) -> tuple[tuple[str, tuple[int, int]], ...]:
    return (("J", (3, 3)), ("Js_inv", (3, 3)), ("Iw", (n, 1)), ("A", (3, n)),
            ("w0", (1, 1)), ("dt", (1, 1)), ("sun_turn", (4, 1)), ("gg_coef", (1, 1)),
            ("solar_coef", (1, 1)),
            ("solar_axis", (3, 1)), ("m_res", (3, 1)), ("field_r", (3, 1)),
            ("ctrl_on", (1, 1)),
            ("pitch_kp", (1, 1)), ("pitch_kd", (1, 1)), ("H_nom", (1, 1)),
            ("roll_kp", (1, 1)), ("roll_kd", (1, 1)), ("h_gain", (1, 1)),
            ("alloc", (n, 2)), ("mtq_gain", (1, 1)), ("mtq_max", (1, 1)))


def input_layout(n: int) -> tuple[tuple[str, int], ...]:
    """Names and sizes of the per-step (mapped) inputs, in call order after x."""
    return (("sun_r", 3), ("sun_scale", 1), ("m_prof", 3), ("n_ext", 3), ("u_wheel", n),
            ("ripple", n))


def n_params(n: int, managed: bool = False) -> int:
    return sum(r * c for _, (r, c) in param_layout(n, managed))


def unpack_params(p, n: int, managed: bool = False) -> dict:
    """Named symbolic slices of the parameter vector (column-major reshapes)."""
    out, i = {}, 0
    for name, (r, c) in param_layout(n, managed):
        out[name] = ca.reshape(p[i:i + r * c], r, c)
        i += r * c
    return out


def pack_params(spacecraft: Spacecraft, orbit: GeoOrbit, env: Environment,
                control: Control, dt_s: float, managed: bool = False) -> np.ndarray:
    """Numeric parameter vector in ``param_layout`` order.

    The field is that of a geostationary satellite at the orbit's longitude.  It
    is always present: ``environment.magnetic.enabled`` switches the magnetic
    *disturbance* (residual and prescribed dipoles), while the torquers belong
    to the control and keep working."""
    mag = env.magnetic
    field_r = geomag.geo_field_orbit_frame(
        orbit.longitude_rad, orbit.radius_m, moment_Am2=mag.earth_dipole_Am2,
        pole_lat_deg=mag.pole_lat_deg, pole_lon_deg=mag.pole_lon_deg)
    n = spacecraft.n_wheels
    J = spacecraft.J
    A = spacecraft.wheel_axes.T
    Iw = spacecraft.wheel_inertias
    Js = J - (A * Iw) @ A.T
    w0 = orbit.rate_radps
    Iy = J[1, 1]
    on = control.enabled
    pitch, roll_yaw = float(control.pitch_loop), float(control.roll_yaw_loop)
    vals = {
        "J": J, "Js_inv": np.linalg.inv(Js), "Iw": Iw, "A": A, "w0": w0, "dt": dt_s,
        # cos/sin of the Sun's turn in the orbit frame over half and a whole step:
        # constants of the run, so they are not recomputed in every step.
        "sun_turn": [np.cos(w0 * dt_s / 2), np.sin(w0 * dt_s / 2),
                     np.cos(w0 * dt_s), np.sin(w0 * dt_s)],
        "gg_coef": 3.0 * w0**2 * env.gravity_gradient.enabled,
        "solar_coef": env.solar.coefficient_Nm * env.solar.enabled,
        "solar_axis": np.asarray(env.solar.lever_axis),
        "m_res": np.asarray(mag.residual_dipole_Am2) * mag.enabled, "field_r": field_r,
        "ctrl_on": float(on),
        "pitch_kp": Iy * control.pitch_bandwidth_radps**2 * pitch,
        "pitch_kd": Iy * 2.0 * control.pitch_damping * control.pitch_bandwidth_radps * pitch,
        "H_nom": spacecraft.pitch_bias_Nms(),
        "roll_kp": control.roll_gain_per_s * roll_yaw,
        "roll_kd": control.roll_rate_gain * roll_yaw,
        "h_gain": control.yaw_momentum_gain_per_s * roll_yaw,
        "alloc": wheel_allocation(spacecraft.wheel_axes, spacecraft.standby_wheel,
                                  control.yaw_on_standby_wheel),
        "mtq_gain": control.unloading_gain_per_s * control.magnetic_unloading,
        "mtq_max": control.torquer_max_Am2,
        "offset_coef": env.solar.offset_coefficient_Nm * env.solar.enabled,
        "dir_gain": control.momentum_direction_gain_per_s * roll_yaw,
    }
    if not managed and is_managed(env, control):
        raise ValueError("an array offset torque or the momentum direction law needs the "
                         "managed step (managed=True)")
    parts = [np.asarray(vals[name], dtype=float).reshape((r, c)).ravel(order="F")
             for name, (r, c) in param_layout(n, managed)]
    return np.concatenate(parts)


def _rates(x, u, n_ext_total, prm, n: int):
    q, w, wheel = x[0:4], x[4:7], x[7:7 + n]
    c_br = dyn.dcm_from_quat(q)
    w_rn_r = ca.vertcat(0, -prm["w0"], 0)
    w_br = w - c_br @ w_rn_r
    w_dot, wheel_dot = dyn.motor_torque_rates(w, wheel, u, n_ext_total, prm["J"],
                                              prm["Js_inv"], prm["Iw"], prm["A"])
    return ca.vertcat(dyn.quat_rate(q, w_br), w_dot, wheel_dot)


def _env_torques(q, sun_r, ex, prm, m_ctrl):
    """Gravity gradient, solar (with the array offset's in the managed step), magnetic
    disturbance and magnetic control torques."""
    c_br = dyn.dcm_from_quat(q)
    t_gg = dyn.gravity_gradient_torque(c_br[:, 2], prm["J"], prm["gg_coef"])
    sun_b = c_br @ sun_r
    t_sol = dyn.solar_torque(sun_b, prm["solar_coef"] * ex["sun_scale"], prm["solar_axis"])
    if "offset_coef" in prm:
        t_sol = t_sol + dyn.offset_torque(sun_b, prm["offset_coef"] * ex["sun_scale"],
                                          prm["solar_axis"])
    t_mag = dyn.magnetic_torque(prm["m_res"] + ex["m_prof"], c_br @ prm["field_r"])
    t_mtq = dyn.magnetic_torque(m_ctrl, c_br @ prm["field_r"])
    return t_gg, t_sol, t_mag, t_mtq


@lru_cache(maxsize=8)
def build_step(n: int, managed: bool = False) -> ca.Function:
    """One RK4 step ``(x, e, p) -> (x_next, aux)``, expanded to SX.

    The control is evaluated once from the state at the start of the step and
    held (zero-order hold); environment torques are re-evaluated at each RK4
    stage, with the Sun vector rotated to the stage time.  The quaternion is
    renormalised after the step.  ``aux`` = [u_cmd (n), m_cmd (3), T_gg (3),
    T_solar (3), T_mag (3), T_torquer (3), yaw, roll, pitch, ω_BR (3), ŝ_B (3), H, h], at the
    start of the step (see ``aux_layout``).
    """
    x = ca.SX.sym("x", 7 + n)
    ex = {name: ca.SX.sym(name, k) for name, k in input_layout(n)}
    p = ca.SX.sym("p", n_params(n, managed))
    prm = unpack_params(p, n, managed)
    dt = prm["dt"]

    c_br0 = dyn.dcm_from_quat(x[0:4])
    w_br0 = x[4:7] - c_br0 @ ca.vertcat(0, -prm["w0"], 0)
    u_cmd, m_cmd = control_law(c_br0, w_br0, x[7:7 + n], prm["field_r"], prm,
                               x[4:7] if managed else None)
    u = u_cmd + ex["u_wheel"] + ex["ripple"]

    def f(xs, sun_r):
        torques = _env_torques(xs[0:4], sun_r, ex, prm, m_cmd)
        return _rates(xs, u, sum(torques[1:], torques[0]) + ex["n_ext"], prm, n)

    turn = prm["sun_turn"]
    sun_half = dyn.rot_about_y_cs(turn[0], turn[1]) @ ex["sun_r"]
    sun_full = dyn.rot_about_y_cs(turn[2], turn[3]) @ ex["sun_r"]
    k1 = f(x, ex["sun_r"])
    k2 = f(x + dt / 2 * k1, sun_half)
    k3 = f(x + dt / 2 * k2, sun_half)
    k4 = f(x + dt * k3, sun_full)
    xn = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    xn = ca.vertcat(xn[0:4] / ca.norm_2(xn[0:4]), xn[4:])

    t_gg, t_sol, t_mag, t_mtq = _env_torques(x[0:4], ex["sun_r"], ex, prm, m_cmd)
    # Output conversions are done here, in compiled code, rather than as numpy
    # passes over (N, 3, 3) histories afterwards.
    wheel_h = prm["A"] @ (prm["Iw"] * x[7:7 + n])
    aux = ca.vertcat(u_cmd, m_cmd, t_gg, t_sol, t_mag, t_mtq, *dyn.euler312(c_br0), w_br0,
                     c_br0 @ ex["sun_r"], wheel_h[1], wheel_h[2])
    # Common-subexpression elimination: the RK4 stages rebuild the same DCM terms;
    # cse() trims the step by about a fifth for both the VM and compiled code.
    xn, aux = ca.vertsplit(ca.cse(ca.vertcat(xn, aux)), [0, xn.numel(), xn.numel() + aux.numel()])
    names = [name for name, _ in input_layout(n)]
    name = f"dynprop_step{n}" + ("m" if managed else "")
    return ca.Function(name, [x, *(ex[k] for k in names), p], [xn, aux],
                       ["x", *names, "p"], ["xn", "aux"])


def aux_layout(n: int) -> tuple[tuple[str, int], ...]:
    return (("u_cmd", n), ("m_cmd", 3), ("t_gg", 3), ("t_solar", 3), ("t_mag", 3),
            ("t_mtq", 3), ("euler", 3), ("w_br", 3), ("sun_b", 3), ("H", 1), ("h", 1))


def n_aux(n: int) -> int:
    return sum(k for _, k in aux_layout(n))


def split_aux(aux: np.ndarray, n: int) -> dict[str, np.ndarray]:
    """Named column blocks of an (N, n_aux) aux history."""
    out, i = {}, 0
    for name, k in aux_layout(n):
        out[name] = aux[:, i] if k == 1 else aux[:, i:i + k]
        i += k
    return out


def aux_slice(n: int, name: str) -> slice:
    """The columns of ``name`` in an aux history (``aux_layout``)."""
    i = 0
    for key, k in aux_layout(n):
        if key == name:
            return slice(i, i + k)
        i += k
    raise KeyError(name)
