"""Momentum management (issue 45): the magnetic momentum-direction law and the daily
solar torque loop, against their hand-derived closed-loop eigenvalues
(docs/conventions.md, "Momentum management"), and momentum conservation with them off.

Each test was seen failing on a planted sign: ``+ dir_gain`` in ``sim.control`` (the
orbit-rate pair's real part +2.0e-5 instead of −2.0e-5), and ``target + mean`` in
``sim.momentum.command`` (a root at 1.5, outside the unit circle)."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from sim import geomag
from sim.control import Control
from sim.environment import Environment
from sim.momentum import SolarManagement, actuator_directions, command
from sim.step import build_step, input_layout, pack_params
from sim.truth import InitialState, simulate_truth

from .conftest import EQUINOX
from .test_dynamics import inertial_momentum

K_D = 2e-5   # 1/s: a 14 h time constant, the scenario default


def _managed_eigenvalues(spacecraft, orbit, control, env=None):
    n = spacecraft.n_wheels
    env = Environment.torque_free() if env is None else env
    p = pack_params(spacecraft, orbit, env, control, 0.512, managed=True)
    step = build_step(n, managed=True)
    x = ca.SX.sym("x", 7 + n)
    zeros = [np.zeros(k) for _, k in input_layout(n)]
    jac = ca.Function("managed_jacobian", [x], [ca.jacobian(step(x, *zeros, p)[0], x)])
    return np.linalg.eigvals(np.array(jac(InitialState().state_vector(spacecraft, orbit))))


def _hand_pair(orbit, k_d):
    """The transverse momentum in the orbit frame obeys Ḣ⊥ = S H⊥ − k_d P H⊥ with
    S = [[0, ω0], [−ω0, 0]] (from Ḣ_R = T_R − ω_RN × H_R, ω_RN = −ω0 ŷ) and P = I − b bᵀ,
    b the field's unit vector's (x, z) components: m × B with m = B × T/|B|² delivers T
    less its part along B.  Trace −k_d(2 − |b|²), determinant ω0² + k_d²(1 − |b|²)."""
    field = geomag.geo_field_orbit_frame(orbit.longitude_rad, orbit.radius_m)
    b = field[[0, 2]] / np.linalg.norm(field)
    w0 = orbit.rate_radps
    tr = -k_d * (2 - b @ b)
    det = w0**2 + k_d**2 * (1 - b @ b)
    return tr / 2 + 1j * np.sqrt(det - tr**2 / 4)


@pytest.mark.parametrize("k_d", [K_D, 1e-4])
def test_direction_law_places_the_orbit_rate_pair(spacecraft, orbit, k_d):
    """The nonlinear managed step's Jacobian at Earth pointing, unloading off: the
    orbit-rate pair, neutral without an external torque (test_dynamics), sits at the
    hand-derived −k_d(1 − |b|²/2) ± iω0.  The held dipole over a 0.512 s step moves it by
    O(k_d Δt) ~ 1e-5 relative; 1e-3 is the tolerance."""
    dt = 0.512
    eig = _managed_eigenvalues(spacecraft, orbit,
                               Control(magnetic_unloading=False, momentum_direction_gain_per_s=k_d))
    lam = np.log(eig[np.abs(eig) > 1e-8].astype(complex)) / dt
    pair = lam[np.abs(np.abs(lam.imag) / orbit.rate_radps - 1) < 0.05]
    assert len(pair) == 2
    want = _hand_pair(orbit, k_d)
    np.testing.assert_allclose(np.sort_complex(pair), [want.conjugate(), want], rtol=1e-3)
    assert np.all(pair.real < 0)


def test_managed_step_with_the_loops_off_is_the_plain_step(spacecraft, orbit):
    """k_d = 0 and no offset torque: the managed step's Jacobian has the plain step's
    eigenvalues (the neutral orbit-rate pair included), to the eigenproblem's round-off."""
    from .test_dynamics import _step_eigenvalues
    c = Control(magnetic_unloading=False)
    plain = np.sort_complex(_step_eigenvalues(spacecraft, orbit, c))
    managed = np.sort_complex(_managed_eigenvalues(spacecraft, orbit, c, Environment()))
    np.testing.assert_allclose(managed, plain, rtol=0, atol=1e-12)


def test_momentum_is_conserved_with_the_loops_off_and_decays_with_them_on(spacecraft, orbit):
    """Torque-free, the managed step with k_d = 0 keeps the inertial momentum to RK4's
    round-off over 2 h; with k_d on, the torquers take the transverse momentum of a
    0.0005° yaw offset (1.1e-3 N m s, a torque of 2e-7 N m: unsaturated) down as
    e^(Re λ t), Re λ the hand-derived pair's."""
    env = Environment.torque_free()
    initial = InitialState(yaw_rad=np.deg2rad(0.0005))
    k_on = 2e-4
    runs = {}
    for k_d in (0.0, k_on):
        c = Control(magnetic_unloading=False, momentum_direction_gain_per_s=k_d)
        res = simulate_truth(spacecraft, orbit, env, c, initial, EQUINOX, 7200.0,
                             model=None, managed=True)
        runs[k_d] = inertial_momentum(res, spacecraft, orbit)
    h = runs[0.0]
    assert np.max(np.abs(h - h[0])) < 1e-9
    transverse = np.linalg.norm(runs[k_on][:, :2], axis=1)
    want = np.exp(_hand_pair(orbit, k_on).real * 7200.0)     # 0.24
    assert abs(transverse[-1] / transverse[0] / want - 1) < 0.1


def test_solar_loop_eigenvalues_match_the_hand_derivation():
    """``command`` closed around the daily plant H_{k+1} = H_k + T N_{k+1},
    N_{k+1} = N_k + D Δκ (D the two actuators' directions): the 4 × 4 map built by
    applying the code to unit states has, on each axis, the roots of
    z² − (2 − g − gT/τ) z + (1 − g) = 0 (sim.momentum)."""
    sun = np.array([np.cos(0.3), np.sin(0.3), 0.2])
    sun /= np.linalg.norm(sun)
    directions = actuator_directions(sun, np.array([0.0, 0.0, -1.0]))
    for g, tau_days in ((1.0, 2.0), (0.5, 3.0)):
        law = SolarManagement(torque_gain=g, momentum_time_constant_s=tau_days * 86400.0)
        T = law.period_s

        def day(state, law=law, T=T):
            h, n = state[:2], state[2:]
            dk = command(law, h, n, directions)
            n_next = n + directions @ dk
            return np.concatenate([h + T * n_next, n_next])
        M = np.column_stack([day(e) for e in np.eye(4)])
        roots = np.roots([1, -(2 - g - g * T / (tau_days * 86400.0)), 1 - g])
        got = np.linalg.eigvals(M)
        # Repeated roots: compare characteristic polynomials, not sorted lists.
        np.testing.assert_allclose(np.poly(got).real, np.poly(np.concatenate([roots, roots])).real,
                                   atol=1e-9)
        assert np.all(np.abs(got) < 1)
        np.testing.assert_allclose(np.sort_complex(np.linalg.eigvals(law.transition())),
                                   np.sort_complex(roots), atol=1e-12)
