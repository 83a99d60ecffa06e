"""The nonlinear truth in the coordinates of the paper's model (Eq. 10).

The truth's attitude becomes [r, ṙ/ω_n, y, ẏ/ω_n, h] through its 3-1-2 Euler rates
(``sim.frames.euler312_rates``).  Its external roll and yaw torques, less the
estimator's modelled N_x*, N_z*, are fitted with the model's own form (constant +
an ω0 sinusoid, Eqs. 9 and 18, ``estimator.model.project_torques``): the fit is
the "true" value of the torque states N_c, N_p, and the residual drives the linear
twin as an input.  Gravity gradient is not an external torque here: the linear
model carries it (in its approximated form) in F.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from dynprop.estimator.linear import model as em
from dynprop.sim.frames import euler312_rates
from dynprop.sim.history import EXTERNAL_TORQUES


def external_torque(truth) -> np.ndarray:
    """The truth's external torque (N, 3), body axes: every source of
    ``sim.history.EXTERNAL_TORQUES`` the truth holds (gravity gradient excluded; the
    disturbance and the thrusters only in runs that fly them)."""
    return sum(truth.torques[k] for k in EXTERNAL_TORQUES if k in truth.torques)


def step_rates(h_Nms: np.ndarray, dt_s: float, h_next: float | None = None) -> np.ndarray:
    """The mean rate of h over each step, (h_{k+1} − h_k)/Δt: the true N_w = ḣ held
    over the step, exact for h.  The last step needs the next sample's h (``h_next``,
    a following window's first); without it its rate is 0 (no sample follows)."""
    h = h_Nms if h_next is None else np.append(h_Nms, h_next)
    rates = np.diff(h) / dt_s
    return np.append(rates, 0.0) if h_next is None else rates


@dataclass(frozen=True)
class TruthTorques:
    """The truth's Euler rates, and its external roll/yaw torques less the modelled
    N_x*, N_z*, split into the torque states' fit and the residual (Eqs. 9, 18).
    None of it depends on the spacecraft's ω_n, so one serves every model."""

    rates: np.ndarray        # (ψ̇, φ̇, θ̇), rad/s
    torque_states: np.ndarray
    res_x: np.ndarray
    res_z: np.ndarray
    known: np.ndarray | None = None   # (N, 2) the torques the filter knows, or None


def truth_torques(truth, model_torques, omega0_radps: float,
                  known_Nm: np.ndarray | None = None) -> TruthTorques:
    """The split above; ``known_Nm`` (N, 2), roll and yaw torques the filter takes as
    known (``estimator.known_torques``), is left out of the torque states' truth as
    the modelled torques are (the filter's torque states estimate what remains)."""
    ext = external_torque(truth)
    mt = model_torques
    kx, kz = (0.0, 0.0) if known_Nm is None else (known_Nm[:, 0], known_Nm[:, 1])
    thruster = truth.torques["thruster"] if "thruster" in truth.torques else None
    if thruster is not None:
        # A firing is no environment torque: the torque states (Eqs. 9, 18) do not
        # model it, so it stays whole in the residual rather than smeared over the
        # window's constant and orbit-rate fit.
        ext = ext - thruster
    states, res_x, res_z = em.project_torques(truth.t_s, ext[:, 0] - mt.roll_Nm - kx,
                                              ext[:, 2] - mt.yaw_Nm - kz, omega0_radps)
    if thruster is not None:
        res_x, res_z = res_x + thruster[:, 0], res_z + thruster[:, 2]
    return TruthTorques(euler312_rates(truth.euler_rad, truth.w_br_radps), states, res_x, res_z,
                        known_Nm)


def _attitude_columns(truth, rates: np.ndarray, omega_n: float, rows) -> list[np.ndarray]:
    return [truth.roll_rad[rows], rates[rows, 1] / omega_n, truth.yaw_rad[rows],
            rates[rows, 0] / omega_n, truth.h_Nms[rows]]


def model_attitude(truth, rates: np.ndarray, omega_n: float, rows=slice(None)) -> np.ndarray:
    """The truth as [r, ṙ/ω_n, y, ẏ/ω_n, h] (N, 5) from its Euler ``rates``, or only
    the samples ``rows``."""
    return np.column_stack(_attitude_columns(truth, rates, omega_n, rows))


def model_truth(params: em.ModelParams, truth, tt: TruthTorques, rows=slice(None)
                ) -> np.ndarray:
    """The nonlinear truth in the coordinates of the model ``params``: (N, 9), or
    only the samples ``rows``."""
    return np.column_stack([*_attitude_columns(truth, tt.rates, params.omega_n_radps, rows),
                            tt.torque_states[rows]])


def pitch_truth(truth, tt: TruthTorques, rows=slice(None)) -> np.ndarray:
    """The truth in the pitch filter's states (Eq. 3b, ``estimator.pitch``): the 3-1-2
    pitch θ, its Euler rate θ̇ and the external pitch torque N_y (every source the
    truth flies; the gravity gradient is the model's k θ), (N, 3)."""
    return np.column_stack([truth.euler_rad[rows, 2], tt.rates[rows, 2],
                            external_torque(truth)[rows, 1]])
