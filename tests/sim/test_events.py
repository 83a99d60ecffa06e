"""Scheduled events in the truth (``sim.events``, ``TruthStream``'s schedule) against
independent references: Euler's law for a thruster firing, the solar torque's
κ = untrimmed − effectiveness · tab for a trim-tab command, and the contract's
sample rule t0 ≤ t_k < t0 + duration written out by hand."""

from __future__ import annotations

import numpy as np
import pytest

from sim import ephemeris
from sim.control import Control
from sim.disturbance import Disturbance
from sim.environment import Environment, SolarTorque
from sim.events import Event, Schedule, repeated
from sim.frames import GeoOrbit, dcm_from_quat
from sim.spacecraft import goes_next
from sim.truth import InitialState, TruthStream, simulate_truth

from .conftest import EQUINOX

DT = 0.512


def _inside(t0: float, duration: float, n: int) -> np.ndarray:
    """Samples k with t0 ≤ k·Δt < t0 + duration, counted by hand (not via sim.events)."""
    first = int(np.ceil(t0 / DT))
    last = int(np.ceil((t0 + duration) / DT))      # first sample at or after the end
    k = np.zeros(n, dtype=bool)
    k[first:last] = True
    return k


# --------------------------------------------------------------------------- schedule


def test_schedule_queries_follow_the_sample_rule():
    """Inside is t0 ≤ t_k < t0 + duration (the start sample in, the end sample out);
    outages are per sensor; commands are those with t_from ≤ t < t_to, in time order."""
    t = np.arange(40) * 0.5
    s = Schedule((Event("trim_tab", 7.0, angle_deg=3.0),
                  Event("thruster", 2.0, 3.0, (1.0, 0.0, -2.0)),
                  Event("thruster", 4.0, 1.0, (0.5, 0.0, 0.0)),
                  Event("sensor_outage", 10.0, 2.0, sensor="sun"),
                  Event("array_offset", 2.0, angle_deg=1.0)))
    assert [e.t_s for e in s.events] == [2.0, 2.0, 4.0, 7.0, 10.0]   # sorted, stable
    torque = s.thruster_torque(t)
    expected = np.zeros((40, 3))
    expected[(t >= 2.0) & (t < 5.0)] += [1.0, 0.0, -2.0]
    expected[(t >= 4.0) & (t < 5.0)] += [0.5, 0.0, 0.0]
    assert np.array_equal(torque, expected)
    assert torque[4, 0] == 1.0 and torque[10, 0] == 0.0      # t = 2.0 in, t = 5.0 out
    assert np.array_equal(s.maneuver(t), (t >= 2.0) & (t < 5.0))
    assert np.array_equal(s.outage("sun", t), (t >= 10.0) & (t < 12.0))
    assert not s.outage("earth", t).any() and not s.outage("tachometer", t).any()
    assert [e.kind for e in s.commands(2.0, 7.0)] == ["array_offset"]
    assert [e.kind for e in s.commands(2.0, 7.5)] == ["array_offset", "trim_tab"]
    assert not Schedule() and s
    with pytest.raises(ValueError, match="sensor"):
        s.outage("gyro", t)


def test_every_days_repeats_to_the_runs_end():
    """Every N days from the start while the start is before the run's end."""
    day = 86400.0
    e = Event("thruster", 3600.0, 600.0, (0.0, 0.0, 1e-3))
    starts = [x.t_s for x in repeated(e, 14 * day, 30 * day)]
    assert starts == [3600.0, 3600.0 + 14 * day, 3600.0 + 28 * day]
    assert [x.t_s for x in repeated(e, 14 * day, 28 * day + 3600.0)] == starts[:2]
    assert repeated(e, None, 30 * day) == (e,)


# --------------------------------------------------------------------------- thruster


@pytest.fixture(scope="module")
def fired():
    """20 min of the closed loop with every environment torque and the torquers off,
    so that the thruster is the only external torque; and the same without it."""
    env = Environment.torque_free()
    ctl = Control(magnetic_unloading=False)
    n_torque = np.array([0.01, 0.002, -0.005])
    sched = Schedule((Event("thruster", 200.1, 300.0, tuple(n_torque)),))
    res = simulate_truth(goes_next(), GeoOrbit(), env, ctl, InitialState(), EQUINOX, 1200.0, DT,
                         schedule=sched)
    return res, n_torque


def test_thruster_changes_inertial_momentum_by_its_impulse(fired):
    """Euler's law in inertial axes: the total angular momentum H_N = C_NB (J ω_BN +
    Σ I_w Ω_i a_i) changes by ∫ C_NB N dt over the firing and by nothing else (every
    other external torque is off; the wheels' motor torques are internal).  The firing
    covers the samples t0 ≤ t_k < t0 + T, each step holding N in body axes; so the
    reference is Σ_k (∫ C_NR over step k) C_RB(t_k) N over those samples, counted
    here by hand, with the orbit frame's integral by Simpson ((ω0 Δt)⁴/2880 ≈ 0).

    Tolerance: holding C_RB at the step's start misses ≤ ½ Δt² |ω_BR| |N| a step,
    ½ Δt T max|ω_BR| |N| in all (as tests/sim/test_dynamics.py's law test); the
    torque-free drift is 3e-12 N m s a day.  |N| T = 3.4 N m s, one sample's impulse
    5.8e-3 N m s: a firing a sample early or late, a sign, a frame (body vs orbit
    axes) or a torque only recorded and not flown is far outside."""
    res, n = fired
    sc, orbit = goes_next(), GeoOrbit()
    h_b = res.w_bn_radps @ sc.J.T + sc.wheel_momentum(res.wheel_speeds_radps)
    gmst0 = ephemeris.gmst_rad(ephemeris.julian_date(EQUINOX))
    c_nr = np.swapaxes(orbit.orbit_frame(res.t_s, gmst0), -1, -2)
    c_rb = np.swapaxes(dcm_from_quat(res.q_br), -1, -2)
    h_n = np.einsum("nij,nj->ni", c_nr @ c_rb, h_b)
    inside = _inside(200.1, 300.0, len(res.t_s))
    assert inside.sum() == 586 and not inside[-1]
    k = np.flatnonzero(inside)
    mid = np.swapaxes(orbit.orbit_frame(res.t_s[k] + DT / 2, gmst0), -1, -2)
    end = np.swapaxes(orbit.orbit_frame(res.t_s[k] + DT, gmst0), -1, -2)
    step = DT / 6 * (c_nr[k] + 4 * mid + end)
    impulse = np.einsum("nij,njk,k->i", step, c_rb[k], n)
    err = np.linalg.norm(h_n[-1] - h_n[0] - impulse)
    w_br = np.max(np.linalg.norm(res.w_br_radps, axis=1))
    tol = 0.5 * DT * 300.0 * w_br * np.linalg.norm(n) + 1e-11
    assert np.linalg.norm(impulse) > 1e3 * tol         # the check is sharp
    assert err < tol, (err, tol)
    # In the large: the inertial change is N T to within the body's turn in T.
    assert np.linalg.norm(h_n[-1] - h_n[0]) == pytest.approx(np.linalg.norm(n) * k.size * DT,
                                                             rel=0.03)


def _held_impulse(res, torque_b: np.ndarray) -> np.ndarray:
    """Σ_k (∫ C_NR over step k) C_RB(t_k) N_k: a body torque held over each step, in
    inertial axes (the orbit frame's integral by Simpson)."""
    orbit = GeoOrbit()
    gmst0 = ephemeris.gmst_rad(ephemeris.julian_date(EQUINOX))
    t = res.t_s[:-1]
    c_rb = np.swapaxes(dcm_from_quat(res.q_br[:-1]), -1, -2)
    step = DT / 6 * sum(w * np.swapaxes(orbit.orbit_frame(t + dt, gmst0), -1, -2)
                        for w, dt in ((1, 0.0), (4, DT / 2), (1, DT)))
    return np.einsum("nij,njk,nk->i", step, c_rb, torque_b[:-1])


def test_thruster_disturbance_and_extra_torque_all_fly(fired):
    """With a disturbance and a caller's torque as well, the step flies the sum of the
    three (each recorded apart): the momentum changes by their held impulse.  The
    thruster's and the extra torque are this test's own; the disturbance's, a random
    draw, is read from its record.  Tolerance as above, with the largest total torque
    over the whole run."""
    _, n = fired
    sc = goes_next()
    m = int(1200.0 / DT) + 1
    extra = np.zeros((m, 3))
    extra[:, 1] = 3e-3
    res = simulate_truth(sc, GeoOrbit(), Environment.torque_free(),
                         Control(magnetic_unloading=False), InitialState(), EQUINOX, 1200.0,
                         DT, extra_torque=extra,
                         disturbance=Disturbance("gauss_markov", sigma_Nm=(2e-3, 1e-3, 2e-3),
                                                 correlation_time_s=60.0),
                         disturbance_rng=np.random.default_rng(9),
                         schedule=Schedule((Event("thruster", 200.1, 300.0, tuple(n)),)))
    assert np.array_equal(res.torques["external"], extra)
    assert np.abs(res.torques["disturbance"]).max() > 1e-3
    total = (extra + res.torques["disturbance"]
             + np.outer(_inside(200.1, 300.0, m), n))
    h_b = res.w_bn_radps @ sc.J.T + sc.wheel_momentum(res.wheel_speeds_radps)
    gmst0 = ephemeris.gmst_rad(ephemeris.julian_date(EQUINOX))
    c_nb = np.swapaxes(GeoOrbit().orbit_frame(res.t_s, gmst0), -1, -2) \
        @ np.swapaxes(dcm_from_quat(res.q_br), -1, -2)
    h_n = np.einsum("nij,nj->ni", c_nb, h_b)
    # The last sample's torque acts after the run: the momentum is taken at the last
    # sample, so the impulse runs over the steps before it.
    err = np.linalg.norm(h_n[-1] - h_n[0] - _held_impulse(res, total))
    w_br = np.max(np.linalg.norm(res.w_br_radps, axis=1))
    tol = 0.5 * DT * 1200.0 * w_br * np.max(np.linalg.norm(total, axis=1)) + 1e-11
    one_step = DT * np.linalg.norm(n)
    assert one_step > 5 * tol        # a firing a sample off is outside
    assert err < tol, (err, tol)


def test_thruster_torque_is_its_own_recorded_source(fired):
    """truth.csv's thruster_* columns: N on the firing's samples, 0 elsewhere; the
    caller's external torque stays apart (zero here)."""
    res, n = fired
    inside = _inside(200.1, 300.0, len(res.t_s))
    assert "thruster" in res.torques
    assert np.array_equal(res.torques["thruster"][inside], np.tile(n, (inside.sum(), 1)))
    assert not res.torques["thruster"][~inside].any()
    assert not res.torques["external"].any()


# --------------------------------------------------------------------------- commands


def _stream(schedule, duration=900.0, managed=False):
    return TruthStream(goes_next(), GeoOrbit(), Environment(), Control(),
                       InitialState(yaw_rad=1e-3), EQUINOX, duration, DT,
                       rng=np.random.default_rng(3), schedule=schedule, managed=managed)


@pytest.mark.parametrize("t_cmd", [400.3, 400.384])    # between samples; on sample 782
def test_trim_tab_command_changes_the_solar_torque_from_its_sample(t_cmd):
    """A command at t applies from the first sample with t_k ≥ t (sample 782, t = 400.384
    s, for a command between 399.872 s and that very time).  Until then the run is
    the run without it, bit for bit; at that sample the state is still the same (it
    depends only on the steps before), so the solar torque κ d̂ × ŝ scales exactly by
    the ratio of the two κ = untrimmed − effectiveness · tab (Section 2.2), here from
    the defaults 5e-5 − 2.5e-6 · 19.6 = 1e-6 N m to 5e-5 − 2.5e-6 · 10 = 2.5e-5 N m."""
    solar = SolarTorque()
    assert (solar.untrimmed_torque_Nm, solar.tab_effectiveness_Nm_per_deg,
            solar.trim_tab_deg) == (5e-5, 2.5e-6, 19.6)
    k = 782
    plain = _stream(None).window(0, 1758)
    cmd = _stream(Schedule((Event("trim_tab", t_cmd, angle_deg=10.0),))).window(0, 1758)
    assert np.array_equal(cmd.torques["solar"][:k], plain.torques["solar"][:k])
    assert np.array_equal(cmd.q_br[:k + 1], plain.q_br[:k + 1])
    ratio = (5e-5 - 2.5e-6 * 10.0) / (5e-5 - 2.5e-6 * 19.6)
    assert ratio == pytest.approx(25.0)
    np.testing.assert_allclose(cmd.torques["solar"][k], ratio * plain.torques["solar"][k],
                               rtol=1e-9)
    assert np.linalg.norm(cmd.torques["solar"][k]) > 1e-5
    # It stays commanded: at the run's end, its attitude a little apart, the same ratio.
    np.testing.assert_allclose(np.linalg.norm(cmd.torques["solar"][-1])
                               / np.linalg.norm(plain.torques["solar"][-1]), ratio, rtol=0.01)


def test_array_offset_command_adds_its_torque_from_its_sample():
    """An array offset δ adds κ_o ŝ⊥ (1 AU/r)² shadow with κ_o = untrimmed_offset −
    effectiveness · δ = 0 − 5e-7 · 4 = −2e-6 N m and ŝ⊥ = ŝ − (d̂·ŝ) d̂ the Sun direction
    normal to the lever d̂ = y (docs/conventions.md, "The array offset"), from the first
    sample at or after the command on.  The scale (1 AU/r)² shadow is read off the tab's
    torque κ d̂ × ŝ of the run without the command, at the same state (the managed step
    both, so their steps are the same code)."""
    solar = SolarTorque()
    assert (solar.offset_effectiveness_Nm_per_deg, solar.untrimmed_offset_torque_Nm,
            solar.array_offset_deg, solar.lever_axis) == (5e-7, 0.0, 0.0, (0.0, 1.0, 0.0))
    k = 782                                          # 400.384 s, the first at or after 400.3
    plain = _stream(None, managed=True).window(0, 1758)
    cmd = _stream(Schedule((Event("array_offset", 400.3, angle_deg=4.0),))).window(0, 1758)
    assert np.array_equal(cmd.torques["solar"][:k], plain.torques["solar"][:k])
    s_hat = plain.sun_body[k] / np.linalg.norm(plain.sun_body[k])
    d_hat = np.array([0.0, 1.0, 0.0])
    scale = np.linalg.norm(plain.torques["solar"][k]) / (1e-6 * np.linalg.norm(
        np.cross(d_hat, s_hat)))
    s_perp = s_hat - (d_hat @ s_hat) * d_hat
    expected = plain.torques["solar"][k] + (0.0 - 5e-7 * 4.0) * s_perp * scale
    np.testing.assert_allclose(cmd.torques["solar"][k], expected, rtol=1e-9, atol=1e-18)
    assert np.linalg.norm(expected - plain.torques["solar"][k]) > 1e-6


def test_windows_and_pieces_with_events_concatenate_to_the_whole_run():
    """The rollout split at a command, inside a window or at its edge, and sensed a
    piece at a time (``window(sense=...)``), gives the one-window run's arrays bit for
    bit."""
    sched = Schedule((Event("trim_tab", 200.0, angle_deg=12.0),
                      Event("trim_tab", 600.0, angle_deg=20.0),
                      Event("thruster", 300.0, 100.0, (1e-3, 0.0, 2e-3))))
    whole = _stream(sched).window(0, 1758)
    stream = _stream(sched)
    k600 = int(np.ceil(600.0 / DT))
    parts = [stream.window(a, b) for a, b in ((0, 500), (500, k600), (k600, 1758))]
    sensed, _ = _stream(sched).window(0, 1758, sense=lambda rows, lo, hi: None, piece=333)
    for name in whole.torques:
        joined = np.concatenate([p.torques[name] for p in parts])
        assert np.array_equal(joined, whole.torques[name]), name
        assert np.array_equal(sensed.torques[name], whole.torques[name]), name
    assert np.array_equal(np.concatenate([p.q_br for p in parts]), whole.q_br)
    assert np.array_equal(sensed.q_br, whole.q_br)
    assert np.array_equal(stream.x, whole.final_state)
