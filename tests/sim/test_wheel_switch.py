"""The switch to the backup yaw wheel (``wheel_switch``, ``Spacecraft.standby_wheel``)
against independent references.

The references: the two-wheel GOES-Next closed loop (tests/sim/test_dynamics.py checks
it on its own), which the three-wheel spacecraft must fly identically, since an idle
wheel at rest and a yaw demand delivered by another wheel change nothing the body
feels; each wheel's absolute axial momentum I_w (Ω_i + a_i·ω), which changes only by
its own motor torque (so an uncommanded wheel's is constant, and equal torques on the
V pair keep its difference); and the total inertial momentum, which internal motor
torques cannot change."""

from __future__ import annotations

import dataclasses

import casadi as ca
import numpy as np
import pytest

from sim import ephemeris
from sim.control import Control
from sim.environment import Environment, WheelRipple
from sim.events import Event, Schedule
from sim.frames import GeoOrbit, dcm_from_quat
from sim.spacecraft import GOES_NEXT_YAW_WHEEL_INERTIA_KGM2, goes_next
from sim.step import build_step, input_layout, pack_params
from sim.truth import InitialState, simulate_truth

from .conftest import EQUINOX

DT = 0.512
T_SWITCH = 1800.1          # between samples: the switch flies from sample 3516
K_SWITCH = int(np.ceil(T_SWITCH / DT))
INIT = InitialState(yaw_rad=1e-3, roll_rad=2e-4, rate_wrt_orbit_radps=(2e-6, 0.0, -1e-6))
SWITCH = Schedule((Event("wheel_switch", T_SWITCH),))


def _three():
    return goes_next(standby_yaw_wheel_inertia_kgm2=GOES_NEXT_YAW_WHEEL_INERTIA_KGM2)


def _absolute(sc, res) -> np.ndarray:
    """Each wheel's absolute axial momentum I_w (Ω_i + a_i·ω_BN), (N, n)."""
    return sc.wheel_inertias * (res.wheel_speeds_radps + res.w_bn_radps @ sc.wheel_axes.T)


@pytest.fixture(scope="module")
def quiet_ripple():
    """2 h of the default environment and control with the ripple off (every other
    torque on, so the loop moves h), switched at T_SWITCH; and the two-wheel run."""
    env = dataclasses.replace(Environment(), ripple=WheelRipple(enabled=False))
    three = simulate_truth(_three(), GeoOrbit(), env, Control(), INIT, EQUINOX, 7200.0, DT,
                           schedule=SWITCH)
    two = simulate_truth(goes_next(), GeoOrbit(), env, Control(), INIT, EQUINOX, 7200.0, DT)
    return three, two


def test_the_switch_changes_nothing_the_body_feels(quiet_ripple):
    """The yaw demand ḣ is the same whichever wheel delivers it, and the idle wheel at
    rest adds nothing but its freedom: frictionless, it does not follow the body's yaw
    accelerations, which a rigid part of the body would, so the body's yaw inertia is
    in effect smaller by I_rw / J_zz = 2.5e-6.  So the three-wheel run's attitude and
    total yaw wheel momentum h are the two-wheel run's, before and after the switch,
    to that fraction of their swings (measured 5e-6 of each swing, both sides of the
    switch; tolerance 4 I_rw / J_zz = 1e-5).  A wrong sign or a lost share of the
    yaw demand changes the loop by order one: its swing, not 1e-5 of it."""
    three, two = quiet_ripple
    ratio = 4 * GOES_NEXT_YAW_WHEEL_INERTIA_KGM2 / goes_next().J[2, 2]
    np.testing.assert_allclose(three.euler_rad, two.euler_rad, rtol=0,
                               atol=ratio * np.max(np.ptp(two.euler_rad, axis=0)))
    np.testing.assert_allclose(three.h_Nms, two.h_Nms, rtol=0, atol=ratio * np.ptp(two.h_Nms))
    assert np.ptp(two.h_Nms[K_SWITCH:]) > 1e-3         # the loop moves h after the switch


def test_the_yaw_wheel_idles_then_carries_the_loops_h(quiet_ripple):
    """Before the switch the yaw wheel has no command: its absolute momentum stays
    where it started, 0 rpm relative to the body save the body's yaw rate change
    (1e-7 rad/s, 1e-6 rpm).  From the switch's sample on the V pair gets equal
    torques (the common mode): the difference of its two absolute momenta stays at
    the switch's value, and the changes of the total absolute yaw momentum of the
    wheels are the yaw wheel's alone.  Before it the V pair's difference moves with h."""
    sc = _three()
    three, _ = quiet_ripple
    ab = _absolute(sc, three)
    rw = ab[:, 2]
    assert np.max(np.abs(rw[:K_SWITCH + 1] - rw[0])) < 1e-15
    # Its tachometer reads 0: the body's yaw-rate change (5e-6 rad/s, 5e-5 rpm) is
    # below the quantum, 0.0163 rpm.
    assert np.max(np.abs(three.wheel_speeds_radps[:K_SWITCH + 1, 2])) * 60 / (2 * np.pi) < 1e-3
    diff = ab[:, 0] - ab[:, 1]
    # |I_w Ω| = 62 N m s each: the difference holds to its round-off, 1e-14 · 62.
    assert np.max(np.abs(diff[K_SWITCH:] - diff[K_SWITCH])) < 1e-11
    assert np.ptp(diff[:K_SWITCH]) > 1e-2             # the pair carried the loop before
    yaw_total = ab @ sc.wheel_axes[:, 2]
    np.testing.assert_allclose(yaw_total[K_SWITCH:] - yaw_total[K_SWITCH],
                               rw[K_SWITCH:] - rw[K_SWITCH], rtol=0, atol=1e-11)
    assert np.ptp(rw[K_SWITCH:]) > 1e-3


def test_the_idle_wheel_has_no_ripple_until_the_switch(rng):
    """Ripple on: an unpowered motor makes none, so the yaw wheel's absolute momentum
    is constant until the switch (to round-off, while the ripple walks each momentum
    wheel's by sqrt(q t) = 0.03 N m s in 30 min), and the ripple moves it after."""
    sc = _three()
    res = simulate_truth(sc, GeoOrbit(), Environment(), Control(), INIT, EQUINOX, 2400.0, DT,
                         rng=rng, schedule=SWITCH)
    ab = _absolute(sc, res)
    assert np.max(np.abs(ab[:K_SWITCH + 1, 2] - ab[0, 2])) < 1e-15
    assert np.ptp(ab[K_SWITCH:, 2]) > 1e-4


def test_switch_conserves_total_inertial_momentum(orbit):
    """Torque-free (every environment torque and the torquers off), the loop on and
    switched mid-run: the motor torques are internal, so the total angular momentum
    in inertial axes, C_NR C_RB (J ω + Σ I_w Ω_i a_i), keeps its value across the
    switch.  Its size is the 124 N m s bias; the torque-free RK4 drift is 3e-12 N m s a
    day (tests/sim/test_dynamics.py), so 1e-10 over 40 min is sharp: a wheel respun at
    the switch (its momentum put in or taken out, ±1e-3 N m s) is far outside."""
    sc = _three()
    res = simulate_truth(sc, orbit, Environment.torque_free(),
                         Control(magnetic_unloading=False), INIT, EQUINOX, 2400.0, DT,
                         schedule=SWITCH)
    h_b = res.w_bn_radps @ sc.J.T + sc.wheel_momentum(res.wheel_speeds_radps)
    gmst0 = ephemeris.gmst_rad(ephemeris.julian_date(EQUINOX))
    c_nr = np.swapaxes(orbit.orbit_frame(res.t_s, gmst0), -1, -2)
    c_rb = np.swapaxes(dcm_from_quat(res.q_br), -1, -2)
    h_n = np.einsum("nij,njk,nk->ni", c_nr, c_rb, h_b)
    assert np.max(np.linalg.norm(h_n - h_n[0], axis=1)) < 1e-10
    assert np.ptp(_absolute(sc, res)[K_SWITCH:, 2]) > 1e-5   # the yaw wheel did work


def _eigenvalues(sc, control, orbit):
    """Eigenvalues of the nonlinear step's Jacobian at Earth pointing (the Sun off),
    as tests/sim/test_dynamics.py forms them."""
    n = sc.n_wheels
    p = pack_params(sc, orbit, Environment(), control, DT)
    x = ca.SX.sym("x", 7 + n)
    zeros = [np.zeros(k) for _, k in input_layout(n)]
    jac = ca.Function("step_jacobian", [x], [ca.jacobian(build_step(n)(x, *zeros, p)[0], x)])
    return np.linalg.eigvals(np.array(jac(InitialState().state_vector(sc, orbit))))


@pytest.mark.parametrize("switched", [False, True])
def test_closed_loop_after_the_switch(orbit, switched):
    """Standby and switched: two neutral modes (the V pair's common speed, which the
    pitch loop does not hold, as with two wheels; and, idle, the yaw wheel's momentum,
    or, switched, the pair's difference, which nothing commands any more); every other
    mode is the two-wheel loop's (an independent step Jacobian, checked against its
    own bounds in test_dynamics), so all decay, nutation within 30 min.  The free
    yaw wheel takes I_rw / J_zz = 2.5e-6 off the body's effective yaw inertia
    (test above), which moves the nutation pole by that fraction of its angle, 0.031
    rad a step: measured 3.9e-8, tolerance 4 I_rw / J_zz · 0.031 = 3e-7.  A yaw demand
    given with the wrong sign or size to the yaw wheel moves the poles by far more."""
    control = Control(yaw_on_standby_wheel=switched)
    eig = _eigenvalues(_three(), control, orbit)
    neutral = np.abs(eig - 1) < 1e-10
    assert np.sum(neutral) == 2
    rest = eig[~neutral & (np.abs(eig) > 1e-8)]
    ref = _eigenvalues(goes_next(), Control(), orbit)
    ref = ref[(np.abs(ref - 1) >= 1e-10) & (np.abs(ref) > 1e-8)]
    assert len(rest) == len(ref)
    tol = 4 * GOES_NEXT_YAW_WHEEL_INERTIA_KGM2 / goes_next().J[2, 2] * np.max(np.angle(ref))
    np.testing.assert_allclose(np.sort(rest), np.sort(ref), rtol=0, atol=tol)
    tau = -DT / np.log(np.abs(rest))
    assert np.all(np.abs(rest) < 1) and np.max(tau) < 8 * 3600
    nutation = np.abs(np.angle(rest)) / DT > 0.02
    assert np.sum(nutation) == 2 and np.max(tau[nutation]) < 1800


def test_a_switch_needs_a_standby_wheel(orbit):
    """Without the backup wheel on board a switch is refused, not flown as nothing."""
    with pytest.raises(ValueError, match="standby"):
        simulate_truth(goes_next(), orbit, Environment.torque_free(), Control(), INIT,
                       EQUINOX, 10.0, DT, schedule=SWITCH)
    with pytest.raises(ValueError, match="yaw wheel"):
        dataclasses.replace(_three(), standby_wheel=0)
