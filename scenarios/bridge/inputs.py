"""Telemetry to the paper filter's measurements, inputs and prior.

``telemetry_inputs`` is the single path from telemetry.csv's columns to SI arrays
(``records.Measured``), for `run` (which filters the columns exactly as it writes
them) and `estimate` (which reads them back).  ``filter_inputs`` turns those into
the filter's ``Measurements``, its inputs ū (Eq. 12a, with N_w* = ḣ from the
tachometers) and any dropout noise.  A streamed run's window is filtered padded
with its neighbours' samples (``join_padded``), so the wheel-torque derivative
equals the whole run's; every filter pads through that one routine.
"""

from __future__ import annotations

import numpy as np
from dynprop.estimator.kalman.filter import ExtraNoise
from dynprop.estimator.kalman.maneuver import ATTITUDE, Maneuver, maneuver_intensity
from dynprop.estimator.kalman.preprocess import (
    cadence,
    prepare,
    prepare_at_times,
    quantisation_inflation,
)
from dynprop.estimator.linear import model as em
from dynprop.estimator.linear.transition import discretize
from dynprop.sim.telemetry import Telemetry

from ..config import build
from ..config.management import TORQUER_COLUMNS
from ..config.schema import Scenario
from ..records import Measured
from ..units import DEG, RPM2RADPS

FALLBACK_YAW_SIGMA_DEG = 1.0  # yaw σ for files without a yaw_sigma_deg column


def initial_prior(s: Scenario, params: em.ModelParams) -> tuple[np.ndarray, np.ndarray]:
    """Zero initial estimate, diagonal P0 from ``estimator.initial_sigma`` (model units)."""
    i, wn = s.estimator.initial_sigma, abs(params.omega_n_radps)
    sig = [i.roll_deg * DEG, i.roll_rate_degps * DEG / wn, i.yaw_deg * DEG,
           i.yaw_rate_degps * DEG / wn, i.h_Nms, i.N_px_Nm, i.N_pz_Nm, i.N_cx_Nm, i.N_cz_Nm]
    return np.zeros(em.N_STATES), np.diag(np.square(sig))


def yaw_correlation_inflation(s: Scenario, sun_head, dt_s: float | None = None) -> np.ndarray:
    """Per-sample factor on the ground yaw variance for the filter
    (``estimator.preprocess.quantisation_inflation``).

    A head's quantisation error is not white: it counts once per correlation time.
    For the DSS that time is ``estimator.dss_error_correlation_s`` (600 s by
    default): its yaw error is set mostly by the out-of-plane Sun angle, which moves
    slowly (measured autocorrelation 0.5 at 8.5 min).  With 30 s, the time to cross
    one 0.125° quantum, yaw e²/σ² was 11 in DSS periods; with 600 s it is 1.3, and
    the yaw RMS drops from 0.024° to 0.014°.  A CASS (white 1° noise) uses the time
    the Sun takes to cross a quantum, q/(ω0 Δt) samples, and is barely changed.
    Heads are telemetry ``sun_head`` indices; ``dt_s`` the telemetry's cadence (the
    scenario's sample interval if None)."""
    w0 = build.orbit(s).rate_radps
    dt = s.sample_interval_s if dt_s is None else dt_s
    heads = [s.sensors.sun.dss, s.sensors.sun.cass1, s.sensors.sun.cass2]
    factors = []
    for h in heads:
        n_corr = max(1.0, h.quantum_deg * DEG / (w0 * dt))
        if h.kind == "dss":
            n_corr = max(n_corr, s.estimator.dss_error_correlation_s / dt)
        factors.append(quantisation_inflation(h.noise_deg, h.quantum_deg, n_corr))
    idx = np.asarray(sun_head, dtype=float)
    out = np.ones(len(idx))
    ok = np.isfinite(idx) & (idx >= 0)
    out[ok] = np.asarray(factors)[idx[ok].astype(int)]
    return out


def prepared_inputs(s: Scenario, params, roll, yaw, speeds, yaw_sigma=None, sun_head=None,
                    maneuver=None, known_Nm=None, t_s=None,
                    record: tuple[float, float] | None = None):
    """Telemetry arrays to the filter's measurements and inputs
    (``estimator.preprocess.FilterInputs``, with a dropout's measured wheel noise).
    ``maneuver`` (the thruster-firing flag) changes none of them: ``filter_inputs``
    answers it.
    ``known_Nm`` (N, 2), roll and yaw torques known per sample, joins the modelled
    N_x*, N_z* (Eq. 9).  ``t_s``: the samples' own times, for telemetry off the
    scenario's grid (``estimator.linear.steps``); None on the grid.  ``record``: the
    cadence and first time of the file ``t_s`` is a window of (its N_w* resampled onto
    the file's points, ``preprocess.wheel_torque_at``); None: ``t_s``'s own."""
    e = s.estimator
    cadence_s, origin_s = (None, None) if record is None else record
    if yaw_sigma is not None and sun_head is not None:
        dt = None if t_s is None else cadence(t_s) if cadence_s is None else cadence_s
        yaw_sigma = np.asarray(yaw_sigma) * np.sqrt(yaw_correlation_inflation(s, sun_head, dt))
    nx, nz = e.model_torques.roll_Nm, e.model_torques.yaw_Nm
    if known_Nm is not None:
        nx, nz = nx + known_Nm[:, 0], nz + known_Nm[:, 1]
    if t_s is not None:
        return prepare_at_times(params, t_s, roll, yaw, speeds, build.yaw_factors(s),
                                build.estimator_sensor_specs(s), yaw_sigma, nx, nz,
                                e.wheel_torque_window_s, cadence_s, origin_s)
    return prepare(params, s.sample_interval_s, roll, yaw, speeds, build.yaw_factors(s),
                   build.estimator_sensor_specs(s), yaw_sigma, nx, nz, e.wheel_torque_window_s)


def filter_inputs(s: Scenario, params, roll, yaw, speeds, yaw_sigma=None, sun_head=None,
                  maneuver=None, known_Nm=None, t_s=None, record=None):
    """Telemetry arrays to the filter's measurements, inputs u and any dropout noise
    (``ExtraNoise`` or None); ``prepared_inputs`` says what each is.  With ``t_s`` the
    dropout noise's unit matrix is each step's own (``estimator.steps.StepTable``), and
    ``ExtraNoise.Qd_unit`` is not used.  A ``maneuver`` flag (N,) rides in the
    ``ExtraNoise`` as the scenario's response to it (``maneuver_response``)."""
    e = s.estimator
    inputs = prepared_inputs(s, params, roll, yaw, speeds, yaw_sigma, sun_head, None,
                             known_Nm, t_s, record)
    extra = None
    if inputs.wheel_noise is not None:
        unit = np.zeros((em.N_STATES, em.N_STATES)) if t_s is not None else discretize(
            params, em.ProcessNoise(q_x=0.0, q_z=0.0, q_w=1.0), s.sample_interval_s).Qd
        # The bridge's measured q_w is the whole wheel-torque uncertainty there; the
        # filter's own q_w already carries part of it.
        extra = ExtraNoise(np.maximum(inputs.wheel_noise - e.process_noise.q_w, 0.0), unit)
    response = maneuver_response(s, params, maneuver)
    if response is not None:
        extra = ExtraNoise(np.zeros(len(response)), np.zeros((em.N_STATES, em.N_STATES)),
                           response) if extra is None else \
            ExtraNoise(extra.scale, extra.Qd_unit, response)
    return inputs.measurements, inputs.u, extra


def maneuver_response(s: Scenario, params, flag, prior=None,
                      states: tuple[int, ...] = ATTITUDE) -> Maneuver | None:
    """The scenario's response (``estimator.maneuver``) to a telemetry's thruster-firing
    ``flag`` (``estimator.kalman.maneuver``): None without a flag or with ``ignore``.
    ``prior``, ``states``: the reset's block and the states it covers (the paper
    filter's attitude and ``estimator.initial_sigma`` unless given)."""
    if flag is None:
        return None
    if prior is None:
        prior = initial_prior(s, params)[1][np.ix_(states, states)]
    r = s.estimator.maneuver
    return Maneuver.of(flag, r.response, maneuver_intensity(r.torque_Nm, r.max_duration_s),
                       params, prior, states)


def telemetry_inputs(s: Scenario, cols: dict[str, np.ndarray]) -> Measured:
    """The telemetry in SI (``records.Measured``) from the columns of a telemetry.csv;
    the single path used by `run` and `estimate`."""
    n_wheels = len(build.yaw_factors(s))
    speeds = np.column_stack([cols[f"wheel{i + 1}_rpm"] for i in range(n_wheels)]) \
        * RPM2RADPS
    if "yaw_sigma_deg" in cols:
        sigma = cols["yaw_sigma_deg"] * DEG
    else:
        # A file with only the contract columns does not say which head each yaw
        # came from: take the coarse sensors' ~1° (Section 2.1), not the DSS's 0.036°,
        # which would make the filter badly over-confident on CASS yaw.
        sigma = np.full(len(cols["t_s"]), FALLBACK_YAW_SIGMA_DEG * DEG)
    head = cols.get("sun_head")
    dipoles = np.column_stack([cols[k] for k in TORQUER_COLUMNS]) \
        if all(k in cols for k in TORQUER_COLUMNS) else None
    return Measured(cols["roll_deg"] * DEG, cols["yaw_deg"] * DEG, speeds, sigma, head,
                    cols.get("maneuver"), known_torques(s, dipoles))


def measured(tel: Telemetry, known_Nm: np.ndarray | None = None) -> Measured:
    """Simulated telemetry as the filter reads it (the Sun head NaN where none), with
    the torques the ground knows (``known_torques``), if any."""
    head = np.where(tel.yaw_head >= 0, tel.yaw_head, np.nan)
    return Measured(tel.roll_rad, tel.yaw_rad, tel.wheel_speeds_radps, tel.yaw_sigma_rad, head,
                    tel.maneuver, known_Nm)


def known_torques(s: Scenario, dipole_Am2: np.ndarray | None) -> np.ndarray | None:
    """The roll and yaw torques the ground knows per sample (N, 2), for the filter's
    N_x*, N_z* (Eq. 9): with 'magnetic_control' in ``estimator.known_torques``, the
    commanded dipoles m × the field model B_R at Earth pointing (body = orbit frame;
    a degree of attitude error changes the torque by under 2%).  None when none is
    known."""
    if "magnetic_control" not in s.estimator.known_torques:
        return None
    if dipole_Am2 is None:
        raise ValueError("estimator.known_torques: magnetic_control needs the torquers' "
                         f"dipoles ({', '.join(TORQUER_COLUMNS)}), and the telemetry has none")
    torque = np.cross(np.asarray(dipole_Am2, dtype=float), build.field_orbit_frame(s))
    return torque[:, [0, 2]]


def join_padded(prev_tail: tuple | None, cur: tuple, nxt: tuple | None, pad: int
                ) -> tuple[tuple, slice]:
    """A window's per-sample arrays ``cur`` (a tuple; None for an absent one) joined
    with ``prev_tail`` (the previous window's last ``pad`` samples; None at the run's
    start) and the first ``pad`` samples of ``nxt`` (None at its end), and the slice
    of the joined arrays that is the window itself."""
    pieces = ([prev_tail] if prev_tail is not None else []) + [cur] + \
        ([tuple(None if v is None else v[:pad] for v in nxt)] if nxt is not None else [])
    joined = tuple(None if cur[i] is None else np.concatenate([p[i] for p in pieces])
                   for i in range(len(cur)))
    # A file's window brings padding of its own length (to the nearest wheel reading).
    lo = 0 if prev_tail is None else len(prev_tail[0])
    return joined, slice(lo, lo + len(cur[0]))


def padded_filter_inputs(s: Scenario, params, prev_tail: Measured | None, cur: Measured,
                         nxt: Measured | None, pad: int, t_s=None, record=None):
    """``filter_inputs`` of a window from its telemetry padded with ``pad`` samples of
    each neighbour, so the wheel-torque derivative equals the whole run's (``t_s``:
    the padded samples' times, off the grid, and ``record`` their file's cadence and
    first time, ``prepared_inputs``')."""
    joined, sl = join_padded(prev_tail, cur, nxt, pad)
    meas, u, extra = filter_inputs(s, params, *Measured(*joined), t_s=t_s,
                                   record=record)
    meas = type(meas)(*(v[sl] if np.ndim(v) else v for v in
                        (meas.roll_rad, meas.yaw_rad, meas.h_Nms, meas.var_roll, meas.var_yaw,
                         meas.var_h)))
    if extra is not None:
        extra = extra.cut(sl)
    return meas, u[sl], extra
