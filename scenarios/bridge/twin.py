"""The linear twin: the paper's model (Eq. 11) of the spacecraft that flies,
propagated exactly (Φ, Γ) from the truth's initial deviation under the truth's
torques, and sensed with the same noise draws by the same sensor code.

Filtering both the truth's and the twin's telemetry with the identical filter
separates what the nonlinearities and the model's approximations cost (real −
linearized) from what the sensors and process noise cost (linearized).  The twin's
inputs (Eq. 12a) are the modelled torques plus the residual of the torque states'
fit (``coordinates.truth_torques``) and the true N_w averaged over each step.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from dynprop.estimator.linear import model as em
from dynprop.estimator.linear.propagate import propagate_lti, propagate_lti_final
from dynprop.estimator.linear.transition import discretize
from dynprop.sim.frames import rotate_312
from dynprop.sim.telemetry import Telemetry, make_telemetry, with_events

from ..config import build
from ..config.schema import Scenario
from ..records import Measured
from .coordinates import TruthTorques, model_truth, step_rates
from .inputs import measured


def twin_input(params, model_torques, tt: TruthTorques, h_Nms, dt_s: float,
               h_next: float | None = None) -> np.ndarray:
    """The twin's inputs (Eq. 12a): the modelled torques plus the fit's residual, and
    the true N_w, the mean of ḣ over each step (``coordinates.step_rates``; the last
    step needs the next window's first h, ``h_next``)."""
    mt = model_torques
    nx, nz = mt.roll_Nm + tt.res_x, mt.yaw_Nm + tt.res_z
    if tt.known is not None:   # the known torques drive the twin as the filter's inputs
        nx, nz = nx + tt.known[:, 0], nz + tt.known[:, 1]
    return em.input_vector(params, nx, nz, step_rates(h_Nms, dt_s, h_next))


@dataclass(frozen=True)
class TwinTruth:
    """What the twin reads of a window's truth (kept, in a streamed run, until the
    next window's first h exists): times, attitude, wheel momentum and speeds, the
    shadow and the Sun in the orbit frame."""

    t_s: np.ndarray
    roll_rad: np.ndarray
    pitch_rad: np.ndarray
    yaw_rad: np.ndarray
    h_Nms: np.ndarray
    wheel_speeds_radps: np.ndarray
    shadow: np.ndarray
    sun_orbit_frame: np.ndarray

    @classmethod
    def of(cls, truth) -> TwinTruth:
        return cls(truth.t_s, truth.roll_rad, truth.pitch_rad, truth.yaw_rad, truth.h_Nms,
                   truth.wheel_speeds_radps, truth.shadow, truth.sun_orbit_frame)


@dataclass(frozen=True)
class SensedState:
    """What the sensors read of a state (``sim.telemetry.make_telemetry``'s truth)."""

    t_s: np.ndarray
    roll_rad: np.ndarray
    pitch_rad: np.ndarray
    wheel_speeds_radps: np.ndarray
    shadow: np.ndarray
    sun_orbit_frame: np.ndarray
    sun_body: np.ndarray


def sense_twin(s: Scenario, truth, twin: np.ndarray, suite, rngs) -> Telemetry:
    """Telemetry of the twin's states ``twin`` (model coordinates), sensed by ``suite``
    with the generators ``rngs`` (the same seeds as the truth's: the same draws).
    The twin flies the truth's pitch and orbit: its wheels carry the twin's h."""
    speeds = build.build_spacecraft(s).speeds_with_yaw_momentum(
        truth.wheel_speeds_radps, truth.h_Nms, twin[:, em.H_WHEEL])
    twin_truth = SensedState(
        t_s=truth.t_s, roll_rad=twin[:, em.R], pitch_rad=truth.pitch_rad,
        wheel_speeds_radps=speeds, shadow=truth.shadow, sun_orbit_frame=truth.sun_orbit_frame,
        sun_body=rotate_312(twin[:, em.Y], twin[:, em.R], truth.pitch_rad,
                            truth.sun_orbit_frame))
    # The twin's sensors are out when the truth's are, and it flies the same flag.
    return with_events(make_telemetry(twin_truth, suite, rngs,
                                      s.sensors.sun.min_sun_separation_deg),
                       build.build_schedule(s))


def linear_twin(s: Scenario, truth, run: int, model_torques, tt: TruthTorques):
    """The twin of the spacecraft of ``s`` over a whole run, from the truth's initial
    deviation: its states in the coordinates of ``s``'s model, its telemetry and the
    model.  Fresh generators from the same seed: its noise draws equal the truth's."""
    params, noise = build.estimator_model(s)
    disc = discretize(params, noise, s.sample_interval_s)
    u_twin = twin_input(params, model_torques, tt, truth.h_Nms, s.sample_interval_s)
    twin = propagate_lti(disc.Phi, disc.Gamma, model_truth(params, truth, tt, [0])[0], u_twin)
    twin_tel = sense_twin(s, truth, twin, build.build_sensors(s), build.streams(s.seed, run))
    return twin, twin_tel, params


def twin_window(s: Scenario, params, disc, truth, tt: TruthTorques, h_next, x_prev, rngs,
                suite) -> tuple[np.ndarray, Measured, np.ndarray]:
    """The twin over one window of a streamed run, ``linear_twin`` with its state and
    generators carried from the previous window (``x_prev``, None for the first).
    Its torque states are set to the new window's fit at its first sample, so that
    its total torque stays the truth's (``run.stream.windows``'s module doc says why).
    Returns its states, its telemetry and the state where the next window starts."""
    u = twin_input(params, s.estimator.model_torques, tt, truth.h_Nms, s.sample_interval_s,
                   h_next)
    if x_prev is None:
        x0 = model_truth(params, truth, tt, [0])[0]
    else:
        x0 = x_prev.copy()
        x0[em.NPX:] = tt.torque_states[0]
    twin, x_next = propagate_lti_final(disc.Phi, disc.Gamma, x0, u)
    return twin, measured(sense_twin(s, truth, twin, suite, rngs)), x_next
