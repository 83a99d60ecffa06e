"""Noise tuning by maximum likelihood (estimator/tuning/maximum.py) on telemetry drawn from the
filter's own linear model, where the answer is known: θ_true, the noise the data
were drawn with (``lik_helpers.simulate``: x_{k+1} = Φ x_k + w_k, w ~ N(0, Q_d(θ_true)),
roll, yaw and h with the stated variances, a Sun gap in yaw).

References: θ_true (the maximum-likelihood estimate is consistent and, on a record
this long, Gaussian with the inverse Fisher information as covariance); central
differences of ``Likelihood.evaluate`` for the gradient at the optimum (no use of the
score the optimiser climbs with); scipy's L-BFGS-B on −ln L in ln θ, with a gradient
from central differences, as an independent maximiser; and the filter's consistency
functions (estimator/kalman/consistency.py) against series with known autocorrelation.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import brentq, minimize
from scipy.signal import lfilter
from scipy.stats import chi2

from estimator.kalman.consistency import autocorrelation, whiteness
from estimator.linear.model import N_STATES, ProcessNoise
from estimator.linear.transition import discretize
from estimator.tuning.likelihood import Likelihood, noise_model
from estimator.tuning.maximum import maximize, nearest_allowed, profile

from .lik_helpers import DT, P0, PARAMS, measurements, simulate

GROUPS = {"q_x": {"q_x": 1.0}, "q_z": {"q_z": 1.0}, "q_w": {"q_w": 1.0}}
TRUE = ProcessNoise(q_x=3e-6, q_z=1e-6, q_w=5e-10, q_px=3e-18, q_pz=2e-18, q_cx=4e-18,
                    q_cz=1e-18)
THETA_TRUE = np.array([TRUE.q_x, TRUE.q_z, TRUE.q_w])
# Far from the truth, as a scenario's guess may be: 10×, 1/10×, 5×.
THETA_START = THETA_TRUE * np.array([10.0, 0.1, 5.0])
LOWER, UPPER = np.full(3, 1e-14), np.full(3, 1e-4)
N = 20_000   # 2.8 h at 0.512 s: σ of ln θ ≈ 0.1–0.2 for each parameter
# The fall of ln L at a one-sided 95% limit (docs/tune.md, "Uncertainty"): the signed
# root of the likelihood ratio, ±√(2Δ), is N(0, 1) under the value tested, so a one-sided
# 95% test rules the value out where √(2Δ) > z_0.95, i.e. Δ > z_0.95²/2 = χ²₁(0.90)/2
# (1.3528), from scipy, not from the code under test.
ONE_SIDED_95_DROP = chi2.ppf(0.90, df=1) / 2


def central_log_gradient(lik: Likelihood, theta, h: float = 1e-3) -> np.ndarray:
    """∂ln L/∂ln θ by central differences of ``evaluate``, Richardson-extrapolated
    with 2h: truncation ~h⁴ ∂⁵ln L, rounding ~1.5 δ/h with δ ≈ 1e-14 of Σ|terms|
    (test_likelihood) ≈ 5e-9 here, so ~1e-5 absolute."""
    out = np.empty(len(theta))
    for j in range(len(theta)):
        def at(step, j=j):
            t = np.array(theta, dtype=float)
            t[j] *= np.exp(step)
            return lik.evaluate(t).loglik
        d1 = (at(h) - at(-h)) / (2 * h)
        d2 = (at(2 * h) - at(-2 * h)) / (4 * h)
        out[j] = (4 * d1 - d2) / 3
    return out


@pytest.fixture(scope="module")
def lik() -> Likelihood:
    """20,000 samples of the model at TRUE with a 57-minute yaw gap; the filter's
    torque-walk densities held at their true values, q_x, q_z and q_w free."""
    rng = np.random.default_rng(1)
    _, z = simulate(TRUE, N, rng)
    z[9000:15700, 1] = np.nan
    model = noise_model(PARAMS, DT, GROUPS, TRUE)
    # The filter is built from a wrong guess (the start): only Φ and Γ are read from
    # it, Q_d comes from θ.
    disc = discretize(PARAMS, ProcessNoise(*THETA_START), DT)
    return Likelihood(measurements(z), disc, np.zeros(N_STATES), P0, model)


@pytest.fixture(scope="module")
def fit(lik):
    return maximize(lik, THETA_START, LOWER, UPPER)


def test_maximum_likelihood_recovers_the_noise_the_data_were_drawn_with(fit):
    """The fit converges inside the bounds and each θ̂_j is within 3σ of θ_true, σ of
    ln θ from the inverse Fisher information (the estimator's asymptotic covariance;
    3σ holds for 99.7% of records per parameter).  Measured: 0.88σ, 0.05σ, 0.38σ with
    σ = 0.12, 0.18, 0.10; over 12 seeds the deviations in units of σ had standard
    deviations 0.7–1.2, as the Fisher σ says."""
    assert fit.converged
    assert np.all(fit.at_bound == 0) and np.all(fit.determined)
    sigma = fit.sigma_log
    assert np.all(np.isfinite(sigma)) and np.all(sigma < 0.3)
    z = np.log(fit.theta / THETA_TRUE) / sigma
    assert np.all(np.abs(z) < 3), z
    # ln L rose from the start, and the best evaluation is the fit's.
    assert fit.best.loglik > fit.start.loglik
    assert np.array_equal(fit.best.theta, fit.theta)


def test_the_optimum_has_zero_gradient_by_finite_differences(lik, fit):
    """At θ̂ the gradient in ln θ, from central differences of ``evaluate`` (not the
    score the optimiser used), is small against the curvature: |∂ln L/∂ln θ_j| σ_j
    < 0.1, i.e. a further step would gain less than a tenth of a σ along θ_j (a
    stopping rule in the optimiser's own terms; its rule is a step within 0.1σ).
    The differences are good to ~1e-5 (``central_log_gradient``), against
    0.1/σ_j ≥ 0.3.  Measured ≤ 0.056 (q_w; 0.018 and 0.027 for q_x and q_z)."""
    g = central_log_gradient(lik, fit.theta)
    assert np.all(np.abs(g) * fit.sigma_log < 0.1), (g, fit.sigma_log)
    # And the optimiser's own gradient agrees with the differences (test_likelihood
    # holds the score to them more tightly; here only at the optimum).
    assert fit.log_gradient == pytest.approx(g, abs=1e-4 + 1e-6 * np.abs(g).max())


def test_lbfgsb_on_the_likelihood_reaches_the_same_maximum(lik, fit):
    """An independent maximiser: scipy's L-BFGS-B on −ln L in ln θ with the same bounds,
    its gradient from central differences of ``evaluate``, from the same start.  It
    must reach the same ln L within 0.05 (the fit's own stopping tolerance on the
    predicted gain) and the same θ within 0.2σ of ln θ (σ from the fit's
    information; the fit stops within 0.1σ of its maximum, L-BFGS-B once its projected
    gradient in ln θ is below 1e-3, i.e. within 1e-3 σ² ≪ 0.1σ of it).  Measured:
    L-BFGS-B 0.0023 higher in ln L, θ within 0.06σ."""
    lam0 = np.log(THETA_START)
    ref = lik.evaluate(THETA_START).loglik

    def f(lam):
        return -(lik.evaluate(np.exp(lam)).loglik - ref)

    def jac(lam):       # central differences, h = 1e-4: rounding ~δ/h ≈ 3e-5
        g = np.empty(3)
        for j in range(3):
            step = np.eye(3)[j] * 1e-4
            g[j] = (f(lam + step) - f(lam - step)) / 2e-4
        return g

    res = minimize(f, lam0, jac=jac, method="L-BFGS-B",
                   bounds=list(zip(np.log(LOWER), np.log(UPPER), strict=True)),
                   options={"ftol": 1e-13, "gtol": 1e-3, "maxiter": 200})
    best = ref - res.fun
    assert best == pytest.approx(fit.best.loglik, abs=0.05), (best, fit.best.loglik)
    gap = np.abs(res.x - np.log(fit.theta)) / fit.sigma_log
    assert np.all(gap < 0.2), gap


def test_profile_and_limits_against_their_definitions(lik, fit):
    """``profile``: ln L at ln θ_j = ln θ̂_j ± 2σ_j with the other parameters at their
    conditional optimum to second order.  Reference: the same point with the others
    re-maximised by L-BFGS-B (central-difference gradient, h = 1e-3, stopped at a
    gradient of 1e-3: within ~1e-8 of the maximum for an information of ~50).  The
    profile's value cannot exceed the re-maximised one (beyond 1e-4) and, the
    likelihood being near quadratic, falls short of it by little: bound 0.05
    (measured 0.002 and 0.021: the second-order step uses the expected information,
    which differs from this record's observed one by 10–30%).  Its drop is near
    k²/2 = 2: within a factor 1.5 either way, for the same reason (measured 1.64 and
    1.83).

    ``nearest_allowed`` for a value 1000× the fit: a one-sided limit where ln L (the
    others held at the fit) has fallen by χ²₁(0.90)/2, found to 0.7 in ln θ (its
    documented bracket, a factor 2), on the allowed side: ln L at the limit is within
    the drop and at 0.7 beyond it is not (the crossing, found to 1e-6 by Brent's method
    while writing this, lay 0.18–0.29 beyond: with σ ≈ 0.1–0.2 it is within 0.7 of the
    fit, which is then the limit).  For a value inside 1σ it returns the value itself,
    allowed."""
    j = 0
    t, drop = profile(lik, fit, j, offsets=(-2.0, 2.0))
    assert np.allclose(np.log(t / fit.theta[j]), [-2 * fit.sigma_log[j], 2 * fit.sigma_log[j]])
    assert np.all((drop < -2 / 1.5) & (drop > -2 * 1.5)), drop
    for tj, d in zip(t, drop, strict=True):
        def f(lam_others, tj=tj):
            return -(lik.evaluate(np.r_[tj, np.exp(lam_others)]).loglik - fit.best.loglik)

        def jac(lam_others, tj=tj):
            h, g = 1e-3, np.empty(2)
            for k in range(2):
                up, down = lam_others.copy(), lam_others.copy()
                up[k] += h
                down[k] -= h
                g[k] = (f(up) - f(down)) / (2 * h)
            return g
        res = minimize(f, np.log(fit.theta[1:]), jac=jac, method="L-BFGS-B",
                       options={"ftol": 1e-12, "gtol": 1e-3})
        assert d <= -res.fun + 1e-4 and -res.fun - d <= 0.05, (d, -res.fun)
    target = fit.best.loglik - ONE_SIDED_95_DROP
    for j in range(3):
        value = 1000 * fit.theta[j]
        limit, allowed, _ = nearest_allowed(lik, fit, j, value)
        assert not allowed and fit.theta[j] <= limit < value

        def excess(lam, j=j):
            t = fit.theta.copy()
            t[j] = np.exp(lam)
            return lik.evaluate(t).loglik - target
        # ln L falls monotonically away from the fit, so these two say the crossing
        # lies in [limit, limit·e^0.7].
        assert excess(np.log(limit)) >= 0 > excess(np.log(limit) + 0.7), (j, limit)
        inside = fit.theta[j] * np.exp(0.5 * fit.sigma_log[j])
        assert nearest_allowed(lik, fit, j, inside)[:2] == (inside, True)


def test_nearest_allowed_rules_a_value_out_where_ln_L_has_fallen_by_the_95_percent_drop(
        lik, fit):
    """Whether ``nearest_allowed`` allows a value, against the one-sided 95% drop from
    scipy (``ONE_SIDED_95_DROP``, χ²₁(0.90)/2): along q_x, above and below the fit (the
    others held at it, as its slice is defined), the values where ln L has fallen by
    0.97 and 1.03 times the drop are found by Brent's method on ``evaluate`` (to 1e-5
    in ln θ, 1e-4 in ln L); the first must be allowed (and returned as it is), the
    second ruled out, with an allowed limit between the fit and it.  The ±3% margin is
    0.04 in ln L, against rounding of ~1e-9 in a ln L of 10⁵ (test_likelihood), so the
    verdicts cannot flip by arithmetic; a drop 3% off, or χ²₁(0.90) itself (not halved),
    or a two-sided 95% (χ²₁(0.95)/2 = 1.92), gives the wrong verdict on one of them.
    The crossings lie 1.7–1.8σ from the fit (1.645σ for an exact quadratic), inside
    the 1σ–3σ bracket searched."""
    j = 0
    lam_hat, s = np.log(fit.theta[j]), fit.sigma_log[j]

    def fall(lam):
        t = fit.theta.copy()
        t[j] = np.exp(lam)
        return fit.best.loglik - lik.evaluate(t).loglik

    for side in (1.0, -1.0):
        for share, allowed in ((0.97, True), (1.03, False)):
            lam = brentq(lambda x, share=share: fall(x) - share * ONE_SIDED_95_DROP,
                         lam_hat + side * s, lam_hat + side * 3 * s, xtol=1e-5)
            value = float(np.exp(lam))
            limit, ok, _ = nearest_allowed(lik, fit, j, value)
            assert ok is allowed, (side, share, fall(lam))
            if allowed:
                assert limit == value
            else:
                assert side * (limit - fit.theta[j]) >= 0 and side * (value - limit) > 0
                assert fall(np.log(limit)) <= ONE_SIDED_95_DROP, (side, limit)


def test_a_bound_that_excludes_the_maximum_holds_the_fit(lik):
    """q_z's lower bound at 3× its truth (≈ 6σ above the maximum) and q_x's upper
    bound at a third of its truth: the fit ends on both bounds, flagged −1 and +1,
    with no symmetric σ there (NaN) and not 'determined'; the central-difference
    gradient points out of the box on both (ln L would rise beyond them), and is
    zero within 0.1σ for the free q_w."""
    lower, upper = LOWER.copy(), UPPER.copy()
    lower[1] = 3 * TRUE.q_z
    upper[0] = TRUE.q_x / 3
    f = maximize(lik, THETA_START, lower, upper)
    assert list(f.at_bound) == [1, -1, 0]
    assert f.theta[0] == pytest.approx(upper[0], rel=1e-9)
    assert f.theta[1] == pytest.approx(lower[1], rel=1e-9)
    assert np.all(np.isnan(f.sigma_log[:2])) and list(f.determined) == [False, False, True]
    g = central_log_gradient(lik, f.theta)
    assert g[0] > 0 and g[1] < 0
    assert abs(g[2]) * f.sigma_log[2] < 0.1


def test_a_noise_the_data_do_not_inform_is_not_determined():
    """Data drawn with no roll torque noise at all (q_x = 0): below ~1e-9 (N m)² s the
    roll noise is lost under the Earth sensor's, so the likelihood is flat in ln q_x
    (it moves by 0.1 over three decades): σ of ln q_x comes out above 1 (a factor e)
    and q_x is not 'determined', while q_z and q_w are still recovered within 3σ.
    Above ~1e-8 it falls fast: there lies its 95% upper limit."""
    true = ProcessNoise(q_x=0.0, q_z=1e-6, q_w=5e-10)
    _, z = simulate(true, N, np.random.default_rng(5))
    z[9000:15700, 1] = np.nan
    model = noise_model(PARAMS, DT, GROUPS, true)
    lik = Likelihood(measurements(z), discretize(PARAMS, true, DT), np.zeros(N_STATES), P0,
                     model)
    f = maximize(lik, THETA_START, LOWER, UPPER)
    assert f.converged
    assert not f.determined[0] and not f.sigma_log[0] <= 1.0
    assert np.all(f.determined[1:])
    z = np.log(f.theta[1:] / np.array([true.q_z, true.q_w])) / f.sigma_log[1:]
    assert np.all(np.abs(z) < 3), z
    # What the telemetry allows of q_x instead: a one-sided 95% upper limit below the
    # scenario-like 1e-5, where ln L (the others at the fit) has fallen by χ²₁(0.90)/2,
    # found to 0.7 in ln θ on the allowed side (the crossing lies 2.7 above the fit in
    # ln θ here, so the search itself is exercised; measured: limit 1.54e-8 in 4
    # passes, the crossing at 1.97e-8).
    limit, allowed, _ = nearest_allowed(lik, f, 0, 1e-5)
    assert not allowed and f.theta[0] < limit < 1e-5
    target = f.best.loglik - ONE_SIDED_95_DROP

    def excess(lam):
        return lik.evaluate(np.r_[np.exp(lam), f.theta[1:]]).loglik - target
    assert excess(np.log(limit)) >= 0 > excess(np.log(limit) + 0.7), limit
    assert np.log(limit / f.theta[0]) > 1.0


# --------------------------------------------------------------------------- consistency


def test_white_noise_has_five_percent_of_lags_outside_the_bounds():
    """A white series of 40,000 with 10% of its samples missing at random and a
    block of 3000 gone: ρ(k) for k = 1 … 400 lie within ±1.96/√pairs 95% of the time,
    nearly independently of each other, so the share outside is binomial(400, 0.05)/400:
    0.05 ± 0.011; bounds 0.01–0.10 (±4.5σ; measured 0.0625).  ρ(0) = 1; the pair
    counts are the numbers of present pairs at each lag, counted here directly."""
    rng = np.random.default_rng(3)
    e = rng.standard_normal(40_000)
    e[rng.random(e.size) < 0.1] = np.nan
    e[20_000:23_000] = np.nan
    w = whiteness(e, 400)
    assert w["lags"] == 400
    assert 0.01 <= w["fraction_outside"] <= 0.10, w
    rho, pairs = autocorrelation(e, 400)
    assert rho[0] == pytest.approx(1.0, rel=1e-14)
    present = np.isfinite(e)
    for k in (0, 1, 2, 37, 400):
        assert pairs[k] == np.sum(present[:e.size - k] & present[k:])
    assert w["rho_1"] == rho[1]
    assert w["max_abs_rho"] == pytest.approx(np.abs(rho[1:]).max(), rel=1e-15)
    # Each ρ(k) of a white series is ~N(0, 1/pairs): the largest of 400 stays below 4σ
    # (measured 3.2σ).
    assert np.all(np.abs(rho[1:]) < 4 / np.sqrt(pairs[1:]))


def test_ar1_autocorrelation_is_a_to_the_k_with_gaps():
    """An AR(1) series e_t = a e_{t−1} + w_t (a = 0.8, zero mean) of 60,000 with 15% of
    samples missing and two blocks gone has ρ(k) = a^k.  Bartlett's formula gives the
    sampling error: var ρ̂(k) ≈ [(1 + a²)(1 − a^{2k})/(1 − a²) − 2k a^{2k}]/n_eff ≤
    4.6/n_eff, so σ ≤ 0.011 with n_eff ≥ 41,000 pairs; bound 5σ (measured ≤ 0.86σ).
    The estimator
    itself (mean of e_t e_{t+k} over present pairs, over the mean of e_t²) is checked
    against the sum written out lag by lag, to rounding of the FFT (1e-12)."""
    a, n = 0.8, 60_000
    rng = np.random.default_rng(4)
    w = rng.standard_normal(n) * np.sqrt(1 - a * a)
    w[0] /= np.sqrt(1 - a * a)                  # e_0 from the stationary N(0, 1)
    e = lfilter([1.0], [1.0, -a], w)
    e[rng.random(n) < 0.15] = np.nan
    e[10_000:12_000] = np.nan
    e[40_000:40_500] = np.nan
    max_lag = 30
    rho, pairs = autocorrelation(e, max_lag)
    k = np.arange(max_lag + 1)
    var = ((1 + a * a) * (1 - a ** (2 * k)) / (1 - a * a) - 2 * k * a ** (2 * k)) / pairs
    assert np.all(np.abs(rho - a ** k) <= 5 * np.sqrt(var) + 1e-12), rho - a ** k
    x = np.where(np.isfinite(e), e, 0.0)
    m = np.isfinite(e)
    direct = np.array([np.sum(x[:n - j] * x[j:]) / np.sum(m[:n - j] & m[j:]) for j in k])
    assert rho == pytest.approx(direct / direct[0], rel=0, abs=1e-12)
    # Far from white: every lag with a^k ≫ 1.96/√pairs (k ≤ 15, a^k ≥ 0.035 against
    # 0.009) is outside, ρ(1) ≈ a.
    white = whiteness(e, max_lag)
    assert white["fraction_outside"] >= 15 / 30
    assert white["rho_1"] == rho[1] == pytest.approx(a, abs=0.05)
