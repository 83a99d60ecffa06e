"""The filter with sensor-bias states and outlier gating (``estimator.augmented``).

The compiled steps against a textbook reference written in the tests
(``dense_reference``: its own prior, F_a, Q_a, expm/Van Loan discretisation and rows)
and against the paper's filter; then the physics on the linear model's own
measurements (Eq. 11 driven by noise of exactly the filter's statistics, drawn from the
reference's prior and Φ, Q_d; the paper's R from ``estimator.analysis.covariance``): biases
recovered and consistent, spikes gated, a random walk's σ growing as √(q t), and what
the measurements cannot separate (a constant bias from a constant torque).

Estimates are compared state by state in units of σ_i + |x_i| and covariances element
by element in units of √(P_ii P_jj), as in test_kalman.py: the states mix rad, N m s and
N m.
"""

import numpy as np
import pytest
from scipy.stats import chi2

from estimator.analysis.observability import rank_progression, unobservable_subspace
from estimator.augmented.filter import (
    BiasModel,
    _roll,
    augmented_filter,
    augmented_model,
    augmented_params,
    augmented_prior,
    augmented_smoother,
    measurement_row,
)
from estimator.augmented.steps import engine
from estimator.kalman.filter import ExtraNoise, Measurements, kalman_filter, rts_smoother
from estimator.linear.model import H_WHEEL, N_STATES, NCX, NCZ, ProcessNoise, R, Y, input_vector
from estimator.linear.noise import h_variance, roll_variance, yaw_variance
from estimator.linear.transition import discretize

from . import dense_reference as ref
from .cov_helpers import cov_dev
from .test_kalman import DT, NOISE, PARAMS

H = PARAMS.H_Nms

DISC = discretize(PARAMS, NOISE, DT)
R3 = np.array([roll_variance(), yaw_variance(), h_variance()])   # Eqs. 46–47
P0 = np.diag([1e-6, 1e-6, 1e-4, 1e-6, 1e-4, 1e-12, 1e-12, 1e-12, 1e-12])
DEG = np.pi / 180
BIASES = BiasModel.of(earth_roll=(0.1 * DEG, 0.0), dss_yaw=(0.1 * DEG, 0.0))
ROLL_BIAS = BiasModel.of(earth_roll=(0.1 * DEG, 0.0))
YAW_BIAS = BiasModel.of(dss_yaw=(0.1 * DEG, 0.0))
HEAD_BIAS = ("dss_yaw", "cass1_yaw", "cass2_yaw")


def simulate(n_steps, n_runs, rng, bias, yaw_on, head, b_true=None):
    """Truth (n_steps, n_runs, 9 + nb) of the augmented linear model from its prior (the
    biases ``b_true`` if given) and the measurements r + b_roll, y + b_head (where
    ``yaw_on``; a head without a bias state measures y) and h, with the paper's R.
    Prior, Φ and Q_d are the reference's (``dense_reference``), not the package's."""
    d = ref.discretization(PARAMS, NOISE, bias, DT)
    Phi, Qd = d.Phi, d.Qd
    n = len(Phi)
    L = np.linalg.cholesky(Qd + 1e-40 * np.eye(n))
    x = rng.multivariate_normal(np.zeros(n), ref.prior(np.zeros(9), P0, bias)[1],
                                size=n_runs)
    if b_true is not None:
        x[:, N_STATES:] = b_true
    xs, PhiT = np.empty((n_steps, n_runs, n)), np.ascontiguousarray(Phi.T)
    for start in range(0, n_steps, 4096):   # noise a block at a time: less overhead
        stop = min(start + 4096, n_steps)
        drive = rng.standard_normal((stop - start, n_runs, n)) @ L.T
        for k in range(start, stop):
            xs[k] = x
            x = x @ PhiT + drive[k - start]
    z = np.stack([xs[..., R], xs[..., Y], xs[..., H_WHEEL]], axis=-1)
    names = bias.names
    if "earth_roll" in names:
        z[..., 0] += xs[..., N_STATES + names.index("earth_roll")]
    for code, name in enumerate(HEAD_BIAS):
        if name in names:
            z[..., 1] += (head == code)[:, None] * xs[..., N_STATES + names.index(name)]
    z += np.sqrt(R3) * rng.standard_normal(z.shape)
    z[~yaw_on, :, 1] = np.nan
    return xs, z


def meas(z):
    return Measurements(z[:, 0], z[:, 1], z[:, 2], *R3)


def est_dev(x, x_ref, P_ref):
    return np.abs(x - x_ref) / (np.sqrt(np.einsum("...ii->...i", P_ref)) + np.abs(x_ref))


@pytest.mark.parametrize("bias", [
    BiasModel.of(earth_roll=(0.1 * DEG, 1e-12), dss_yaw=(0.1 * DEG, 0.0),
                 cass1_yaw=(0.05 * DEG, 4e-12), cass2_yaw=(0.2 * DEG, 0.0)),
    BiasModel.of(earth_roll=(0.1 * DEG, 0.0), cass1_yaw=(0.1 * DEG, 1e-12)),
], ids=["all_four", "roll_and_cass1"])
def test_compiled_filter_and_smoother_match_dense_numpy_reference(rng, bias):
    """Every head in turn (with 'roll_and_cass1', DSS and CASS2 samples measure y alone),
    gaps in every measurement, inputs, extra noise, random walks and a gate with spikes
    to reject: the compiled filter and smoother (closed-form Φ, Γ, Q_d) equal the
    textbook reference of ``dense_reference`` (its own prior, augmented F and Q,
    expm/Van Loan, rows), x, P, ν, S, the gate's decisions and the prior after the
    run.  The two discretisations differ by ~1e-13 relative and rounding differences
    are amplified where an update cancels most of P (P0/R up to 250 in the first steps)
    and carried over the filter's and the smoother's memory: measured ≤ 9e-13 in the
    filter's x (σ + |x| units), P, ν (σ units) and S, ≤ 1.7e-11 in the smoother's P,
    the same with DYNPROP_BACKEND=vm; 1e-9 allowed.  Seen failing by 570 (a bias prior
    of diag(σ0)), 0.8 (a yaw sample given another head's bias) and 9e-3 (q_b without
    its Δt)."""
    n = 600
    u = input_vector(PARAMS, 1e-6 * np.sin(np.arange(n) / 50), -2e-6, 1e-5)
    yaw_on = np.arange(n) % 5 != 0
    head = np.where(yaw_on, rng.integers(0, 3, n), np.nan)
    xs, z = simulate(n, 1, rng, bias, yaw_on, head)
    z = z[:, 0]
    z[::7, 0] = np.nan
    z[::11, 2] = np.nan
    z[[200, 400], 0] += 30 * np.sqrt(R3[0])     # to be rejected
    z[[301, 501], 1] -= 30 * np.sqrt(R3[1])
    extra = ExtraNoise(np.where(np.arange(n) % 50 < 5, 1e-8, 0.0),
                       discretize(PARAMS, ProcessNoise(0.0, 0.0, 1.0), DT).Qd)
    kw = dict(bias=bias, sun_head=head, gate_chi2=16.0, extra=extra)
    res = augmented_filter(meas(z), DISC, np.zeros(9), P0, u, **kw)
    f = ref.reference_filter(z, R3, DT, PARAMS, NOISE, bias, np.zeros(9), P0, u,
                             sun_head=head, gate=16.0, extra_scale=extra.scale)
    x_ref, P_ref = f.x, f.P
    # No gate decision within rounding of the threshold (it would flip on last bits).
    nis = res.innovations**2 / res.innovation_var
    assert np.nanmin(np.abs(nis / 16.0 - 1)) > 1e-6
    assert np.array_equal(res.rejected, f.rejected)
    assert {200, 400} <= set(np.flatnonzero(res.rejected[:, 0]))
    assert {301, 501} <= set(np.flatnonzero(res.rejected[:, 1]))
    assert cov_dev(res.P, P_ref).max() < 1e-9
    assert est_dev(res.x, x_ref, P_ref).max() < 1e-9
    assert cov_dev(res.P_next, f.P_next).max() < 1e-9
    assert est_dev(res.x_next, f.x_next, f.P_next).max() < 1e-9
    # ν and S are kept where a measurement was rejected, NaN where it was absent.
    assert np.array_equal(np.isnan(res.innovations), np.isnan(f.nu))
    present = np.isfinite(f.nu)
    assert np.max(np.abs(res.innovation_var[present] / f.S[present] - 1)) < 1e-9
    assert np.max(np.abs(res.innovations - f.nu)[present] / np.sqrt(f.S[present])) < 1e-9
    assert np.all(np.isfinite(res.innovations[[200, 400], 0]))
    assert np.all(np.isnan(res.innovation_var[::7, 0]))

    sm = augmented_smoother(res, DISC, u, bias=bias, extra=extra)
    s = ref.reference_smoother(f, DT, PARAMS, NOISE, bias, u, extra_scale=extra.scale)
    xs_ref, Ps_ref = s.x, s.P
    assert cov_dev(sm.P, Ps_ref).max() < 1e-9
    assert est_dev(sm.x, xs_ref, Ps_ref).max() < 1e-9
    sx = augmented_smoother(res, DISC, u, bias=bias, extra=extra, covariance=False)
    assert est_dev(sx.x, xs_ref, Ps_ref).max() < 1e-9


def test_without_biases_or_gate_it_is_the_papers_filter(rng):
    """nb = 0, no gate: the same expressions as ``kalman.steps`` (measured bit for bit;
    1e-12 allowed, as another compiler may order them otherwise); and a 9-state prior
    and its augmented form are one prior."""
    n = 3000
    xs, z = simulate(n, 1, rng, BiasModel((), (), ()), np.arange(n) % 3 > 0,
                     np.zeros(n))
    z = z[:, 0]
    u = input_vector(PARAMS, 1e-6, -2e-6, 1e-5)[None].repeat(n, 0)
    a = augmented_filter(meas(z), DISC, np.zeros(9), P0, u, bias=None)
    k = kalman_filter(meas(z), DISC, np.zeros(9), P0, u)
    assert cov_dev(a.P, k.P).max() < 1e-12
    assert est_dev(a.x, k.x, k.P).max() < 1e-12
    assert not a.rejected.any()
    sa, sk = augmented_smoother(a, DISC, u, bias=None), rts_smoother(k, DISC, u)
    assert est_dev(sa.x, sk.x, sk.P).max() < 1e-12
    assert cov_dev(sa.P, sk.P).max() < 1e-12

    b = augmented_filter(meas(z), DISC, *augmented_prior(np.zeros(9), P0, BIASES),
                         bias=BIASES, sun_head=np.zeros(n))
    c = augmented_filter(meas(z), DISC, np.zeros(9), P0, bias=BIASES, sun_head=np.zeros(n))
    assert np.array_equal(b.x, c.x) and np.array_equal(b.P_packed, c.P_packed)


def test_a_rollout_in_segments_is_the_whole_rollout_and_rows_are_its_rows(rng):
    """What a caller with one Δt per segment does: ``_roll`` per segment with its own
    parameters, carrying the final state, gives the whole run bit for bit; ``rows`` and
    ``covariance_rows`` keep the whole run's rows."""
    n, cut = 1500, 977
    head = np.zeros(n)
    _, z = simulate(n, 1, rng, BIASES, np.ones(n, bool), head)
    z = z[:, 0]
    full = augmented_filter(meas(z), DISC, np.zeros(9), P0, bias=BIASES, sun_head=head,
                            gate_chi2=25.0)
    x0, Pa = augmented_prior(np.zeros(9), P0, BIASES)
    eng = engine("filter", BIASES.names, True, 4096, None)
    p = augmented_params(DISC, BIASES, None, 25.0)
    present = np.isfinite(z)
    zin = [np.where(present, z, 0.0), present.astype(float), np.tile(R3, (n, 1)),
           np.zeros((n, 9)), np.zeros(n), np.ones((n, 1))]
    s = np.concatenate([x0, Pa[np.triu_indices(11)]])
    parts = []
    for seg in (slice(0, cut), slice(cut, n)):
        s, front, P = _roll(eng, s, [a[seg] for a in zin], p)
        parts.append((front, P))
    assert np.array_equal(np.vstack([f[:, :11] for f, _ in parts]), full.x)
    assert np.array_equal(np.vstack([P for _, P in parts]), full.P_packed)
    assert np.array_equal(s[:11], full.x_next)
    rows = np.array([0, 5, 976, 977, 1499])
    kept = augmented_filter(meas(z), DISC, np.zeros(9), P0, bias=BIASES, sun_head=head,
                            gate_chi2=25.0, rows=rows)
    assert np.array_equal(kept.x, full.x[rows])
    assert np.array_equal(kept.P_packed, full.P_packed[rows])
    cov = augmented_filter(meas(z), DISC, np.zeros(9), P0, bias=BIASES, sun_head=head,
                           gate_chi2=25.0, covariance_rows=rows)
    assert np.array_equal(cov.x, full.x) and np.array_equal(cov.P_packed, full.P_packed[rows])


def test_known_biases_are_recovered_within_3_sigma():
    """Earth-sensor roll bias +0.03° and DSS yaw bias −0.05° (prior σ 0.1°), yaw from the
    DSS for hours 0–2 and 4–5 of 6: at 1, 3 and 6 h each estimate is within 3σ of the
    truth and its σ has fallen, monotonically, to well under the prior's (measured
    0.042°, 0.037°, 0.029° for roll; 0.062°, 0.042°, 0.031° for yaw; errors ≤ 1.3σ).
    Not to zero: each bias trades against a constant torque
    (``test_a_constant_bias_is_a_constant_torque_in_disguise``)."""
    rng = np.random.default_rng(11)
    n = int(6 * 3600 / DT)
    t_h = np.arange(n) * DT / 3600
    yaw_on = (t_h < 2) | ((t_h >= 4) & (t_h < 5))
    head = np.where(yaw_on, 0.0, np.nan)
    b_true = np.array([0.03, -0.05]) * DEG
    xs, z = simulate(n, 1, rng, BIASES, yaw_on, head, b_true=b_true)
    idx = (np.array([1, 3, 6]) * 3600 / DT).astype(int) - 1
    res = augmented_filter(meas(z[:, 0]), DISC, np.zeros(9), P0, bias=BIASES,
                           sun_head=head, covariance_rows=idx)
    sig, err = res.sigma[:, N_STATES:], res.x[idx, N_STATES:] - b_true
    assert np.all(np.abs(err) < 3 * sig)
    assert np.all(np.diff(sig, axis=0) < 0)
    assert np.all(sig[-1] < 0.4 * np.array(BIASES.sigma0_rad))


@pytest.mark.slow_in_vm
def test_nees_of_the_augmented_state_is_chi2_over_a_monte_carlo():
    """20 runs of 6 h, every state (biases included) drawn from the prior: the NEES
    of all 11 states averaged over the runs lies within the two-sided 99% bounds of
    χ²(20·11)/20 at 1, 3 and 6 h (measured 12.3, 11.6, 10.8 in [8.5, 13.9]).  With 200
    runs the means are 11.0, 11.1, 10.7 (±0.33) at 51 s, 8.5 min and 1 h; with three
    checks a seed fails one ~3% of the time by chance (seed 12 gave 8.3 at 1 h)."""
    rng = np.random.default_rng(13)
    runs, n = 20, int(6 * 3600 / DT)
    t_h = np.arange(n) * DT / 3600
    yaw_on = (t_h < 2) | ((t_h >= 4) & (t_h < 5))
    head = np.where(yaw_on, 0.0, np.nan)
    xs, z = simulate(n, runs, rng, BIASES, yaw_on, head)
    idx = (np.array([1, 3, 6]) * 3600 / DT).astype(int) - 1
    eps = np.empty((runs, len(idx)))
    for j in range(runs):
        res = augmented_filter(meas(z[:, j]), DISC, np.zeros(9), P0, bias=BIASES,
                               sun_head=head, covariance_rows=idx)
        e = res.x[idx] - xs[idx, j]
        eps[j] = np.einsum("ki,ki->k", e, np.linalg.solve(res.P, e[..., None])[..., 0])
    n_x = N_STATES + len(BIASES.names)
    lo, hi = chi2.ppf([0.005, 0.995], runs * n_x) / runs
    assert np.all((eps.mean(0) > lo) & (eps.mean(0) < hi)), (eps.mean(0), lo, hi)


def test_spikes_are_gated_flagged_and_would_otherwise_pull_the_estimate():
    """Three 20σ spikes each in roll and in DSS yaw after 1.3 h, γ = 25 (5σ): exactly
    those six are rejected over 2e4 samples (P(χ²₁ > 25) ≈ 6e-7 per clean one), each
    rejection is the update left out (the run with those values absent, bit for bit),
    and every state stays within 3σ of the truth at the spikes (measured ≤ 1.6σ).
    Ungated, each spike moves the measured combination (r + b, y + b) by more than the
    gated run's error in it (measured 3.3–3.7σ against ≤ 2.0σ for roll, 1.9–2.0σ
    against ≤ 1.3σ for yaw); the largest clean ν²/S after start-up is 15."""
    rng = np.random.default_rng(7)
    n = 20000
    head = np.zeros(n)
    xs, z = simulate(n, 1, rng, BIASES, np.ones(n, bool), head)
    xs, z = xs[:, 0], z[:, 0]
    spikes = {0: [9000, 12000, 15000], 1: [10000, 13000, 16000]}
    clean = z.copy()
    for i, ks in spikes.items():
        z[ks, i] += 20 * np.sqrt(R3[i]) * np.array([1, -1, 1])
        clean[ks, i] = np.nan
    gated = augmented_filter(meas(z), DISC, np.zeros(9), P0, bias=BIASES, sun_head=head,
                             gate_chi2=25.0)
    loose = augmented_filter(meas(z), DISC, np.zeros(9), P0, bias=BIASES, sun_head=head)
    absent = augmented_filter(meas(clean), DISC, np.zeros(9), P0, bias=BIASES,
                              sun_head=head)
    assert gated.rejected.sum(0).tolist() == [3, 3, 0]
    for i, ks in spikes.items():
        assert np.flatnonzero(gated.rejected[:, i]).tolist() == ks
    assert not loose.rejected.any()
    assert np.array_equal(gated.x, absent.x)
    assert np.array_equal(gated.P_packed, absent.P_packed)
    for i, ks in spikes.items():
        assert np.all(np.abs(gated.x[ks] - xs[ks]) < 3 * gated.sigma[ks])
        G = ref.row(BIASES, ("roll", "yaw")[i], 0)
        err = np.abs((gated.x[ks] - xs[ks]) @ G)
        shift = np.abs((loose.x[ks] - gated.x[ks]) @ G)
        assert np.all(shift > err), (shift, err)


def test_a_random_walk_bias_sigma_grows_as_sqrt_q_t_without_measurements(rng):
    """After 20 min of data, 30 min with none: a random-walk bias's variance grows by
    exactly q_b Δt a step (Φ_b = 1, and nothing else feeds the bias block), so σ(t)² =
    σ(t0)² + q_b (t − t0); a random constant's σ stays put."""
    q = 1e-10
    bias = BiasModel.of(earth_roll=(0.1 * DEG, 0.0), dss_yaw=(0.1 * DEG, q))
    n, k0 = int(50 * 60 / DT), int(20 * 60 / DT)
    head = np.where(np.arange(n) < k0, 0.0, np.nan)
    _, z = simulate(n, 1, rng, bias, np.arange(n) < k0, head)
    z = z[:, 0]
    z[k0:] = np.nan
    res = augmented_filter(meas(z), DISC, np.zeros(9), P0, bias=bias, sun_head=head)
    var = res.sigma[k0 - 1:] ** 2
    steps = np.arange(len(var))
    np.testing.assert_allclose(var[:, 10], var[0, 10] + q * DT * steps, rtol=1e-12)
    np.testing.assert_allclose(var[:, 9], var[0, 9], rtol=1e-12)
    # The growth is 9% of the variance here, so 1e-12 checks it, not only its start.
    assert var[-1, 10] - var[0, 10] > 0.05 * var[0, 10]


def test_a_constant_bias_is_a_constant_torque_in_disguise():
    """Observability of the augmented model (F_a = blockdiag(F, 0)): with roll, DSS yaw
    and h, rank 9 of 10 with either bias, the null vector a constant roll (yaw) offset
    δ, the torque N_cx (N_cz) = −ω0 H δ that holds it there (Eq. 11), and a bias −δ;
    without yaw the DSS bias is unobservable outright (rank 8: it and the paper's yaw /
    N_cz direction, Eq. 27); with an unbiased CASS1 seen as well, full rank 10."""
    w0 = PARAMS.omega0_radps
    for bias, state, other in ((ROLL_BIAS, R, NCX), (YAW_BIAS, Y, NCZ)):
        F = augmented_model(PARAMS, bias)
        G = np.vstack([measurement_row(bias, k, 0) for k in ("roll", "yaw", "h")])
        assert rank_progression(F, G)[-1] == 9
        v = unobservable_subspace(F, G)[:, 0]
        v = v / v[state]
        expect = np.zeros(10)
        expect[state], expect[other], expect[9] = 1.0, -w0 * H, -1.0
        np.testing.assert_allclose(v, expect, atol=1e-9)
    F = augmented_model(PARAMS, YAW_BIAS)
    rows = {k: measurement_row(YAW_BIAS, k, 0) for k in ("roll", "yaw", "h")}
    assert rank_progression(F, np.vstack([rows["roll"], rows["h"]]))[-1] == 8
    cass1 = measurement_row(YAW_BIAS, "yaw", 1)      # no bias state: y alone
    assert rank_progression(F, np.vstack([*rows.values(), cass1]))[-1] == 10


@pytest.mark.slow_in_vm
def test_a_constant_roll_bias_is_known_no_better_than_its_torque_prior():
    """What the null vector above means for the filter: the data say nothing along
    (δ_r, δ_Ncx, δ_b) = (1, −ω0 H, −1), so the σ of a constant roll bias never falls
    below the prior's information along it allows (Cauchy–Schwarz on the information
    matrix), σ² ≥ (1/σ_b0² + (ω0 H)²/P0_Ncx + 1/P0_r)⁻¹ (1.09e-4 rad here), and the
    rest of its variance falls as 1/t: five days with a daily 8 h yaw gap, torque
    states without process noise (which would raise the bound day by day).  Measured:
    (σ² − bound)·t within 5.3% over days 1–5, σ 2.75 → 1.50 times the bound."""
    disc = discretize(PARAMS, ProcessNoise(5.4e-7, 5.4e-7, 5e-10, 3e-18, 3e-18), DT)
    n = int(5 * 86400 / DT)
    yaw_on = (np.arange(n) * DT / 3600) % 24 < 16
    z = np.where(yaw_on[:, None] | (np.arange(3) != 1), 0.0, np.nan)   # P needs no values
    days = (np.arange(1, 6) * 86400 / DT).astype(int) - 1
    res = augmented_filter(meas(z), disc, np.zeros(9), P0, bias=ROLL_BIAS,
                           covariance_rows=days)
    w0 = PARAMS.omega0_radps
    bound = 1 / (1 / ROLL_BIAS.sigma0_rad[0] ** 2 + (w0 * H) ** 2 / P0[NCX, NCX]
                 + 1 / P0[R, R])
    var = res.sigma[:, 9] ** 2
    assert np.all(var > bound)
    excess_t = (var - bound) * np.arange(1, 6)
    assert excess_t.max() < 1.08 * excess_t.min()
