"""The extended Kalman filter's design and inputs from a scenario and its telemetry.

The EKF (``estimator.ekf``) gets the same preprocessing as the paper's filter
(``inputs.filter_inputs``: the same yaw variances with the DSS correlation
inflation, the same N_w* = ḣ from the tachometers, the same modelled torques),
plus what only it uses: the Earth sensor's pitch and the pitch wheels' momentum H
and its rate Ḣ.
"""

from __future__ import annotations

import numpy as np
from dynprop.estimator.ekf import model as m
from dynprop.estimator.ekf.filter import ROLL_YAW, EkfInputs, initial_state
from dynprop.estimator.kalman.maneuver import Maneuver
from dynprop.estimator.kalman.preprocess import wheel_torque, wheel_torque_at, yaw_momentum
from dynprop.estimator.linear import model as em

from ..config import build
from ..config.schema import Scenario
from ..records import Measured
from ..units import DEG
from .inputs import filter_inputs, initial_prior, join_padded, maneuver_response


def ekf_design(s: Scenario) -> tuple[np.ndarray, float, np.ndarray, np.ndarray]:
    """(model parameters, ω_n, X0, P0) of the EKF for ``s``: the nominal full inertia
    (products included), the orbit rate, the sample interval and the scenario's
    process noise, with pitch's white torque noise ``q_y`` (the pitch filter's: the
    paper has no pitch state); the prior is the paper filter's, pitch getting roll's σ."""
    params, noise = build.estimator_model(s)
    J = build.build_spacecraft(s).J
    q = {"q_x": noise.q_x, "q_y": s.estimator.process_noise.q_y, "q_z": noise.q_z, "q_w": noise.q_w,
         "q_px": noise.q_px, "q_pz": noise.q_pz, "q_cx": noise.q_cx, "q_cz": noise.q_cz}
    pm = m.pack_params(J, params.omega0_radps, s.sample_interval_s, q)
    x0, P0 = initial_prior(s, params)
    i = s.estimator.initial_sigma
    X0, P0e = initial_state(x0, P0, i.roll_deg * DEG, i.roll_rate_degps * DEG,
                            params.omega_n_radps)
    return pm, params.omega_n_radps, X0, P0e


def ekf_maneuver(s: Scenario, params: em.ModelParams, flag) -> Maneuver | None:
    """The scenario's response to a thruster-firing ``flag`` for the EKF
    (``inputs.maneuver_response``): its roll and yaw error states (``ROLL_YAW``), the
    reset to its own prior."""
    if flag is None:
        return None
    P0e = ekf_design(s)[3]
    return maneuver_response(s, params, flag, P0e[np.ix_(ROLL_YAW, ROLL_YAW)], ROLL_YAW)


def ekf_inputs(s: Scenario, params: em.ModelParams, roll, pitch, yaw, speeds,
               yaw_sigma=None, sun_head=None, known_Nm=None, t_s=None, record=None,
               maneuver=None) -> EkfInputs:
    """Telemetry arrays (SI) to the EKF's measurements and inputs (``t_s``: the
    samples' own times, for telemetry off the grid; ``record`` their file's cadence
    and first time, ``inputs.prepared_inputs'``; ``maneuver`` the thruster-firing
    flag, ``ekf_maneuver``)."""
    meas, u, _ = filter_inputs(s, params, roll, yaw, speeds, yaw_sigma, sun_head,
                               known_Nm=known_Nm, t_s=t_s, record=record)
    H = params.H_Nms
    Nx, Nz, Nw = em.input_torques(params, u)
    Hm = yaw_momentum(speeds, build.build_spacecraft(s).momentum_factors(1))
    Hm = np.where(np.isfinite(Hm), Hm, H)
    Hdot = (wheel_torque(Hm, s.sample_interval_s, s.estimator.wheel_torque_window_s)
            if t_s is None else wheel_torque_at(t_s, Hm, s.estimator.wheel_torque_window_s,
                                                *(record if record is not None else ())))
    z = np.column_stack([meas.roll_rad, pitch, meas.yaw_rad, meas.h_Nms])
    r = meas.r()
    r = np.column_stack([r[:, 0], r[:, 0], r[:, 1], r[:, 2]])
    return EkfInputs(z, r, np.column_stack([Hm, Hdot, Nw, Nx, Nz]),
                     ekf_maneuver(s, params, maneuver))


def padded_ekf_inputs(s: Scenario, params: em.ModelParams, prev_tail: tuple | None,
                      cur: tuple, nxt: tuple | None, pad: int, t_s=None, record=None
                      ) -> EkfInputs:
    """``ekf_inputs`` of a window from its telemetry (``records.Measured``'s fields and
    the pitch, as one tuple) padded with ``pad`` samples of each neighbour
    (``inputs.join_padded``), so the derivatives N_w* and Ḣ equal the whole run's."""
    joined, sl = join_padded(prev_tail, cur, nxt, pad)
    *telemetry, pitch = joined
    m = Measured(*telemetry)
    full = ekf_inputs(s, params, m.roll_rad, pitch, m.yaw_rad, m.speeds_radps,
                      m.yaw_sigma_rad, m.sun_head, t_s=t_s, record=record,
                      maneuver=m.maneuver)
    return full.cut(sl)
