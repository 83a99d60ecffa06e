"""The filters with each sample's own Δt (``estimator.linear.steps``): telemetry at any
cadence, with jitter and gaps, against independent references.

Φ, Γ and Q_d of each step here come from scipy's expm and Van Loan's method
(``test_kalman.expm_discretization``), not from the closed forms, so the test checks
the per-step bookkeeping and the closed forms together."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from estimator.ekf import model as em
from estimator.ekf.filter import EkfInputs, ekf_filter
from estimator.kalman.filter import ExtraNoise, Measurements, kalman_filter, rts_smoother
from estimator.linear.model import N_STATES, ProcessNoise
from estimator.linear.steps import StepTable, discretize_many, step_intervals
from estimator.linear.transition import discretize

from .cov_helpers import cov_dev
from .test_kalman import NOISE, P0, PARAMS, R_H, R_ROLL, R_YAW, expm_discretization


def _jittered(n, rng, gap_at=None, gap_s=0.0):
    t = np.cumsum(np.r_[0.0, 0.512 + rng.uniform(-0.05, 0.05, n - 1)])
    if gap_at is not None:
        t[gap_at:] += gap_s
    return t


def _measurements(n, rng, yaw_every=3):
    yaw = rng.normal(0, 1e-3, n)
    yaw[np.arange(n) % yaw_every == 0] = np.nan
    return Measurements(rng.normal(0, 2e-4, n), yaw, rng.normal(0, 1e-3, n),
                        R_ROLL, R_YAW, R_H)


def _intervals_from_tags(t):
    """Δt after each sample from the time tags themselves, as ``step_intervals``'s
    docstring defines it (not by calling it): t_{k+1} − t_k, and for the last sample,
    whose step only forms the prior after the run, the step before it."""
    t = np.asarray(t, dtype=float)
    return np.r_[t[1:] - t[:-1], t[-1] - t[-2]]


def _expm_filter(meas, t, x0, P0_):
    """The paper's filter, one numpy step at a time, each step's Φ, Γ, Q_d from expm
    and Van Loan at its own interval taken from the tags: the a-posteriori history
    and the prior after the last step."""
    z, r = meas.z(), meas.r()
    x, P = x0.copy(), P0_.copy()
    xs, Ps = [], []
    eye = np.eye(N_STATES)
    for k, dt in enumerate(_intervals_from_tags(t)):
        for i, idx in enumerate((0, 2, 4)):
            if np.isnan(z[k, i]):
                continue
            G = eye[idx:idx + 1]
            S = (G @ P @ G.T).item() + r[k, i]
            K = P @ G.T / S
            x = x + (K * (z[k, i] - x[idx])).ravel()
            IKG = eye - K @ G
            P = IKG @ P @ IKG.T + r[k, i] * K @ K.T
        xs.append(x)
        Ps.append(P)
        d = expm_discretization(dt=dt)
        x, P = d.Phi @ x, d.Phi @ P @ d.Phi.T + d.Qd
    return np.array(xs), np.array(Ps), x, P


def test_jittered_steps_with_a_gap_match_an_expm_reference(rng):
    """±50 ms jitter and a one-hour gap: the compiled per-step filter equals the
    expm/Van Loan reference, whose intervals come from the tags (t_{k+1} − t_k after
    sample k; the last sample's prior one step of t_N − t_{N−1} on), so a step applied
    one sample early or late (an off-by-one in ``step_intervals``) moves the gap's
    growth of σ to another sample and the estimates by ~σ.  Tolerance: the
    reference's expm of a one-hour step loses ~1e-10 relative (‖F‖Δt ~ 100 rad of
    nutation phase), which sets the bound on the estimates (1e-8 of σ + |x|) and
    covariances (1e-8 of √(P_ii P_jj)), the prior after the run included."""
    n = 400
    t = _jittered(n, rng, gap_at=200, gap_s=3600.0)
    meas = _measurements(n, rng)
    x0 = np.zeros(N_STATES)
    result = kalman_filter(meas, StepTable.from_times(PARAMS, NOISE, t), x0, P0)
    xs, Ps, x_next, P_next = _expm_filter(meas, t, x0, P0)
    sig = np.sqrt(np.einsum("kii->ki", Ps))
    assert np.max(np.abs(result.x - xs) / (sig + np.abs(xs))) < 1e-8
    assert np.max(cov_dev(result.P, Ps)) < 1e-8
    sig_next = np.sqrt(np.diag(P_next))
    assert np.max(np.abs(result.x_next - x_next) / (sig_next + np.abs(x_next))) < 1e-8
    assert np.max(cov_dev(result.P_next, P_next)) < 1e-8
    # The gap costs what the process noise says: σ_yaw grows across it.
    assert result.sigma[200, 2] > 3 * result.sigma[199, 2]


def test_one_cadence_as_a_table_equals_the_fixed_step_filter(rng):
    """Every step 0.512 s: the table's filter and smoother are the fixed-step ones, to
    rounding (the batched closed forms sum in another order: 1e-12 of σ)."""
    n = 2000
    meas = _measurements(n, rng)
    x0 = np.zeros(N_STATES)
    disc = discretize(PARAMS, NOISE, 0.512)
    table = StepTable.from_times(PARAMS, NOISE, np.arange(n) * 0.512)
    a, b = kalman_filter(meas, disc, x0, P0), kalman_filter(meas, table, x0, P0)
    assert np.max(np.abs(a.x - b.x) / a.sigma) < 1e-12
    assert np.max(np.abs(b.sigma / a.sigma - 1)) < 1e-12
    sa, sb = rts_smoother(a, disc), rts_smoother(b, table)
    assert np.max(np.abs(sa.x - sb.x) / sa.sigma) < 1e-10
    assert np.max(np.abs(sb.sigma / sa.sigma - 1)) < 1e-10


def test_a_long_step_equals_the_same_span_in_grid_steps(rng):
    """Φ(a + b) = Φ(a)Φ(b) and Q_d adds up: one 3 h step without measurements equals
    21,094 steps of 0.512 s (almost exactly 3 h: 10800.128 s) without them."""
    m = 21094
    pre = 300
    meas_short = _measurements(pre + 2, rng)
    t_long = np.r_[np.arange(pre + 1) * 0.512, pre * 0.512 + m * 0.512]
    x0 = np.zeros(N_STATES)
    long = kalman_filter(meas_short, StepTable.from_times(PARAMS, NOISE, t_long), x0, P0)
    blank = np.full(m - 1, np.nan)
    grid = Measurements(*(np.r_[v[:pre + 1], blank, v[pre + 1:]] for v in
                          (meas_short.roll_rad, meas_short.yaw_rad, meas_short.h_Nms)),
                        R_ROLL, R_YAW, R_H)
    fine = kalman_filter(grid, discretize(PARAMS, NOISE, 0.512), x0, P0)
    # 21,094 products of Φ accumulate ~1e-12 relative; the one long step is exact.
    assert np.max(np.abs(long.x[-1] - fine.x[-1]) / fine.sigma[-1]) < 1e-8
    assert np.max(np.abs(long.sigma[-1] / fine.sigma[-1] - 1)) < 1e-8


def test_batched_closed_forms_equal_the_single_ones():
    dt = np.array([0.3, 0.512, 0.561, 1.0, 2.0, 100.0, 10800.0])
    many = discretize_many(PARAMS, NOISE, dt)
    for i, d in enumerate(dt):
        one = discretize(PARAMS, NOISE, d)
        for a, b in ((many.Phi[i], one.Phi), (many.Gamma[i], one.Gamma), (many.Qd[i], one.Qd)):
            assert np.max(np.abs(a - b)) <= 1e-13 * np.abs(b).max()
        unit = discretize(PARAMS, ProcessNoise(q_x=0.0, q_z=0.0, q_w=1.0), d).Qd
        assert np.max(np.abs(many.Qd_unit[i] - unit)) <= 1e-13 * np.abs(unit).max()


def test_dropout_noise_uses_each_steps_own_unit(rng):
    """``ExtraNoise`` on a table: step k adds scale_k × Q_d(q_w = 1) at its own Δt, so a
    long bridged step gets the matching (larger) unit, not the 0.512 s one."""
    n = 50
    t = np.r_[np.arange(25) * 0.512, 25 * 0.512 + 600.0 + np.arange(25) * 0.512]
    meas = _measurements(n, rng)
    meas.roll_rad[25] = meas.yaw_rad[25] = np.nan   # h alone at 25: S_h = P⁻_hh + R_h
    x0 = np.zeros(N_STATES)
    table = StepTable.from_times(PARAMS, NOISE, t)
    scale = np.zeros(n)
    scale[24] = 1e-8
    with_extra = kalman_filter(meas, table, x0, P0, extra=ExtraNoise(scale, np.zeros((9, 9))))
    noise2 = ProcessNoise(q_x=NOISE.q_x, q_z=NOISE.q_z, q_w=NOISE.q_w + 1e-8, q_px=NOISE.q_px,
                          q_pz=NOISE.q_pz, q_cx=NOISE.q_cx, q_cz=NOISE.q_cz)
    P_prior = with_extra.P[24]
    d_ref = discretize(PARAMS, noise2, 600.512)
    # Before the update at sample 25 the prior is Φ P Φᵀ + Q_d(q_w + 1e-8) at 600.512 s.
    ref = d_ref.Phi @ P_prior @ d_ref.Phi.T + d_ref.Qd
    np.testing.assert_allclose(np.sqrt(ref[4, 4]), np.sqrt(_prior_h(with_extra, meas, 25)),
                               rtol=1e-9)


def _prior_h(result, meas, k):
    """The prior variance of h at sample k, from the h update: S − R."""
    return result.innovation_var[k, 2] - R_H


@pytest.mark.parametrize("gap_steps", [1, 40])
def test_ekf_long_steps_are_cut_into_nominal_sub_steps(gap_steps, rng):
    """The EKF cuts a step of n × the nominal Δt into n sub-steps without measurements:
    exactly the fixed-step EKF with those samples missing (the same arithmetic; 1e-12
    of σ allows another rounding of the per-step Δt)."""
    from .test_ekf import PM, WN, _prior, _twin_data
    n = 300
    _, data = _twin_data(n, rng)
    X0, Pe = _prior()
    dt0 = float(PM[em.DT_INDEX])
    keep = np.r_[0:100, 100 + gap_steps - 1:n]
    dt = step_intervals(np.arange(n)[keep] * dt0)
    sparse = ekf_filter(EkfInputs(data.z[keep], data.r[keep], data.u[keep]), PM, WN, X0, Pe,
                        dt_s=dt)
    zz = data.z.copy()
    zz[100:100 + gap_steps - 1] = np.nan
    full = ekf_filter(EkfInputs(zz, data.r, data.u), PM, WN, X0, Pe)
    assert np.max(np.abs(sparse.x - full.x[keep]) / full.sigma[keep]) < 1e-12
    assert np.max(np.abs(sparse.sigma / full.sigma[keep] - 1)) < 1e-12


def _skew(v):
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _a_of_q(q):
    """A(q), scalar last (Markley & Crassidis Eq. 2.125): the frame rotation C_BR."""
    qv, q4 = q[:3], q[3]
    return (q4**2 - qv @ qv) * np.eye(3) + 2 * np.outer(qv, qv) - 2 * q4 * _skew(qv)


def _r2(a):
    """Frame rotation about y by a (docs/conventions.md)."""
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]])


def _inertial_propagation(X0, u, J, w0, t_out):
    """The EKF model's physics integrated in the inertial frame N instead of the orbit
    frame: C_BN and ω_BN by DOP853, C_RN(t) = R2(−ω0 t) (R = N at t = 0, R turning at
    −ω0 about y_R), the gravity gradient 3ω0² n̂ × J n̂ about the nadir n̂ = C_BN
    C_RNᵀ ẑ, wheel momentum (0, H, h) with ḣ = N_w, the torques N_x* + N_px + N_cx
    about x and N_z* + N_pz + N_cz about z, N_p turning at the orbit rate (Eq. 9) in
    closed form.  The state at each of ``t_out`` in the EKF's form (q_BR as C_BR,
    ω_BR = ω_BN − C_BR (0, −ω0, 0), h, N)."""
    H, Hdot, Nw, Nx, Nz = u
    Jinv = np.linalg.inv(J)
    C_BR0 = _a_of_q(X0[:4])
    w_bn0 = X0[4:7] + C_BR0 @ np.array([0.0, -w0, 0.0])
    npx0, npz0, ncx, ncz = X0[8:12]

    def n_p(t):   # Ṅ_px = ω0 N_pz, Ṅ_pz = −ω0 N_px
        c, s = np.cos(w0 * t), np.sin(w0 * t)
        return npx0 * c + npz0 * s, -npx0 * s + npz0 * c

    def rhs(t, y):
        C, w, h = y[:9].reshape(3, 3), y[9:12], y[12]
        nadir = C @ _r2(-w0 * t).T @ np.array([0.0, 0.0, 1.0])
        npx, npz = n_p(t)
        torque = (3 * w0**2 * np.cross(nadir, J @ nadir)
                  + np.array([Nx + npx + ncx, 0.0, Nz + npz + ncz])
                  - np.cross(w, J @ w + np.array([0.0, H, h])) - np.array([0.0, Hdot, Nw]))
        return np.r_[(-_skew(w) @ C).ravel(), Jinv @ torque, Nw]

    y0 = np.r_[C_BR0.ravel(), w_bn0, X0[7]]
    atol = np.r_[np.full(9, 1e-15), np.full(3, 1e-18), 1e-15]
    sol = solve_ivp(rhs, (0.0, t_out[-1]), y0, method="DOP853", t_eval=t_out,
                    rtol=1e-13, atol=atol)
    assert sol.success
    C_BR = np.array([y[:9].reshape(3, 3) @ _r2(-w0 * t).T for t, y in zip(sol.t, sol.y.T,
                                                                             strict=True)])
    w_br = sol.y[9:12].T - C_BR @ np.array([0.0, -w0, 0.0])
    npx, npz = n_p(sol.t)
    N = np.column_stack([npx, npz, np.full_like(npx, ncx), np.full_like(npx, ncz)])
    return C_BR, w_br, sol.y[12], N


def test_ekf_propagates_each_sample_over_its_own_interval(rng):
    """No measurements, so the EKF's nominal state is its propagation alone: over
    jittered steps (±50 ms about the nominal 0.512 s, so about half are cut into two
    sub-steps), a 37.3 s and a 600.7 s gap and, after the last sample, 1234.567 s, its
    state at each tag (and after the run) equals the same physics integrated
    independently to the tags' own times (``_inertial_propagation``: inertial frame,
    DCM kinematics, DOP853 at rtol 1e-13).  A large nutation (|ω_BR| = 1e-3 rad/s,
    ~1.6°) makes the time propagated over visible: each 0.1 ms of error there moves
    the attitude by 1e-7 rad.  Tolerance: RK4 leaves ~(ω_n Δt)⁵/120 ≈ 2e-11 of the
    nutation amplitude (0.027 rad) per 0.512 s sub-step, ~5e-13 rad, over ~4300
    sub-steps ~2e-9 rad (measured 2.2e-9 rad in attitude, 8e-11 rad/s in ω_BR, the
    same with DYNPROP_BACKEND=vm); 1e-7 rad and ω_n × that for the rates.  h and the
    torque states RK4 integrates exactly (ḣ = N_w held, N_p turning at ω0 with
    ω0Δt ~ 4e-5): rounding only, 1e-13 of their size measured, 1e-10 allowed.
    Sub-steps of the nominal length in place of each interval's own (a 0.462 s step
    taken as 0.512 s, a 0.562 s one as 2 × 0.512 s) gave 0.064 rad."""
    from .test_ekf import PM, W0, WN, H, J
    t = np.r_[0.0, np.cumsum(0.512 + rng.uniform(-0.05, 0.05, 399))]
    t[150:] += 37.3 - (t[150] - t[149])
    t[300:] += 600.7 - (t[300] - t[299])
    after_last = 1234.567
    n = len(t)
    X0 = np.r_[0.02, -0.01, 0.03, 1.0, 1e-3, 2e-4, -5e-4, 0.3, 2e-5, -1e-5, 3e-6, -2e-6]
    X0[:4] /= np.linalg.norm(X0[:4])
    u = np.array([H, 0.0, 2e-4, 3e-6, -2e-6])
    dt = np.r_[t[1:] - t[:-1], after_last]     # the interval after each sample
    res = ekf_filter(EkfInputs(np.full((n, 4), np.nan), np.ones((n, 4)), np.tile(u, (n, 1))),
                     PM, WN, X0, np.eye(11) * 1e-8, dt_s=dt, keep_nominal=True)
    X = np.vstack([res.X, res.x_next])
    C_ref, w_ref, h_ref, N_ref = _inertial_propagation(X0, u, J, W0,
                                                       np.r_[t, t[-1] + after_last])
    # The angle of the small rotation between the two C_BR, from its skew part.
    dC = np.array([_a_of_q(x[:4]) for x in X]) @ np.swapaxes(C_ref, 1, 2)
    angle = np.linalg.norm(np.column_stack([dC[:, 1, 2] - dC[:, 2, 1],
                                            dC[:, 2, 0] - dC[:, 0, 2],
                                            dC[:, 0, 1] - dC[:, 1, 0]]), axis=1) / 2
    assert angle.max() < 1e-7, angle.max()
    assert np.abs(X[:, 4:7] - w_ref).max() < abs(WN) * 1e-7
    assert np.abs(X[:, 7] - h_ref).max() < 1e-10 * abs(X0[7])
    assert np.abs(X[:, 8:] - N_ref).max() < 1e-10 * np.abs(X0[8:]).max()
