"""`dynprop run`: truth → telemetry → filter and smoother, and the linear twin.

The linear twin is the paper's model (Eq. 11) propagated exactly (Φ, Γ) from the
same initial deviation, under the same torques, and sensed with the same noise
draws by the same sensor code.  Filtering both with the identical filter
separates what the nonlinearities and the model's approximations cost
(real − linearized) from what the sensors and process noise cost (linearized).

Torques in model coordinates: the true external roll and yaw torques, less the
estimator's modelled N_x*, N_z*, are fitted over the run with the model's own
form (constant + an ω0 sinusoid, Eqs. 9 and 18); the fit is the "true" value of
the torque states N_c, N_p, and the residual drives the twin as an input.
Gravity gradient is not an external torque here: the linear model carries it
(in its approximated form) in F.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from types import SimpleNamespace

import casadi as ca
import numpy as np
from dynprop.estimator import model as em
from dynprop.estimator.kalman import (
    ExtraNoise,
    FilterResult,
    SmootherResult,
    kalman_filter,
    rts_smoother,
)
from dynprop.estimator.preprocess import prepare
from dynprop.estimator.transition import discretize
from dynprop.rollout.chunks import ChunkedRollout
from dynprop.sim.frames import rotate_312
from dynprop.sim.telemetry import make_telemetry

from ..config import build
from ..config.schema import Scenario
from .simulate import Simulation, simulate

DEG = np.pi / 180.0
EXTERNAL = ("solar", "magnetic", "magnetic_control", "external")


def euler_rates(euler_rad: np.ndarray, w_br: np.ndarray) -> np.ndarray:
    """(ψ̇, φ̇, θ̇) from ω_BR (body) for C_BR = R2(θ)R1(φ)R3(ψ):
    ω = (cθ φ̇ − sθ cφ ψ̇, θ̇ + sφ ψ̇, sθ φ̇ + cθ cφ ψ̇)."""
    _, roll, pitch = euler_rad.T
    cth, sth, cph, sph = np.cos(pitch), np.sin(pitch), np.cos(roll), np.sin(roll)
    roll_dot = cth * w_br[:, 0] + sth * w_br[:, 2]
    yaw_dot = (-sth * w_br[:, 0] + cth * w_br[:, 2]) / cph
    pitch_dot = w_br[:, 1] - sph * yaw_dot
    return np.column_stack([yaw_dot, roll_dot, pitch_dot])


def project_torques(t_s, nx, nz, w0):
    """Least-squares fit N_x = N_cx + c0 a + s0 b, N_z = N_cz − s0 a + c0 b (Eqs. 9, 18).
    Returns the torque-state histories (N, 4) [N_px, N_pz, N_cx, N_cz] and residuals."""
    c, s = np.cos(w0 * t_s), np.sin(w0 * t_s)
    one = np.ones_like(c)
    # Unknowns (a, b, N_cx, N_cz).  The normal equations need only a few sums over
    # the run (no 2N×4 matrix): with c² + s² = 1 they are well conditioned once the
    # run covers a fair part of an orbit; shorter runs go to lstsq (minimum norm).
    n, sc, ss = len(c), c.sum(), s.sum()
    G = np.array([[n, 0.0, sc, -ss], [0.0, n, ss, sc], [sc, ss, n, 0.0], [-ss, sc, 0.0, n]])
    # np.sum, not BLAS dot: a threaded BLAS sums in an order that depends on the
    # thread count, and a Monte Carlo case must give the same bits in any process.
    rhs = np.array([np.sum(c * nx - s * nz), np.sum(s * nx + c * nz), nx.sum(), nz.sum()])
    if n and np.linalg.cond(G) < 1e4:
        a, b, ncx, ncz = np.linalg.solve(G, rhs)
    else:
        zero = np.zeros_like(c)
        A = np.vstack([np.column_stack([c, s, one, zero]), np.column_stack([-s, c, zero, one])])
        a, b, ncx, ncz = np.linalg.lstsq(A, np.concatenate([nx, nz]), rcond=None)[0]
    states = np.column_stack([c * a + s * b, -s * a + c * b, ncx * one, ncz * one])
    return states, nx - states[:, 0] - ncx, nz - states[:, 1] - ncz


@lru_cache(maxsize=4)
def _linear_engine(n_x: int = em.N_STATES, n_u: int = em.N_STATES) -> ChunkedRollout:
    """x_{k+1} = Φ x_k + Γ u_k compiled once per shape (Φ, Γ as parameters)."""
    x, u = ca.SX.sym("x", n_x), ca.SX.sym("u", n_u)
    p = ca.SX.sym("p", n_x * n_x + n_x * n_u)
    n2 = n_x * n_x
    phi = ca.reshape(p[:n2], n_x, n_x)
    gam = ca.reshape(p[n2:], n_x, n_u)
    name = "dynprop_linear" if (n_x, n_u) == (em.N_STATES, em.N_STATES) \
        else f"dynprop_linear_{n_x}x{n_u}"
    step = ca.Function(name, [x, u, p], [phi @ x + gam @ u, x])
    return ChunkedRollout(step)


def propagate_lti(Phi, Gamma, x0, u) -> np.ndarray:
    """x_{k+1} = Φ x_k + Γ u_k from x_0 = x0 for each row of u (N, m); returns the
    states at every sample (N, n), x0 first.  Compiled, no Python loop per step."""
    Phi, Gamma = np.asarray(Phi, float), np.asarray(Gamma, float)
    p = np.concatenate([Phi.ravel(order="F"), Gamma.ravel(order="F")])
    _, aux = _linear_engine(*Gamma.shape).run(np.asarray(x0, float),
                                              [np.asarray(u, float)], p)
    return aux


def propagate_lti_final(Phi, Gamma, x0, u) -> tuple[np.ndarray, np.ndarray]:
    """``propagate_lti``'s states at every sample, and the state one step after the
    last (where a following window starts)."""
    Phi, Gamma = np.asarray(Phi, float), np.asarray(Gamma, float)
    p = np.concatenate([Phi.ravel(order="F"), Gamma.ravel(order="F")])
    last, aux = _linear_engine(*Gamma.shape).run_final(np.asarray(x0, float),
                                                       [np.asarray(u, float)], p)
    return aux, last


def propagate_linear(disc, x0, u) -> np.ndarray:
    """The linear model's states at every sample (N, 9), exact for ZOH inputs."""
    return propagate_lti(disc.Phi, disc.Gamma, x0, u)


@dataclass(frozen=True)
class TwoRuns:
    """Everything a run directory is made of.  With ``rows`` the filter histories
    (``real``, ``linear``) hold only those samples; the truth arrays are always full."""

    sim: Simulation
    twin_telemetry: object | None
    params: em.ModelParams
    truth_model: np.ndarray     # nonlinear truth in the filter's model coordinates (N, 9)
    twin_model: np.ndarray | None  # linear twin's states, same coordinates (N, 9)
    real: FilterResult
    linear: FilterResult | None
    smoothed: SmootherResult | None
    yaw_factors: np.ndarray
    rows: np.ndarray | None = None


def initial_prior(s: Scenario, params: em.ModelParams) -> tuple[np.ndarray, np.ndarray]:
    """Zero initial estimate, diagonal P0 from ``estimator.initial_sigma`` (model units)."""
    i, wn = s.estimator.initial_sigma, abs(params.omega_n_radps)
    sig = [i.roll_deg * DEG, i.roll_rate_degps * DEG / wn, i.yaw_deg * DEG,
           i.yaw_rate_degps * DEG / wn, i.h_Nms, i.N_px_Nm, i.N_pz_Nm, i.N_cx_Nm, i.N_cz_Nm]
    return np.zeros(em.N_STATES), np.diag(np.square(sig))


def yaw_correlation_inflation(s: Scenario, sun_head) -> np.ndarray:
    """Per-sample factor on the ground yaw variance for the filter.

    A head's quantisation error is not white, and treating correlated samples as
    independent makes the filter over-confident.  The quantisation share of the
    variance therefore counts once per correlation time: var·(n² + q²/12·N)/(n² +
    q²/12), N samples.  For the DSS, N covers ``estimator.dss_error_correlation_s``
    (600 s by default): its yaw error is set mostly by the out-of-plane Sun angle,
    which moves slowly (measured autocorrelation 0.5 at 8.5 min).  With 30 s, the
    time to cross one 0.125° quantum, yaw e²/σ² was 11 in DSS periods; with 600 s it
    is 1.3, and the yaw RMS drops from 0.024° to 0.014°.  A CASS (white 1° noise)
    uses q/(ω0 Δt) and is barely changed.  Heads are telemetry ``sun_head`` indices.
    """
    w0 = build.orbit(s).rate_radps
    dt = s.sample_interval_s
    heads = [s.sensors.sun.dss, s.sensors.sun.cass1, s.sensors.sun.cass2]
    factors = []
    for h in heads:
        quant = h.quantum_deg**2 / 12
        n_corr = max(1.0, h.quantum_deg * DEG / (w0 * dt))
        if h.kind == "dss":
            n_corr = max(n_corr, s.estimator.dss_error_correlation_s / dt)
        factors.append((h.noise_deg**2 + quant * n_corr) / (h.noise_deg**2 + quant))
    idx = np.asarray(sun_head, dtype=float)
    out = np.ones(len(idx))
    ok = np.isfinite(idx) & (idx >= 0)
    out[ok] = np.asarray(factors)[idx[ok].astype(int)]
    return out


def filter_inputs(s: Scenario, params, roll, yaw, speeds, yaw_sigma=None, sun_head=None,
                  known_Nm=None):
    """Telemetry arrays to the filter's measurements, inputs u and any dropout noise
    (``ExtraNoise`` or None).  ``known_Nm`` (N, 2), roll and yaw torques known per
    sample, joins the modelled N_x*, N_z* (Eq. 9)."""
    e = s.estimator
    if yaw_sigma is not None and sun_head is not None:
        yaw_sigma = np.asarray(yaw_sigma) * np.sqrt(yaw_correlation_inflation(s, sun_head))
    nx, nz = e.model_torques.roll_Nm, e.model_torques.yaw_Nm
    if known_Nm is not None:
        nx, nz = nx + known_Nm[:, 0], nz + known_Nm[:, 1]
    inputs = prepare(params, s.sample_interval_s, roll, yaw, speeds, build.yaw_factors(s),
                     build.estimator_sensor_specs(s), yaw_sigma, nx, nz,
                     e.wheel_torque_window_s)
    extra = None
    if inputs.wheel_noise is not None:
        unit = discretize(params, em.ProcessNoise(q_x=0.0, q_z=0.0, q_w=1.0),
                          s.sample_interval_s).Qd
        # The bridge's measured q_w is the whole wheel-torque uncertainty there; the
        # filter's own q_w already carries part of it.
        extra = ExtraNoise(np.maximum(inputs.wheel_noise - e.process_noise.q_w, 0.0), unit)
    return inputs.measurements, inputs.u, extra


def filter_telemetry(s: Scenario, params, disc, roll, yaw, speeds, yaw_sigma=None,
                     sun_head=None, rows=None) -> tuple[FilterResult, dict]:
    """Preprocess telemetry arrays and run the filter; returns the result (the
    history only at ``rows`` if given) and what the smoother needs besides it
    (``rts_smoother(result, disc, **that)``: the inputs u and any dropout noise)."""
    meas, u, extra = filter_inputs(s, params, roll, yaw, speeds, yaw_sigma, sun_head)
    x0, P0 = initial_prior(s, params)
    result = kalman_filter(meas, disc, x0, P0, u=u, rows=rows, extra=extra)
    return result, {"u": u, "extra": extra}


FALLBACK_YAW_SIGMA_DEG = 1.0  # yaw σ for files without a yaw_sigma_deg column


def telemetry_inputs(s: Scenario, cols: dict[str, np.ndarray]):
    """(roll, yaw, wheel speeds, yaw σ or None, Sun head or None) in SI from the
    columns of a telemetry.csv; the single path used by `run` and `estimate`."""
    n_wheels = len(build.yaw_factors(s))
    speeds = np.column_stack([cols[f"wheel{i + 1}_rpm"] for i in range(n_wheels)]) \
        * (np.pi / 30.0)
    if "yaw_sigma_deg" in cols:
        sigma = cols["yaw_sigma_deg"] * DEG
    else:
        # A file with only the contract columns does not say which head each yaw
        # came from: take the coarse sensors' ~1° (Section 2.1), not the DSS's 0.036°,
        # which would make the filter badly over-confident on CASS yaw.
        sigma = np.full(len(cols["t_s"]), FALLBACK_YAW_SIGMA_DEG * DEG)
    head = cols.get("sun_head")
    return cols["roll_deg"] * DEG, cols["yaw_deg"] * DEG, speeds, sigma, head


@dataclass(frozen=True)
class TruthTorques:
    """The truth's Euler rates, and its external roll/yaw torques less the modelled
    N_x*, N_z*, split into the torque states' fit and the residual (Eqs. 9, 18).
    None of it depends on the spacecraft's ω_n, so one serves every model."""

    rates: np.ndarray        # (ψ̇, φ̇, θ̇), rad/s
    torque_states: np.ndarray
    res_x: np.ndarray
    res_z: np.ndarray


def truth_torques(truth, model_torques, omega0_radps: float) -> TruthTorques:
    ext = sum(truth.torques[k] for k in EXTERNAL)
    mt = model_torques
    states, res_x, res_z = project_torques(truth.t_s, ext[:, 0] - mt.roll_Nm,
                                           ext[:, 2] - mt.yaw_Nm, omega0_radps)
    return TruthTorques(euler_rates(truth.euler_rad, truth.w_br_radps), states, res_x, res_z)


def model_truth(params: em.ModelParams, truth, tt: TruthTorques, rows=slice(None)
                ) -> np.ndarray:
    """The nonlinear truth in the coordinates of the model ``params``: (N, 9), or
    only the samples ``rows``."""
    wn = params.omega_n_radps
    return np.column_stack([truth.roll_rad[rows], tt.rates[rows, 1] / wn, truth.yaw_rad[rows],
                            tt.rates[rows, 0] / wn, truth.h_Nms[rows],
                            tt.torque_states[rows]])


def twin_input(params, model_torques, tt: TruthTorques, h_Nms, dt_s: float,
               h_next: float | None = None) -> np.ndarray:
    """The twin's inputs (Eq. 12a): the modelled torques plus the fit's residual, and
    the true N_w, the mean of ḣ over each step (exact for h).  The last step needs
    the next sample's h (``h_next``, a following window's first); without it its N_w
    is 0 (no sample follows it)."""
    mt = model_torques
    h = h_Nms if h_next is None else np.append(h_Nms, h_next)
    nw = np.diff(h) / dt_s
    if h_next is None:
        nw = np.append(nw, 0.0)
    return em.input_vector(params, mt.roll_Nm + tt.res_x, mt.yaw_Nm + tt.res_z, nw)


def sense_twin(s: Scenario, truth, twin: np.ndarray, suite, rngs):
    """Telemetry of the twin's states ``twin`` (model coordinates), sensed by ``suite``
    with the generators ``rngs`` (the same seeds as the truth's: the same draws)."""
    k = build.yaw_factors(s)
    speeds = truth.wheel_speeds_radps + np.outer(twin[:, em.H_WHEEL] - truth.h_Nms, k / (k @ k))
    twin_truth = SimpleNamespace(
        t_s=truth.t_s, roll_rad=twin[:, em.R], pitch_rad=truth.pitch_rad,
        wheel_speeds_radps=speeds, shadow=truth.shadow, sun_orbit_frame=truth.sun_orbit_frame,
        sun_body=rotate_312(twin[:, em.Y], twin[:, em.R], truth.pitch_rad,
                            truth.sun_orbit_frame))
    return make_telemetry(twin_truth, suite, rngs, s.sensors.sun.min_sun_separation_deg)


def linear_twin(s: Scenario, truth, run: int, model_torques, tt: TruthTorques):
    """The paper's model of the spacecraft of ``s`` (Eq. 11) propagated exactly from the
    truth's initial deviation under the same torques (fit in the states, residual and
    the true N_w as inputs; N_w averaged over each step is exact for h), and sensed
    with the same seeded noise draws.  Returns its states in the coordinates of ``s``'s
    model, its telemetry and the model."""
    params, noise = build.estimator_model(s)
    disc = discretize(params, noise, s.sample_interval_s)
    u_twin = twin_input(params, model_torques, tt, truth.h_Nms, s.sample_interval_s)
    twin = propagate_linear(disc, model_truth(params, truth, tt, [0])[0], u_twin)
    # Fresh generators from the same seed: the twin's noise draws equal the real ones.
    twin_tel = sense_twin(s, truth, twin, build.build_sensors(s), build.streams(s.seed, run))
    return twin, twin_tel, params


def run_scenario(s: Scenario, sim: Simulation | None = None,
                 telemetry_columns: dict[str, np.ndarray] | None = None, run: int = 0,
                 smooth: bool = True, truth_scenario: Scenario | None = None,
                 rows=None, twin: bool = True) -> TwoRuns:
    """Both runs.  ``telemetry_columns`` (telemetry.csv read back) makes the real
    filter see exactly the file's values, so that ``dynprop estimate`` on that file
    reproduces the estimates bit for bit.  ``smooth=False`` skips the smoother
    (``smoothed`` is None) for analyses that need only the filters.

    ``truth_scenario`` (default ``s``) is the spacecraft that flies: a Monte Carlo
    case's dispersed scenario.  The filter is always designed from ``s``, the
    nominal one, as it would be in flight; the linear twin is the paper's model of
    the spacecraft that flies.  ``rows`` keeps only those samples of the filter
    histories (no smoother); ``twin=False`` skips the linear twin."""
    truth_scenario = truth_scenario or s
    if smooth and rows is not None:
        raise ValueError("the smoother needs the full filter history (rows=None)")
    sim = sim or simulate(truth_scenario, run)
    truth, tel, dt = sim.truth, sim.telemetry, s.sample_interval_s
    params, noise = build.estimator_model(s)
    disc = discretize(params, noise, dt)
    mt = s.estimator.model_torques
    tt = truth_torques(truth, mt, params.omega0_radps)
    truth_model = model_truth(params, truth, tt)

    if telemetry_columns is None:
        head = np.where(tel.yaw_head >= 0, tel.yaw_head, np.nan)
        measured = (tel.roll_rad, tel.yaw_rad, tel.wheel_speeds_radps, tel.yaw_sigma_rad, head)
    else:
        measured = telemetry_inputs(s, telemetry_columns)
    real, smoother_args = filter_telemetry(s, params, disc, *measured, rows=rows)
    twin_model = twin_tel = linear = None
    if twin:
        twin_model, twin_tel, twin_params = linear_twin(truth_scenario, truth, run,
                                                            mt, tt)
        if twin_params != params:
            # The twin's rate states are ṙ/ω_n of its own spacecraft; the filter's use
            # the nominal ω_n.
            twin_model = twin_model.copy()
            twin_model[:, [1, 3]] *= twin_params.omega_n_radps / params.omega_n_radps
        twin_head = np.where(twin_tel.yaw_head >= 0, twin_tel.yaw_head, np.nan)
        linear, _ = filter_telemetry(s, params, disc, twin_tel.roll_rad, twin_tel.yaw_rad,
                                     twin_tel.wheel_speeds_radps, twin_tel.yaw_sigma_rad,
                                     twin_head, rows=rows)
    smoothed = rts_smoother(real, disc, **smoother_args) if smooth else None
    return TwoRuns(sim, twin_tel, params, truth_model, twin_model, real, linear, smoothed,
                   build.yaw_factors(s), None if rows is None else np.asarray(rows))
