"""The extended Kalman filter (``estimator.ekf``) on a scenario's telemetry: its
design from the scenario, and its inputs from the same preprocessing the paper's
filter gets (``pipeline.filter_inputs``: the same yaw variances with the DSS
correlation inflation, the same N_w* = ḣ from the tachometers, the same modelled
torques), plus what only the EKF uses, the Earth sensor's pitch and the pitch
wheels' momentum H and its rate Ḣ.
"""

from __future__ import annotations

import numpy as np
from dynprop.estimator import ekf_model as m
from dynprop.estimator import model as em
from dynprop.estimator.ekf import EkfInputs, EkfResult, ekf_filter, initial_state
from dynprop.estimator.preprocess import wheel_torque

from ..config import build
from ..config.schema import Scenario
from .whole import filter_inputs, initial_prior

DEG = np.pi / 180.0


def ekf_design(s: Scenario) -> tuple[np.ndarray, float, np.ndarray, np.ndarray]:
    """(model parameters, ω_n, X0, P0) of the EKF for ``s``: the nominal full inertia
    (products included), the orbit rate, the sample interval and the scenario's
    process noise, with pitch's torque noise taken as roll's (the paper has no pitch
    state); the prior is the paper filter's, pitch getting roll's σ."""
    params, noise = build.estimator_model(s)
    J = build.build_spacecraft(s).J
    q = {"q_x": noise.q_x, "q_y": noise.q_x, "q_z": noise.q_z, "q_w": noise.q_w,
         "q_px": noise.q_px, "q_pz": noise.q_pz, "q_cx": noise.q_cx, "q_cz": noise.q_cz}
    pm = m.pack_params(J, params.omega0_radps, s.sample_interval_s, q)
    x0, P0 = initial_prior(s, params)
    i = s.estimator.initial_sigma
    X0, P0e = initial_state(x0, P0, i.roll_deg * DEG, i.roll_rate_degps * DEG,
                            params.omega_n_radps)
    return pm, params.omega_n_radps, X0, P0e


def ekf_inputs(s: Scenario, params: em.ModelParams, roll, pitch, yaw, speeds,
               yaw_sigma=None, sun_head=None, known_Nm=None) -> EkfInputs:
    """Telemetry arrays (SI) to the EKF's measurements and inputs."""
    meas, u, _ = filter_inputs(s, params, roll, yaw, speeds, yaw_sigma, sun_head, known_Nm)
    H = params.H_Nms
    Nw = u[:, em.H_WHEEL]
    Nx, Nz = u[:, em.RDOT] * H, u[:, em.YDOT] * H + Nw
    sc = build.build_spacecraft(s)
    pitch_k = sc.wheel_inertias * sc.wheel_axes[:, 1]
    Hm = np.asarray(speeds) @ pitch_k
    Hm = np.where(np.isfinite(Hm), Hm, H)
    Hdot = wheel_torque(Hm, s.sample_interval_s, s.estimator.wheel_torque_window_s)
    z = np.column_stack([meas.roll_rad, pitch, meas.yaw_rad, meas.h_Nms])
    r = meas.r()
    r = np.column_stack([r[:, 0], r[:, 0], r[:, 1], r[:, 2]])
    return EkfInputs(z, r, np.column_stack([Hm, Hdot, Nw, Nx, Nz]))


def run_ekf(s: Scenario, roll, pitch, yaw, speeds, yaw_sigma=None, sun_head=None,
            rows=None, keep_nominal: bool = False) -> EkfResult:
    params, _ = build.estimator_model(s)
    pm, wn, X0, P0 = ekf_design(s)
    inputs = ekf_inputs(s, params, roll, pitch, yaw, speeds, yaw_sigma, sun_head)
    return ekf_filter(inputs, pm, wn, X0, P0, rows=rows, keep_nominal=keep_nominal)


class EkfStream:
    """The EKF through a streamed run's windows (``stream.filtered``), each continuing
    from the state and covariance the previous one ended with.  Its inputs are made
    from the window padded with ``plan.pad`` samples of each neighbour, as the paper
    filter's (``twin_stream.padded_inputs``), so the derivatives N_w* and Ḣ equal the
    whole run's."""

    def __init__(self, s: Scenario, params: em.ModelParams):
        self.s, self.params = s, params
        self.pm, self.wn, self.X, self.P = ekf_design(s)

    def window(self, plan, prev, cur, nxt) -> EkfResult:
        lo, n, pad = (0 if prev is None else plan.pad), len(cur["t_s"]), plan.pad
        parts = ([(prev["meas"], prev["pitch"])] if prev is not None else []) \
            + [(cur["meas"], cur["pitch"])] \
            + ([(tuple(None if v is None else v[:pad] for v in nxt["meas"]),
                 nxt["pitch"][:pad])] if nxt is not None else [])
        meas = [None if parts[0][0][i] is None else np.concatenate([p[0][i] for p in parts])
                for i in range(len(parts[0][0]))]
        pitch = np.concatenate([p[1] for p in parts])
        roll, yaw, speeds, sigma, head = meas
        full = ekf_inputs(self.s, self.params, roll, pitch, yaw, speeds, sigma, head)
        sl = slice(lo, lo + n)
        r = ekf_filter(EkfInputs(full.z[sl], full.r[sl], full.u[sl]), self.pm, self.wn,
                       self.X, self.P)
        self.X, self.P = r.x_next, r.P_next
        return r
