"""The unmodelled random torque (``sim.disturbance``) against its definitions, and in
the truth: the statistics of its draws, bit identity of pieces and windows with the
whole, and Euler's law with the held torque.

The statistics tests draw long sequences directly (no dynamics); each tolerance is
five standard deviations of the estimator's own sampling error, derived in the test
(and checked over 12 seeds while writing it: the measured spread is quoted)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import welch

from sim import ephemeris
from sim.control import Control
from sim.disturbance import Disturbance, DisturbanceDraw, draw
from sim.environment import Environment
from sim.frames import GeoOrbit, dcm_from_quat
from sim.history import OPTIONAL_TORQUES, TORQUE_SOURCES
from sim.spacecraft import goes_next
from sim.truth import InitialState, TruthStream, simulate_truth

from .conftest import EQUINOX
from .test_dynamics import inertial_momentum
from .test_truth_stream import EPOCH, _concat, _equal_fields

DT = 0.512
N_LONG = 2_000_000          # 11.9 days at 0.512 s
TAU = 25.6                  # 50 steps: 40 000 correlation times in N_LONG
SIGMA = (2.0, 0.0, 0.5)     # arbitrary units: the statistics are linear in σ
Q = (3e-7, 0.0, 1e-6)
K_SIGMA = 5.0               # tolerances: five standard deviations of the estimator


@pytest.fixture(scope="module")
def markov_long():
    gm = Disturbance("gauss_markov", sigma_Nm=SIGMA, correlation_time_s=TAU)
    return draw(gm, DT, N_LONG, np.random.default_rng(20260320))


def test_gauss_markov_variance_and_autocorrelation(markov_long):
    """Sample variance σ² and autocorrelation exp(−mΔt/τ) at lags m = 1, 5, 50, 150.

    The draw is an AR(1) with φ = exp(−Δt/τ).  With the mean known (zero), the sample
    variance s² = Σx²/N has Var(s²) = 2σ⁴/N · (1 + φ²)/(1 − φ²) ≈ 2σ⁴ (τ/T) for Δt ≪ τ
    (T = NΔt): relative 1σ = √(2 coth(Δt/τ)/N) = 0.71% here (measured 0.65%).  The
    sample autocorrelation ρ̂_m = Σ x_k x_{k+m}/(N − m) / s² has Bartlett's variance
    for an AR(1), Var(ρ̂_m) = [(1 + φ²)(1 − φ^{2m})/(1 − φ²) − 2m φ^{2m}]/N: 1.4e-4,
    6.6e-4, 3.9e-3 and 5.0e-3 for the four lags (measured 1.2e-4, 6.4e-4, 3.9e-3,
    4.4e-3).  The axis with σ = 0 is exactly zero."""
    phi = np.exp(-DT / TAU)
    coth = (1 + phi**2) / (1 - phi**2)
    assert np.all(markov_long[:, 1] == 0.0)
    for axis in (0, 2):
        u = markov_long[:, axis] / SIGMA[axis]
        s2 = np.mean(u * u)
        assert abs(s2 - 1.0) < K_SIGMA * np.sqrt(2 * coth / N_LONG), (axis, s2)
        for m in (1, 5, 50, 150):
            rho = np.dot(u[:-m], u[m:]) / (N_LONG - m) / s2
            p2m = phi ** (2 * m)
            sd = np.sqrt(((1 + phi**2) * (1 - p2m) / (1 - phi**2) - 2 * m * p2m) / N_LONG)
            assert abs(rho - np.exp(-m * DT / TAU)) < K_SIGMA * sd, (axis, m, rho)


def test_gauss_markov_acts_at_low_frequency_as_white_noise_of_2_sigma2_tau(markov_long):
    """The module doc's zero-frequency equivalent: S(0) = 2σ²τ.  The integral of the
    held torque over a block T = MΔt (the momentum it delivers) has variance
    2σ²τ [T − τ(1 − e^{−T/τ})] for the continuous process; the zero-order-hold sum
    Δt Σ x_k differs from it by 4e-5 relative at Δt/τ = 0.02 (the exact AR(1) sum,
    Δt²σ²[M + 2Σ_{m<M}(M − m)φ^m], computed below).  Over K = N/M = 4000 blocks of 10τ
    (nearly independent: neighbours share ~τ/T of their variance) the sample mean
    square has relative 1σ √(2/K) = 2.2% (measured 1.8%).  Eq. 45's q = σ²τ, half of
    2σ²τ, would be 50% (22σ) off."""
    m_block = 500
    t_block = m_block * DT
    phi = np.exp(-DT / TAU)
    lags = np.arange(1, m_block)
    exact = DT**2 * (m_block + 2 * np.sum((m_block - lags) * phi**lags))
    continuous = 2 * TAU * (t_block - TAU * (1 - np.exp(-t_block / TAU)))
    assert continuous == pytest.approx(exact, rel=1e-4)
    k = N_LONG // m_block
    for axis in (0, 2):
        u = markov_long[: k * m_block, axis] / SIGMA[axis]
        walk = DT * u.reshape(k, m_block).sum(axis=1)
        assert abs(np.mean(walk**2) / continuous - 1) < K_SIGMA * np.sqrt(2 / k), axis


def test_gauss_markov_starts_stationary():
    """x_0 ~ N(0, σ²), and x_1 too (not a process started from rest, whose first
    samples would have variance (1 − φ^{2(k+1)})σ², 4% of σ² at k = 0 here).  Over
    K = 8000 independent runs the sample variance has relative 1σ √(2/K) = 1.6%."""
    gm = Disturbance("gauss_markov", sigma_Nm=(3.0, 3.0, 3.0), correlation_time_s=TAU)
    rng = np.random.default_rng(7)
    k = 8000
    first = np.empty((k, 2, 3))
    for i in range(k):
        DisturbanceDraw(gm, DT, rng).fill(first[i])
    for j in range(2):
        var = np.mean(first[:, j] ** 2, axis=0) / 9.0
        assert np.all(np.abs(var - 1) < K_SIGMA * np.sqrt(2 / k)), (j, var)


def test_white_spectral_density_is_q():
    """Welch's two-sided PSD in (N m)²/Hz of the held white draws equals q, the
    intensity of E[w(t)w(t')] = q δ(t − t') (Eq. 35; two-sided, so S(f) = q at every
    f), both near zero frequency (|f| < 0.1 f_N) and near Nyquist (> 0.9 f_N): the
    held value's variance q/Δt is spread flat over the band 1/Δt.  Each band's mean
    is the power of x in a one-sided band W = 0.1 f_N observed for T = NΔt, a χ² of
    2WT degrees of freedom: relative 1σ 1/√(WT) = 0.32% (measured 0.32%).  The axis
    with q = 0 is exactly zero."""
    x = draw(Disturbance("white", q_Nm2s=Q), DT, N_LONG, np.random.default_rng(11))
    assert np.all(x[:, 1] == 0.0)
    nyquist = 0.5 / DT
    tol = K_SIGMA / np.sqrt(0.1 * nyquist * N_LONG * DT)
    for axis in (0, 2):
        f, s = welch(x[:, axis], fs=1 / DT, nperseg=1024, return_onesided=False,
                     detrend=False, scaling="density")
        for band in (np.abs(f) < 0.1 * nyquist, np.abs(f) > 0.9 * nyquist):
            assert abs(np.mean(s[band]) / Q[axis] - 1) < tol, (axis, np.mean(s[band]))


@pytest.mark.parametrize("kind", ["white", "gauss_markov"])
def test_pieces_drawn_in_order_are_the_whole_draw(kind):
    """Any split of a run, pieces of 1 and 0 samples included, gives the very bits of
    one draw: the generator's stream continues, and the Gauss–Markov filter state is
    carried (lfilter with its state passed on)."""
    d = Disturbance(kind, q_Nm2s=Q, sigma_Nm=SIGMA, correlation_time_s=TAU)
    whole = draw(d, DT, 20_000, np.random.default_rng(3))
    pieces = DisturbanceDraw(d, DT, np.random.default_rng(3))
    out = np.empty_like(whole)
    cuts = [0, 1, 1, 2, 777, 4096, 4097, 13_000, 20_000]
    for a, b in zip(cuts[:-1], cuts[1:], strict=True):
        pieces.fill(out[a:b])
    assert np.array_equal(out, whole)


def test_parameters_are_checked():
    for bad in (dict(kind="pink"), dict(sigma_Nm=(1e-6, -1e-9, 0.0)),
                dict(q_Nm2s=(np.nan, 0.0, 0.0)), dict(correlation_time_s=0.0),
                dict(correlation_time_s=-5.0), dict(correlation_time_s=np.inf)):
        with pytest.raises(ValueError, match="disturbance"):
            Disturbance(**bad)
    with pytest.raises(ValueError, match="none"):
        DisturbanceDraw(Disturbance(), DT, np.random.default_rng(0))


# --------------------------------------------------------------------------- in the truth

GM = Disturbance("gauss_markov", sigma_Nm=(2e-6, 1e-6, 3e-6), correlation_time_s=600.0)


def _stream(disturbance, extra=None, disturbance_rng=None):
    """test_truth_stream's 3 h run across the eclipse, with ``disturbance``."""
    return TruthStream(goes_next(), GeoOrbit(), Environment(), Control(),
                       InitialState(yaw_rad=1e-3, roll_rad=5e-4), EPOCH, 3 * 3600.0,
                       rng=np.random.default_rng(1), extra_torque=extra,
                       disturbance=disturbance, disturbance_rng=disturbance_rng)


def test_windows_with_a_disturbance_are_the_whole_run():
    """TruthStream's promise with a disturbance: windows of uneven lengths, one of them
    sensed a piece at a time, and ``sun`` called between them (it draws nothing)
    concatenate to the whole run's arrays bit for bit; the disturbance is the one
    draw of its generator, recorded apart from the caller's extra torque, and the
    source list is the always-present sources plus it."""
    n = int(3 * 3600 / DT) + 1
    extra = np.zeros((n, 3))
    extra[:, 2] = 1e-6 * np.sin(np.arange(n) / 5000.0)
    whole = _stream(GM, extra, np.random.default_rng(4)).window(0, n)
    stream = _stream(GM, extra, np.random.default_rng(4))
    bounds = [0, 1, 1000, 5160, 9001, n]
    parts = []
    for i, (a, b) in enumerate(zip(bounds[:-1], bounds[1:], strict=True)):
        stream.sun(0, n)
        if i == 3:
            truth, _ = stream.window(a, b, sense=lambda rows, lo, hi: None, piece=777)
            parts.append(truth)
        else:
            parts.append(stream.window(a, b))
    assert _equal_fields(whole, _concat(parts)) == []
    assert list(whole.torques) == [s for s in TORQUE_SOURCES if s != "thruster"]
    assert np.array_equal(whole.torques["disturbance"],
                          draw(GM, DT, n, np.random.default_rng(4)))
    assert np.array_equal(whole.torques["external"], extra)


def test_kind_none_flies_and_records_what_no_disturbance_does():
    """``kind: none`` (with or without a generator) is the run without the argument,
    bit for bit: no disturbance source, the external torque zero."""
    plain = _stream(None).window(0, 2000)
    for rng in (None, np.random.default_rng(9)):
        none = _stream(Disturbance("none", sigma_Nm=(1.0, 1.0, 1.0)), None, rng).window(0, 2000)
        assert _equal_fields(plain, none) == []
        assert list(none.torques) == [s for s in TORQUE_SOURCES if s not in OPTIONAL_TORQUES]
        assert not np.any(none.torques["external"])
    with pytest.raises(ValueError, match="disturbance_rng"):
        _stream(GM)


@pytest.mark.parametrize("with_extra", [False, True])
def test_inertial_momentum_change_equals_the_held_disturbance(orbit, with_extra):
    """Euler's law with the disturbance (alone, or with an extra torque beside it) as
    the only torques on a torque-free gyrostat (environment, ripple and control off, as
    scenarios/bundled/torque_free.yaml): the change of inertial angular momentum over
    the run equals Σ_k ∫_step C_NB τ_k dt of the recorded torques, each held over its
    step in body axes.  As in test_dynamics' test of every torque: in orbit axes a held
    body torque g = C_RB τ_k moves only at ω_BR, so each step takes g at its start
    times the exact ∫ C_NR dt (Simpson on the analytic orbit frame); what that misses
    is ≤ ½ dt T max|ω_BR| max|τ| over the run.  So the check fails if the disturbance
    acts other than as recorded (scaled, a step late, in the wrong frame, or not at
    all), or the external torque is recorded as the sum.  Here the bound is 2.6e-6
    N m s (measured error 3.1e-7: the body's slow drift and the torque, correlated over
    900 s, err the same way for many steps), and the disturbance moves 0.16 N m s
    (asserted ≥ 1e4 times the tolerance)."""
    sc = goes_next()
    d = Disturbance("gauss_markov", sigma_Nm=(2e-5, 1e-5, 3e-5), correlation_time_s=900.0)
    duration = 7200.0
    n = int(duration / DT) + 1
    extra = np.zeros((n, 3))
    extra[:, 0] = 5e-6 * np.cos(2 * np.pi * np.arange(n) * DT / 28800.0) * with_extra
    res = simulate_truth(sc, orbit, Environment.torque_free(), Control(enabled=False),
                         InitialState(yaw_rad=1e-3, roll_rad=2e-4), EQUINOX, duration,
                         extra_torque=extra if with_extra else None, disturbance=d,
                         disturbance_rng=np.random.default_rng(12))
    assert np.array_equal(res.torques["external"], extra)
    gmst0 = ephemeris.gmst_rad(ephemeris.julian_date(EQUINOX))
    c_nr = np.swapaxes(orbit.orbit_frame(res.t_s, gmst0), -1, -2)
    c_rb = np.swapaxes(dcm_from_quat(res.q_br), -1, -2)
    mid = np.swapaxes(orbit.orbit_frame(res.t_s[:-1] + DT / 2, gmst0), -1, -2)
    step_integral = DT / 6 * (c_nr[:-1] + 4 * mid + c_nr[1:])   # ∫ C_NR over each step

    def held(name):
        g = np.einsum("nij,nj->ni", c_rb, res.torques[name])[:-1]
        return np.einsum("nij,nj->i", step_integral, g)

    parts = {name: held(name) for name in ("external", "disturbance")}
    h_n = inertial_momentum(res, sc, orbit)
    err = np.linalg.norm(h_n[-1] - h_n[0] - sum(parts.values()))
    w_br = np.max(np.linalg.norm(res.w_br_radps, axis=1))
    tau_max = np.max(np.linalg.norm(res.torques["disturbance"] + extra, axis=1))
    tol = 0.5 * DT * duration * w_br * tau_max
    assert err < tol, (err, tol)
    assert np.linalg.norm(parts["disturbance"]) > 1e4 * tol
