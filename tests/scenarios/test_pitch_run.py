"""The pitch filter (Eq. 3b, ``estimator.pitch``) beside the roll/yaw filter in a run.

References, none of them the code under test:
- the pitch σ: the steady state of its own model, discretised by Van Loan's matrix
  exponential (not the closed forms) and solved by ``scipy.linalg.solve_discrete_are``,
  with R, q_w, q_c taken from the scenario's sensor and noise numbers;
- the errors: the nonlinear truth's 3-1-2 pitch;
- the EKF's pitch: the extended Kalman filter's quaternion on the same telemetry.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy import stats
from scipy.linalg import expm, solve_discrete_are, solve_discrete_lyapunov

from estimator.pitch.model import PitchNoise, continuous_model
from scenarios.bridge.pitch import pitch_design
from scenarios.config import build
from scenarios.config.loader import load_scenario
from scenarios.files.csvio import read_csv
from scenarios.run.ekf import run_ekf
from scenarios.run.estimate import estimate_inputs, estimate_to_directory
from scenarios.run.pitch import run_pitch
from scenarios.run.simulate import simulate
from scenarios.run.stream.directory import stream_to_directory
from scenarios.units import DEG
from sim.frames import euler312_from_quat

DAY = ["duration_s=86400", "output.interval_s=64", "output.telemetry=true"]
SETTLED_S = 3600.0


def _run(tmp_path_factory, name, overrides):
    s = load_scenario(name, overrides)
    out = tmp_path_factory.mktemp(name)
    # Two windows, so the filter's prior and Ḣ's padding cross a boundary.
    summary = stream_to_directory(s, out, window_samples=100_000, processes=1,
                                  progress=False)
    with np.load(out / "comparison.npz") as z:
        c = {k: z[k] for k in z.files}
    return s, out, summary, c


@pytest.fixture(scope="module")
def equinox(tmp_path_factory):
    return _run(tmp_path_factory, "goes_next_equinox", DAY)


@pytest.fixture(scope="module")
def torque_free(tmp_path_factory):
    return _run(tmp_path_factory, "torque_free", DAY)


def van_loan_steady(s):
    """(Φ, Q_d, R, P⁻) of Eq. 3b's filter at the scenario's sample interval: Φ and Q_d
    from Van Loan's exponential, P⁻ the steady a-priori covariance from the DARE, R the
    Earth sensor's pitch variance (its noise and quantum), all in rad and s."""
    params, noise = build.estimator_model(s)
    F, _, Qc = continuous_model(params, PitchNoise(noise.q_x, noise.q_cx))
    dt = s.sample_interval_s
    n = 3
    M = np.zeros((2 * n, 2 * n))
    M[:n, :n], M[:n, n:], M[n:, n:] = -F, Qc, F.T
    E = expm(M * dt)
    Phi = E[n:, n:].T
    Qd = Phi @ E[:n, n:]
    e = s.sensors.earth
    R = (e.noise_deg**2 + e.quantum_deg**2 / 12) * DEG**2
    P = solve_discrete_are(Phi.T, np.array([[1.0], [0.0], [0.0]]), Qd, np.array([[R]]))
    return Phi, Qd, R, P


def van_loan_steady_sigma(s) -> float:
    """A-posteriori steady-state pitch σ (rad) of Eq. 3b's filter at the scenario's
    sample interval, from Van Loan's exponential and the DARE."""
    _, _, R, P = van_loan_steady(s)
    return float(np.sqrt(P[0, 0] - P[0, 0] ** 2 / (P[0, 0] + R)))


def noise_floor(s):
    """(P_true, P⁺): the error covariance the steady-state filter has when the truth
    flies no torque and no Ḣ, only the Earth sensor's noise, and the covariance the
    filter reports (both a posteriori, rad, rad/s, N m).  The error then obeys
    e⁺_k = (I − KH)Φ e⁺_{k−1} − K v_k, so P_true solves the Lyapunov equation
    P = A P Aᵀ + R K Kᵀ, A = (I − KH)Φ (``scipy.linalg.solve_discrete_lyapunov``), K the
    DARE's gain.  P_true < P⁺: the filter carries q_w and q_c that such a truth lacks.
    With torques the truth adds error independent of the sensor's noise, so P_true is
    the floor of the error covariance of any truth."""
    Phi, _, R, P = van_loan_steady(s)
    K = P[:, :1] / (P[0, 0] + R)
    IKH = np.eye(3) - K @ np.array([[1.0, 0.0, 0.0]])
    return solve_discrete_lyapunov(IKH @ Phi, R * K @ K.T), IKH @ P


def n_effective(x) -> float:
    """Effectively independent samples in the series ``x``: N / τ, τ = 1 + 2 Σ ρ_k the
    integrated autocorrelation, its sum cut by Geyer's initial positive sequence (1992:
    summed in pairs ρ_2m + ρ_2m+1 while they stay positive, where noise takes over); at
    most N, so that a series anticorrelated by chance does not narrow the bounds."""
    x = np.asarray(x, dtype=float) - np.mean(x)
    n = x.size
    rho = np.correlate(x, x, "full")[n - 1:] / (x @ x)
    tau = -1.0
    for m in range(n // 2):
        pair = rho[2 * m] + rho[2 * m + 1]
        if pair <= 0:
            break
        tau += 2 * pair
    return n / max(tau, 1.0)


def mean_bounds(lam, n_eff: float, alpha: float = 1e-3) -> tuple[float, float]:
    """Two-sided 1 − α bounds on the mean of n_eff independent values of Σ λ_i χ²(1)
    (e = Gaussian of covariance P_true, judged by P⁻¹: λ the eigenvalues of P⁻¹ P_true):
    the mean has mean Σλ and variance 2Σλ²/n_eff, matched by a χ²(d) of d =
    n_eff (Σλ)²/Σλ², scaled by Σλ/d.  With every λ = 1 (a consistent filter) this is
    exactly the χ²(n·n_eff)/n_eff of a mean NEES."""
    lam = np.asarray(lam, dtype=float)
    mu = lam.sum()
    d = n_eff * mu**2 / np.sum(lam**2)
    return tuple(mu / d * stats.chi2.ppf([alpha / 2, 1 - alpha / 2], d))


def settled(c):
    return c["t_s"] >= SETTLED_S


def test_pitch_errors_stay_within_3_sigma(equinox):
    """With every torque, the ripple and the pitch loop on: the pitch error within the
    filter's 3σ at ≥ 99% of the settled rows (a consistent Gaussian filter: 99.73%),
    and its RMS within a factor 1.5 of the σ.  The summary's figure (every sample)
    agrees with the rows'."""
    _, _, summary, c = equinox
    k = settled(c)
    e, sig = c["err_pitch"][k, 0].astype(float), c["sigma_pitch"][k, 0].astype(float)
    inside = np.mean(np.abs(e) <= 3 * sig)
    assert inside >= 0.99
    ratio = np.sqrt(np.mean(e**2)) / np.sqrt(np.mean(sig**2))
    assert 1 / 1.5 < ratio < 1.5
    p = summary["pitch"]
    assert p["pitch_within_3sigma_fraction_after_1h"] == pytest.approx(inside, abs=0.01)
    assert p["pitch_error_rms_after_1h_deg"] == pytest.approx(np.sqrt(np.mean(e**2)),
                                                              rel=0.1)


def test_pitch_sigma_is_its_models_steady_state(equinox):
    """The settled σ against Van Loan + DARE: to 0.5% (the rows are float32, 6e-8; the
    only departures from the steady state are dropouts, where σ grows for a few
    samples, which the median ignores).  The summary's settled mean σ, over every
    sample, dropouts included, to the same 0.5% (measured 7e-5 above: the dropouts'
    share); the summary's steady state is the same equation's, to 1e-6."""
    s, _, summary, c = equinox
    ref = van_loan_steady_sigma(s) / DEG
    sig = c["sigma_pitch"][settled(c), 0].astype(float)
    assert np.median(sig) == pytest.approx(ref, rel=5e-3)
    assert summary["pitch"]["sigma_pitch_mean_after_1h_deg"] == pytest.approx(ref, rel=5e-3)
    assert summary["pitch"]["sigma_pitch_steady_state_deg"] == pytest.approx(ref, rel=1e-6)


def test_pitch_prior_is_the_scenarios_initial_sigma(equinox):
    """The prior (``bridge.pitch``'s design: roll's initial σ for pitch, its rate and
    N_y) against the scenario's initial_sigma converted here by hand (π/180), to 1e-12.
    And in the run: the first row's σ of the rate and N_y are the prior's (the first
    update, on θ alone with a diagonal P₀, leaves them), to float32's 6e-8 (1e-6)."""
    s, _, _, c = equinox
    i = s.estimator.initial_sigma
    want = np.array([i.roll_deg * np.pi / 180, i.roll_rate_degps * np.pi / 180, i.N_cx_Nm])
    np.testing.assert_allclose(pitch_design(s).P0, np.diag(want**2), rtol=1e-12, atol=0)
    np.testing.assert_allclose(c["sigma_pitch"][0, 1:].astype(float),
                               [i.roll_rate_degps, i.N_cx_Nm], rtol=1e-6)


def test_pitch_truth_rate_is_the_euler_rate(equinox):
    """The truth's pitch rate the errors and NEES are judged against (x̂ − e in
    comparison.npz) against θ̇ of the 3-1-2 angles derived here by hand from truth.csv's
    ω_BN and the orbit rate ω0 = √(μ/r³): with C_BR = R2(θ)R1(φ)R3(ψ),
    ω_BR = ω_BN + ω0·C_BR ŷ (the orbit frame turns at −ω0 about y_R), and
    ω_BR = [cθ φ̇ − sθ cφ ψ̇, θ̇ + sφ ψ̇, sθ φ̇ + cθ cφ ψ̇], so
    θ̇ = ω_y − tan φ (cθ ω_z − sθ ω_x).  The pitch loop keeps θ̇ at 2e-4 deg/s RMS
    (the roll rate is 3e-6).  Tolerance 1e-9 deg/s: float32 rows (6e-8 of ≤ 1e-3
    deg/s) and the CSV's 9 digits of ω_BN (1e-13 rad/s) allow 7e-11 (measured 8e-11);
    it is 5e-6 of the rate's σ."""
    s, out, _, c = equinox
    t = read_csv(out / "truth.csv")
    np.testing.assert_array_equal(t["t_s"], c["t_s"])
    yaw, roll, pitch = (t[k] * np.pi / 180 for k in ("yaw_deg", "roll_deg", "pitch_deg"))
    w0 = np.sqrt(3.986004418e14 / s.orbit.radius_m**3)       # IERS/WGS-84 GM
    cy, sy, cr, sr = np.cos(yaw), np.sin(yaw), np.cos(roll), np.sin(roll)
    cp, sp = np.cos(pitch), np.sin(pitch)
    wx = t["wx_radps"] + w0 * (cp * sy + sp * sr * cy)
    wy = t["wy_radps"] + w0 * cr * cy
    wz = t["wz_radps"] + w0 * (sp * sy - cp * sr * cy)
    theta_dot = wy - np.tan(roll) * (cp * wz - sp * wx)
    truth = c["x_pitch"][:, 1].astype(float) - c["err_pitch"][:, 1].astype(float)
    np.testing.assert_allclose(truth, theta_dot * 180 / np.pi, rtol=0, atol=1e-9)


def settled_normalised(c):
    """The settled rows' 3-state NEES samples (every other 64 s row: the NEES is formed
    on every 10th 0.512 s sample) and the pitch angle's (e/σ)² on every settled row."""
    k = settled(c)
    nees = c["nees_pitch"][k].astype(float)
    e, sig = c["err_pitch"][k, 0].astype(float), c["sigma_pitch"][k, 0].astype(float)
    return nees[np.isfinite(nees)], (e / sig) ** 2


def test_pitch_nees_is_its_noise_floor_torque_free(torque_free):
    """Torque-free, the truth's pitch flies no torque and no Ḣ: its error is the Earth
    sensor's noise through the filter and nothing else, so its covariance is exactly
    ``noise_floor``'s P_true, not the filter's P⁺ (which carries the roll axis's q_w and
    q_c for the rate and N_y).  A consistent filter's mean NEES of 3, χ²(3N)/N, is then
    not what this truth gives; P_true's is: Σλ, λ the eigenvalues of P⁺⁻¹P_true
    (0.857, 0.150, 4e-14; Σ 1.007), and the angle's own (e/σ)² P_true/P⁺ = 0.757.

    Both means are judged against the 99.9% bounds of a mean of N_eff such values
    (``mean_bounds``: χ² matched to the mean's mean and variance; exactly χ²(3N)/N for
    a consistent filter).  N_eff is estimated from each series' autocorrelation
    (``n_effective``); the filter's own correlation time says the same: its fast error
    modes decay by 0.973 a 0.512 s step (τ = 18 s), so rows 64 s apart correlate by
    ≤ 0.03, and its slow N_y mode carries no weight (λ = 4e-14) in this truth.  The
    bounds are about ±15% (NEES, 647 samples, N_eff ≈ 590; the angle, 1294 rows):
    the filter's R 20% low (σ 8% low) fails both (1.26, 0.95), where χ²(3)'s one-sample
    bounds, 0.22–9.35, passed it.  (q_w or q_c scaled leaves both ratios: with a
    noise-free truth the error and σ scale together; σ's steady-state test sees them.)
    And NIS, the one figure no truth enters, inside χ²(n)/n's 99.9% bounds over the
    rows."""
    s, _, summary, c = torque_free
    P_true, P = noise_floor(s)
    nees, angle = settled_normalised(c)
    lam = np.linalg.eigvals(np.linalg.solve(P, P_true)).real
    lo, hi = mean_bounds(lam, n_effective(nees))
    assert lo <= nees.mean() <= hi, (nees.mean(), lo, hi)
    lo, hi = mean_bounds([P_true[0, 0] / P[0, 0]], n_effective(angle))
    assert lo <= angle.mean() <= hi, (angle.mean(), lo, hi)
    # The summary's NEES is on every 10th sample, these on every 250th.
    assert summary["pitch"]["nees_mean_after_1h"] == pytest.approx(nees.mean(), rel=0.2)
    nis = c["nis_pitch"][settled(c)].astype(float)
    nis = nis[np.isfinite(nis)]
    n = nis.size
    assert stats.chi2.ppf(5e-4, n) / n <= nis.mean() <= stats.chi2.ppf(1 - 5e-4, n) / n


def test_pitch_errors_between_noise_floor_and_consistency(equinox):
    """Every torque, the ripple and the pitch loop on: the truth's torques add error
    independent of the sensor's noise, so the settled mean NEES and the angle's mean
    (e/σ)² lie above the torque-free noise floor's lower bound (as in the torque-free
    test, ``noise_floor``), and, for a filter whose σ covers its errors, below a
    consistent filter's upper bound: χ²(3N_eff)/N_eff and χ²(N_eff)/N_eff, 99.9%, N_eff
    from each series' autocorrelation.  Measured: NEES 1.15 in [0.86, 3.33] (the
    torques add 0.14 to the floor's 1.007), the angle 0.75 in [0.66, 1.14].

    This judges the sign of Ḣ in the filter (Eq. 3b): flipped, the NEES mean is 3.93
    and the angle's 1.46, 60 and 23 times the floor's spread of those means
    (√(2Σλ²/N_eff): 0.047, 0.031) from the right sign's, and 6σ and 8σ above the
    consistent bounds; the within-3σ share only fell to 98.8%."""
    s, _, _, c = equinox
    P_true, P = noise_floor(s)
    nees, angle = settled_normalised(c)
    lam = np.linalg.eigvals(np.linalg.solve(P, P_true)).real
    for name, values, floor, k in (("NEES", nees, lam, 3),
                                   ("angle (e/σ)²", angle, [P_true[0, 0] / P[0, 0]], 1)):
        n_eff = n_effective(values)
        lo = mean_bounds(floor, n_eff)[0]
        hi = mean_bounds(np.ones(k), n_eff)[1]
        assert lo <= values.mean() <= hi, (name, values.mean(), lo, hi, n_eff)


def test_estimate_gives_the_streamed_pitch(equinox, tmp_path):
    """`dynprop estimate` on the run's telemetry.csv holds the record whole; the stream
    pads Ḣ across windows so it is the same computation: the same bits."""
    s, out, _, _ = equinox
    grid, truth = estimate_inputs(s, out / "telemetry.csv", out / "truth.csv")
    stage = tmp_path / "est"
    stage.mkdir()
    summary = estimate_to_directory(s, grid, truth, stage, {})
    a, b = read_csv(out / "estimate.csv"), read_csv(stage / "estimate.csv")
    for col in ("pitch_deg", "sigma_pitch_deg", "N_y_Nm", "sigma_N_y_Nm"):
        np.testing.assert_array_equal(a[col], b[col], err_msg=col)
    run = json.loads((out / "summary.json").read_text())["pitch"]
    assert summary["pitch"]["nis_mean"] == run["nis_mean"]
    # Both judged at the truth.csv rows (64 s): the truth read back at 10 digits.
    with np.load(out / "comparison.npz") as x, np.load(stage / "comparison.npz") as y:
        np.testing.assert_allclose(x["err_pitch"][:, 0], y["err_pitch"][:, 0], rtol=0,
                                   atol=1e-8)


def test_pitch_agrees_with_the_ekf(tmp_path):
    """The EKF estimates pitch too (its quaternion): on the same telemetry the two
    differ by far less than either σ once settled (RMS below 0.3σ: both weigh the same
    Earth-sensor pitch; they differ in the model that carries it between samples)."""
    s = load_scenario("goes_next_equinox", ["duration_s=21600"])
    sim = simulate(s)
    tel = sim.telemetry
    ekf = run_ekf(s, tel.roll_rad, tel.pitch_rad, tel.yaw_rad, tel.wheel_speeds_radps,
                  tel.yaw_sigma_rad, np.where(tel.yaw_head >= 0, tel.yaw_head, np.nan),
                  keep_nominal=True)
    _, _, pitch_ekf = euler312_from_quat(ekf.X[:, :4])
    p = run_pitch(s, tel.pitch_rad, tel.wheel_speeds_radps)
    k = sim.truth.t_s >= SETTLED_S
    d = p.x[k, 0] - pitch_ekf[k]
    sig = p.sigma[k, 0]
    assert np.sqrt(np.mean(d**2)) < 0.3 * np.sqrt(np.mean(sig**2))
    # And both against the truth: the same accuracy, to 20%.
    truth = sim.truth.euler_rad[k, 2]
    rms_kf = np.sqrt(np.mean((p.x[k, 0] - truth) ** 2))
    rms_ekf = np.sqrt(np.mean((pitch_ekf[k] - truth) ** 2))
    assert rms_kf == pytest.approx(rms_ekf, rel=0.2)
