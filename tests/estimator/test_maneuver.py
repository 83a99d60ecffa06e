"""The filters' response to a maneuver flag (``estimator.kalman.maneuver``) against
independent references.

* inflate: the paper's own discrete model (Eqs. 31-32) driven by a thruster impulse
  the filter does not know (±τ on roll and yaw over a flagged stretch of D_max): after
  it, the NEES over many runs lies in its χ² bounds with the inflated noise, and far
  above them with the flag ignored;
* reset: the prior at the first sample after a flagged stretch has the attitude block
  of P0 exactly, uncorrelated, the estimate kept, and not a sample earlier;
* the smoother: the filter and RTS smoother over a flagged stretch equal the
  posterior of the whole trajectory, formed in one piece from its joint Gaussian
  prior (every step's Φ, Γ, Q_d from scipy's expm and Van Loan's method, with the
  white torque added on the flagged steps, or the reset's transition), conditioned
  on every measurement: no Kalman recursion, no closed form of the package;
* windows: a run cut into windows, the flag's padding carrying a reset across the
  cut, equals the whole run.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sl

from estimator.ekf import model as em_ekf
from estimator.ekf.filter import ROLL_YAW, EkfInputs, ekf_filter, inflated_params
from estimator.kalman.consistency import chi2_bounds, nees
from estimator.kalman.filter import (
    ExtraNoise,
    Measurements,
    kalman_filter,
    rts_smoother,
    unpack,
)
from estimator.kalman.maneuver import ATTITUDE, Maneuver
from estimator.linear.model import ModelParams, ProcessNoise, dynamics_matrix, input_vector
from estimator.linear.transition import discretize

from .cov_helpers import cov_dev

# GOES-Next (Section 2, Eq. 1), typed here.
H = -0.1082 * 2 * 5485 * 2 * np.pi / 60 * np.cos(np.deg2rad(1.656))
PARAMS = ModelParams(3364.376, 954.936, 3461.393, H, np.sqrt(3.986004418e14 / 42164170.0**3))
NOISE = ProcessNoise(q_x=5.4e-7, q_z=5.4e-7, q_w=5e-10, q_px=3e-18, q_pz=3e-18, q_cx=3e-18,
                     q_cz=3e-18)
R_ROLL, R_YAW, R_H = 3.3e-8, (0.04 * np.pi / 180) ** 2, 1.5e-7
P0 = np.diag([np.deg2rad(0.05) ** 2, 1e-6, np.deg2rad(0.5) ** 2, 1e-6, 2.5e-3,
              2.5e-11, 2.5e-11, 2.5e-11, 2.5e-11])
TAU, D_MAX = 0.01, 600.0          # the thruster's largest torque and stretch
Q_M = TAU**2 * D_MAX             # the white torque's intensity, (N m)² s
ATT = list(ATTITUDE)             # r, ṙ/ω_n, y, ẏ/ω_n: Eq. 10's first four


def _maneuver(flag, response):
    return Maneuver.of(flag, response, Q_M, PARAMS, P0[np.ix_(ATT, ATT)])


def _extra(flag, response):
    m = _maneuver(flag, response)
    return None if m is None else ExtraNoise(np.zeros(len(flag)), np.zeros((9, 9)), m)


def _truth_runs(rng, n_runs, n, dt, flagged, torque):
    """``n_runs`` trajectories of the filter's own discrete model (x_{k+1} = Φx_k +
    Γu_k + w_k, w_k ~ N(0, Q_d), x_0 ~ N(0, P0)), u the thruster's ``torque`` (roll,
    yaw per run) on the ``flagged`` steps, with roll and h measured at every sample
    and no yaw (a Sun gap, where yaw is inferred)."""
    d = discretize(PARAMS, NOISE, dt)
    Lq = np.linalg.cholesky(d.Qd + 1e-30 * np.eye(9))
    x = rng.standard_normal((n_runs, 9)) @ np.linalg.cholesky(P0).T
    kick = input_vector(PARAMS, torque[:, 0], torque[:, 1]) @ d.Gamma.T   # (runs, 9)
    xs = np.empty((n, n_runs, 9))
    for k in range(n):
        xs[k] = x
        x = x @ d.Phi.T + rng.standard_normal((n_runs, 9)) @ Lq.T + (kick if flagged[k] else 0)
    roll = xs[:, :, 0] + np.sqrt(R_ROLL) * rng.standard_normal((n, n_runs))
    h = xs[:, :, 4] + np.sqrt(R_H) * rng.standard_normal((n, n_runs))
    return d, xs, roll, h


def test_inflate_covers_an_unknown_impulse_and_ignore_does_not(rng):
    """100 runs: 10 min, then ±τ on roll and on yaw (signs at random) for D_max = 10 min
    with the flag set, then 10 min.  Eq. 45's white torque q_m = τ² D_max makes the
    added momentum variance q_m D_max = (τ D_max)², the impulse's square, so at the
    end the 9-state NEES averaged over the runs is inside its 99% χ²(9·100) bounds;
    with the flag ignored the filter, sure of its yaw, is far outside them."""
    n_runs, dt = 100, 4.0
    n = int(3 * D_MAX / dt)
    flag = np.zeros(n)
    flag[n // 3:2 * n // 3] = 1
    torque = TAU * rng.choice([-1.0, 1.0], size=(n_runs, 2))
    d, xs, roll, h = _truth_runs(rng, n_runs, n, dt, flag > 0, torque)
    end = n - 1
    lo, hi = chi2_bounds(9, n_runs, 0.99)
    mean = {}
    for response in ("inflate", "ignore"):
        values = []
        for j in range(n_runs):
            meas = Measurements(roll[:, j], np.full(n, np.nan), h[:, j], R_ROLL, R_YAW, R_H)
            r = kalman_filter(meas, d, np.zeros(9), P0, extra=_extra(flag, response),
                              rows=[end])
            values.append(nees(r.x, unpack(r.P_packed), xs[end, j][None])[0])
        mean[response] = np.mean(values)
    assert lo < mean["inflate"] < hi, mean
    assert mean["ignore"] > 10 * hi, mean


def _no_measurement_at(n, k, rng):
    """Roll and h at every sample but ``k`` (there the posterior is the prior)."""
    roll = 1e-4 * rng.standard_normal(n)
    h = 1e-3 * rng.standard_normal(n)
    roll[k] = h[k] = np.nan
    return Measurements(roll, np.full(n, np.nan), h, R_ROLL, R_YAW, R_H)


def test_reset_returns_the_attitude_block_to_the_prior_at_the_first_sample_after(rng):
    """Flag on samples 20–29: at sample 30 (no measurement, so its posterior is its
    prior) P's attitude block is P0's to the bit and uncorrelated with h and the torque
    states, whose own block and the estimate are the plain prediction from sample 29;
    a run with the stretch ending at sample 31 has sample 30 not reset."""
    n, dt = 60, 2.0
    d = discretize(PARAMS, NOISE, dt)
    flag = np.zeros(n)
    flag[20:30] = 1
    meas = _no_measurement_at(n, 30, rng)
    r = kalman_filter(meas, d, np.zeros(9), P0, extra=_extra(flag, "reset"))
    P = unpack(r.P_packed)
    assert np.array_equal(P[30][np.ix_(ATT, ATT)], P0[np.ix_(ATT, ATT)])
    assert np.all(P[30][ATT, 4:] == 0.0)
    pred = d.Phi @ P[29] @ d.Phi.T + d.Qd
    assert cov_dev(P[30][4:, 4:], pred[4:, 4:]).max() < 1e-12
    assert np.allclose(r.x[30], d.Phi @ r.x[29], rtol=1e-12, atol=0)
    later = flag.copy()
    later[30] = 1
    r2 = kalman_filter(meas, d, np.zeros(9), P0, extra=_extra(later, "reset"))
    P2 = unpack(r2.P_packed)
    assert not np.allclose(P2[30][np.ix_(ATT, ATT)], P0[np.ix_(ATT, ATT)])
    assert cov_dev(P2[30], d.Phi @ P2[29] @ d.Phi.T + d.Qd).max() < 1e-12


def _expm_step(dt, q):
    """Φ, Γ, Q_d from scipy's expm and Van Loan's method (Eqs. 31-32)."""
    F = dynamics_matrix(PARAMS)
    Q = np.zeros((9, 9))
    Q[1, 1] = q.q_x / H**2                          # Eq. 34, typed from the paper
    Q[3, 3] = (q.q_z + q.q_w) / H**2
    Q[3, 4] = Q[4, 3] = -q.q_w / H
    Q[4, 4] = q.q_w
    Q[5, 5], Q[6, 6], Q[7, 7], Q[8, 8] = q.q_px, q.q_pz, q.q_cx, q.q_cz
    n = 9
    van = sl.expm(np.block([[-F, Q], [np.zeros((n, n)), F.T]]) * dt)
    gam = sl.expm(np.block([[F, np.eye(n)], [np.zeros((n, 2 * n))]]) * dt)[:n, n:]
    Qd = van[n:, n:].T @ van[:n, n:]
    return sl.expm(F * dt), gam, 0.5 * (Qd + Qd.T)


def _posterior(steps, z, r, u, upto=None):
    """The trajectory's joint Gaussian (x_0 ~ N(0, P0), x_{k+1} = A_k x_k + Γ_k u_k +
    b_k + w_k, w_k ~ N(0, Q_k)) conditioned on the measurements of roll, yaw, h (NaN:
    none) at samples ≤ ``upto``: each sample's mean and covariance."""
    n = len(z)
    upto = n - 1 if upto is None else upto
    mu = np.zeros((n, 9))
    S = np.zeros((9 * n, 9 * n))
    S[:9, :9] = P0
    for k in range(n - 1):
        A, G, Q, b = steps[k]
        mu[k + 1] = A @ mu[k] + G @ u[k] + b
        blk = slice(9 * k, 9 * k + 9)
        nxt = slice(9 * k + 9, 9 * k + 18)
        S[nxt, :9 * k + 9] = A @ S[blk, :9 * k + 9]
        S[:9 * k + 9, nxt] = S[nxt, :9 * k + 9].T
        S[nxt, nxt] = A @ S[blk, blk] @ A.T + Q
    rows, values, var = [], [], []
    for k in range(upto + 1):
        for j, state in enumerate((0, 2, 4)):
            if np.isfinite(z[k, j]):
                rows.append(9 * k + state)
                values.append(z[k, j] - mu[k, state])
                var.append(r[j])
    Hs = S[rows]
    gain = np.linalg.solve(Hs[:, rows] + np.diag(var), Hs).T
    mean = mu.ravel() + gain @ np.asarray(values)
    cov = S - gain @ Hs
    return mean.reshape(n, 9), np.array([cov[9 * k:9 * k + 9, 9 * k:9 * k + 9]
                                         for k in range(n)])


def _data(rng, n):
    z = np.column_stack([1e-4 * rng.standard_normal(n), np.full(n, np.nan),
                         1e-2 * rng.standard_normal(n)])
    z[::5, 1] = 3e-3 * rng.standard_normal(len(z[::5]))     # yaw every fifth sample
    u = input_vector(PARAMS, 1e-6, -2e-6, 1e-5 * rng.standard_normal(n))
    return z, np.array([R_ROLL, R_YAW, R_H]), u


def _compare(x, P, mean, cov, tol):
    sig = np.sqrt(np.einsum("kii->ki", cov))
    assert np.max(np.abs(x - mean) / sig) < tol
    assert cov_dev(P, cov).max() < tol


@pytest.mark.parametrize("response", ["inflate", "reset"])
def test_filter_and_smoother_are_the_posterior_of_the_flagged_model(rng, response):
    """40 samples 10 s apart, flag on samples 12–20.  The model the response stands
    for: inflate, Q_d of q_x + q_m, q_z + q_m on the flagged steps; reset, over the
    step into sample 21 the attitude drawn afresh around the filter's prediction
    (A = Φ with the attitude rows zero, b = those rows of Φ x̂⁺_20, Q = Q_d with the
    attitude block P0's and uncorrelated), x̂⁺_20 from the reference itself.  The
    smoother (with and without its covariance) equals that trajectory's posterior
    on all the data, and the filter at samples 20, 21 and 39 the posterior on the data
    up to each."""
    n, dt = 40, 10.0
    flag = np.zeros(n)
    flag[12:21] = 1
    z, r, u = _data(rng, n)
    Phi, Gam, Qd = _expm_step(dt, NOISE)
    inflated = _expm_step(dt, ProcessNoise(NOISE.q_x + Q_M, NOISE.q_z + Q_M, NOISE.q_w,
                                           NOISE.q_px, NOISE.q_pz, NOISE.q_cx, NOISE.q_cz))
    steps = [(Phi, Gam, Qd, np.zeros(9))] * (n - 1)
    if response == "inflate":
        for k in range(12, 21):
            steps[k] = (*inflated, np.zeros(9))
    else:
        before, _ = _posterior(steps, z, r, u, upto=20)
        A = Phi.copy()
        A[ATT] = 0.0
        b = np.zeros(9)
        b[ATT] = (Phi @ before[20])[ATT]
        Q = Qd.copy()
        Q[ATT] = 0.0
        Q[:, ATT] = 0.0
        Q[np.ix_(ATT, ATT)] = P0[np.ix_(ATT, ATT)]
        steps[20] = (A, Gam, Q, b)
    mean, cov = _posterior(steps, z, r, u)
    meas = Measurements(z[:, 0], z[:, 1], z[:, 2], *r)
    d = discretize(PARAMS, NOISE, dt)
    extra = _extra(flag, response)
    f = kalman_filter(meas, d, np.zeros(9), P0, u=u, extra=extra)
    for k in (20, 21, n - 1):
        m_k, c_k = _posterior(steps, z, r, u, upto=k)
        _compare(f.x[k:k + 1], f.P[k:k + 1], m_k[k:k + 1], c_k[k:k + 1], 1e-6)
    s = rts_smoother(f, d, u=u, extra=extra)
    _compare(s.x, s.P, mean, cov, 1e-6)
    s_x = rts_smoother(f, d, u=u, extra=extra, covariance=False)
    assert np.max(np.abs(s_x.x - s.x) / s.sigma) < 1e-9


def _window(meas, rows):
    return Measurements(*(v[rows] if np.ndim(v) else v for v in
                          (meas.roll_rad, meas.yaw_rad, meas.h_Nms, meas.var_roll,
                           meas.var_yaw, meas.var_h)))


@pytest.mark.parametrize("response", ["inflate", "reset"])
def test_windows_with_the_flag_formed_on_padded_telemetry_equal_the_whole(rng, response):
    """A flagged stretch ending with the first window (samples 30–49 of 0–49): the
    response formed on the whole flag and cut to each window (as a streamed run forms
    it on its padded telemetry) carries the reset into the next window's prior, and
    the smoother continued across the cut (``x_after``, ``P_after``) equals the whole
    run's."""
    n, cut, dt = 90, 50, 2.0
    flag = np.zeros(n)
    flag[30:cut] = 1
    z, r, u = _data(rng, n)
    meas = Measurements(z[:, 0], z[:, 1], z[:, 2], *r)
    d = discretize(PARAMS, NOISE, dt)
    extra = _extra(flag, response)
    whole = kalman_filter(meas, d, np.zeros(9), P0, u=u, extra=extra)
    sm = rts_smoother(whole, d, u=u, extra=extra)
    a, b = slice(0, cut), slice(cut, n)
    first = kalman_filter(_window(meas, a), d, np.zeros(9), P0, u=u[a], extra=extra.cut(a))
    second = kalman_filter(_window(meas, b), d, first.x_next, first.P_next, u=u[b],
                           extra=extra.cut(b))
    assert np.array_equal(np.vstack([first.x, second.x]), whole.x)
    assert np.array_equal(np.vstack([first.P_packed, second.P_packed]), whole.P_packed)
    later = rts_smoother(second, d, u=u[b], extra=extra.cut(b))
    earlier = rts_smoother(first, d, u=u[a], extra=extra.cut(a), x_after=later.x[0],
                           P_after=later.P_packed[0])
    assert np.max(np.abs(np.vstack([earlier.x, later.x]) - sm.x) / sm.sigma) < 1e-9
    assert cov_dev(np.vstack([earlier.P, later.P]), sm.P).max() < 1e-9


# The EKF (``estimator.ekf``): J with products of inertia, the paper's numbers.
J = np.array([[3364.4, 12.0, -8.0], [12.0, 954.9, 5.0], [-8.0, 5.0, 3461.4]])
EKF_NOISE = {"q_x": 5.4e-7, "q_y": 1e-12, "q_z": 5.4e-7, "q_w": 5e-10, "q_px": 3e-18,
             "q_pz": 3e-18, "q_cx": 3e-18, "q_cz": 3e-18}


def test_ekf_inflates_on_flagged_steps_and_resets_after():
    """The EKF without measurements from a state at rest: one flagged step adds the
    white torque's ½Δt(Φ G Q_m Gᵀ Φᵀ + G Q_m Gᵀ) (its trapezoid Q_d) to P, where Q_m
    puts q_m on the roll and yaw torques, and the rest of P is the unflagged run's;
    reset gives the roll and yaw block of P0 at the first sample after, uncorrelated."""
    dt, n = 0.512, 6
    wn = H / np.sqrt(J[0, 0] * J[2, 2])
    pm = em_ekf.pack_params(J, PARAMS.omega0_radps, dt, EKF_NOISE)
    X0 = np.r_[0.0, 0.0, 0.0, 1.0, np.zeros(8)]
    Pe = np.diag([1e-8, 1e-8, 1e-6, 1e-10, 1e-10, 1e-10, 1e-3, 1e-12, 1e-12, 1e-12, 1e-12])
    inputs = EkfInputs(np.full((n, 4), np.nan), np.ones((n, 4)), np.tile([H, 0, 0, 0, 0],
                                                                          (n, 1)))
    flag = np.zeros(n)
    flag[2] = 1
    block = Pe[np.ix_(ROLL_YAW, ROLL_YAW)]
    plain = ekf_filter(inputs, pm, wn, X0, Pe)
    inflate = Maneuver.of(flag, "inflate", Q_M, None, block, ROLL_YAW)
    r = ekf_filter(EkfInputs(inputs.z, inputs.r, inputs.u, inflate), pm, wn, X0, Pe)
    assert np.array_equal(r.x, plain.x)                 # no measurement: no estimate moves
    assert np.array_equal(r.P_packed[:3], plain.P_packed[:3])
    # The white torque on body roll and yaw through J⁻¹ (δω̇ = J⁻¹ N).
    G = np.zeros((11, 2))
    G[3:6] = np.linalg.inv(J)[:, [0, 2]]
    expected = dt * Q_M * G @ G.T
    head = slice(0, 3)
    after = ekf_filter(EkfInputs(inputs.z[head], inputs.r[head], inputs.u[head],
                                 inflate.cut(head)), pm, wn, X0, Pe)
    base = ekf_filter(EkfInputs(inputs.z[head], inputs.r[head], inputs.u[head]), pm, wn,
                      X0, Pe)
    added = after.P_next - base.P_next
    # Φ over 0.512 s is I to ω_n Δt ≈ 0.02 in the rate block: the trapezoid within 5%.
    rates = np.ix_([3, 5], [3, 5])
    assert np.allclose(added[rates], expected[rates], rtol=0.05, atol=0.05 * expected[3, 3])
    reset = Maneuver.of(flag, "reset", Q_M, None, block, ROLL_YAW)
    rr = ekf_filter(EkfInputs(inputs.z, inputs.r, inputs.u, reset), pm, wn, X0, Pe)
    first = ekf_filter(EkfInputs(inputs.z[head], inputs.r[head], inputs.u[head],
                                 reset.cut(head)), pm, wn, X0, Pe)
    assert np.array_equal(first.P_next[np.ix_(ROLL_YAW, ROLL_YAW)], block)
    others = [i for i in range(11) if i not in ROLL_YAW]
    assert np.all(first.P_next[np.ix_(ROLL_YAW, others)] == 0.0)
    assert not np.allclose(rr.P_packed[3], plain.P_packed[3], rtol=1e-3, atol=0)
    assert np.array_equal(rr.P_packed[:3], plain.P_packed[:3])


def test_inflated_params_touch_roll_and_yaw_noise_only():
    pm = em_ekf.pack_params(J, PARAMS.omega0_radps, 0.512, EKF_NOISE)
    p = inflated_params(pm, ProcessNoise(q_x=Q_M, q_z=Q_M, q_w=0.0))
    changed = np.flatnonzero(p != pm)
    tail = em_ekf.N_PARAMS - len(em_ekf.NOISE_NAMES)
    assert set(changed) == {tail + 0, tail + 2}          # q_x, q_z in NOISE_NAMES' order
    assert p[tail] == pytest.approx(EKF_NOISE["q_x"] + Q_M)
