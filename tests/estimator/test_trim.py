"""The κ fit of `dynprop trim` (estimator.analysis.trim) against references it does not use:
the model's own torque form, generalised least squares' χ² statistics, and the
imbalance law of the truth's SolarTorque."""

from __future__ import annotations

import numpy as np
import pytest

from estimator.analysis.trim import equivalent_states, fit_kappa, recommend, torque_basis
from sim.environment import SolarTorque

W0 = 7.2921e-5


def _model_torque(t, theta, w0=W0):
    """Roll and yaw torque of the states θ = [N_px, N_pz, N_cx, N_cz] at t = 0,
    propagated as the filter's Φ does: the exact solution of Ṅ_px = ω0 N_pz,
    Ṅ_pz = −ω0 N_px (Eq. 18), written out independently of torque_basis."""
    a, b, cx, cz = theta
    c, s = np.cos(w0 * t), np.sin(w0 * t)
    return np.column_stack([a * c + b * s + cx, -a * s + b * c + cz])


def test_a_torque_of_the_models_form_maps_to_its_own_states():
    t = np.linspace(0.0, 2 * 86400.0, 4001)
    theta0 = np.array([3e-6, -7e-6, 2e-7, -4e-7])
    y = _model_torque(t, theta0)
    # At the batch end the states have turned by ω0 t_end.
    c, s = np.cos(W0 * t[-1]), np.sin(W0 * t[-1])
    expected = np.array([theta0[0] * c + theta0[1] * s, -theta0[0] * s + theta0[1] * c,
                         theta0[2], theta0[3]])
    got = equivalent_states(t, y, t[-1], W0)
    # A 4×4 solve of well-conditioned sums: a few ulps of 1e-5.
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-17)
    # And the basis reproduces the torque it was fitted to.
    np.testing.assert_allclose(np.einsum("nki,i->nk", torque_basis(t, t[-1], W0), got), y,
                               rtol=0, atol=1e-17)


def test_gls_error_over_sigma_is_unit_normal_and_the_spare_dof_is_chi2_1():
    rng = np.random.default_rng(7)
    v = np.array([0.8, -0.55, 0.1, 0.05])
    A = rng.normal(size=(4, 4))
    P = (A @ A.T + 4 * np.eye(4)) * 1e-15
    L = np.linalg.cholesky(P)
    kappa, c = 1e-5, np.array([3e-7, -2e-7])
    z, chi2 = [], []
    for _ in range(4000):
        theta = kappa * v + np.r_[0, 0, c] + L @ rng.standard_normal(4)
        f = fit_kappa(theta, P, v)
        z.append((f.kappa_Nm - kappa) / f.sigma_Nm)
        chi2.append(f.out_of_phase_chi2)
    z, chi2 = np.array(z), np.array(chi2)
    # 4000 draws: the mean of z has σ 0.016, the sample std ≈ 0.011, the χ²(1) mean 0.022.
    assert abs(z.mean()) < 0.07
    assert 0.95 < z.std() < 1.05
    assert 0.9 < chi2.mean() < 1.1


def test_a_periodic_torque_out_of_phase_with_the_sun_is_flagged():
    v = np.array([1.0, 0.0, 0.0, 0.0])
    P = np.diag([1e-14, 1e-14, 1e-14, 1e-14])   # σ 1e-7 N m each
    f = fit_kappa(np.array([0.0, 5e-7, 0.0, 0.0]), P, v)   # a torque 90° from the Sun's
    assert abs(f.kappa_Nm) < 1e-20
    assert f.out_of_phase_chi2 == pytest.approx(25.0)   # (5e-7 / 1e-7)²
    assert f.out_of_phase_Nm == pytest.approx(5e-7)


def test_the_recommended_tab_leaves_the_residual_the_law_predicts():
    solar = SolarTorque.with_residual(1e-5)
    f = fit_kappa(np.array([1e-5, 0, 0, 0]), np.eye(4) * 1e-16, np.array([1.0, 0, 0, 0]))
    rec = recommend(f, solar.trim_tab_deg, solar.tab_effectiveness_Nm_per_deg)
    after = SolarTorque(trim_tab_deg=rec.trim_tab_deg_new)
    assert rec.move
    assert abs(after.coefficient_Nm) < 1e-18
    assert rec.trim_tab_deg_new == pytest.approx(20.0)
    assert rec.sigma_deg == pytest.approx(1e-8 / 2.5e-6)


def test_a_kappa_within_three_sigma_of_zero_asks_for_no_move():
    f = fit_kappa(np.array([2e-7, 0, 0, 0]), np.eye(4) * 1e-14, np.array([1.0, 0, 0, 0]))
    rec = recommend(f, 19.6, 2.5e-6)
    assert not rec.move
    assert rec.trim_tab_deg_new == 19.6
