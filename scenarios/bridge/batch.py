"""Telemetry to the batch estimator's data (``estimator.batch``, ``batch.nonlinear``):
the paper filter's measurements and inputs (``inputs.filter_inputs``: the same yaw
variances with the DSS correlation inflation, the same N_w* = ḣ), the EKF's inputs
for the nonlinear model (``ekf.ekf_inputs``), the Earth sensor's smoothed pitch, and
the consider parameters: each data set rebuilt with one of them moved (the linear
model's central differences)."""

from __future__ import annotations

import numpy as np
from dynprop.estimator.batch import steps as bs
from dynprop.estimator.batch.linear import ConsiderCase, LinearData
from dynprop.estimator.batch.nonlinear import NonlinearData
from dynprop.estimator.kalman.preprocess import cadence, earth_pitch
from dynprop.estimator.linear.steps import StepTable, step_intervals
from dynprop.estimator.linear.transition import discretize

from ..config import build
from ..config.loader import validate
from ..config.schema import Scenario
from ..records import Measured
from ..units import DEG, RPM2RADPS
from .ekf import ekf_design, ekf_inputs
from .inputs import filter_inputs


def linear_data(s: Scenario, tel: Measured, t_s=None) -> LinearData:
    """The paper model's data from telemetry (``t_s``: the samples' own times, off the
    grid)."""
    params, noise = build.estimator_model(s)
    meas, u, _ = filter_inputs(s, params, *tel.readings, t_s=t_s)
    disc = (discretize(params, noise, s.sample_interval_s) if t_s is None
            else StepTable.from_times(params, noise, t_s))
    return LinearData(meas, u, disc)


def nonlinear_data(s: Scenario, tel: Measured, pitch_rad, t_s=None) -> NonlinearData:
    """The nonlinear model's data: the paper filter's roll, yaw, h and variances, the
    EKF's inputs, the smoothed Earth-sensor pitch and the model's parameters."""
    params, _ = build.estimator_model(s)
    pm, wn, _, _ = ekf_design(s)
    inputs = ekf_inputs(s, params, tel.roll_rad, pitch_rad, tel.yaw_rad, tel.speeds_radps,
                        tel.yaw_sigma_rad, tel.sun_head, t_s=t_s)
    z = inputs.z[:, [0, 2, 3]]
    r = inputs.r[:, [0, 2, 3]]
    dt = s.sample_interval_s if t_s is None else cadence(t_s)
    pitch = earth_pitch(pitch_rad, dt, s.estimator.wheel_torque_window_s)
    p = bs.pack_batch_params(pm, s.spacecraft.wheels.cant_deg * DEG, wn)
    return NonlinearData(z, r, inputs.u, pitch, p,
                         None if t_s is None else step_intervals(t_s))


def consider_sigma(s: Scenario) -> dict[str, float]:
    """1σ of each consider parameter (SI): the inertia's entries, the wheels' nominal
    speed and their cant, from ``batch.consider``."""
    c = s.batch.consider
    J = np.asarray(c.inertia_sigma_kgm2, dtype=float)
    return {"Ixx": J[0, 0], "Iyy": J[1, 1], "Izz": J[2, 2], "Ixy": J[0, 1], "Ixz": J[0, 2],
            "Iyz": J[1, 2], "speed": c.wheel_speed_sigma_rpm * RPM2RADPS,
            "cant": c.cant_sigma_deg * DEG}


def nonlinear_consider(s: Scenario) -> np.ndarray:
    """The nonlinear model's consider 1σ in ``batch.steps.CONSIDER_NONLINEAR`` order.
    (Its pitch momentum H comes from the tachometers, so the nominal wheel speed is
    not one of them.)"""
    sig = consider_sigma(s)
    return np.array([sig[k] for k in bs.CONSIDER_NONLINEAR])


# The linear model's consider parameters: the paper's model holds I_x and I_z
# (I = √(I_x I_z), Eq. 5), H (the wheels' nominal speed and cant, Eq. 1) and, through
# the tachometers' h and N_w* (Eq. 2), the cant; I_y and the products are not in it.
_LINEAR_KEYS = {"Ixx": ("spacecraft", "inertia_kgm2", 0, 0),
                "Izz": ("spacecraft", "inertia_kgm2", 2, 2),
                "speed": ("spacecraft", "wheels", "speed_rpm"),
                "cant": ("spacecraft", "wheels", "cant_deg")}
_TO_FILE_UNITS = {"speed": 1 / RPM2RADPS, "cant": 1 / DEG}


def _moved(s: Scenario, name: str, delta_si: float) -> Scenario:
    raw = s.model_dump(mode="json")
    path = _LINEAR_KEYS[name]
    step = delta_si * _TO_FILE_UNITS.get(name, 1.0)
    if path[1] == "inertia_kgm2":
        raw["spacecraft"]["inertia_kgm2"][path[2]][path[3]] += step
    else:
        raw[path[0]][path[1]][path[2]] += step
    return validate(raw)


def linear_consider(s: Scenario, tel: Measured, t_s=None, rows=slice(None)
                    ) -> tuple[ConsiderCase, ...]:
    """The linear batch's consider parameters, each with the span's data (telemetry
    ``rows``) rebuilt at ±δ = σ/1000.  The response is far from linear at σ itself:
    an inertia or H error shifts the nutation frequency, and over a span of hours the
    fit's phase error grows to radians (at σ/100 the central difference was still up
    to 70% off the derivative in places; at σ/1000 within 7%), while δI/I ~ 2e-5
    stays far above round-off."""
    sig = consider_sigma(s)
    cut = Measured(*(None if v is None else v[rows] for v in tel))
    t = None if t_s is None else t_s[rows]
    cases = []
    for name in _LINEAR_KEYS:
        if not sig[name] > 0:
            continue
        d = 1e-3 * sig[name]
        cases.append(ConsiderCase(name, sig[name], d, linear_data(_moved(s, name, d), cut, t),
                                  linear_data(_moved(s, name, -d), cut, t)))
    return tuple(cases)
