"""Batch least squares (``estimator.batch``, ``batch.nonlinear``, ``batch.steps``) against
independent references.

The linear batch against the RTS smoother (with no process noise they minimise the
same cost, so they are the same estimate); the nonlinear batch on data of its own
model (round-off) and on the simulator's noise-free truth (the model mismatch); on
the paper's scenarios (a day of noisy telemetry, and a 5° yaw error where the
linear model is biased); the compiled pass's Jacobians and consider columns
against central differences of its rollout; the consider covariance against a
Monte Carlo over the consider parameters; and the errors a user can meet.

Estimates are compared state by state in units of σ_i + |x_i| (``est_dev``) or of
σ_i, covariances element by element in units of √(P_ii P_jj) (``cov_dev``): the
states mix rad, N m s and N m.
"""

from __future__ import annotations

import dataclasses
from functools import lru_cache

import casadi as ca
import numpy as np
import pytest

from estimator.batch import steps as bs
from estimator.batch.linear import (
    BatchError,
    ConsiderCase,
    LinearData,
    Prior,
    linear_batch,
    solve_normal,
)
from estimator.batch.nonlinear import NonlinearData, Options, nonlinear_batch, run_pass
from estimator.ekf import model as m
from estimator.kalman.consistency import chi2_bounds
from estimator.kalman.filter import Measurements, kalman_filter, rts_smoother
from estimator.linear.model import (
    N_STATES,
    NCZ,
    STATE_NAMES,
    ProcessNoise,
    dynamics_matrix,
    input_vector,
)
from estimator.linear.propagate import propagate_lti, zoh
from estimator.linear.transition import discretize
from rollout.chunks import ChunkedRollout
from scenarios.bridge import batch as bb
from scenarios.bridge.coordinates import model_truth, truth_torques
from scenarios.bridge.inputs import initial_prior, measured
from scenarios.config import build
from scenarios.config.loader import load_scenario
from scenarios.run.simulate import simulate

from .cov_helpers import cov_dev
from .test_kalman import DT, P0, PARAMS, R_H, R_ROLL, R_YAW, est_dev

DEG = np.pi / 180
NO_NOISE = ProcessNoise(0.0, 0.0, 0.0)
R3 = np.array([R_ROLL, R_YAW, R_H])

# --- the nonlinear model's own data ------------------------------------------------
# GOES-Next numbers typed independently (as test_ekf.py), with the products of inertia.
W0 = PARAMS.omega0_radps
H_NOM = PARAMS.H_Nms
J_NOM = np.array([[3364.4, 12.0, -8.0], [12.0, 954.9, 5.0], [-8.0, 5.0, 3461.4]])
CANT = 1.656 * DEG
WN = H_NOM / np.sqrt(J_NOM[0, 0] * J_NOM[2, 2])
# Entries of J in ``batch.steps.CONSIDER_NONLINEAR`` order.
J_ENTRIES = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))
# A prior's 1σ (the scenarios' estimator.initial_sigma, rates in units of ω_n) and the
# consider parameters' (batch.consider's defaults), as scales for the checks below.
SIGMA_X = np.array([0.05 * DEG, 0.001 * DEG / abs(WN), 0.5 * DEG, 0.001 * DEG / abs(WN), 0.05,
                    5e-6, 5e-6, 5e-6, 5e-6])
SIGMA_C = np.array([67.0, 19.0, 69.0, 10.0, 10.0, 10.0, 0.1 * DEG])


def batch_params(J=J_NOM) -> np.ndarray:
    pm = m.pack_params(J, W0, DT, dict.fromkeys(m.NOISE_NAMES, 0.0))
    return bs.pack_batch_params(pm, CANT, WN)


@lru_cache(maxsize=1)
def _truth_engine() -> ChunkedRollout:
    """The batch's model (``model_step``, ``predicted``) stepped by a rollout of its own:
    (X, u, pitch at the step's end, p) -> (X_next, [ẑ (3), x (9, paper coordinates)])."""
    X, u = ca.SX.sym("X", m.NX), ca.SX.sym("u", m.NU)
    pitch, p = ca.SX.sym("pitch", 2), ca.SX.sym("p", bs.N_PB + 1)
    zero = ca.SX.zeros(bs.N_C)
    pb = p[:bs.N_PB]
    aux = ca.vertcat(bs.predicted(X, pb, zero), m.paper_coordinates(X, pb[:m.N_PARAMS], p[-1]))
    step = ca.Function("test_batch_truth", [X, u, pitch, p],
                       [bs.model_step(X, u, pitch, pb, zero), aux])
    return ChunkedRollout(step, 4096)


def own_rollout(x0, u, pitch, p) -> tuple[np.ndarray, np.ndarray]:
    """Noise-free roll, yaw, h and the paper-coordinate state at every sample, from the
    paper-coordinate x0 at the first: step k ends at sample k+1's pitch."""
    X0, _ = bs.initial_map()(x0, pitch[0], p[-1])
    pitch_next = np.vstack([pitch[1:], pitch[-1:]])
    _, aux = _truth_engine().run(np.asarray(X0).ravel(), [u, pitch_next], p)
    return aux[:, :3].copy(), aux[:, 3:].copy()


def smooth_inputs(n: int) -> tuple[np.ndarray, np.ndarray]:
    """The EKF's inputs (H, Ḣ, N_w*, N_x*, N_z*) with torques that start from zero
    smoothly (no nutation kicked off at t = 0), and the Earth sensor's pitch and rate."""
    t = np.arange(n) * DT
    u = np.zeros((n, m.NU))
    u[:, 0] = H_NOM
    u[:, 2] = 3e-6 * np.sin(2 * W0 * t)
    u[:, 3] = 2e-6 * np.sin(W0 * t / 2) ** 2
    u[:, 4] = -1e-6 * (1 - np.cos(W0 * t))
    pitch = np.column_stack([0.02 * DEG * np.sin(2 * np.pi * t / 3000),
                             0.02 * DEG * 2 * np.pi / 3000 * np.cos(2 * np.pi * t / 3000)])
    return u, pitch


def with_consider(u, c) -> tuple[np.ndarray, np.ndarray, float]:
    """The true model for consider values c (``CONSIDER_NONLINEAR``), exactly: J moved
    (its inverse recomputed), and a cant of CANT + c_6, which scales the tachometers'
    H, Ḣ by cos(cant)/cos(CANT) and N_w* by sin(cant)/sin(CANT).  Returns the batch
    parameters, the true inputs, and the h the telemetry reports (true h ×
    sin(CANT)/sin(cant), its nominal processing) as a factor."""
    J = J_NOM.copy()
    for v, (a, b) in zip(c[:6], J_ENTRIES, strict=True):
        J[a, b] += v
        if a != b:
            J[b, a] += v
    cant = CANT + c[6]
    u = u.copy()
    u[:, :2] *= np.cos(cant) / np.cos(CANT)
    u[:, 2] *= np.sin(cant) / np.sin(CANT)
    return batch_params(J), u, np.sin(CANT) / np.sin(cant)


# --- Monte Carlo helpers -------------------------------------------------------------

def consider_chi2(E: np.ndarray, D: np.ndarray, rel: float = 1e-3) -> tuple[float, int, float]:
    """Σ_i e_iᵀ D⁺ e_i over the draws E (M, 9), D⁺ the pseudo-inverse on D's
    significant directions (eigenvalues of the Jacobi-scaled D above ``rel`` of the
    largest; the others are the consider parameters' near-collinear combinations, at
    round-off), its degrees of freedom, and the fraction of Σ‖e‖² (scaled) outside
    those directions (e = −S c lies in S's column space)."""
    s = np.sqrt(np.clip(np.diag(D), 0.0, None))
    s = np.where(s > 0, s, 1.0)
    w, v = np.linalg.eigh(D / np.outer(s, s))
    keep = w > rel * w.max()
    Es = E / s
    proj = Es @ v[:, keep]
    outside = float(np.sum((Es - proj @ v[:, keep].T) ** 2) / np.sum(Es**2))
    return float(np.sum(proj**2 / w[keep])), int(proj.size), outside


# === 1. the linear batch is the RTS smoother without process noise ===================

def test_linear_batch_equals_the_rts_smoother_without_process_noise(rng):
    """12 h of the paper's model (Φ, Γ from expm, not the closed forms), noisy roll, yaw
    (for the first 8 h) and h with gaps, modelled inputs: with Q = 0 the RTS smoother's
    estimate at sample 0 is the minimiser of the batch's J (the same a priori, the same
    weights), and the filter's last state is the batch solution propagated to the end.
    So state, covariance, the whole history and the end agree to rounding."""
    n = int(12 * 3600 / DT)
    t = np.arange(n) * DT
    u = input_vector(PARAMS, 2e-6 * np.sin(W0 * t), -1e-6, 3e-6 * np.cos(1e-4 * t))
    F = dynamics_matrix(PARAMS)
    Phi, Gam = zoh(F, np.eye(N_STATES), DT)
    x_true = rng.multivariate_normal(np.zeros(N_STATES), P0)
    xs = propagate_lti(Phi, Gam, x_true, u)
    z = xs[:, [0, 2, 4]] + np.sqrt(R3) * rng.standard_normal((n, 3))
    z[t >= 8 * 3600, 1] = np.nan
    z[::13, 0] = np.nan
    z[::17, 2] = np.nan
    meas = Measurements(z[:, 0], z[:, 1], z[:, 2], R_ROLL, R_YAW, R_H)
    disc = discretize(PARAMS, NO_NOISE, DT)
    x_bar = np.zeros(N_STATES)
    f = kalman_filter(meas, disc, x_bar, P0, u)
    sm = rts_smoother(f, disc, u)
    rows = np.array([0, n // 3, n - 1])
    sol = linear_batch(LinearData(meas, u, disc), Prior(x_bar, P0), rows)
    assert sol.fixed == () and sol.converged
    # Two algorithms, one answer: 2e5 sequential Joseph updates with Q = 0 (each P
    # shrinking further below P0: rounding relative to a P 1e4 times smaller than
    # P0's) and the smoother's backward gains, against one Cholesky solve of the
    # Jacobi-scaled information (condition number 1.5e3).  Measured 1.8e-11 of σ + |x|
    # in the state (3e-9 along the history, in units of the epoch's σ), 3.0e-8 in the
    # epoch covariance, 2e-11 at the end; the same in the VM.  1e-6 for all: a
    # margin of 30 on the covariance (the scenario twin's 24 h measure 4e-8).
    assert est_dev(sol.x0, sm.x[0], sm.P[0]).max() < 1e-6
    assert cov_dev(sol.P0, sm.P[0]).max() < 1e-6
    assert est_dev(sol.x, sm.x, sm.P[0]).max() < 1e-6
    for k, r in enumerate(rows):
        assert cov_dev(sol.P_rows[k], sm.P[r]).max() < 1e-6
    assert est_dev(sol.x[-1], f.x[-1], f.P[-1]).max() < 1e-6
    assert cov_dev(sol.P_rows[-1], f.P[-1]).max() < 1e-6
    # J at the solution from its definition.  The batch forms it as c − 2bᵀx + xᵀΛx
    # about 0, c summed sample by sample over 1.6e5 samples and ~1e3 times J here: a
    # sequential sum's rounding is at worst N·ε·c ≈ 3e-8 J, typically √N·ε·c ≈ 7e-11 J;
    # measured 8e-11, 1e-7 allowed.
    e = np.where(np.isfinite(z), z - sol.x[:, [0, 2, 4]], 0.0)
    dx = sol.x0 - x_bar
    J = np.sum(e**2 / R3) + dx @ np.linalg.solve(P0, dx)
    assert sol.cost == pytest.approx(J, rel=1e-7)
    # The noise is R's: e²/r averages 1 (1e5 samples each, 1σ of the RMS 0.2%;
    # measured 1.0016 to 1.0030).
    np.testing.assert_allclose(sol.residual_normalized, 1.0, atol=0.02)
    np.testing.assert_array_equal(sol.n_measurements, np.isfinite(z).sum(axis=0))


# === 2. the nonlinear batch recovers a noise-free truth ===============================

X_OWN = np.array([0.3 * DEG, 0.002, -1.0 * DEG, -0.001, 0.05, 2e-6, -1e-6, 1.5e-6, -1e-6])


def test_nonlinear_batch_recovers_its_own_models_state_to_round_off():
    """2 h of noise-free roll, yaw (the first 1.5 h) and h from the batch's own model
    (``model_step`` and ``predicted`` rolled out here, from ``initial_map``), no a
    priori, the start hundreds of σ off (0.5° roll, 2° yaw, every state): Gauss–Newton
    lands on the state that made the data, and the history it propagates is the data's."""
    n = int(2 * 3600 / DT)
    u, pitch = smooth_inputs(n)
    p = batch_params()
    z, x_hist = own_rollout(X_OWN, u, pitch, p)
    z[int(1.5 * 3600 / DT):, 1] = np.nan
    data = NonlinearData(z, np.tile(R3, (n, 1)), u, pitch, p)
    start = X_OWN + np.array([0.5 * DEG, -0.002, 2.0 * DEG, 0.002, -0.03, -2e-6, 1e-6, -1e-6,
                              1e-6])
    sol = nonlinear_batch(data, None, start, rows=[0, n - 1], options=Options(20, 1e-9))
    assert sol.converged, sol.message
    sigma = np.sqrt(np.diag(sol.P0))
    err = np.abs(sol.x0 - X_OWN) / sigma
    # The floor: predictions of |ẑ| ≤ 0.02 rad carry ε|ẑ| ≈ 4e-18 rad of rounding against
    # measurement σ of 1.8e-4 rad, and the stop at a Gauss–Newton step of 1e-9 σ.
    # Measured 7e-12 σ at the epoch, 1.4e-11 σ along the history, the same in the
    # VM; 1e-8 allowed.  J falls from 8e8 to 3e-22.
    assert err.max() < 1e-8, err
    end_sigma = np.sqrt(np.diag(sol.P_rows[-1]))
    assert (np.abs(sol.x - x_hist) / end_sigma).max() < 1e-8
    assert sol.cost < 1e-12


@pytest.fixture(scope="module")
def torque_free_truth():
    """The bundled torque_free scenario, noise-free and with quanta of 1e-9 (quantum_deg
    must be > 0), started 0.2° in roll and 1° in yaw with a rate offset.  Its gravity
    gradient is turned back on: the batch's model always has it (the EKF's process
    model), and without it in the truth the one mismatch would be the model's own
    gravity gradient (3ω0²(I_z − I_y)φ ≈ 1e-7 N m at 0.2°), which biases yaw by 8σ."""
    quanta = [f"sensors.{k}.quantum_deg=1e-9" for k in ("earth", "sun.dss", "sun.cass1",
                                                           "sun.cass2")]
    s = load_scenario("torque_free", [
        "duration_s=43200", "sensors.noise.enabled=false", *quanta,
        "sensors.tachometer.quantum_rpm=1e-9", "environment.gravity_gradient.enabled=true",
        "initial_state.roll_deg=0.2", "initial_state.yaw_deg=1.0",
        "initial_state.rate_wrt_orbit_degps=[0.0005,0,-0.0003]"])
    return s, simulate(s)


@pytest.mark.slow_in_vm
def test_nonlinear_batch_recovers_the_simulators_noise_free_truth(torque_free_truth):
    """12 h of the simulator's noise-free telemetry (the truth integrated with its own
    RK4 on the wheel speeds, sensed without noise), no a priori, started from the
    linear batch: the epoch state is the truth's to 2.4e-4 σ.

    What is left is what the batch is fed, not the integrator: halving or doubling
    Δt leaves it (1.7e-4 σ at 0.256 s, 3.5e-4 σ at 1.024 s).  The pitch it is
    slaved to, the Earth sensor's smoothed (its rate 1% off the truth's 1.8e-7
    rad/s), sets the yaw and torque states' 1e-4 σ; the tachometers' h and the
    N_w* differenced from it set h's 1.2e-11 N m s (2.4e-4 σ) and the yaw rate's
    2e-4 σ.  With the truth's pitch, h and ḣ in their place the error is 3e-7 σ.
    Measured 2.4e-4 σ at the epoch, 2.0e-4 σ at the end; 2e-3 σ allowed, a margin
    of 8.  The residuals are ≤ 1.2e-6 of the sensors' σ."""
    s, sim = torque_free_truth
    params, _ = build.estimator_model(s)
    tt = truth_torques(sim.truth, s.estimator.model_torques, params.omega0_radps)
    truth = model_truth(params, sim.truth, tt)
    tel = measured(sim.telemetry)
    x_bar, P_bar = initial_prior(s, params)
    lin = linear_batch(bb.linear_data(s, tel), Prior(x_bar, P_bar))
    data = bb.nonlinear_data(s, tel, sim.telemetry.pitch_rad)
    assert np.isnan(data.z[:, 1]).any()      # the Sun gap is in the span
    n = len(truth)
    sol = nonlinear_batch(data, None, lin.x0, rows=[0, n - 1], options=Options(20, 1e-6))
    assert sol.converged, sol.message
    err = np.abs(sol.x0 - truth[0]) / np.sqrt(np.diag(sol.P0))
    err_end = np.abs(sol.x[-1] - truth[-1]) / np.sqrt(np.diag(sol.P_rows[-1]))
    assert err.max() < 2e-3, err
    assert err_end.max() < 2e-3, err_end
    assert np.all(sol.residual_normalized < 1e-4), sol.residual_normalized
    # The linear model at 1° is another matter (600 σ in roll rate): the check has teeth.
    assert (np.abs(lin.x0 - truth[0]) / np.sqrt(np.diag(lin.P0))).max() > 100


# === 3, 4. the paper's scenarios =====================================================

def _scenario_batches(name: str, overrides: list[str]):
    """A day of the scenario's telemetry (noise on) through the linear batch and the
    nonlinear one (started from the linear solution, consider σ of batch.consider),
    both with the filter's prior; rows: the epoch, the sample before yaw returns
    after the night's Sun gap (the gap end), the last sample."""
    s = load_scenario(name, ["duration_s=86400", *overrides])
    sim = simulate(s)
    params, _ = build.estimator_model(s)
    tt = truth_torques(sim.truth, s.estimator.model_torques, params.omega0_radps)
    truth = model_truth(params, sim.truth, tt)
    tel = measured(sim.telemetry)
    idx = np.flatnonzero(np.isfinite(tel.yaw_rad))
    longest = int(np.argmax(np.diff(idx)))
    assert np.diff(idx)[longest] * s.sample_interval_s > 4 * 3600   # the night's gap
    rows = np.array([0, idx[longest + 1] - 1, len(truth) - 1])
    prior = Prior(*initial_prior(s, params))
    lin = linear_batch(bb.linear_data(s, tel), prior, rows)
    nl = nonlinear_batch(bb.nonlinear_data(s, tel, sim.telemetry.pitch_rad), prior, lin.x0,
                         rows, bb.nonlinear_consider(s))
    return truth[rows], lin, nl


def _roll_yaw(sol, truth_rows):
    """Roll and yaw errors (rad) at the rows, their σ and consider σ, (rows, 2) each."""
    i = [0, 2]
    e = sol.x[sol.rows][:, i] - truth_rows[:, i]
    sig = np.sqrt(np.einsum("kii->ki", sol.P_rows))[:, i]
    sig_c = (np.sqrt(np.einsum("kii->ki", sol.P_consider_rows))[:, i]
             if sol.P_consider_rows is not None else np.full_like(sig, np.nan))
    return e, sig, sig_c


@pytest.mark.slow_in_vm
def test_nonlinear_batch_on_a_day_of_the_equinox():
    """goes_next_equinox, 24 h: Gauss–Newton from the linear solution converges in a
    handful of passes (measured 2), and roll and yaw at the epoch, at the end of the
    night's 7.9 h yaw gap and at the day's end are within 3 consider-σ of the truth
    (measured |e|/σ_c ≤ 1.4; the gap end's yaw 0.0005° against σ_c = 0.0044°, 0.11)."""
    truth_rows, _, nl = _scenario_batches("goes_next_equinox", [])
    assert nl.converged and nl.iterations <= 5, (nl.iterations, nl.message)
    e, _, sig_c = _roll_yaw(nl, truth_rows)
    assert abs(e[1, 1]) < 3 * sig_c[1, 1], (e[1, 1] / DEG, sig_c[1, 1] / DEG)
    assert np.all(np.abs(e) < 3 * sig_c), e / sig_c


@pytest.mark.slow_in_vm
def test_at_a_5_degree_yaw_error_the_nonlinear_batch_is_unbiased_and_the_linear_is_not():
    """large_offset (3° roll, 2° pitch, rate offsets) at 5° of yaw, the prior's yaw σ
    10°: the nonlinear batch converges (4 passes) and its epoch roll and yaw are within
    3 consider-σ (measured 0.004 and 0.12 σ_c); the paper's linear model, fitted to the
    same day, puts the epoch roll 0.011° off, 100 of its σ and 30 times the nonlinear
    batch's error (both 0.0012°, 11 σ, on the equinox day without the offset: the
    models' common mismatch)."""
    truth_rows, lin, nl = _scenario_batches("large_offset", [
        "initial_state.yaw_deg=5.0", "estimator.initial_sigma.yaw_deg=10"])
    assert nl.converged, nl.message
    e_nl, _, sig_c = _roll_yaw(nl, truth_rows)
    e_lin, sig_lin, _ = _roll_yaw(lin, truth_rows)
    both = (f"epoch roll error: linear {e_lin[0, 0] / DEG:.5f}° ({e_lin[0, 0] / sig_lin[0, 0]:.0f}"
            f" σ), nonlinear {e_nl[0, 0] / DEG:.5f}° (σ_c {sig_c[0, 0] / DEG:.4f}°)")
    assert np.all(np.abs(e_nl[0]) < 3 * sig_c[0]), both
    assert abs(e_lin[0, 0]) > 3 * sig_lin[0, 0], both
    assert abs(e_lin[0, 0]) > 10 * abs(e_nl[0, 0]), both


# === 5. the compiled pass's derivatives against finite differences ===================

def test_pass_sensitivities_and_consider_columns_against_central_differences(rng):
    """10 min at 2° roll and 5° yaw (the nonlinear terms matter), noisy data, the pass
    evaluated 3 prior-σ off: its Λ (16 × 16 with the seven consider parameters), b and
    ∂x/∂(x_0, c) at three samples against central differences of the rollout's
    paper-coordinate history, with the consider parameters applied exactly (J and its
    inverse, the cant on H, Ḣ, N_w* and on the h reported), not to first order as the
    pass does.

    Steps: 0.01 prior-σ for x_0 (truncation ~(h/1 rad)²/6 ≈ 1e-14 for the angles,
    rounding ε|x|/h ≈ 1e-11 relative); 0.15 kg m² for every entry of J: the nutation
    phase (ω_n t ≈ 22 rad over the span) bends the response to I_xx and I_zz on a
    scale of 2I/(ω_n t) ≈ 300 kg m², so truncation is ~(0.15/300)²/6 ≈ 4e-8 (at
    6.7 kg m² it was 9e-5, as (6.7/300)²/6 says), while a weakly seen entry (I_yy,
    the products) needs the step to stay above rounding (at 0.019 kg m² I_yy's
    column was 3e-7 off); 1e-3 σ for the cant.  Measured, relative
    to each matrix's scale: ≤ 3e-10 for the x_0 columns of ∂x/∂(x_0, c), 5e-8 for
    I_xx and I_zz, ≤ 4e-10 for the other consider columns; Λ 4e-8, b 6e-9; the same
    in the VM.  1e-6 allowed, a margin of 20 over the truncation."""
    n = int(600 / DT)
    u, pitch = smooth_inputs(n)
    p = batch_params()
    x_true = np.array([2.0 * DEG, 0.003, 5.0 * DEG, -0.002, 0.4, 2e-6, -1e-6, 1.5e-6, -1e-6])
    z, _ = own_rollout(x_true, u, pitch, p)
    z += np.sqrt(R3) * rng.standard_normal((n, 3))
    z[n // 2:, 1] = np.nan
    data = NonlinearData(z, np.tile(R3, (n, 1)), u, pitch, p)
    x_eval = x_true + 3 * SIGMA_X * rng.standard_normal(N_STATES)
    rows = np.array([0, n // 2, n - 1])
    k = N_STATES + bs.N_C
    pas = run_pass(data, x_eval, bs.N_C, with_paper=True, rows=rows)
    assert pas.Lam.shape == (k, k) and pas.T.shape == (3, N_STATES, k)

    def history(dx, dc):
        """The paper-coordinate history and ẑ with x_0 + dx and consider values dc."""
        pb, uc, h_scale = with_consider(u, dc)
        x = run_pass(dataclasses.replace(data, params=pb, u=uc), x_eval + dx,
                     with_paper=True, rows=rows).x
        return x, np.column_stack([x[:, 0], x[:, 2], x[:, 4] * h_scale])

    steps = np.r_[0.01 * SIGMA_X, np.full(6, 0.15), 1e-3 * SIGMA_C[6]]
    dX = np.empty((n, N_STATES, k))
    dZ = np.empty((n, 3, k))
    for j in range(k):
        e = np.zeros(k)
        e[j] = steps[j]
        xp, zp = history(e[:N_STATES], e[N_STATES:])
        xm, zm = history(-e[:N_STATES], -e[N_STATES:])
        dX[:, :, j] = (xp - xm) / (2 * steps[j])
        dZ[:, :, j] = (zp - zm) / (2 * steps[j])
    x0h, zh = history(np.zeros(N_STATES), np.zeros(bs.N_C))
    # The same rollout by the pass without consider columns (other compiled code:
    # equal here to the last bit, measured; rounding allowed) and the same residuals
    # (measured 1.4e-17 rad apart, of residuals ~2e-4 rad).
    np.testing.assert_allclose(x0h, pas.x, rtol=1e-12, atol=0)
    w = np.where(np.isfinite(z), 1 / R3, 0.0)
    res = np.where(np.isfinite(z), z - zh, 0.0)
    np.testing.assert_allclose(pas.res, res, rtol=0, atol=1e-15)
    Lam_fd = np.einsum("nik,ni,nil->kl", dZ, w, dZ)
    b_fd = np.einsum("nik,ni,ni->k", dZ, w, res)
    d = np.sqrt(np.diag(pas.Lam))
    assert (np.abs(pas.Lam - Lam_fd) / np.outer(d, d)).max() < 1e-6
    assert (np.abs(pas.b - b_fd) / d).max() < 1e-6 * (np.abs(pas.b) / d).max()
    # ∂x_k/∂(x_0, c) in units of the prior's σ per parameter σ: O(1) entries.
    scale = np.r_[SIGMA_X, SIGMA_C][None, None, :] / SIGMA_X[None, :, None]
    T, T_fd = pas.T * scale, dX[rows] * scale
    dev = np.abs(T - T_fd).max(axis=(0, 1)) / np.abs(T).max()
    assert dev.max() < 1e-6, dict(zip(STATE_NAMES + bs.CONSIDER_NONLINEAR, dev, strict=True))


# === 6. the consider covariance against a Monte Carlo ================================
# The consider covariance is first order: P_c − P = S C Sᵀ, S = ∂x̂/∂c.  How far that
# holds is physics, not code: an inertia or H error moves ω_n, and the fit's phase
# error at the nutation frequency grows as ω_n t δI/(2I) (≈ 1 rad at δI = 4 kg m²
# over 12 h).  With batch.consider's σ (67 kg m², 25 rpm) the epoch error of these
# noise-free fits is nowhere near S c (its variance 0.002 to 9 times S C Sᵀ's, state by
# state, over 8 to 12 h), and at 1e-2 of them it still is 70% off in places; at 1e-3
# of them the remainder is ≤ 7% (measured draw by draw).  So the Monte Carlo draws
# at 1e-3 of those σ: it checks the sensitivities and their algebra, in the regime
# where the first-order covariance is the right answer.
MC_SCALE = 1e-3
MC_DRAWS = 30


def _check_monte_carlo(E, D, label):
    """The draws' errors E (M, 9) against the consider part D of the covariance: the
    χ² over D's significant directions inside its two-sided 99.9% bounds, roll's and
    yaw's mean e²/D_ii inside theirs (M draws of χ²(1)), and E in D's column space."""
    stat, dof, outside = consider_chi2(E, D)
    lo, hi = chi2_bounds(1, dof, 0.999)
    assert lo < stat / dof < hi, (label, stat / dof, dof, (lo, hi))
    lo, hi = chi2_bounds(1, len(E), 0.999)
    for i in (0, 2):
        ratio = np.mean(E[:, i] ** 2) / D[i, i]
        assert lo < ratio < hi, (label, STATE_NAMES[i], ratio, (lo, hi))
    assert outside < 1e-2, (label, outside)
    return stat / dof


@pytest.mark.slow_in_vm
def test_linear_consider_covariance_matches_a_monte_carlo(rng):
    """The paper's model over 8 h (yaw the first 6 h), noise-free, from rest under
    torques that start smoothly (no nutation at t = 0), I_x, I_z and H drawn from
    their σ (1e-3 of batch.consider's, above) for each of 30 runs and the data made
    with them (Φ, Γ by expm), each fitted with the nominal model: the epoch and end
    errors' scatter is P_c − P of ``ConsiderCase``'s central differences (δ = σ).
    I_x and I_z enter the model only through I = √(I_x I_z), so S C Sᵀ has rank 2.
    Measured χ²/dof 0.77 at the epoch and at the end (60 dof, 99.9% bounds 0.51 to
    1.71: the draws' own scatter), roll's and yaw's e²/D 0.67 to 0.85 (0.36 to 2.07),
    2.6e-4 of Σe² outside S's columns (1e-2 allowed).  Doubling S or propagating the
    moved solutions with the nominal model fail it."""
    n = int(8 * 3600 / DT)
    t = np.arange(n) * DT
    torques = (2e-6 * np.sin(W0 * t / 2) ** 2, -1e-6 * (1 - np.cos(W0 * t)),
               3e-6 * np.sin(2 * W0 * t))
    sigma = {"Ix_kgm2": 67.0 * MC_SCALE, "Iz_kgm2": 69.0 * MC_SCALE,
             "H_Nms": abs(H_NOM) * 25 / 5485 * MC_SCALE}
    x_true = np.zeros(N_STATES)
    prior = Prior(x_true, P0)
    rows = np.array([0, n - 1])

    def model(c):
        p = dataclasses.replace(PARAMS, **{k: getattr(PARAMS, k) + v for k, v in c.items()})
        return p, input_vector(p, *torques)

    def data(meas, c):
        p, u = model(c)
        return LinearData(meas, u, discretize(p, NO_NOISE, DT))

    def truth(c):
        p, u = model(c)
        xs = propagate_lti(*zoh(dynamics_matrix(p), np.eye(N_STATES), DT), x_true, u)
        z = xs[:, [0, 2, 4]].copy()
        z[t >= 6 * 3600, 1] = np.nan
        return xs, Measurements(z[:, 0], z[:, 1], z[:, 2], R_ROLL, R_YAW, R_H)

    _, meas0 = truth({})
    cases = tuple(ConsiderCase(k, s, s, data(meas0, {k: s}), data(meas0, {k: -s}))
                  for k, s in sigma.items())
    ref = linear_batch(data(meas0, {}), prior, rows, cases)
    E0, EN = [], []
    for _ in range(MC_DRAWS):
        c = {k: s * rng.standard_normal() for k, s in sigma.items()}
        xs, meas = truth(c)
        sol = linear_batch(data(meas, {}), prior, rows)
        E0.append(sol.x0 - x_true)
        EN.append(sol.x[-1] - xs[-1])
    _check_monte_carlo(np.array(E0), ref.P0_consider - ref.P0, "epoch")
    _check_monte_carlo(np.array(EN), ref.P_consider_rows[-1] - ref.P_rows[-1], "end")


@pytest.mark.slow_in_vm
def test_nonlinear_consider_covariance_matches_a_monte_carlo(rng):
    """The nonlinear model over 2 h (yaw the first 1.5 h), noise-free, from rest under
    smoothly starting torques; the six inertia entries and the cant drawn from their σ
    (1e-3 of batch.consider's) for each of 30 runs and applied exactly
    (``with_consider``: J and its inverse, the cant on the tachometers' H, Ḣ, N_w* and
    on the h they report), each fitted with the nominal model: the epoch and end
    errors' scatter is P_c − P of the pass's first-order consider columns.  Measured
    χ²/dof 0.75 at both (120 dof over 4 significant directions, bounds 0.63 to 1.48),
    roll's and yaw's e²/D 0.57 to 0.75, 2e-5 of Σe² outside S's columns.  Halving S
    or dropping the direct term ∂x_k/∂c of the end's sensitivity fail it."""
    n = int(2 * 3600 / DT)
    u, pitch = smooth_inputs(n)
    yaw_off = np.arange(n) * DT >= 1.5 * 3600
    sigma = SIGMA_C * MC_SCALE
    x_true = np.zeros(N_STATES)
    prior = Prior(x_true, np.diag(SIGMA_X**2))
    rows = np.array([0, n - 1])
    options = Options(20, 1e-9)

    def truth(c):
        pb, uc, h_scale = with_consider(u, c)
        z, x = own_rollout(x_true, uc, pitch, pb)
        z[:, 2] *= h_scale
        z[yaw_off, 1] = np.nan
        return x, NonlinearData(z, np.tile(R3, (n, 1)), u, pitch, batch_params())

    _, data0 = truth(np.zeros(bs.N_C))
    ref = nonlinear_batch(data0, prior, x_true, rows, sigma, options)
    assert ref.converged
    E0, EN = [], []
    for _ in range(MC_DRAWS):
        x, data = truth(sigma * rng.standard_normal(bs.N_C))
        sol = nonlinear_batch(data, prior, x_true, rows, None, options)
        assert sol.converged, sol.message
        E0.append(sol.x0 - x_true)
        EN.append(sol.x[-1] - x[-1])
    _check_monte_carlo(np.array(E0), ref.P0_consider - ref.P0, "epoch")
    _check_monte_carlo(np.array(EN), ref.P_consider_rows[-1] - ref.P_rows[-1], "end")


# === 7. what a user can get wrong =====================================================

def _no_yaw_linear(rng, n=int(4 * 3600 / DT)):
    u = input_vector(PARAMS, 1e-6, -1e-6, 0.0) * np.ones((n, 1))
    disc = discretize(PARAMS, NO_NOISE, DT)
    xs = propagate_lti(disc.Phi, disc.Gamma, rng.multivariate_normal(np.zeros(N_STATES), P0), u)
    z = xs[:, [0, 2, 4]] + np.sqrt(R3) * rng.standard_normal((n, 3))
    z[:, 1] = np.nan
    return LinearData(Measurements(z[:, 0], z[:, 1], z[:, 2], R_ROLL, R_YAW, R_H), u, disc)


def test_without_yaw_the_constant_yaw_torque_is_held_at_the_prior(rng):
    """No yaw measurement in the span (Section 4: N_cz is then unobservable): both batches
    hold N_cz at the a priori and say so in ``fixed``, its variance the prior's, and
    carry that uncertainty into the other states as a consider parameter's.  The
    epoch covariance is then the RTS smoother's (Q = 0, the same prior and data: the
    same posterior) to within what the roll data say about N_cz through the others
    (measured: yaw σ 0.1% above, never below; holding N_cz as known made it 2.3×
    smaller).  Without an a priori there is nothing to hold it at: an error naming it."""
    data = _no_yaw_linear(rng)
    prior = Prior(rng.multivariate_normal(np.zeros(N_STATES), P0), P0)
    sol = linear_batch(data, prior, rows=[0])
    assert sol.fixed == ("N_cz",)
    assert sol.n_measurements[1] == 0 and np.isnan(sol.residual_rms[1])
    assert sol.x0[NCZ] == prior.x[NCZ]
    assert sol.P0[NCZ, NCZ] == prior.P[NCZ, NCZ]
    f = kalman_filter(data.meas, data.disc, prior.x, prior.P, data.u)
    smoothed = rts_smoother(f, data.disc, data.u)
    ratio = np.sqrt(np.diag(sol.P0)) / smoothed.sigma[0]
    assert np.all(ratio >= 1 - 1e-6) and np.all(ratio <= 1.01), ratio
    with pytest.raises(BatchError, match="constant yaw torque N_cz"):
        linear_batch(data, None)

    n = int(600 / DT)
    u, pitch = smooth_inputs(n)
    z, _ = own_rollout(X_OWN, u, pitch, batch_params())
    z[:, 1] = np.nan
    nl_data = NonlinearData(z, np.tile(R3, (n, 1)), u, pitch, batch_params())
    nl_prior = Prior(X_OWN + SIGMA_X * rng.standard_normal(N_STATES), np.diag(SIGMA_X**2))
    start = X_OWN.copy()
    start[NCZ] += 3e-6          # the start's N_cz is not the prior's: the prior's is held
    nl = nonlinear_batch(nl_data, nl_prior, start, rows=[0])
    assert nl.converged and nl.fixed == ("N_cz",)
    assert nl.x0[NCZ] == nl_prior.x[NCZ]
    assert nl.P0[NCZ, NCZ] == nl_prior.P[NCZ, NCZ]
    with pytest.raises(BatchError, match="constant yaw torque N_cz"):
        nonlinear_batch(nl_data, None, start)


def test_a_batch_stopped_before_it_converges_says_so():
    """One pass allowed on a start 2° off in yaw, which needs several: not converged,
    and the message says after how many passes and how large the last step was."""
    n = int(3600 / DT)
    u, pitch = smooth_inputs(n)
    z, _ = own_rollout(X_OWN, u, pitch, batch_params())
    data = NonlinearData(z, np.tile(R3, (n, 1)), u, pitch, batch_params())
    start = X_OWN + np.r_[0.0, 0.0, 2.0 * DEG, np.zeros(6)]
    sol = nonlinear_batch(data, None, start, rows=[0], options=Options(max_iterations=1))
    assert not sol.converged and sol.iterations == 1
    assert "not converged after 1 iterations" in sol.message
    np.testing.assert_array_equal(sol.x0, start)      # no step was taken
    full = nonlinear_batch(data, None, start, rows=[0])
    assert full.converged and full.iterations > 1 and full.message == ""


def test_solve_normal_names_the_state_the_data_do_not_determine():
    """An information matrix with no information on h (a zero row), or with roll and yaw
    indistinguishable (two equal columns): a BatchError naming the state, not a
    LinAlgError or a NaN solution.  Holding the state (``fixed``) removes the error."""
    N = np.diag([1e10, 1e12, 1e9, 1e12, 1e13, 1e17, 1e17, 1e17, 1e17])
    g = np.ones(N_STATES)
    no_h = N.copy()
    no_h[4, 4] = 0.0
    with pytest.raises(BatchError, match=r"no information on h\b"):
        solve_normal(no_h, g)
    delta, inv = solve_normal(no_h, g, fixed=(4,))
    assert delta[4] == 0.0 and np.all(inv[4] == 0.0)
    np.testing.assert_allclose(delta[[0, 2]], 1 / np.diag(N)[[0, 2]], rtol=1e-12)
    same = N.copy()
    same[0, 0] = same[2, 2] = same[0, 2] = same[2, 0] = 1e9    # roll ≡ yaw
    with pytest.raises(BatchError, match=r"singular.*(roll|yaw) is not determined"):
        solve_normal(same, g)
