"""The extended Kalman filter on the simulator's telemetry: its process model against
the truth's own rollout, the paper's filter near Earth pointing (to first order the
two are the same filter), and the 10° case where the paper's filter fails."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from estimator.ekf import model as m
from scenarios.bridge.coordinates import external_torque
from scenarios.config import build
from scenarios.config.loader import load_scenario
from scenarios.run.ekf import run_ekf
from scenarios.run.simulate import simulate
from scenarios.run.whole import run_scenario

DEG = np.pi / 180


def _offset(deg: float) -> list[str]:
    """The linearization report's attitude sweep: δ on roll, pitch and yaw, the
    filters' initial σ widened to cover it."""
    return [*(f"initial_state.{a}_deg={deg}" for a in ("roll", "pitch", "yaw")),
            f"estimator.initial_sigma.roll_deg={deg}", f"estimator.initial_sigma.yaw_deg={deg}"]


def test_the_process_model_propagates_the_truth():
    """Open loop from the truth's initial state, driven by the truth's own wheel
    momenta and external torques (the pitch torque, which the filter leaves to its
    noise, folded into Ḣ), the EKF's RK4 stays within 1e-2° of the truth over 8 h at
    10° of attitude: the same equations (eom.gyrostat), the inputs differenced from
    the samples (first order in Δt) being the only difference."""
    s = load_scenario("goes_next_equinox", ["duration_s=28800", "sensors.noise.enabled=false",
                                            *_offset(10.0)])
    tr = simulate(s).truth
    sc = build.build_spacecraft(s)
    H = tr.wheel_speeds_radps @ (sc.wheel_inertias * sc.wheel_axes[:, 1])
    dt = s.sample_interval_s
    Hdot, hdot = np.append(np.diff(H) / dt, 0.0), np.append(np.diff(tr.h_Nms) / dt, 0.0)
    ext = external_torque(tr)
    u = np.column_stack([H, Hdot - ext[:, 1], hdot, ext[:, 0], ext[:, 2]])
    params, _ = build.estimator_model(s)
    pm = m.pack_params(sc.J, params.omega0_radps, dt, dict.fromkeys(m.NOISE_NAMES, 0.0))
    X, U, P = ca.SX.sym("X", m.NX), ca.SX.sym("u", m.NU), ca.SX.sym("p", m.N_PARAMS)
    step = ca.Function("s", [X, U, P], [m.rk4(X, U, P), m.measure(X)])
    roll = step.mapaccum(len(u) - 1)
    _, z = roll(np.concatenate([tr.q_br[0], tr.w_br_radps[0], [tr.h_Nms[0]], np.zeros(4)]),
                u[:-1].T, pm)
    z = np.array(z).T
    err = np.column_stack([z[:, 0] - tr.roll_rad[:-1], z[:, 1] - tr.pitch_rad[:-1],
                           z[:, 2] - tr.yaw_rad[:-1]]) / DEG
    assert np.abs(err).max() < 1e-2
    assert np.abs(tr.roll_rad).max() > 9 * DEG   # it really was at 10°


def _both(overrides, duration_s=172800.0):
    s = load_scenario("goes_next_equinox", [f"duration_s={duration_s}", *overrides])
    two = run_scenario(s, smooth=False, twin=False)
    tel = two.sim.telemetry
    head = np.where(tel.yaw_head >= 0, tel.yaw_head, np.nan)
    ekf = run_ekf(s, tel.roll_rad, tel.pitch_rad, tel.yaw_rad, tel.wheel_speeds_radps,
                  tel.yaw_sigma_rad, head)
    yaw = np.isfinite(tel.yaw_rad)
    idx = np.flatnonzero(yaw)
    ends = idx[1:][np.diff(idx) > 4 * 3600 / s.sample_interval_s] - 1
    return two, ekf, ends


def test_near_earth_pointing_the_ekf_is_the_papers_filter_to_first_order():
    """Torque-free, noisy, no initial error: the EKF's estimates stay within 0.1σ of
    the paper filter's and its σ within 3%.  They differ only by what the paper's
    model approximates (I = √(I_x I_z), Eq. 6's dropped terms: ≤ 1.4% in the
    coefficients, errata 11), measured here at 0.022σ and 1%."""
    s = load_scenario("torque_free", ["duration_s=21600"])
    two = run_scenario(s, smooth=False, twin=False)
    tel = two.sim.telemetry
    head = np.where(tel.yaw_head >= 0, tel.yaw_head, np.nan)
    ekf = run_ekf(s, tel.roll_rad, tel.pitch_rad, tel.yaw_rad, tel.wheel_speeds_radps,
                  tel.yaw_sigma_rad, head)
    k = slice(2000, None)   # after the first minutes' convergence from the prior
    p = two.real
    assert np.max(np.abs(ekf.x[k] - p.x[k]) / p.sigma[k]) < 0.1
    np.testing.assert_allclose(ekf.sigma[k], p.sigma[k], rtol=0.03)


@pytest.mark.parametrize("deg", [0.0, 10.0])
def test_gap_end_yaw_within_3_sigma_where_the_paper_filter_fails_at_10_deg(deg):
    """Equinox, two days.  At 0°, the EKF's gap-end yaw σ is within 20% of the paper
    filter's (measured: 0.3%) and its errors within 3σ.  At 10° (the linearization
    report's large offset) the EKF's gap-end errors stay within 3σ while the paper
    filter's exceed it (measured −0.22°, −0.15° against σ 0.051°, 0.045°)."""
    two, ekf, ends = _both(_offset(deg) if deg else [])
    assert len(ends) == 2
    e_ekf = ekf.x[ends, 2] - two.truth_model[ends, 2]
    e_paper = two.real.x[ends, 2] - two.truth_model[ends, 2]
    assert np.all(np.abs(e_ekf) < 3 * ekf.sigma[ends, 2])
    np.testing.assert_allclose(ekf.sigma[ends, 2], two.real.sigma[ends, 2], rtol=0.2)
    if deg:
        assert np.any(np.abs(e_paper) > 3 * two.real.sigma[ends, 2])
