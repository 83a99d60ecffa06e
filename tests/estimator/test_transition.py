"""The closed-form propagation (estimator/linear/transition.py) against independent references.

References: scipy's expm of Fτ (Φ and its blocks φ, θ, ψ), of the augmented matrix
[[F, I], [0, 0]]τ (Γ) and Van Loan's [[−F, Q], [0, Fᵀ]]τ (Q_d; Van Loan 1978); an exact
rational-arithmetic Taylor series at the filter step; and the semigroup identities.
Parameter sets: GOES-Next (H < 0), the same with H > 0, and two made-up ones
(ω_n/ω0 = −30 and +3), so nothing is tuned to one case.
"""

from fractions import Fraction
from functools import cache

import numpy as np
import pytest
import scipy.linalg as sl
from hypothesis import given, settings
from hypothesis import strategies as st

from estimator.linear.model import ModelParams, ProcessNoise, blocks, dynamics_matrix, noise_density
from estimator.linear.transition import (
    Discretization,
    discretize,
    input_integral,
    phi_closed,
    process_noise_integral,
    psi_closed,
    theta_closed,
    transition_matrix,
)

# GOES-Next numbers from the paper (Section 2, Eq. 1), typed here independently.
W0 = np.sqrt(3.986004418e14 / 42164170.0**3)
H_GOES = -0.1082 * 2 * (5485 * 2 * np.pi / 60) * np.cos(np.deg2rad(1.656))
PARAMS = {
    "goes": ModelParams(3364.376, 954.936, 3461.393, H_GOES, W0),
    "goes_pos_H": ModelParams(3364.376, 954.936, 3461.393, -H_GOES, W0),
    "ratio_-30": ModelParams(1000.0, 800.0, 1200.0, -30 * 1e-3 * np.sqrt(1000 * 1200.0), 1e-3),
    "ratio_+3": ModelParams(1.8e4, 1.2e4, 2.2e4, 3 * 2e-4 * np.sqrt(1.8e4 * 2.2e4), 2e-4),
}
TAUS = [0.512, 1.0, 10.0, 173.0, 3600.0, 21600.0, 86400.0, 172800.0]
NOISE = ProcessNoise(q_x=5.4e-7, q_z=4e-7, q_w=5e-10, q_px=3e-18, q_pz=2e-18, q_cx=4e-18,
                     q_cz=1e-18)
_L = np.random.default_rng(20260321).standard_normal((9, 9))
Q_DENSE = _L @ _L.T   # couples every state, so every G_k Q G_lᵀ term is exercised
EPS = np.finfo(float).eps


def rel(a, b) -> float:
    """‖a − b‖_max / ‖b‖_max."""
    return float(np.abs(a - b).max() / np.abs(b).max())


def expm_tol(M: np.ndarray, tau: float) -> float:
    """Tolerance (max-norm relative, as ``rel``) against a float64 reference from
    ``scipy.linalg.expm(M τ)``: M = F for Φ, [[F, I], [0, 0]] for Γ, Van Loan's
    [[−F, Q], [0, Fᵀ]] for Q_d.  Scaling and squaring leaves that reference an error
    growing as eps‖Mτ‖ (and the float phase ω_n τ of either side carries eps|ω_n τ| ≤
    eps‖Fτ‖).  Measured: ≤ 18 eps (1 + ‖Mτ‖₁) over every case here and 1500 random
    parameter sets (the worst at ω_n τ ≈ 5000, ω0 τ ≈ 170); 2000 leaves a margin of 100.
    At the filter step that is 2.3e-13; at two days up to 5e-9."""
    return 2000 * EPS * (1 + np.linalg.norm(M * tau, 1))


def generators(p: ModelParams, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """F, the augmented [[F, I], [0, 0]] (Γ) and Van Loan's [[−F, Q], [0, Fᵀ]] (Q_d)."""
    F, Z = dynamics_matrix(p), np.zeros((9, 9))
    return F, np.block([[F, np.eye(9)], [Z, Z]]), np.block([[-F, Q], [Z, F.T]])


@cache
def expm_refs(name: str, tau: float, dense: bool):
    p = PARAMS[name]
    n = 9
    F, aug, vl = generators(p, Q_DENSE if dense else noise_density(p, NOISE))
    Phi = sl.expm(F * tau)
    Gam = sl.expm(aug * tau)[:n, n:]
    V = sl.expm(vl * tau)
    Qd = V[n:, n:].T @ V[:n, n:]      # Φ · (top-right block), Van Loan (1978)
    return Phi, Gam, 0.5 * (Qd + Qd.T)


CASES = [(name, tau) for name in PARAMS for tau in TAUS]


@pytest.mark.parametrize(("name", "tau"), CASES)
def test_phi_theta_psi_and_Phi_match_expm(name, tau):
    """Against expm(Fτ) block by block (tolerance: ``expm_tol``).  The zero block below φ
    is structural (every G_k is zero there), so it is checked for exact zeros."""
    p = PARAMS[name]
    E = expm_refs(name, tau, False)[0]
    tol = expm_tol(dynamics_matrix(p), tau)
    Phi = transition_matrix(p, tau)
    assert rel(phi_closed(p, tau), E[:4, :4]) <= tol
    assert rel(theta_closed(p, tau), E[:4, 4:]) <= tol
    assert rel(psi_closed(p, tau), E[4:, 4:]) <= tol
    assert rel(Phi, E) <= tol
    # Stable form = Eq. 22: both take cos/sin of the same float phases and sum O(1) pieces
    # (|ω_n/(ω_n − ω0)| ≤ 1.5), so they differ by a few roundings: measured ≤ 4.8e-16.
    assert rel(Phi[:4, :4], phi_closed(p, tau)) <= 1e-12
    assert np.all(Phi[4:, :4] == 0)
    # ψ ≤ 1 in magnitude, the same cos/sin of ω0τ by two routes (through the 1/ω0, 1/ω0²
    # factors of G_k and back): a few roundings of O(1) terms, measured ≤ 1.5 eps (3.3e-16);
    # 3e-14 ≈ 135 eps.
    np.testing.assert_allclose(Phi[4:, 4:], psi_closed(p, tau), rtol=0, atol=3e-14)


@pytest.mark.parametrize(("name", "tau"), CASES)
def test_gamma_and_qd_match_augmented_expm_and_van_loan(name, tau):
    """Γ and Q_d (Q of Eq. 34) at every τ (tolerance: ``expm_tol`` of the augmented and
    Van Loan matrices).  With the dense Q, Van Loan's own error grows past that beyond a
    few hundred seconds (1e-11 at 1 h, 1e-7–1e-5 at 1–2 days for these sets, against
    50-digit references: exp(−Fτ) and exp(Fτ) both carry θ's secular growth and Φ·V12
    cancels), so there the semigroup test below is the check."""
    p = PARAMS[name]
    _, Gam, Qd = expm_refs(name, tau, False)
    _, aug, vl = generators(p, noise_density(p, NOISE))
    assert rel(input_integral(p, tau), Gam) <= expm_tol(aug, tau)
    assert rel(process_noise_integral(p, NOISE, tau), Qd) <= expm_tol(vl, tau)
    if tau <= 173.0:
        vl_dense = generators(p, Q_DENSE)[2]
        assert rel(process_noise_integral(p, Q_DENSE, tau),
                   expm_refs(name, tau, True)[2]) <= expm_tol(vl_dense, tau)


def test_expm_reference_is_good_to_the_tolerance():
    """expm(Fτ) against expm(Fτ/3)³ at 2 days: two independent roundings of the reference
    agree to a fifth of ``expm_tol`` (measured: 1/160 of it at worst), so the tolerance
    granted to the reference covers its error.  (Not expm(Fτ/2)²: scaling and squaring
    computes expm(Fτ) as exactly that product, and the two agree bit for bit.)"""
    for name, p in PARAMS.items():
        F, tau = dynamics_matrix(p), TAUS[-1]
        E = expm_refs(name, tau, False)[0]
        third = sl.expm(F * tau / 3)
        assert rel(third @ third @ third, E) < expm_tol(F, tau) / 5, name


def _exact_taylor(p: ModelParams, Q: np.ndarray, tau: float, order: int = 24):
    """Φ, Γ, Q_d from their Taylor series in exact rational arithmetic (entries of F, Q and τ
    taken as the exact binary fractions they are): A_{k+1} = F A_k/(k+1),
    C_{k+1} = (F C_k + C_k Fᵀ)/(k+1), Φ = Σ A_k τ^k, Γ = Σ A_k τ^{k+1}/(k+1),
    Q_d = Σ C_k τ^{k+1}/(k+1).  Truncation < (2‖F‖τ)^25/25! ≈ 1e-30 for τ ≤ 10 s.

    Done in integers (F = F_i/d_F, Q = Q_i/d_Q, τ = a/b, every term over one common
    denominator), which is exact like ``Fraction`` arithmetic but ~70 times faster; the
    sums are rounded once, correctly (Python's int/int division)."""
    def ints(M):
        fr = [Fraction(float(v)) for v in M.ravel()]
        d = max(f.denominator for f in fr)           # powers of two: the largest is the lcm
        return np.array([int(f * d) for f in fr], dtype=object).reshape(M.shape), d

    Fi, dF = ints(dynamics_matrix(p))
    Qi, dQ = ints(np.asarray(Q))
    t = Fraction(tau)
    a, b, m = t.numerator, t.denominator, order
    fact = [1]
    for k in range(1, m + 2):
        fact.append(fact[-1] * k)
    A, C = np.eye(9, dtype=int).astype(object), Qi     # F_i^k and Ĉ_k = k! d_F^k d_Q C_k
    Phi, Gam, Qd = (np.zeros((9, 9), object) for _ in range(3))
    for k in range(m + 1):
        # Everything over D = (m+1)! (d_F b)^m b (times d_Q for Q_d).
        w_phi = fact[m + 1] // fact[k] * a**k * (dF * b) ** (m - k) * b
        w_int = fact[m + 1] // fact[k + 1] * a ** (k + 1) * (dF * b) ** (m - k)
        Phi, Gam, Qd = Phi + A * w_phi, Gam + A * w_int, Qd + C * w_int
        A, C = Fi.dot(A), Fi.dot(C) + C.dot(Fi.T)
    D = fact[m + 1] * (dF * b) ** m * b

    def to_float(M, den):
        return np.array([v / den for v in M.ravel()], dtype=float).reshape(M.shape)
    return to_float(Phi, D), to_float(Gam, D), to_float(Qd, D * dQ)


@pytest.mark.parametrize("name", ["goes", "ratio_-30"])
@pytest.mark.parametrize("tau", [0.512, 1.0, 10.0])
def test_every_element_is_exact_at_filter_steps(name, tau):
    """Element by element, not just in max norm: the small entries (θ's roll row, ~τ³, and
    their Q_d products, ~τ⁵–τ⁷) keep their relative accuracy at the 0.512 s filter step.
    Where the exact series is zero the closed form must be exactly zero too: those zeros are
    structural (zero entries of every G_k and of Q, multiplied, never computed to cancel)."""
    p = PARAMS[name]
    for Q in (noise_density(p, NOISE), Q_DENSE):
        ref = _exact_taylor(p, Q, tau)
        got = (transition_matrix(p, tau), input_integral(p, tau),
               process_noise_integral(p, Q, tau))
        for g, r in zip(got, ref, strict=True):
            nz = r != 0
            assert np.all(g[~nz] == 0)
            # Each element is a sum of a few terms that cancel mildly (the short basis is
            # in Newton order): measured ≤ 1.3e-15 (6 eps) relative; 2e-13 ≈ 900 eps.
            assert np.max(np.abs(g - r)[nz] / np.abs(r[nz])) < 2e-13


@pytest.mark.parametrize("name", list(PARAMS))
def test_semigroup_identities(name):
    """Φ(τ1+τ2) = Φ(τ2)Φ(τ1), Γ(τ1+τ2) = Γ(τ2) + Φ(τ2)Γ(τ1),
    Q_d(τ1+τ2) = Q_d(τ2) + Φ(τ2) Q_d(τ1) Φ(τ2)ᵀ, including sums that cross the switch
    between series and closed forms; Φ(0) = I, Γ(0) = Q_d(0) = 0 exactly (every f_k and
    each of their integrals carries a power of τ, so those zeros are structural)."""
    p = PARAMS[name]
    assert np.array_equal(transition_matrix(p, 0.0), np.eye(9))
    assert not input_integral(p, 0.0).any() and not process_noise_integral(p, Q_DENSE, 0.0).any()
    tn, t0 = 2 / abs(p.omega_n_radps), 2 / p.omega0_radps
    pairs = [(0.512, 0.512), (0.7 * tn, 0.6 * tn), (0.9 * t0, 0.3 * t0), (tn, t0), (3600, 86400)]
    pairs += [(t, t) for t in TAUS]
    for t1, t2 in pairs:
        P1, G1, Q1 = (f(p, t1) for f in (transition_matrix, input_integral,
                                         lambda p, t: process_noise_integral(p, Q_DENSE, t)))
        P2, G2, Q2 = (f(p, t2) for f in (transition_matrix, input_integral,
                                         lambda p, t: process_noise_integral(p, Q_DENSE, t)))
        # Products of matrices whose entries reach ‖Φ‖ ~ 1e3–1e4 at days (θ's secular
        # growth), relative to the largest entry: a few eps per product, plus eps|ω_n τ|
        # of the float phase.  Measured ≤ 7.2e-15 for all three; 1e-12.
        assert rel(P2 @ P1, transition_matrix(p, t1 + t2)) < 1e-12
        assert rel(G2 + P2 @ G1, input_integral(p, t1 + t2)) < 1e-12
        assert rel(Q2 + P2 @ Q1 @ P2.T, process_noise_integral(p, Q_DENSE, t1 + t2)) < 1e-12


@pytest.mark.parametrize("name", list(PARAMS))
def test_regime_switches_are_seamless(name):
    """Series and closed forms meet at |ω_n τ| = 2 and |ω0 τ| = 2 without a step."""
    p = PARAMS[name]
    for edge in (2 / abs(p.omega_n_radps), 2 / p.omega0_radps):
        taus = edge * (1 + np.arange(-8, 9) * 2.0**-52)   # a few ulp either side of it
        for f in (transition_matrix, input_integral,
                  lambda p, t: process_noise_integral(p, Q_DENSE, t)):
            M = f(p, taus)
            # Neighbours one ulp of τ apart: each side is good to a few ulps of its largest
            # O(1) pieces (the long basis's S_n and S_0 pieces partly cancel at |ω_n τ| = 2).
            # Measured ≤ 3.5e-15 (16 eps); 5e-13 is still far below any mismatch between
            # the two forms (a wrong or missing term is O(1e-3) or more).
            assert max(rel(a, b) for a, b in zip(M[:-1], M[1:], strict=True)) < 5e-13


@pytest.mark.parametrize("name", list(PARAMS))
def test_qd_is_symmetric_positive_semidefinite(name):
    """Exact symmetry is the requirement (identity): Q_d is returned as (X + Xᵀ)/2, whose
    two halves are the same floating-point sums."""
    p = PARAMS[name]
    for Q in (noise_density(p, NOISE), Q_DENSE):
        Qd = process_noise_integral(p, Q, np.array(TAUS))
        assert np.array_equal(Qd, np.swapaxes(Qd, -1, -2))
        for M in Qd:
            d = np.sqrt(np.diag(M))
            assert np.all(d > 0)
            # Eigenvalues of the 9×9 correlation matrix are good to ~9 eps; its smallest
            # is measured ≥ 2.4e-4 here, so −1e-12 only allows rounding.
            assert np.linalg.eigvalsh(M / np.outer(d, d)).min() > -1e-12


def test_vectorised_over_tau():
    """An array of τ gives what each τ alone gives.  The zero pattern is structural and must
    match exactly; the values may differ in the last bits (numpy's SIMD sin/cos for arrays
    and BLAS summation order depend on the shape and the CPU): measured ≤ 3.4e-17 relative
    to the largest entry; 1e-14 ≈ 45 eps."""
    p = PARAMS["goes"]
    tau = np.array([[0.0, 0.512, 30.0], [173.0, 3e4, 2e5]])
    for f in (phi_closed, psi_closed, theta_closed, transition_matrix, input_integral,
              lambda p, t: process_noise_integral(p, NOISE, t)):
        many = f(p, tau)
        assert many.shape[:2] == tau.shape
        for idx in np.ndindex(tau.shape):
            one = f(p, tau[idx])
            assert np.array_equal(many[idx] == 0, one == 0)
            assert np.abs(many[idx] - one).max() <= 1e-14 * np.abs(one).max()


def test_discretize_builds_the_filter_matrices():
    """Identity is the requirement here: ``discretize`` must hand the filter exactly the
    matrices ``transition_matrix``, ``input_integral`` and ``process_noise_integral`` give
    (one shared evaluation, no second code path).  Its speed is in ``make bench``."""
    p = PARAMS["goes"]
    d = discretize(p, NOISE, 0.512)
    assert isinstance(d, Discretization) and d.dt == 0.512
    np.testing.assert_array_equal(d.Phi, transition_matrix(p, 0.512))
    np.testing.assert_array_equal(d.Gamma, input_integral(p, 0.512))
    np.testing.assert_array_equal(d.Qd, process_noise_integral(p, NOISE, 0.512))
    with pytest.raises(ValueError):
        d.Phi[0, 0] = 2.0
    with pytest.raises(AttributeError):
        d.dt = 1.0
    # Structure of Eq. 15 (what estimator.kalman packs): zeros below φ and outside ψ.
    pattern = np.zeros((9, 9), bool)
    pattern[:4, :] = True
    pattern[4, 4] = pattern[7, 7] = pattern[8, 8] = True
    pattern[5:7, 5:7] = True
    assert not d.Phi[~pattern].any() and not d.Gamma[~pattern].any()


def test_rejects_bad_input():
    p = PARAMS["goes"]
    with pytest.raises(ValueError):
        transition_matrix(p, np.nan)
    with pytest.raises(ValueError):
        discretize(p, NOISE, 0.0)
    with pytest.raises(ValueError):
        process_noise_integral(p, np.triu(Q_DENSE), 1.0)


def _van_loan(F, Q, tau):
    n, Z = len(F), np.zeros_like(F)
    V = sl.expm(np.block([[-F, Q], [Z, F.T]]) * tau)
    return V[n:, n:].T @ V[:n, n:]


@settings(max_examples=60, deadline=None, derandomize=True)
@given(log_w0=st.floats(-5, -2), log_ratio=st.floats(np.log10(2.2), 3),
       sign=st.sampled_from([-1.0, 1.0]), log_H=st.floats(0.5, 2.5), frac=st.floats(0, 1))
def test_random_parameters_match_expm(log_w0, log_ratio, sign, log_H, frac):
    """Any momentum-biased set (|H| 3–300 N m s, ω_n/ω0 = ±2.2…±1000, ω0 = 1e-5…1e-2 rad/s)
    and τ from 0.1 s to min(2 days, 1000/|ω_n|, 30/ω0), so every series/closed-form
    combination is exercised.  For the largest ‖F‖τ the expm references themselves drift;
    ``expm_tol`` of each reference's generator allows for it (it was calibrated on 1500
    such draws)."""
    w0, H = 10.0**log_w0, sign * 10.0**log_H
    inertia = abs(H) / (10.0**log_ratio * w0)
    p = ModelParams(inertia, inertia / 2, inertia, H, w0)
    tau = 0.1 * (min(172800.0, 1000 / abs(p.omega_n_radps), 30 / w0) / 0.1) ** frac
    F, aug, vl = generators(p, noise_density(p, NOISE))
    refs = (sl.expm(F * tau), sl.expm(aug * tau)[:9, 9:], _van_loan(F, noise_density(p, NOISE),
                                                                   tau))
    closed = (transition_matrix(p, tau), input_integral(p, tau),
              process_noise_integral(p, NOISE, tau))
    for c, r, M in zip(closed, refs, (F, aug, vl), strict=True):
        assert rel(c, r) < expm_tol(M, tau)


# --- The paper as printed ------------------------------------------------------------------


def printed_eq22(w0, wn, tau):
    """Eq. 22b + 22c transcribed element by element from the printed paper."""
    c0, s0, cn, sn = np.cos(w0 * tau), np.sin(w0 * tau), np.cos(wn * tau), np.sin(wn * tau)
    phi0 = np.array([[wn * c0, -wn * s0, wn * s0, wn * c0],
                     [-w0 * s0, -w0 * c0, w0 * c0, -w0 * s0],
                     [-wn * s0, -wn * c0, wn * c0, -wn * s0],
                     [-w0 * c0, w0 * s0, -w0 * s0, -w0 * c0]]) / (wn - w0)
    phin = np.array([[-w0 * cn, wn * sn, -w0 * sn, -wn * cn],
                     [w0 * sn, wn * cn, -w0 * cn, wn * sn],
                     [w0 * sn, wn * cn, -w0 * cn, wn * sn],
                     [w0 * cn, -wn * sn, w0 * sn, wn * cn]]) / (wn - w0)
    return phi0 + phin


@pytest.mark.parametrize("name", list(PARAMS))
def test_printed_eq18_21_22_hold_element_by_element(name):
    """Eq. 22 as printed has no typo: every one of the 16 elements (|φ| ≤ ~1.5) matches
    exp(Aτ) to the reference's own accuracy, for H < 0 and H > 0 alike (ω_n signed,
    docs/paper-errata.md entry 1); Eq. 21's eigenvalues ±iω0, ±iω_n and Eq. 18's ψ hold
    too."""
    p = PARAMS[name]
    A, _, C = blocks(p)
    w0, wn = p.omega0_radps, p.omega_n_radps
    for tau in TAUS[:5]:
        E = sl.expm(A * tau)
        # measured ≤ 1.4e-13 at τ = 1 h (‖Aτ‖₁ ≈ 260, tolerance 1.2e-10)
        assert np.abs(printed_eq22(w0, wn, tau) - E).max() < expm_tol(A, tau)
        # The module's Eq. 22 and this transcription: same float phases, four O(1) pieces
        # summed in another order; measured ≤ 3.3e-16 (1.5 eps), 3e-14 ≈ 135 eps.
        np.testing.assert_allclose(phi_closed(p, tau), printed_eq22(w0, wn, tau), rtol=0,
                                   atol=3e-14)
        # ψ ≤ 1: measured ≤ 1.3e-14
        assert np.abs(psi_closed(p, tau) - sl.expm(C * tau)).max() < expm_tol(C, tau)
    # An eigenvalue is computed to about eps‖A‖ absolute (‖A‖ ≈ |ω_n|), which for ±iω0 is
    # ~eps|ω_n|/ω0 ≈ 1e-13 relative at GOES-Next (measured 1.1e-15 relative, 1e-19 absolute).
    ev = np.linalg.eigvals(A)
    atol = 100 * EPS * np.linalg.norm(A, 2)
    np.testing.assert_allclose(np.sort(np.abs(ev.imag)), np.sort([w0, w0, abs(wn), abs(wn)]),
                               rtol=0, atol=atol)
    assert np.abs(ev.real).max() < atol                   # measured 9e-17 |ω_n|


def test_eq22_needs_the_signed_nutation_rate():
    """With the printed ω_n = +0.0364 (Eq. 8) instead of H/I < 0, Eq. 22 is not exp(Aτ) for
    GOES-Next: the sign slip of erratum 1 matters, the formula itself does not."""
    p = PARAMS["goes"]
    E = sl.expm(blocks(p)[0] * 100.0)
    assert np.abs(printed_eq22(p.omega0_radps, abs(p.omega_n_radps), 100.0) - E).max() > 0.1


@pytest.mark.parametrize("name", list(PARAMS))
def test_theta_has_only_the_papers_six_time_dependences(name):
    """Sec. 3: θ's entries combine 1 − cn, sn, 1 − c0, s0, ω0τc0, ω0τs0 only (no constant,
    no plain τ).  Least squares of expm's θ on those six leaves only expm's own error."""
    p = PARAMS[name]
    w0, wn = p.omega0_radps, p.omega_n_radps
    tau = np.linspace(0, 2 / w0 + 40 / abs(wn), 400)
    x0, xn = w0 * tau, wn * tau
    basis = np.stack([1 - np.cos(xn), np.sin(xn), 1 - np.cos(x0), np.sin(x0),
                      x0 * np.cos(x0), x0 * np.sin(x0)], axis=1)
    F = dynamics_matrix(p)
    theta = np.array([sl.expm(F * t)[:4, 4:] for t in tau]).reshape(len(tau), -1)
    scale = np.abs(basis).max(0)
    coef = np.linalg.lstsq(basis / scale, theta, rcond=None)[0]
    # The residual is the references' own error (measured ≤ 3.5e-12 and, closed form
    # against them, 3.8e-12, at ‖Fτ‖₁ up to 6400): expm_tol at the longest τ.
    tol = expm_tol(F, tau[-1])
    assert rel(basis / scale @ coef, theta) < tol
    assert rel(theta_closed(p, tau).reshape(len(tau), -1), theta) < tol
