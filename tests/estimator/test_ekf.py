"""The extended Kalman filter (estimator.ekf) against independent references: the
quaternion algebra against DCM products, its Jacobians against finite differences,
its process model against the truth simulator's own rollout, the paper's filter on
a tiny-angle case (first order: they must agree), and NEES on its own model."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from estimator.ekf import model as m
from estimator.ekf.filter import EkfInputs, ekf_filter, initial_state
from estimator.kalman.consistency import chi2_bounds, fraction_inside, nees
from estimator.kalman.filter import unpack
from rollout.chunks import ChunkedRollout

DT = 0.512
W0 = np.sqrt(3.986004418e14 / 42164170.0**3)
H = -0.1082 * 2 * 5485 * 2 * np.pi / 60 * np.cos(np.deg2rad(1.656))   # Eq. 1, signed
J = np.array([[3364.4, 12.0, -8.0], [12.0, 954.9, 5.0], [-8.0, 5.0, 3461.4]])
NOISE = {"q_x": 5.4e-7, "q_y": 1e-12, "q_z": 5.4e-7, "q_w": 5e-10, "q_px": 3e-18,
         "q_pz": 3e-18, "q_cx": 3e-18, "q_cz": 3e-18}
PM = m.pack_params(J, W0, DT, NOISE)
WN = H / np.sqrt(J[0, 0] * J[2, 2])
R = np.array([3.3e-8, 3.3e-8, np.deg2rad(0.04) ** 2, 1.5e-7])


def _fn(name, args, out):
    return ca.Function(name, args, [out])


X_S, DX_S = ca.SX.sym("X", m.NX), ca.SX.sym("dx", m.NE)
U_S, P_S = ca.SX.sym("u", m.NU), ca.SX.sym("p", m.N_PARAMS)
RK4 = _fn("rk4", [X_S, U_S, P_S], m.rk4(X_S, U_S, P_S))
INJECT = _fn("inject", [X_S, DX_S], m.inject(X_S, DX_S))
PHI, HJ, TJ = m.error_jacobians()
MEASURE = _fn("measure", [X_S], m.measure(X_S))


def _np(f, *a):
    return np.array(f(*a)).squeeze()


def _state(rng, angle=0.2):
    q = rng.standard_normal(4) * np.array([angle, angle, angle, 0.0]) + np.array([0, 0, 0, 1])
    q /= np.linalg.norm(q)
    return np.concatenate([q, rng.standard_normal(3) * 1e-3, [0.3], rng.standard_normal(4) * 1e-5])


def test_quaternion_product_composes_rotations(rng):
    a, b = ca.SX.sym("a", 4), ca.SX.sym("b", 4)
    prod = _fn("prod", [a, b], m.quat_mult(a, b))
    from eom.gyrostat import dcm_from_quat
    dcm = _fn("dcm", [a], dcm_from_quat(a))
    for _ in range(5):
        q, p = rng.standard_normal(4), rng.standard_normal(4)
        q, p = q / np.linalg.norm(q), p / np.linalg.norm(p)
        np.testing.assert_allclose(_np(dcm, _np(prod, q, p)), _np(dcm, q) @ _np(dcm, p),
                                   atol=1e-14)


def _fd(f, X, n_out, h=1e-7):
    """Central differences of f(X ⊕ δx) in each error coordinate."""
    out = np.empty((n_out, m.NE))
    for j in range(m.NE):
        e = np.zeros(m.NE)
        e[j] = h
        out[:, j] = (f(_np(INJECT, X, e)) - f(_np(INJECT, X, -e))) / (2 * h)
    return out


def test_transition_against_finite_differences_of_the_rk4_step(rng):
    """Φ (third-order series of F Δt) against central differences of the RK4 step
    mapped back to the error state (the extraction relative to the nominal step).
    The series leaves out (F Δt)⁴/24 ≈ 5e-9 and differencing with h = 1e-7 in
    double precision is good to ~1e-8 relative, so 1e-6 of ‖Φ‖ is a margin of 100."""
    Xr, Yr = ca.SX.sym("Xr", m.NX), ca.SX.sym("Y", m.NX)
    extract = _fn("ex", [Xr, Yr], m.extract(Xr, Yr))
    for _ in range(3):
        X = _state(rng)
        u = np.array([H, 1e-5, 2e-4, 3e-6, -2e-6])
        Xn = _np(RK4, X, u, PM)
        Phi = _np(PHI, X, u, PM)
        # The error state after the step, relative to the nominal step's result.
        fd = _fd(lambda Y, Xn=Xn, u=u: _np(extract, Xn, _np(RK4, Y, u, PM)), X, m.NE)
        assert np.max(np.abs(Phi - fd)) < 1e-6 * np.max(np.abs(Phi))


def test_measurement_rows_against_finite_differences(rng):
    for _ in range(3):
        X = _state(rng, angle=0.3)
        Hm = _np(HJ, X)
        fd = _fd(lambda Y: _np(MEASURE, Y), X, m.NZ)
        np.testing.assert_allclose(Hm, fd, atol=1e-7)


def _twin_data(n, rng, yaw_every=None):
    """A noisy rollout of the EKF's own model from a random prior draw, sensed with
    the filter's own R: the setting in which the filter must be consistent."""
    Xs, W = ca.SX.sym("X", m.NX), ca.SX.sym("w", m.NE)
    step = ca.Function("ekf_twin", [Xs, W, U_S, P_S],
                       [m.inject(m.rk4(Xs, U_S, P_S), W), Xs])
    roll = ChunkedRollout(step, 4096)
    u = np.tile([H, 0.0, 0.0, 0.0, 0.0], (n, 1))
    X0, P0 = _prior()
    # Q_d near Earth pointing, drawn per step (it barely depends on the state here).
    G = np.array(ca.Function("g", [P_S], [m.noise_map(P_S)])(PM))
    GQG = G @ np.diag([NOISE[k] for k in m.NOISE_NAMES]) @ G.T * DT
    L = np.linalg.cholesky(GQG + 1e-40 * np.eye(m.NE))
    truth0 = _np(INJECT, X0, np.linalg.cholesky(P0) @ rng.standard_normal(m.NE))
    w = rng.standard_normal((n, m.NE)) @ L.T
    _, X = roll.run_final(truth0, [w, u], PM)
    z = np.array(ca.Function("meas_map", [X_S], [m.measure(X_S)]).map(n)(X.T)).T
    z = z + np.sqrt(R) * rng.standard_normal((n, m.NZ))
    if yaw_every is not None:
        z[(np.arange(n) // yaw_every) % 2 == 1, 2] = np.nan
    return X, EkfInputs(z, np.tile(R, (n, 1)), u)


def _prior():
    x0 = np.zeros(9)
    P0 = np.diag([np.deg2rad(0.05) ** 2, 1e-6, np.deg2rad(0.5) ** 2, 1e-6, 1e-2,
                  1e-12, 1e-12, 1e-12, 1e-12])
    return initial_state(x0, P0, np.deg2rad(0.05), 1e-5, WN)


def test_nees_on_its_own_model_pooled_over_runs(rng):
    """20 runs of 3 h of the filter's own model (the nonlinear gyrostat, white torque
    noise, yaw measured half the time): the run-averaged NEES of roll, its rate, yaw,
    its rate and h lies inside the 95% χ²(5) bounds at ≥ 90% of the epochs after
    convergence, and the 9-state NEES over runs and epochs inside its 99% bounds."""
    n_runs, n = 20, int(3 * 3600 / DT)
    X0, P0 = _prior()
    keep = np.arange(1500, n, 200)
    to_paper = ca.Function("tp", [X_S], [m.paper_coordinates(X_S, PM, WN)]).map(len(keep))
    nees5, nees9 = [], []
    for _ in range(n_runs):
        X, inputs = _twin_data(n, rng, yaw_every=1800)
        res = ekf_filter(inputs, PM, WN, X0, P0, rows=keep)
        xt = np.array(to_paper(X[keep].T)).T
        P = unpack(res.P_packed)
        nees5.append(nees(res.x, P, xt, states=range(5)))
        nees9.append(nees(res.x, P, xt))
    assert fraction_inside(np.mean(nees5, axis=0), chi2_bounds(5, n_runs)) >= 0.90
    lo, hi = chi2_bounds(9, n_runs, 0.99)
    assert lo < np.mean(nees9) < hi


@pytest.mark.parametrize("bad", ["R", "u"])
def test_bad_inputs_are_rejected(bad):
    n = 10
    z, r, u = np.zeros((n, 4)), np.tile(R, (n, 1)), np.tile([H, 0, 0, 0, 0], (n, 1))
    if bad == "R":
        r[3, 1] = -1.0
    else:
        u[2, 0] = np.nan
    X0, P0 = _prior()
    with pytest.raises(ValueError):
        ekf_filter(EkfInputs(z, r, u), PM, WN, X0, P0)
