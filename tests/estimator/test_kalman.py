"""The Kalman filter and RTS smoother against independent references.

Φ, Γ and Q_d here come from scipy's expm and Van Loan's method, not from the
closed forms, so these tests check the filter alone.

The states have mixed units (rad next to N m s and N m), so covariances are compared
element by element in units of the reference's own √(P_ii P_jj) (``cov_dev``), and
estimates state by state in units of σ_i + |x_i| (``est_dev``): one absolute tolerance
across all states would check the torque states (P ~ 1e-12) not at all.
"""

from types import SimpleNamespace

import numpy as np
import pytest
import scipy.linalg as sl

from estimator.kalman.consistency import chi2_bounds, fraction_inside, nees, nis
from estimator.kalman.filter import (
    ExtraNoise,
    FilterResult,
    Measurements,
    kalman_filter,
    pack,
    rts_smoother,
    unpack,
)
from estimator.linear.model import (
    H_WHEEL,
    N_STATES,
    ModelParams,
    ProcessNoise,
    Y,
    dynamics_matrix,
    input_vector,
    noise_density,
)

from .cov_helpers import cov_dev
from .dense_reference import kalman_reference

DT = 0.512
# GOES-Next numbers from the paper (Section 2, Eq. 1), typed here independently.
H = -0.1082 * 2 * 5485 * 2 * np.pi / 60 * np.cos(np.deg2rad(1.656))
PARAMS = ModelParams(3364.376, 954.936, 3461.393, H, np.sqrt(3.986004418e14 / 42164170.0**3))
NOISE = ProcessNoise(q_x=5.4e-7, q_z=5.4e-7, q_w=5e-10, q_px=3e-18, q_pz=3e-18, q_cx=3e-18,
                     q_cz=3e-18)
R_ROLL, R_YAW, R_H = 3.3e-8, (0.04 * np.pi / 180) ** 2, 1.5e-7


def expm_discretization(p=PARAMS, q=NOISE, dt=DT):
    F, Q, n = dynamics_matrix(p), noise_density(p, q), N_STATES
    Phi = sl.expm(F * dt)
    aug = sl.expm(np.block([[F, np.eye(n)], [np.zeros((n, n)), np.zeros((n, n))]]) * dt)
    van = sl.expm(np.block([[-F, Q], [np.zeros((n, n)), F.T]]) * dt)  # Van Loan (1978)
    Qd = van[n:, n:].T @ van[:n, n:]
    Phi[np.abs(Phi) < 1e-300] = 0.0
    Phi[4:, :4] = 0.0  # structural zeros of Eq. 15 (expm leaves ~1e-20 there)
    Gam = aug[:n, n:]
    Gam[4:, :4] = 0.0
    return SimpleNamespace(Phi=Phi, Gamma=Gam, Qd=0.5 * (Qd + Qd.T))


DISC = expm_discretization()
P0 = np.diag([1e-6, 1e-6, 1e-4, 1e-6, 1e-4, 1e-12, 1e-12, 1e-12, 1e-12])


def simulate_linear(n_steps, n_runs, rng, disc=DISC, yaw_hours=16.0, u=None):
    """Truth and measurements of the linear model itself (Eq. 11), driven by noise
    of exactly the filter's statistics: x_{k+1} = Φx_k + Γu_k + w_k, w ~ N(0, Q_d)."""
    L = np.linalg.cholesky(disc.Qd + 1e-40 * np.eye(N_STATES))
    x = rng.multivariate_normal(np.zeros(N_STATES), P0, size=n_runs)
    xs = np.empty((n_steps, n_runs, N_STATES))
    u = np.zeros((n_steps, N_STATES)) if u is None else u
    PhiT = np.ascontiguousarray(disc.Phi.T)
    block = 4096  # noise drawn a block of steps at a time: the same stream, less overhead
    for start in range(0, n_steps, block):
        stop = min(start + block, n_steps)
        drive = (rng.standard_normal((stop - start, n_runs, N_STATES)) @ L.T
                 + (u[start:stop] @ disc.Gamma.T)[:, None, :])
        for k in range(start, stop):
            xs[k] = x
            x = x @ PhiT + drive[k - start]
    t_h = np.arange(n_steps) * DT / 3600
    sd = np.sqrt([R_ROLL, R_YAW, R_H])
    z = xs[..., [0, Y, H_WHEEL]] + sd * rng.standard_normal((n_steps, n_runs, 3))
    z[(t_h % 24) >= yaw_hours, :, 1] = np.nan
    return xs, z


def meas(z):
    return Measurements(z[:, 0], z[:, 1], z[:, 2], R_ROLL, R_YAW, R_H)


def est_dev(x, x_ref, P_ref) -> np.ndarray:
    """|x − x_ref| / (σ_i + |x_ref,i|): rounding of x scales with |x|, which reaches
    250 σ here (the estimate follows the truth, which is many σ from zero)."""
    return np.abs(x - x_ref) / (np.sqrt(np.einsum("...ii->...i", P_ref)) + np.abs(x_ref))


def test_compiled_filter_matches_dense_numpy_reference(rng):
    """With process noise, missing yaw and inputs: the compiled filter equals a
    plain-numpy filter (the same sequential Joseph algorithm, other rounding) element by
    element (``dense_reference.kalman_reference``, written in the tests from the
    textbook).  This checks the transcription, not the algorithm: the DARE test below
    is the independent check with process noise."""
    n = 3000
    u = input_vector(PARAMS, 1e-6 * np.sin(np.arange(n) / 500), -2e-6, 1e-5)
    xs, z = simulate_linear(n, 1, rng, u=u, yaw_hours=0.2)
    z = z[:, 0]
    z[::7, 0] = np.nan  # some roll and h gaps too
    z[::11, 2] = np.nan
    res = kalman_filter(meas(z), DISC, np.zeros(N_STATES), P0, u=u)
    ref = kalman_reference(z, (R_ROLL, R_YAW, R_H), DISC, np.zeros(N_STATES), P0, u=u)
    x_ref, P_ref = ref.x, ref.P
    # Rounding differences, amplified where an update cancels most of P (P0/R up to ~700
    # in the first steps) and carried over the filter's memory: measured 1.3e-14 in P and
    # 350 eps of σ + |x| in x (the same with DYNPROP_BACKEND=vm); 1e-11 for both.
    assert cov_dev(res.P, P_ref).max() < 1e-11
    assert est_dev(res.x, x_ref, P_ref).max() < 1e-11
    # No update where a value is missing: NaN innovation there, finite elsewhere.
    assert np.all(np.isnan(res.innovations[::7, 0]))
    assert np.all(np.isfinite(res.innovations[1::7, 0]))


def test_filter_started_at_the_dare_steady_state_stays_there():
    """With process noise: a filter started at the steady-state a-priori covariance of the
    discrete system (``scipy.linalg.solve_discrete_are``, all three measurements every
    step) stays there, a priori and a posteriori, for 2000 steps.

    The DARE's update is the batch one, P⁺ = P − PGᵀ(GPGᵀ + R)⁻¹GP; for a given P the
    filter's three sequential scalar Joseph updates (Eqs. 36–38) give the same P⁺ in exact
    arithmetic when R is diagonal, so the DARE's fixed point is the filter's too.  The DARE
    is solved in scaled coordinates z = S⁻¹x, S = diag(1, 1, 1, 1, |H|, |H|ω0 ×4) (h/|H| is
    the roll it offsets, N/(|H|ω0) the yaw a constant torque balances), where every state
    is an angle and the solution is good to ~eps × its condition; unscaled it is ~6e-9
    off."""
    n = 2000
    H, w0 = abs(PARAMS.H_Nms), PARAMS.omega0_radps
    s = np.array([1.0, 1.0, 1.0, 1.0, H, H * w0, H * w0, H * w0, H * w0])
    G = np.eye(N_STATES)[[0, Y, H_WHEEL]]
    Rm = np.diag([R_ROLL, R_YAW, R_H])
    Phi_z = DISC.Phi * s[None, :] / s[:, None]
    Pz = sl.solve_discrete_are(Phi_z.T, (G * s).T, DISC.Qd / np.outer(s, s), Rm)
    Gz = G * s
    Kz = np.linalg.solve(Gz @ Pz @ Gz.T + Rm, Gz @ Pz).T
    prior = np.outer(s, s) * 0.5 * (Pz + Pz.T)
    post_z = Pz - Kz @ Gz @ Pz
    post = np.outer(s, s) * 0.5 * (post_z + post_z.T)

    # The DARE solution's own error, as the change one batch step makes to it: ~eps × its
    # condition, ~1/(1 − |λ|²) for the torque states' slow closed-loop modes (|λ| = 1 −
    # 1.2e-6).  Measured 3e-11.
    step = DISC.Phi @ post @ DISC.Phi.T + DISC.Qd
    residual = cov_dev(step, prior).max()

    z = np.zeros((n, 3))   # the values do not enter P
    res = kalman_filter(meas(z), DISC, np.zeros(N_STATES), prior)
    # First step: the sequential Joseph updates equal the batch update of the same P⁻.
    # Steady-state gains are small (P⁻/P⁺ ≤ 1.05 on the diagonal), so little cancels: a few
    # roundings, measured 2e-16.
    assert cov_dev(unpack(res.P_packed[0]), post).max() < 1e-12
    # From there the filter moves by that residual toward its own fixed point: it settles
    # within ~100 steps in the fast closed-loop modes and drifts linearly in the slow ones,
    # so by at most ~n × residual.  Measured 1.0e-9 (the same with DYNPROP_BACKEND=vm);
    # allowed 10 n × residual (6.5e-7 here; it follows the DARE solver's accuracy on
    # another machine), at least 1e-7.
    tol = max(1e-7, 10 * n * residual)
    assert cov_dev(res.P, post).max() < tol
    assert cov_dev(res.P_next, prior).max() < tol


def test_no_process_noise_equals_batch_weighted_least_squares(rng):
    """Q = 0: the filter's final estimate is the batch weighted least-squares fit of
    the initial state (prior included as one more weighted observation), mapped to
    the final time, and its covariance is the inverse information mapped alike.  Exact
    equivalence, so a tight tolerance."""
    disc = expm_discretization(q=ProcessNoise(0, 0, 0))
    n = 4000
    xs, z = simulate_linear(n, 1, rng, disc=disc, yaw_hours=0.3)
    z = z[:, 0]
    x_prior = np.zeros(N_STATES)
    res = kalman_filter(meas(z), disc, x_prior, P0)
    # Batch: z_k = G_k Φ^k x0 + v_k, plus the prior x0 ~ N(x_prior, P0).
    rows, rhs, w = [], [], []
    Phik = np.eye(N_STATES)
    for k in range(n):
        for i, (idx, r) in enumerate(zip((0, Y, H_WHEEL), (R_ROLL, R_YAW, R_H), strict=True)):
            if np.isfinite(z[k, i]):
                rows.append(Phik[idx])
                rhs.append(z[k, i])
                w.append(1 / r)
        Phik = disc.Phi @ Phik
    A, b, W = np.array(rows), np.array(rhs), np.array(w)
    info = A.T @ (W[:, None] * A) + np.linalg.inv(P0)
    x0_hat = np.linalg.solve(info, A.T @ (W * b) + np.linalg.solve(P0, x_prior))
    x_final = np.linalg.matrix_power(disc.Phi, n - 1) @ x0_hat
    P_final = np.linalg.matrix_power(disc.Phi, n - 1) @ np.linalg.inv(info) \
        @ np.linalg.matrix_power(disc.Phi, n - 1).T
    sig = np.sqrt(np.diag(P_final))
    # Batch and recursion differ by rounding: eps × cond(information) ≲ 6e-10 for the
    # scalings tried; measured 3.4e-11 σ in x and 1.7e-13 in P (per element, in units of
    # √(P_ii P_jj)).  1e-8.
    assert np.max(np.abs(res.x[-1] - x_final) / sig) < 1e-8
    assert cov_dev(res.P[-1], P_final).max() < 1e-8


def test_diffuse_prior_equals_batch_least_squares_without_prior(rng):
    """The issue's form: Q = 0 and a diffuse prior (P0 × 1e8, where the prior's
    information is 1e-8 of the data's), so the final estimate equals batch weighted
    least squares on the data alone, to 1e-3 of its own σ.  The difference is the prior's
    own pull, not rounding: 6.5e-5 σ here, ∝ 1/1e8 (with the prior in the batch fit as well
    the two agree to 1e-9 σ)."""
    disc = expm_discretization(q=ProcessNoise(0, 0, 0))
    n = 6000
    _, z = simulate_linear(n, 1, rng, disc=disc, yaw_hours=24.0)
    z = z[:, 0]
    res = kalman_filter(meas(z), disc, np.zeros(N_STATES), P0 * 1e8)
    rows, rhs, w = [], [], []
    Phik = np.eye(N_STATES)
    for k in range(n):
        for i, (idx, r) in enumerate(zip((0, Y, H_WHEEL), (R_ROLL, R_YAW, R_H), strict=True)):
            rows.append(Phik[idx])
            rhs.append(z[k, i])
            w.append(1 / r)
        Phik = disc.Phi @ Phik
    A, b, W = np.array(rows), np.array(rhs), np.array(w)
    # Column scaling keeps the normal equations well conditioned.
    scale = np.sqrt(np.diag(P0))
    As = A * scale
    x0_hat = scale * np.linalg.lstsq(As * np.sqrt(W)[:, None], b * np.sqrt(W), rcond=None)[0]
    info_s = As.T @ (W[:, None] * As)
    Pn = np.linalg.matrix_power(disc.Phi, n - 1)
    x_final = Pn @ x0_hat
    sig = np.sqrt(np.diag(Pn @ (np.linalg.inv(info_s) * np.outer(scale, scale)) @ Pn.T))
    assert np.max(np.abs(res.x[-1] - x_final) / sig) < 1e-3


def test_nees_and_nis_within_chi2_bounds(rng):
    """Filter on its own linear model with matching noise, 30 independent runs of
    20 h: the run-averaged NEES of the attitude/rate/h states lies inside its 95%
    χ² bounds at ≥ 90% of the epochs after convergence; the 9-state NEES, averaged
    over runs and epochs, inside its 99% bounds; the averaged NIS likewise."""
    n_runs, n = 30, int(20 * 3600 / DT)
    xs, z = simulate_linear(n, n_runs, rng)
    keep = np.arange(2000, n, 500)  # after convergence, decimated
    nees_all, nees5_all, nis_all = [], [], []
    for j in range(n_runs):
        # Only the kept samples are stored (bit for bit the full run's, without its memory).
        res = kalman_filter(meas(z[:, j]), DISC, np.zeros(N_STATES), P0, rows=keep)
        P = unpack(res.P_packed)
        nees_all.append(nees(res.x, P, xs[keep, j]))
        nees5_all.append(nees(res.x, P, xs[keep, j], states=range(5)))
        nis_all.append(nis(res.innovations, res.innovation_var))
    # Attitude, rates and h decorrelate within minutes: a per-epoch test is fair.
    avg5 = np.mean(nees5_all, axis=0)
    assert fraction_inside(avg5, chi2_bounds(5, n_runs)) >= 0.90
    # The torque states barely move from their prior in 20 h, so each run's torque
    # error is one prior draw, constant in time: count one sample per run (99%).
    lo, hi = chi2_bounds(N_STATES, n_runs, 0.99)
    assert lo < np.mean(nees_all) < hi
    nis_all = np.array(nis_all)  # (runs, epochs, 3): roll and h always, yaw off in gaps
    for i in (0, 2):
        assert fraction_inside(nis_all[:, :, i].mean(axis=0), chi2_bounds(1, n_runs)) >= 0.90
    has_yaw = np.isfinite(nis_all[0, :, 1])
    assert has_yaw.any() and not has_yaw.all()
    yaw_avg = nis_all[:, has_yaw, 1].mean(axis=0)
    assert fraction_inside(yaw_avg, chi2_bounds(1, n_runs)) >= 0.90


def test_smoother_covariance_never_exceeds_the_filter_and_errors_are_consistent(rng):
    n_runs, n = 10, int(6 * 3600 / DT)
    xs, z = simulate_linear(n, n_runs, rng, yaw_hours=3.0)
    ratios, nees_s = [], []
    for j in range(n_runs):
        res = kalman_filter(meas(z[:, j]), DISC, np.zeros(N_STATES), P0)
        sm = rts_smoother(res, DISC)
        P_f = unpack(res.P_packed[::200])   # unpack only the samples used
        diff = P_f - unpack(sm.P_packed[::200])
        # P_filter − P_smoothed is positive semi-definite at every sample: the eigenvalues
        # of the difference in units of √(P_ii P_jj) are ≥ 0 up to the smoother's rounding
        # (its elements agree with a dense RTS to ~5e-12 in those units, test below).
        scale = np.sqrt(np.einsum("nii->ni", P_f))
        eig = np.linalg.eigvalsh(diff / scale[:, :, None] / scale[:, None, :])
        assert eig.min() > -1e-9
        ratios.append(sm.sigma[:, Y] / res.sigma[:, Y])
        nees_s.append(nees(sm.x[1000::500], unpack(sm.P_packed[1000::500]), xs[1000::500, j],
                           states=range(5)))
    assert np.all(np.concatenate(ratios) <= 1 + 1e-9)
    avg = np.mean(nees_s, axis=0)
    assert fraction_inside(avg, chi2_bounds(5, n_runs)) >= 0.90


def test_pack_unpack_round_trip():
    """Identity is the requirement here: packing and unpacking only move numbers."""
    a = np.random.default_rng(1).standard_normal((4, N_STATES, N_STATES))
    sym = a + np.swapaxes(a, 1, 2)
    np.testing.assert_array_equal(unpack(pack(sym)), sym)


def test_bad_inputs_are_rejected():
    z = np.zeros((5, 3))
    with pytest.raises(ValueError, match="variances"):
        kalman_filter(Measurements(z[:, 0], z[:, 1], z[:, 2], -1.0, 1.0, 1.0), DISC,
                      np.zeros(N_STATES), P0)
    with pytest.raises(ValueError, match="inputs"):
        kalman_filter(meas(z), DISC, np.zeros(N_STATES), P0, u=np.zeros((5, 3)))
    bad = SimpleNamespace(Phi=np.ones((9, 9)), Gamma=DISC.Gamma, Qd=DISC.Qd)
    with pytest.raises(ValueError, match="structure"):
        kalman_filter(meas(z), bad, np.zeros(N_STATES), P0)


def test_closed_form_discretization_drives_the_filter_like_expm(rng):
    """The filter's Φ, Γ, Q_d in production come from the closed forms
    (estimator.linear.transition); they must give the expm/Van Loan filter's results."""
    from estimator.linear.transition import discretize
    closed = discretize(PARAMS, NOISE, DT)
    n = 4000
    u = input_vector(PARAMS, 2e-6, -1e-6, 3e-6) * np.ones((n, 1))
    _, z = simulate_linear(n, 1, rng, u=u, yaw_hours=0.3)
    a = kalman_filter(meas(z[:, 0]), closed, np.zeros(N_STATES), P0, u=u)
    b = kalman_filter(meas(z[:, 0]), DISC, np.zeros(N_STATES), P0, u=u)
    # The two discretisations differ by a few eps (Q_d by 8e-16 of √(Q_ii Q_jj)); through
    # the filter that is measured 1.7e-14 in P and 7.5e-14 of σ + |x| in x.  1e-11.
    P_b = unpack(b.P_packed)
    assert cov_dev(unpack(a.P_packed), P_b).max() < 1e-11
    assert est_dev(a.x, b.x, P_b).max() < 1e-11


def test_smoother_matches_a_dense_rts_reference(rng):
    """Rauch–Tung–Striebel written out in numpy, from the filter's stored history."""
    n = 1500
    _, z = simulate_linear(n, 1, rng, yaw_hours=0.2)
    res = kalman_filter(meas(z[:, 0]), DISC, np.zeros(N_STATES), P0)
    sm = rts_smoother(res, DISC)
    x, P = res.x, res.P
    xs, Ps = x.copy(), P.copy()
    for k in range(n - 2, -1, -1):
        Pp = DISC.Phi @ P[k] @ DISC.Phi.T + DISC.Qd
        C = P[k] @ DISC.Phi.T @ np.linalg.inv(Pp)
        xs[k] = x[k] + C @ (xs[k + 1] - DISC.Phi @ x[k])
        Ps[k] = P[k] + C @ (Ps[k + 1] - Pp) @ C.T
    # The backward recursion subtracts nearly equal P^s_{k+1} − P⁻ and the compiled step
    # solves with P⁻ where this one inverts it, so rounding builds up over the 1500 steps:
    # measured 5.0e-12 in P (attitude states) and 3.3e-13 of σ + |x| in x.  1e-9.
    assert cov_dev(sm.P, Ps).max() < 1e-9
    assert est_dev(sm.x, xs, Ps).max() < 1e-9
    one = rts_smoother(kalman_filter(meas(z[:1, 0]), DISC, np.zeros(N_STATES), P0), DISC)
    assert one.x.shape == (1, N_STATES)
    # The state-only smoother (a long run's): the same recursion for x^s, with P⁻¹_pred
    # applied to one vector instead of forming the gain; the same bound.
    sx = rts_smoother(res, DISC, covariance=False)
    assert sx.P_packed is None
    assert est_dev(sx.x, xs, Ps).max() < 1e-9
    # In two stretches (a streamed run's window and its overlap), the later smoothed
    # first: the same steps, so the same bits (identity is the requirement here).
    k = 611
    tail = FilterResult(res.x[k:], res.P_packed[k:], res.innovations[k:],
                        res.innovation_var[k:], res.x_next, res.P_next, res.backend)
    head = FilterResult(res.x[:k], res.P_packed[:k], res.innovations[:k],
                        res.innovation_var[:k], res.x_next, res.P_next, res.backend)
    later = rts_smoother(tail, DISC, covariance=False)
    earlier = rts_smoother(head, DISC, covariance=False, x_after=later.x[0])
    assert np.array_equal(np.vstack([earlier.x, later.x]), sx.x)
    # With the covariance (a streamed estimate's smoothed.csv): from the later
    # stretch's smoothed x and P at its first sample, again the same steps and bits.
    later = rts_smoother(tail, DISC)
    earlier = rts_smoother(head, DISC, x_after=later.x[0], P_after=later.P_packed[0])
    assert np.array_equal(np.vstack([earlier.x, later.x]), sm.x)
    assert np.array_equal(np.vstack([earlier.P_packed, later.P_packed]), sm.P_packed)


def test_extra_noise_on_chosen_steps_matches_the_dense_references(rng):
    """``ExtraNoise`` (the dropout wheel-torque noise) adds scale_k · Q_unit to the
    propagation of the steps chosen: filter and smoother against numpy written out,
    with the unit Q_d from expm/Van Loan for q_w = 1 alone.  Zero scale everywhere
    must be the filter without it, bit for bit (the identity is the requirement: a
    run without dropouts may not change)."""
    n = 1500
    _, z = simulate_linear(n, 1, rng, yaw_hours=0.2)
    z = z[:, 0]
    z[400:700] = np.nan                          # a 150 s dropout: no roll, yaw or h
    unit = expm_discretization(q=ProcessNoise(q_x=0.0, q_z=0.0, q_w=1.0)).Qd
    scale = np.zeros(n)
    scale[399:700] = 3e-9                        # the steps that bridge it
    extra = ExtraNoise(scale, unit)
    res = kalman_filter(meas(z), DISC, np.zeros(N_STATES), P0, extra=extra)
    ref = kalman_reference(z, (R_ROLL, R_YAW, R_H), SimpleNamespace(**vars(DISC), Qe=unit),
                           np.zeros(N_STATES), P0, extra_scale=scale)
    x_ref, P_ref = ref.x, ref.P
    # As the dense comparison above: the same algorithm, other rounding.
    assert cov_dev(res.P, P_ref).max() < 1e-9
    assert est_dev(res.x, x_ref, P_ref).max() < 1e-9
    plain = kalman_filter(meas(z), DISC, np.zeros(N_STATES), P0)
    # The noise is there: σ_h² at the end of the dropout grows by Σ scale · Q_unit,hh
    # (4.6e-7 (N m s)²; the coupling to ẏ changes it by under 5%).
    grown = res.sigma[699, H_WHEEL] ** 2 - plain.sigma[699, H_WHEEL] ** 2
    assert grown == pytest.approx(scale.sum() * unit[H_WHEEL, H_WHEEL], rel=0.05)
    zero = kalman_filter(meas(z), DISC, np.zeros(N_STATES), P0,
                         extra=ExtraNoise(np.zeros(n), unit))
    assert np.array_equal(zero.x, plain.x) and np.array_equal(zero.P_packed, plain.P_packed)

    sm = rts_smoother(res, DISC, extra=extra)
    x, P = res.x, res.P
    xs, Ps = x.copy(), P.copy()
    for k in range(n - 2, -1, -1):
        Pp = DISC.Phi @ P[k] @ DISC.Phi.T + DISC.Qd + scale[k] * unit
        C = P[k] @ DISC.Phi.T @ np.linalg.inv(Pp)
        xs[k] = x[k] + C @ (xs[k + 1] - DISC.Phi @ x[k])
        Ps[k] = P[k] + C @ (Ps[k + 1] - Pp) @ C.T
    assert cov_dev(sm.P, Ps).max() < 1e-9
    assert est_dev(sm.x, xs, Ps).max() < 1e-9
    with pytest.raises(ValueError, match="extra noise"):
        kalman_filter(meas(z), DISC, np.zeros(N_STATES), P0,
                      extra=ExtraNoise(-scale, unit))


@pytest.mark.parametrize("chunk", [256, 4096])
def test_covariance_on_chosen_rows_is_the_full_runs(rng, chunk):
    """``covariance_rows``: the estimates, innovations and their variances at every
    sample and the covariance on the chosen ones are the full run's bit for bit (the
    same compiled steps; only what is kept differs), across chunk boundaries and the
    short final chunk; so is ``rows``, which keeps everything on the chosen ones."""
    n = 3000
    u = input_vector(PARAMS, 1e-6 * np.sin(np.arange(n) / 500), -2e-6, 1e-5)
    _, z = simulate_linear(n, 1, rng, u=u, yaw_hours=0.2)
    z = z[:, 0]
    z[::7, 0] = np.nan
    full = kalman_filter(meas(z), DISC, np.zeros(N_STATES), P0, u=u, chunk=chunk)
    keep = np.r_[0, 255, 256, 257, np.arange(300, n, 16), n - 1]
    cut = kalman_filter(meas(z), DISC, np.zeros(N_STATES), P0, u=u, chunk=chunk,
                        covariance_rows=keep)
    for name in ("x", "innovations", "innovation_var", "x_next", "P_next"):
        assert np.array_equal(getattr(cut, name), getattr(full, name), equal_nan=True), name
    assert np.array_equal(cut.P_packed, full.P_packed[keep])
    rows = kalman_filter(meas(z), DISC, np.zeros(N_STATES), P0, u=u, chunk=chunk, rows=keep)
    for name in ("x", "P_packed", "innovations", "innovation_var"):
        assert np.array_equal(getattr(rows, name), getattr(full, name)[keep], equal_nan=True)
    with pytest.raises(ValueError, match="increasing"):
        kalman_filter(meas(z), DISC, np.zeros(N_STATES), P0, covariance_rows=keep[::-1])
    with pytest.raises(ValueError, match="exclude"):
        kalman_filter(meas(z), DISC, np.zeros(N_STATES), P0, rows=keep, covariance_rows=keep)
