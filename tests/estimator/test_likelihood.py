"""The paper filter's log-likelihood and its derivatives in the noise parameters
(estimator/tuning/likelihood.py) against independent references.

References:

- ln L of the compiled pass against ``dense_reference.reference_loglik``, a
  plain-numpy filter in the tests with the textbook update, given Q_d from the closed
  form at the whole ``ProcessNoise`` θ sets (not from ``NoiseModel``'s Σ θ_j U_j),
  the roll factor as a scaled roll variance and the bridged dropout's noise as
  ``extra_Qd`` = max(e − q_w, 0)·Q_d(q_w=1) written out here; and
  ``reference_loglik`` itself against the joint Gaussian density of every
  measurement at once (no recursion at all) on a short record.
- ν and S of ``Likelihood.innovations`` against the production filter
  (``kalman.kalman_filter`` with ``ExtraNoise``).
- The hand-derived score and Fisher information against CasADi's forward-mode AD of
  the whole step (``derived=False``), against central differences of ``evaluate``
  in ln θ, and the expected information against the observed one on data drawn from
  the model.

The telemetry is drawn from the linear model itself (``lik_helpers``), with a yaw
gap, dropouts (NaN rows), NaNs in roll and h alone, per-sample yaw variance, inputs
u and a bridged-dropout noise above q_w on some steps and below it on others.
"""

from __future__ import annotations

import numpy as np
import pytest

from estimator.kalman.filter import ExtraNoise, Measurements, kalman_filter
from estimator.linear.model import N_STATES, ProcessNoise, input_vector
from estimator.linear.transition import discretize
from estimator.tuning.likelihood import Likelihood, noise_model

from .dense_reference import reference_loglik
from .lik_helpers import (
    DT,
    P0,
    PARAMS,
    R_H,
    R_ROLL,
    R_YAW,
    measurements,
    noise_at,
    simulate,
    simulate_many,
    unit_wheel_Qd,
)

FIXED = ProcessNoise(q_x=5.4e-7, q_z=4e-7, q_w=5e-10, q_px=3e-18, q_pz=2e-18, q_cx=4e-18,
                     q_cz=1e-18)
# Parameter sets the likelihood is built for: a tied pair, a held q_w (the bridge then
# subtracts the fixed one), a factor other than 1 in a group, a torque random walk,
# each with and without the roll-variance factor.
CASES = {
    "xz_tied+w+cz": ({"q_x=q_z": {"q_x": 1.0, "q_z": 1.0}, "q_w": {"q_w": 1.0},
                      "q_cz": {"q_cz": 1.0}}, False),
    "xz_tied+w+cz+roll": ({"q_x=q_z": {"q_x": 1.0, "q_z": 1.0}, "q_w": {"q_w": 1.0},
                           "q_cz": {"q_cz": 1.0}}, True),
    "x+z, w held, roll": ({"q_x": {"q_x": 1.0}, "q_z": {"q_z": 1.0}}, True),
    "x+2z, w, px": ({"q_x,2q_z": {"q_x": 1.0, "q_z": 2.0}, "q_w": {"q_w": 1.0},
                     "q_px": {"q_px": 1.0}}, False),
}
N = 4000


def theta_points(groups: dict, roll: bool) -> list[np.ndarray]:
    """θ where the checks are made: at FIXED's values, and moved by factors of a few
    (and the roll factor off 1), so that every term of the likelihood is exercised
    away from the model the data came from."""
    base = np.array([getattr(FIXED, next(iter(g))) / next(iter(g.values()))
                     for g in groups.values()] + ([1.0] if roll else []))
    moved = base * np.array([3.0, 0.2, 7.0, 1.6][:len(base)])
    return [base, moved]


@pytest.fixture(scope="module")
def record():
    """4000 samples (34 min) of the model at FIXED: inputs, a 9-minute yaw gap,
    dropouts of 21, 1 and 3 rows bridged with wheel noise (10 q_w, 0.4 q_w, 20 q_w),
    scattered single roll and h gaps, and a yaw variance that varies per sample."""
    rng = np.random.default_rng(20260321)
    k = np.arange(N)
    u = input_vector(PARAMS, 1e-6 * np.sin(k / 500), -2e-6 + 1e-6 * np.cos(k / 300), 1e-5)
    e = np.zeros(N)
    dropouts = [(700, 721, 10 * FIXED.q_w), (3100, 3101, 0.4 * FIXED.q_w),
                (3300, 3303, 20 * FIXED.q_w)]
    for a, b, q in dropouts:   # steps a−1 … b−1 bridge rows a … b−1
        e[a - 1:b] = q
    var_yaw = R_YAW * (0.5 + 2.5 * rng.random(N))
    _, z = simulate(FIXED, N, rng, u=u, extra=e, var_yaw=var_yaw)
    z[1500:2600, 1] = np.nan
    z[::13, 0] = np.nan
    z[5::17, 2] = np.nan
    for a, b, _ in dropouts:
        z[a:b] = np.nan
    return {"z": z, "u": u, "e": e, "var_yaw": var_yaw,
            "x0": 1e-4 * np.arange(N_STATES) / N_STATES}


def likelihood(record, groups, roll) -> Likelihood:
    model = noise_model(PARAMS, DT, groups, FIXED, roll)
    disc = discretize(PARAMS, FIXED, DT)
    meas = measurements(record["z"], var_yaw=record["var_yaw"])
    return Likelihood(meas, disc, record["x0"], P0, model, u=record["u"],
                      bridge_noise=record["e"])


def reference(record, groups, roll, theta) -> tuple[Measurements, np.ndarray, np.ndarray]:
    """What the filter at θ is, built without ``NoiseModel``: the measurements (roll
    variance times the roll factor), Q_d of the whole ProcessNoise θ sets, and each
    step's extra noise max(e − q_w, 0)·Q_d(q_w = 1)."""
    q = noise_at(groups, FIXED, theta)
    factor = theta[-1] if roll else 1.0
    meas = measurements(record["z"], var_roll=R_ROLL * factor, var_yaw=record["var_yaw"])
    extra = np.maximum(record["e"] - q.q_w, 0.0)[:, None, None] * unit_wheel_Qd()
    return meas, discretize(PARAMS, q, DT).Qd, extra


def _z_and_r(meas: Measurements) -> tuple[np.ndarray, np.ndarray]:
    """The measurements (N, 3) and their variances (N, 3) from the fields themselves,
    for the reference (not through ``Measurements``' own stacking)."""
    n = len(meas.roll_rad)
    z = np.column_stack([meas.roll_rad, meas.yaw_rad, meas.h_Nms])
    r = np.column_stack([np.broadcast_to(np.asarray(v, dtype=float), (n,))
                         for v in (meas.var_roll, meas.var_yaw, meas.var_h)])
    return z, r


def terms_scale(S: np.ndarray, nu: np.ndarray) -> float:
    """Σ |½ (ln 2πS + ν²/S)| over the updates: the size of what ln L sums."""
    ok = np.isfinite(nu)
    return float(0.5 * np.sum(np.abs(np.log(2 * np.pi * S[ok])) + nu[ok] ** 2 / S[ok]))


# --------------------------------------------------------------------------- ln L


@pytest.mark.parametrize("case", list(CASES))
def test_compiled_loglik_equals_dense_numpy_reference(record, case):
    """ln L of one compiled pass equals the plain-numpy filter's at two θ each.

    Tolerance: the two filters differ in rounding only (Joseph against textbook
    update, Q_d as Q_fixed + Σ θ_j U_j against the closed form at once, the order of
    the sums).  Each of the ~11,000 terms (|ln 2πS| ≈ 15) then carries a relative
    error of the order of the filter's own, ~1e-13 (``test_kalman``'s compiled-vs-dense
    comparison: 1e-14 in P, 350 eps in x); summed with random signs that is
    ~1e-13/√N ≈ 1e-15 of Σ|terms|, and 1e-13 of it if every sign agreed.  Measured:
    ≤ 5e-15 of Σ|terms| (also in the VM with another BLAS kernel).  The bound, 1e-11
    of Σ|terms| (≈ 1e-6 in ln L ≈ 7e4), is 100× the worst case and far below any
    change of the model (the bridge noise moved by one step shifts ln L by ~1e-2)."""
    groups, roll = CASES[case]
    lik = likelihood(record, groups, roll)
    for theta in theta_points(groups, roll):
        ev = lik.evaluate(theta)
        meas, Qd, extra = reference(record, groups, roll, theta)
        disc = discretize(PARAMS, FIXED, DT)
        ref = reference_loglik(*_z_and_r(meas), disc.Phi, disc.Gamma, Qd, record["x0"], P0,
                               u=record["u"], extra_Qd=extra)
        nu, S = lik.innovations(theta)
        scale = terms_scale(S, nu)
        assert abs(ev.loglik - ref) <= 1e-11 * scale, (case, theta, ev.loglik, ref)
        # The sums ln L is made of, per measurement kind, add up to it, and the counts
        # are the present values.
        present = np.isfinite(record["z"]).sum(axis=0)
        assert np.array_equal(ev.counts, present)
        total = -0.5 * (ev.sum_log_S.sum() + ev.sum_nis.sum() + np.log(2 * np.pi) * present.sum())
        assert total == pytest.approx(ev.loglik, rel=1e-14)
        # ν and S of ``innovations`` give the same ln L term by term.
        ok = np.isfinite(nu)
        assert np.array_equal(ok, np.isfinite(record["z"]))
        direct = -0.5 * np.sum(np.log(2 * np.pi * S[ok]) + nu[ok] ** 2 / S[ok])
        assert abs(direct - ref) <= 1e-11 * scale


def test_dense_reference_equals_the_joint_gaussian_density(record):
    """``reference_loglik`` against the likelihood written without any recursion: the
    measurements of the first 60 samples are jointly Gaussian, z = G X + v, with the
    states' mean μ_{k+1} = Φ μ_k + Γ u_k and covariance Cov(x_{k+1}, x_j) =
    Φ Cov(x_k, x_j), Var(x_{k+1}) = Φ Var(x_k) Φᵀ + Q_d + extra_k; ln L = ln N(z; Gμ,
    G Σ Gᵀ + R) from a Cholesky factor.  The record's first samples are cut so that
    they hold a dropout with its bridge noise, single roll and h gaps and, with yaw
    blanked for 20 samples, a yaw gap.

    Tolerance: the joint covariance (≤ 180 × 180) has condition ~1e7 (P0's yaw 1e-4
    rad² against R_roll 3e-8), so its log-determinant and quadratic form are good to
    ~1e7 eps ≈ 2e-9 absolute; measured 4e-12 on ln L ≈ 604 (compiled, and in the VM
    with another BLAS kernel).  1e-7 absolute."""
    sl = slice(690, 750)   # the 21-row dropout at 700 and its bridge
    z = record["z"][sl].copy()
    z[30:50, 1] = np.nan
    n = len(z)
    u, e, var_yaw = record["u"][sl], record["e"][sl], record["var_yaw"][sl]
    q = ProcessNoise(q_x=2e-6, q_z=1e-6, q_w=1e-9, q_px=3e-18, q_pz=2e-18, q_cx=4e-18,
                     q_cz=1e-18)
    roll_factor = 1.7
    meas = measurements(z, var_roll=R_ROLL * roll_factor, var_yaw=var_yaw)
    disc = discretize(PARAMS, q, DT)
    extra = np.maximum(e - q.q_w, 0.0)[:, None, None] * unit_wheel_Qd()
    assert np.any(extra[:, 4, 4] > 0)
    x0 = record["x0"]
    ref = reference_loglik(*_z_and_r(meas), disc.Phi, disc.Gamma, disc.Qd, x0, P0, u=u,
                           extra_Qd=extra)

    mu = np.empty((n, N_STATES))
    C = np.zeros((n, n, N_STATES, N_STATES))   # C[k, j] = Cov(x_k, x_j)
    mu[0], C[0, 0] = x0, P0
    for k in range(n - 1):
        mu[k + 1] = disc.Phi @ mu[k] + disc.Gamma @ u[k]
        for j in range(k + 1):
            C[k + 1, j] = disc.Phi @ C[k, j]
            C[j, k + 1] = C[k + 1, j].T
        C[k + 1, k + 1] = disc.Phi @ C[k, k] @ disc.Phi.T + disc.Qd + extra[k]
    states = [0, 2, 4]   # roll, yaw, h
    var = np.column_stack([np.full(n, R_ROLL * roll_factor), var_yaw, np.full(n, R_H)])
    idx = [(k, i) for k in range(n) for i in range(3) if np.isfinite(z[k, i])]
    zz = np.array([z[k, i] for k, i in idx])
    m = np.array([mu[k, states[i]] for k, i in idx])
    cov = np.array([[C[k, j, states[a], states[b]] for j, b in idx] for k, a in idx])
    cov += np.diag([var[k, i] for k, i in idx])
    L = np.linalg.cholesky(cov)
    w = np.linalg.solve(L, zz - m)
    joint = -0.5 * (len(zz) * np.log(2 * np.pi) + 2 * np.sum(np.log(np.diag(L))) + w @ w)
    assert ref == pytest.approx(joint, abs=1e-7)


@pytest.mark.parametrize("case", ["xz_tied+w+cz+roll", "x+z, w held, roll"])
def test_innovations_are_the_production_filters(record, case):
    """``Likelihood.innovations`` at θ equal the ν and S of ``kalman.kalman_filter``
    run with the noise θ sets, the roll variance scaled and ``ExtraNoise`` of
    max(e − q_w, 0): the likelihood is of the filter the runs use.

    Tolerance: the same Joseph-form algorithm; only Q_d is summed differently
    (Σ θ_j U_j against the closed form at once), ~1e-16 of Q_d per step, carried
    through the filter like any rounding (``test_kalman``: 1e-11).  ν is compared
    in units of √S (it is the difference of z and x̂, each ~100 √S away from zero), S
    relatively.  Measured: equal bit for bit (both backends); bound 1e-10."""
    groups, roll = CASES[case]
    lik = likelihood(record, groups, roll)
    theta = theta_points(groups, roll)[1]
    nu, S = lik.innovations(theta)
    meas, _, _ = reference(record, groups, roll, theta)
    q = noise_at(groups, FIXED, theta)
    extra = ExtraNoise(np.maximum(record["e"] - q.q_w, 0.0), unit_wheel_Qd())
    res = kalman_filter(meas, discretize(PARAMS, q, DT), record["x0"], P0, u=record["u"],
                        extra=extra)
    ok = np.isfinite(res.innovations)
    assert np.array_equal(ok, np.isfinite(nu))
    assert np.abs(nu[ok] - res.innovations[ok]).max() <= 1e-10 * np.sqrt(S[ok]).min()
    assert np.abs(S[ok] / res.innovation_var[ok] - 1).max() <= 1e-10


# --------------------------------------------------------------------------- score and Fisher


@pytest.mark.parametrize("case", list(CASES))
def test_derived_score_and_fisher_equal_automatic_differentiation(record, case):
    """The hand-derived sensitivity recursion (``score_step``) against CasADi's
    forward-mode AD of the whole step, Joseph form and all (``score_step_ad``).

    Tolerance: in exact arithmetic the two are equal (the Joseph form's gain terms
    vanish at the optimal gain); they round differently.  The gradient is compared
    in units of the information's own scale √I_jj (a σ of the parameter: an error
    of 1e-8 √I_jj moves a Newton step by 1e-8 σ), the information element by element
    in units of √(I_jj I_kk).  Measured ≤ 1.2e-13 for both (the same in the VM with
    another BLAS kernel); bound 1e-10."""
    groups, roll = CASES[case]
    lik = likelihood(record, groups, roll)
    for theta in theta_points(groups, roll):
        d = lik.score(theta)
        a = lik.score(theta, derived=False)
        assert d.loglik == pytest.approx(lik.evaluate(theta).loglik, rel=1e-13)
        assert a.loglik == pytest.approx(d.loglik, rel=1e-13)
        root = np.sqrt(np.diag(a.fisher))
        assert np.all(root > 0)
        assert np.all(np.abs(d.score - a.score) <= 1e-10 * root), (d.score, a.score)
        assert np.abs((d.fisher - a.fisher) / np.outer(root, root)).max() <= 1e-10


@pytest.mark.parametrize("case", list(CASES))
def test_score_equals_central_differences_of_the_likelihood(record, case):
    """∂ln L/∂ln θ_j = θ_j ∂ln L/∂θ_j against the central difference of ``evaluate``
    in ln θ_j with step h = 1e-3, Richardson-extrapolated with 2h: D = (4 D_h − D_2h)/3.

    Error of D: truncation (h⁴/30)·|∂⁵ ln L/∂ln θ_j⁵|, which for derivatives of the
    order of the information I_jj (in ln θ) is ~1e-13 I_jj, far below; and rounding,
    ≈ 1.5 δ/h with δ the rounding of one ln L.  δ: the compiled and numpy passes
    differ by ≤ 5e-15 of Σ|terms| (the test above), so δ ≤ 1e-14 Σ|terms| ≈ 7e-10.
    Bound: 1e-6 √I_jj (a millionth of the score one σ away) + 2δ/h.  Measured:
    ≤ 3e-8 √I_jj where the telemetry informs θ_j; for the torque random walks
    (√I_jj ≈ 2e-5 in 34 minutes) rounding dominates, ≤ 5e-8 absolute against a floor
    of 1.4e-6 (and the gradient itself ~1e-4).  A dropped or wrong term moves the
    score by a sizeable fraction of itself."""
    groups, roll = CASES[case]
    lik = likelihood(record, groups, roll)
    h = 1e-3
    for theta in theta_points(groups, roll):
        d = lik.score(theta)
        nu, S = lik.innovations(theta)
        rounding = 1e-14 * terms_scale(S, nu)
        root_log = np.sqrt(np.diag(d.fisher)) * theta
        for j in range(len(theta)):
            def at(step, j=j, theta=theta):
                t = theta.copy()
                t[j] *= np.exp(step)
                return lik.evaluate(t).loglik
            d1 = (at(h) - at(-h)) / (2 * h)
            d2 = (at(2 * h) - at(-2 * h)) / (4 * h)
            fd = (4 * d1 - d2) / 3
            derived = d.score[j] * theta[j]
            tol = 1e-6 * root_log[j] + 2 * rounding / h
            assert abs(derived - fd) <= tol, (case, j, derived, fd, tol)


def test_fisher_is_symmetric_positive_semidefinite_and_subsets_are_its_blocks(record):
    """The information is symmetric and positive semi-definite (a sum of outer
    products ½ ∂S∂Sᵀ/S² + ∂ν∂νᵀ/S); ``subset=`` gives the corresponding entries of
    the full pass's gradient and information.  Subset and full passes are different
    compiled functions of the same expressions: rounding only, measured equal bit
    for bit; bound 1e-12 (score in units of √I_jj, information of √(I_jj I_kk))."""
    groups, roll = CASES["xz_tied+w+cz+roll"]
    lik = likelihood(record, groups, roll)
    for theta in theta_points(groups, roll):
        full = lik.score(theta)
        F = full.fisher
        assert np.array_equal(F, F.T)
        root = np.sqrt(np.diag(F))
        eig = np.linalg.eigvalsh(F / np.outer(root, root))
        assert eig.min() >= -1e-12
        for subset in ([0], [2], [1, 3], [3, 0], [0, 1, 2, 3]):
            sub = lik.score(theta, subset=subset)
            idx = np.array(subset)
            assert np.array_equal(sub.subset, idx)
            assert sub.loglik == pytest.approx(full.loglik, rel=1e-14)
            assert np.all(np.abs(sub.score - full.score[idx]) <= 1e-12 * root[idx])
            assert np.abs((sub.fisher - F[np.ix_(idx, idx)])
                          / np.outer(root[idx], root[idx])).max() <= 1e-12


@pytest.mark.slow_in_vm
def test_fisher_information_is_the_covariance_of_the_score_on_model_data():
    """At the θ the data came from, the score is a sum of martingale increments
    g_t = −½ (∂S/S)(1 − ν²/S) − ∂ν ν/S with ν ~ N(0, S) given the past, and ∂S, ∂ν
    functions of the past, so E[g gᵀ] = E[Σ ½ ∂S∂Sᵀ/S² + ∂ν∂νᵀ/S] exactly, at any record
    length: the information the pass accumulates is the covariance of its score.
    Over M = 400 records of 3000 samples (with a yaw gap) drawn from the model, the
    score's sample covariance, whitened by the mean information (I⁻¹ᐟ² C I⁻¹ᐟ²),
    must be the identity: each diagonal element has standard error √(2/M) = 0.071,
    each off-diagonal 1/√M = 0.05; bounds 0.3 and 0.2 (≥ 4σ; measured 0.18 and 0.10
    here, ≤ 0.10 and 0.10 with three other seeds).  The mean score must vanish:
    within 4/√M in units of the whitened σ (measured 1.2/√M).  A factor 2 in either
    term of the information (the ½, or 1/S for 1/S²) moves a diagonal element by 0.5
    or more.  Statistical, a few seconds compiled and half a minute in the VM:
    compiled pass only (the check is of the formula, not of last bits)."""
    groups = {"q_x": {"q_x": 1.0}, "q_z": {"q_z": 1.0}, "q_w": {"q_w": 1.0}}
    true = ProcessNoise(q_x=3e-6, q_z=1e-6, q_w=5e-10)
    n, m = 3000, 400
    z_all = simulate_many(true, n, m, np.random.default_rng(11))
    z_all[:, 1200:1800, 1] = np.nan
    model = noise_model(PARAMS, DT, groups, true, roll=True)
    disc = discretize(PARAMS, true, DT)
    theta = np.array([true.q_x, true.q_z, true.q_w, 1.0])
    scores, infos = [], []
    for z in z_all:
        ev = Likelihood(measurements(z), disc, np.zeros(N_STATES), P0, model).score(theta)
        scores.append(ev.score * theta)                  # in ln θ
        infos.append(ev.fisher * np.outer(theta, theta))
    g, F = np.array(scores), np.mean(infos, axis=0)
    w, V = np.linalg.eigh(F)
    W = V @ np.diag(w ** -0.5) @ V.T                     # F^(−1/2)
    gw = g @ W
    C = gw.T @ gw / m
    off = C - np.diag(np.diag(C))
    assert np.abs(np.diag(C) - 1).max() <= 0.3, np.diag(C)
    assert np.abs(off).max() <= 0.2, C
    assert np.abs(gw.mean(axis=0)).max() <= 4 / np.sqrt(m)
