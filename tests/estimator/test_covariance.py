"""Section 6: steady-state covariance, closed form vs CARE vs the discrete filters."""

import json

import numpy as np
import pytest
from scipy.integrate import quad_vec
from scipy.linalg import expm

from estimator.analysis.covariance import (
    PAPER_SIGMA_YAW_DEG,
    _apply,
    _compose,
    _discrete_model,
    _power,
    _rows,
    alpha,
    approx_yaw_variance,
    care_steady_state,
    closed_form_steady_state,
    periodic_gap_covariance,
    reduced,
    riccati_rates,
    roll_tach_steady_state,
    sigma_yaw_sweep,
    van_loan,
)
from estimator.analysis.covariance_report import covariance_report, format_covariance_report
from estimator.kalman.filter import Measurements, kalman_filter, unpack
from estimator.linear.model import (
    H_WHEEL,
    N_STATES,
    ModelParams,
    ProcessNoise,
    R,
    Y,
    dynamics_matrix,
    noise_density,
    pitch_bias_Nms,
)
from estimator.linear.noise import (
    SensorSpecs,
    continuous_R,
    h_variance,
    ripple_noise_density,
    roll_variance,
    torque_noise_density,
    yaw_variance,
)
from estimator.linear.transition import discretize

from .cov_helpers import cov_dev

W0 = 2 * np.pi / 86164.0905
# scenarios/config/estimation.py defaults for the torque random walks (not in the paper)
Q_RW = 3e-18


def goes_next(sign: float = 1.0, inertia_factor: float = 1.0) -> ModelParams:
    H = pitch_bias_Nms(0.1082, [5485 * 2 * np.pi / 60] * 2, np.deg2rad(1.656))
    f = inertia_factor
    return ModelParams(3364.376 * f, 954.936 * f, 3461.393 * f, sign * H, W0)


def paper_noise(rw: float = Q_RW) -> ProcessNoise:
    q = torque_noise_density()
    return ProcessNoise(q, q, ripple_noise_density(), rw, rw, rw, rw)


@pytest.mark.parametrize("sign", [1.0, -1.0])
@pytest.mark.parametrize("q", [1e-9, 1e-8, 5.385e-7, 1e-5])
def test_eq54_is_the_care_solution(q, sign):
    """Eq. 54 equals solve_continuous_are of Eq. 49 to 1e-10 relative, for either sign of H."""
    H = sign * goes_next().H_Nms
    Rc = continuous_R(H)
    p11, p22, p12 = closed_form_steady_state(q, H, W0, Rc)
    P = care_steady_state(W0, H, Rc, q, q)
    # The CARE solver is good to eps × its condition: measured 1.2e-13 relative.
    np.testing.assert_allclose([P[0, 0], P[1, 1], P[0, 1]], [p11, p22, p12], rtol=1e-10)
    assert P[0, 1] > 0 and np.all(np.linalg.eigvalsh(P) > 0)
    # and Eqs. 53a–c vanish there (relative to the size of their terms, q/H², which
    # cancel: a few roundings, measured 6e-16)
    rates = riccati_rates(np.array([[p11, p12], [p12, p22]]), q, H, W0, Rc)
    assert np.abs(rates).max() < 1e-12 * q / H**2


def test_negative_alpha_root_gives_negative_p22():
    """Section 6: α = −√(…) also solves Eqs. 53 but gives p22 < 0."""
    H = goes_next().H_Nms
    q, Rc = torque_noise_density(), continuous_R(H)
    a = -alpha(q, H, W0, Rc)
    p11 = W0 * Rc * np.sqrt((a + 3) * (a - 1))
    P = np.array([[p11, W0 * Rc * (a - 1)], [W0 * Rc * (a - 1), W0 * Rc * a * np.sqrt(
        (a + 3) * (a - 1))]])
    # terms of size q/H² cancel to rounding: measured 3.7e-16 of q/H²
    assert np.abs(riccati_rates(P, q, H, W0, Rc)).max() < 1e-9 * q / H**2
    assert P[1, 1] < 0


def test_eq55_within_its_approximation():
    """p22 = ω0 R α √((α+3)(α−1)) = q/(ω0H²) (1 + 1/α + O(α⁻²)): Eq. 55 is 1/α ≈ 0.16 % low."""
    H = goes_next().H_Nms
    q, Rc = torque_noise_density(), continuous_R(H)
    a = alpha(q, H, W0, Rc)
    p22 = closed_form_steady_state(q, H, W0, Rc)[1]
    err = p22 / approx_yaw_variance(q, H, W0) - 1
    assert 0.5 / a < err < 2 / a
    assert err < 2e-3


def test_wheel_noise_term_is_negligible():
    """q_w/2 added to q (text after Eq. 43) moves σ_yaw by < 0.1 %."""
    H = goes_next().H_Nms
    Rc, q = continuous_R(H), torque_noise_density()
    base = care_steady_state(W0, H, Rc, q, q)[1, 1]
    with_w = care_steady_state(W0, H, Rc, q, q, ripple_noise_density())[1, 1]
    assert 0 < with_w / base - 1 < 1e-3


def test_van_loan_matches_quadrature():
    """Φ = e^{FΔt}, Q_d = ∫ Φ(s) Q Φ(s)ᵀ ds (Eq. 32) on the 5-state model, and the scaling."""
    p, noise, dt = goes_next(), paper_noise(), 0.512
    F, Q = dynamics_matrix(p)[:5, :5], noise_density(p, noise)[:5, :5]
    Phi, Qd = van_loan(F, Q, dt)
    # |Φ| ≤ ~1 and ‖FΔt‖ ≈ 0.04: both expm calls are good to a few eps (measured 7e-18
    # absolute; 1e-15 ≈ 4.5 eps, with rtol 1e-12 for the O(1) entries).
    np.testing.assert_allclose(Phi, expm(F * dt), rtol=1e-12, atol=1e-15)
    # The quadrature's error control is normwise, so it integrates Q_d in units of
    # √(Q_d,ii Q_d,jj) (from Van Loan's diagonal: only a scaling), where every element is
    # O(1) and epsrel = 1e-12 bounds each of them.  Measured 3e-16; 1e-10.
    d = np.sqrt(np.diag(Qd))
    ref, _ = quad_vec(lambda t: expm(F * t) @ Q @ expm(F * t).T / np.outer(d, d), 0.0, dt,
                      epsabs=0, epsrel=1e-12)
    assert np.abs(Qd / np.outer(d, d) - ref).max() < 1e-10
    # The scaled model is the same model: only the scaling's roundings (measured 5e-23
    # absolute in Φ, 4e-16 of √(Q_ii Q_jj) in Q_d).
    Phi_z, Qd_z, s = _discrete_model(p, noise, dt, 5)
    np.testing.assert_allclose(Phi_z * s[:, None] / s[None, :], Phi, rtol=1e-10, atol=1e-15)
    assert cov_dev(Qd_z * np.outer(s, s), Qd).max() < 1e-12


def test_discrete_roll_tach_filter_matches_the_continuous_yaw_variance():
    """5-state DARE at Δt = 0.512 s vs Eq. 49 with q + q_w/2: σ_yaw within 0.5 %.

    Eq. 49 averages the nutation out and treats the 0.512 s samples as continuous.
    The corrections are of order ω0/|ω_n| = 2.0e-3, 1/α = 1.6e-3 and (ω0 Δt)² ≈ 0
    (continuous measurements); Δt|ω_n| = 0.019 ≪ 1 keeps the sampled nutation
    well resolved.  So σ_yaw must agree to a few parts in 1e3: 0.5 % allowed
    (measured 0.05 %).  Yaw is not measured: a priori and a posteriori σ_yaw are
    the same to 1e-5.
    """
    p, noise = goes_next(), paper_noise()
    d = roll_tach_steady_state(p, noise)
    Rc = continuous_R(p.H_Nms)
    P = care_steady_state(W0, p.H_Nms, Rc, noise.q_x, noise.q_z, noise.q_w)
    assert d["sigma_yaw_prior_rad"] == pytest.approx(np.sqrt(P[1, 1]), rel=5e-3)
    assert d["sigma_yaw_post_rad"] == pytest.approx(d["sigma_yaw_prior_rad"], rel=1e-5)
    assert np.rad2deg(d["sigma_yaw_prior_rad"]) == pytest.approx(PAPER_SIGMA_YAW_DEG, abs=5e-4)


def test_dare_agrees_with_the_recursion_itself():
    p, noise = goes_next(), paper_noise()
    a = roll_tach_steady_state(p, noise, method="dare")
    b = roll_tach_steady_state(p, noise, method="doubling")
    # q_w is tiny, so h's closed-loop mode sits close to the unit circle and the DARE is
    # ill-conditioned; the doubling stops at 1e-12 max-norm.  Measured 2.7e-8 of
    # √(P_ii P_jj); 1e-5.
    assert cov_dev(b["P_prior"], a["P_prior"]).max() < 1e-5


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_nutation_averaged_limit(sign):
    """|ω_n| → ∞ with H and R = R_k Δt fixed: the 5-state filter tends to Eq. 54.

    Shrinking the inertias by 1e-3 (ω_n × 1e3) with Δt and R_k scaled to keep
    Δt|ω_n| and R fixed, the discrete P̃ of x̃ = [r + h/H, y] reaches Eq. 54's
    p22 and p12 (sign included, so Eq. 41b holds for either sign of H), while
    p11 exceeds Eq. 54a by the nutation-band roll error √((q_x + q_z) R)/|H|.
    With F̃ of the opposite sign p12 would be negative.
    """
    f = 1e-3
    p, noise = goes_next(sign, f), paper_noise()
    k = 1 / np.sqrt(f)
    sens = SensorSpecs(dt_s=0.512 * f, roll_noise_deg=0.01 * k, roll_quantum_deg=0.01 * k,
                       tach_noise_3sigma_rpm=0.0978 * k, tach_quantum_rpm=0.0163 * k)
    Rc = continuous_R(p.H_Nms, sens)
    assert Rc == pytest.approx(continuous_R(p.H_Nms))
    Pt = reduced(roll_tach_steady_state(p, noise, sens)["P_prior"], p)
    C = care_steady_state(W0, p.H_Nms, Rc, noise.q_x, noise.q_z, noise.q_w)
    assert Pt[1, 1] == pytest.approx(C[1, 1], rel=3e-3)
    assert Pt[0, 1] == pytest.approx(C[0, 1], rel=1e-2)
    nutation = np.sqrt((noise.q_x + noise.q_z) * Rc) / abs(p.H_Nms)
    assert Pt[0, 0] == pytest.approx(C[0, 0] + nutation, rel=1e-3)
    wrong = care_steady_state(W0, p.H_Nms, Rc, noise.q_x, noise.q_z, noise.q_w, sign=-1.0)
    assert wrong[0, 1] < 0 < Pt[0, 1]


def test_doubling_is_the_step_by_step_recursion():
    """_power(m, N) applied once equals N explicit steps (9 states, yaw measured)."""
    p = goes_next()
    Phi, Qd, s = _discrete_model(p, paper_noise(), 0.512, 9)
    Hm = _rows(9, s, (R, Y, H_WHEEL))
    G = Hm.T @ np.diag(1 / np.array([roll_variance(), yaw_variance(), h_variance()])) @ Hm
    Rm = np.diag([roll_variance(), yaw_variance(), h_variance()])
    P0 = np.diag(np.linspace(1e-6, 1e-4, 9))
    P = P0
    for _ in range(1500):                      # update (Eqs. 37–38), then propagate (Eq. 32)
        K = np.linalg.solve(Hm @ P @ Hm.T + Rm, Hm @ P).T
        P = Phi @ (P - K @ Hm @ P) @ Phi.T + Qd
    Pd = _apply(_power((Phi, G, Qd), 1500), P0)
    # The doubling works in information form, where G reaches 1e14 (1/R_h in scaled
    # units) and I + G P0 has condition 3e9 (P0 is far broader than h's measurement):
    # eps × that, 7e-7, bounds how far the two roundings can drift apart.  Measured on
    # the OpenBLAS kernels Haswell, SkylakeX, Sandybridge and Nehalem, with the compiled
    # code and the VM: 3.4e-13 to 5.3e-13 of √(P_ii P_jj) after 1500 steps, 4e-16 to
    # 2.3e-12 after two.  1e-10 and 1e-9 are 200 and 400 times those, and an algebra
    # slip in _compose or _power changes P at O(1).
    assert cov_dev(Pd, P).max() < 1e-10
    m = (Phi, G, Qd)
    two = _apply(m, _apply(m, P0))
    assert cov_dev(_apply(_compose(m, m), P0), two).max() < 1e-9


@pytest.fixture(scope="module")
def gap():
    return periodic_gap_covariance(goes_next(), paper_noise())


def test_periodic_gap_sigma(gap):
    """9-state filter, yaw 16 h of every 24 h: σ_yaw peaks at the gap end near 0.040°.
    (Its speed is in ``make bench``.)"""
    res = gap
    sig = np.rad2deg(res.sigma_yaw_rad)
    # periodic: the fixed point is settled to 1e-10 (max-norm); measured 7e-16
    assert sig[0] == pytest.approx(sig[-1], rel=1e-8)
    assert np.argmax(sig[:-1]) == 0                          # the maximum is at the gap end
    assert 0.035 < sig[0] < 0.045                            # measured 0.0408°, paper 0.040°
    assert sig.min() < 0.1 * sig[0]                          # yaw measured: ~0.0034°
    yaw_on = res.times_s < 16 * 3600 - 1
    assert np.all(sig[yaw_on][1:] < 0.01)
    gap_part = sig[res.times_s >= 16 * 3600]
    assert np.all(np.diff(gap_part) > 0)                     # grows through the gap
    assert np.sqrt(res.P_gap_end[Y, Y]) == pytest.approx(res.sigma_yaw_rad[0])


def test_periodic_gap_matches_the_kalman_filter_over_a_day(gap):
    """The periodic solution of ``periodic_gap_covariance`` (doubling of the Riccati map in
    scaled coordinates, Van Loan Φ and Q_d) against the compiled filter of
    ``estimator.kalman`` (sequential Joseph updates, closed-form Φ and Q_d of
    ``estimator.linear.transition``) over one day: roll and h every 0.512 s, yaw absent over the
    8 h gap at the end of the day.

    The filter starts from the periodic solution at the matching phase (the gap end, a
    priori) rather than from a broad prior: the doubling needed 128 days to settle, so
    reaching the periodic regime from scratch would cost months of steps.  Started there,
    a correct filter follows the σ_yaw profile all day and returns to the start after one
    day.  That is a strict check because the day map contracts: an error in the start
    shrinks to 5 % in yaw and 60 % in the torque states after a day, so any difference in
    Q_d, R, the updates or the gap phase shows as a departure from the start."""
    p, noise, sensors = goes_next(), paper_noise(), SensorSpecs()
    dt = sensors.dt_s
    n_day, n_gap = round(86400.0 / dt), round(28800.0 / dt)
    z = np.zeros((n_day, 3))
    z[n_day - n_gap:, 1] = np.nan                  # no yaw over the gap
    meas = Measurements(z[:, 0], z[:, 1], z[:, 2], roll_variance(sensors),
                        yaw_variance(sensors), h_variance(sensors))
    k = np.round(gap.times_s / dt).astype(int)     # sample indices; times are k·dt both ways
    assert np.array_equal(k * dt, gap.times_s) and k[0] == 0 and k[-1] == n_day
    disc = discretize(p, noise, dt)
    res = kalman_filter(meas, disc, np.zeros(N_STATES), gap.P_gap_end, rows=k[1:-1] - 1)
    # The profile is a priori: propagate the filter's a-posteriori P at the step before.
    prior = disc.Phi @ unpack(res.P_packed) @ disc.Phi.T + disc.Qd
    sig = np.concatenate([[np.sqrt(gap.P_gap_end[Y, Y])], np.sqrt(prior[:, Y, Y]),
                          [np.sqrt(res.P_next[Y, Y])]])
    # A day is 168 750 steps whose rounding accumulates in the torque states' slow
    # closed-loop modes (time constant ~1e6 steps, longer than the day): at most ~N eps =
    # 4e-11, plus the fixed point's own rounding.  Measured 1.0e-11 of √(P_ii P_jj) for
    # the whole P after the day and 1.7e-13 relative on σ_yaw (the same with
    # DYNPROP_BACKEND=vm); 1e-9.
    np.testing.assert_allclose(sig, gap.sigma_yaw_rad, rtol=1e-9, atol=0)
    assert cov_dev(res.P_next, gap.P_gap_end).max() < 1e-9


def test_periodic_gap_does_not_depend_on_sampling_and_grows_with_the_gap():
    p, noise = goes_next(), paper_noise()
    a = periodic_gap_covariance(p, noise, sample_s=600.0).sigma_yaw_rad[0]
    b = periodic_gap_covariance(p, noise, sample_s=3600.0).sigma_yaw_rad[0]
    # the same fixed point settled to 1e-10 (max-norm): measured 2.8e-15
    assert a == pytest.approx(b, rel=1e-8)
    ends = [periodic_gap_covariance(p, noise, gap_s=h * 3600.0).sigma_yaw_rad[0]
            for h in (0, 4, 8, 12)]
    assert np.all(np.diff(ends) > 0)
    # no torque random walk: N_cz becomes exactly known; settles all the same
    assert periodic_gap_covariance(p, paper_noise(0.0)).sigma_yaw_rad[0] < a


def test_sweep():
    p = goes_next()
    q = np.logspace(-9, -5, 5)
    sw = sigma_yaw_sweep(q, p)
    np.testing.assert_allclose(sw["eq55"], np.sqrt(q / (W0 * p.H_Nms**2)))
    assert np.all(sw["eq54"] > sw["eq55"])
    np.testing.assert_allclose(sw["discrete"], sw["eq54"], rtol=0.03)
    big = q >= 1e-7
    np.testing.assert_allclose(sw["discrete"][big], sw["eq54"][big], rtol=5e-3)
    # q_w = 0 leaves h without noise: the DARE solver gives up, the fallback does not
    assert np.all(np.isfinite(sigma_yaw_sweep([1e-9], p, q_w=0.0)["discrete"]))


def test_covariance_report_and_text():
    rep = covariance_report(goes_next(), paper_noise())
    json.dumps(rep)
    m = rep["methods"]
    # The CARE solver against the closed form: eps × its condition (measured 1.2e-13).
    assert m["eq54"]["p22"] == pytest.approx(m["care"]["p22"], rel=1e-10)
    for key in ("eq54", "eq55", "care", "care_qw", "dare_prior", "dare_post"):
        assert m[key]["sigma_yaw_deg"] == pytest.approx(0.0397, abs=2e-4)
    assert m["gap_end"]["sigma_yaw_deg"] == pytest.approx(m["gap_max"]["sigma_yaw_deg"])
    text = format_covariance_report(rep)
    assert "0.040°" in text and "Eq. 54 closed form" in text and "gap end" in text
    assert f"{m['eq54']['sigma_yaw_deg']:.4f}" in text
