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
from scipy.linalg import expm, solve_discrete_are

from estimator.kalman.consistency import chi2_bounds
from estimator.pitch.model import PitchNoise, continuous_model
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


def van_loan_steady_sigma(s) -> float:
    """A-posteriori steady-state pitch σ (rad) of Eq. 3b's filter at the scenario's
    sample interval, from Van Loan's exponential and the DARE."""
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
    return float(np.sqrt(P[0, 0] - P[0, 0] ** 2 / (P[0, 0] + R)))


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
    samples, which the median ignores)."""
    s, _, summary, c = equinox
    ref = van_loan_steady_sigma(s) / DEG
    sig = c["sigma_pitch"][settled(c), 0].astype(float)
    assert np.median(sig) == pytest.approx(ref, rel=5e-3)
    assert summary["pitch"]["sigma_pitch_steady_state_deg"] == pytest.approx(ref, rel=1e-6)


def test_pitch_nees_within_chi2_bounds_torque_free(torque_free):
    """Torque-free: the 3-state NEES's settled mean inside the χ²(3) 95% bounds, the
    pitch part of it near 1 (the rate and N_y, driven by process noise the torque-free
    truth does not fly, are conservative), and NIS, the one consistency figure no
    truth enters, inside the χ²(n)/n 99.9% bounds of its mean over the rows."""
    _, _, summary, c = torque_free
    k = settled(c)
    nees = c["nees_pitch"][k].astype(float)
    nees = nees[np.isfinite(nees)]
    lo, hi = chi2_bounds(3, 1)
    assert lo <= nees.mean() <= hi
    assert summary["pitch"]["nees_mean_after_1h"] == pytest.approx(nees.mean(), rel=0.2)
    e, sig = c["err_pitch"][k, 0].astype(float), c["sigma_pitch"][k, 0].astype(float)
    assert 0.5 < np.mean((e / sig) ** 2) < 1.5
    nis = c["nis_pitch"][k].astype(float)
    nis = nis[np.isfinite(nis)]
    n = nis.size
    assert stats.chi2.ppf(5e-4, n) / n <= nis.mean() <= stats.chi2.ppf(1 - 5e-4, n) / n


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
