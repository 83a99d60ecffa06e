"""Sensors and synthetic telemetry (sim.sensors, sim.telemetry) against independent references.

References used here, none of them the code's own output:

* Sun geometry: the Sun's hour angle θ from local noon is computed from the *ephemeris*
  (``sim.ephemeris``): θ = (GMST(t) + λ) − RA_sun(t), the satellite's right ascension minus
  the Sun's, with λ = −75° the slot.  It is geocentric, so it differs from the
  satellite-to-Sun direction by the parallax R/AU ≤ 0.016°.  A secondary check uses the
  clock alone: local mean time = UTC + λ/15 h, corrected by Spencer's (1971) Fourier series
  for the equation of time (good to about a minute).
* Fields of view, by hand: with the body on the orbit frame, ŝ = (−sin θ cos δ, −sin δ,
  −cos θ cos δ), so a head with boresight hour angle θ_b sees the Sun at the in-plane angle
  α = θ − θ_b (exactly, whatever δ) and out of plane at tan β = −tan δ / cos α.
* Noise: paper Section 2.1 and 2.3, and Eqs. 46–47 (noise variance plus q²/12), with
  normal-approximation 99.9 % intervals on sample means and variances.
* Ground yaw: the quantisation error of the angles, propagated by hand (see test 7).
"""

from __future__ import annotations

from dataclasses import replace
from datetime import datetime

import numpy as np
import pytest

from scenarios.config.build import build_sensors, streams
from scenarios.config.schema import Scenario
from scenarios.run.simulate import simulate
from sim import ephemeris
from sim.sensors import EarthSensor, SensorSuite, Tachometer
from sim.telemetry import make_telemetry
from sim.truth import InitialState, simulate_truth

DEG = np.pi / 180.0
RPM = 2.0 * np.pi / 60.0
DAY_S = 86400.0
DT_S = 0.512
LON_DEG = -75.0
Z999 = 3.2905  # two-sided 99.9 % point of the standard normal

EQUINOX_UTC = "2026-03-20T12:00:00Z"
SOLSTICE_UTC = "2026-06-21T12:00:00Z"

# Default heads (Section 2.1 and sim.sensors docstring), written out by hand:
# name -> (boresight hour angle, in-plane half FOV, out-of-plane half FOV, quantum, noise), deg.
HEADS = {
    "dss": (90.0, 32.0, 32.0, 0.125, 0.0042),
    "cass1": (-75.0, 45.0, 35.0, 0.039, 1.0),
    "cass2": (15.0, 45.0, 35.0, 0.039, 1.0),
}
HEAD_ORDER = ("dss", "cass1", "cass2")

# Hand union of the in-plane intervals θ_b ± FOV_in:
#   cass1 [−120, −30], cass2 [−30, 60], dss [58, 122]  ->  one interval [−120, 122].
COVER_LO_DEG, COVER_HI_DEG = -120.0, 122.0
COVER_DEG = COVER_HI_DEG - COVER_LO_DEG                       # 242°
GAP_DEG = 360.0 - COVER_DEG                                   # 118°, from 122° to 240°
MIN_SEP_DEG = 10.0                                            # ground yaw withheld band

# The body is on the orbit frame only to within the attitude error (checked < 0.1°), the
# geocentric hour angle differs from the satellite's by ≤ 0.016° of parallax, and a sample
# is 0.512 s = 0.002° of hour angle: any FOV edge crossing lies within this of the hand value.
ATT_MAX_DEG = 0.1
EDGE_TOL_DEG = ATT_MAX_DEG + 0.016 + 0.004


# ------------------------------------------------------------------------- helpers


def _wrap_deg(x):
    return (np.asarray(x) + 180.0) % 360.0 - 180.0


def sun_hour_angle_deg(epoch: datetime, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Geocentric Sun hour angle from local noon, and the declination (deg), from the
    ephemeris only: RA of the slot (GMST + longitude) minus the Sun's RA."""
    jd = ephemeris.julian_date(epoch) + t_s / DAY_S
    unit, _ = ephemeris.sun_position_eci(jd)
    ra_sun = np.arctan2(unit[:, 1], unit[:, 0])
    ra_sat = ephemeris.gmst_rad(jd) + LON_DEG * DEG
    return _wrap_deg((ra_sat - ra_sun) / DEG), np.arcsin(unit[:, 2]) / DEG


def spencer_eot_min(epoch: datetime, t_s: np.ndarray) -> np.ndarray:
    """Equation of time (apparent − mean solar time, minutes), Spencer (1971)."""
    day0 = epoch.timetuple().tm_yday - 1 + (epoch.hour + epoch.minute / 60 - 12) / 24
    g = 2 * np.pi / 365 * (day0 + t_s / DAY_S)
    return 229.18 * (0.000075 + 0.001868 * np.cos(g) - 0.032077 * np.sin(g)
                     - 0.014615 * np.cos(2 * g) - 0.040849 * np.sin(2 * g))


def true_head_angles_deg(sun_body: np.ndarray, boresight_deg: float):
    """In-plane and out-of-plane Sun angles of a head from the Sun in body axes, written
    from the geometry rather than the head's axes: α is the Sun's hour angle in the body
    x–z plane minus the boresight's; β its elevation out of that plane seen from the head."""
    sx, sy, sz = sun_body.T
    alpha = _wrap_deg(np.arctan2(-sx, -sz) / DEG - boresight_deg)
    beta = np.arctan2(sy, np.hypot(sx, sz) * np.cos(alpha * DEG)) / DEG
    return alpha, beta


def transitions(flag: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Indices i of the last sample before a loss (True→False) and a regain (False→True)."""
    d = np.diff(flag.astype(np.int8))
    return np.flatnonzero(d == -1), np.flatnonzero(d == 1)


def frac_off_quantum(x: np.ndarray, q: float) -> float:
    r = np.asarray(x) / q
    return float(np.max(np.abs(r - np.round(r)))) if r.size else 0.0


def telemetry_arrays(tel) -> dict[str, np.ndarray]:
    return {"roll": tel.roll_rad, "pitch": tel.pitch_rad, "yaw": tel.yaw_rad,
            "yaw_sigma": tel.yaw_sigma_rad, "yaw_head": tel.yaw_head,
            "tach": tel.wheel_speeds_radps, "visible": tel.sun.visible,
            "alpha": tel.sun.alpha_rad, "beta": tel.sun.beta_rad}


def bit_identical(a: np.ndarray, b: np.ndarray) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    return a.shape == b.shape and a.dtype == b.dtype and a.tobytes() == b.tobytes()


def variance_bound(n: int, var: float, mu4: float) -> float:
    """Half-width of the 99.9 % normal-approximation interval of a sample variance:
    Var(s²) ≈ (μ4 − σ⁴)/n."""
    return Z999 * np.sqrt((mu4 - var**2) / n)


def _day(epoch_utc: str, **overrides):
    return simulate(Scenario(name="sensors-test", epoch_utc=epoch_utc, duration_s=DAY_S,
                             **overrides))


# ------------------------------------------------------------------------- fixtures


@pytest.fixture(scope="module")
def equinox_day():
    """One day from the default epoch, control on, every torque and noise on."""
    return _day(EQUINOX_UTC)


@pytest.fixture(scope="module")
def solstice_day():
    return _day(SOLSTICE_UTC)


@pytest.fixture(scope="module", params=[EQUINOX_UTC, SOLSTICE_UTC], ids=["equinox", "solstice"])
def day(request, equinox_day, solstice_day):
    sim = equinox_day if request.param == EQUINOX_UTC else solstice_day
    epoch = ephemeris.parse_epoch(request.param)
    theta, dec = sun_hour_angle_deg(epoch, sim.truth.t_s)
    return request.param, epoch, sim, theta, dec


# ------------------------------------------------- 1. field-of-view coverage over one day


def test_heads_are_the_documented_defaults(equinox_day):
    """The scenario defaults and SensorSuite's defaults are the hand table HEADS."""
    for suite in (build_sensors(equinox_day.scenario), SensorSuite()):
        assert tuple(h.name for h in suite.sun_heads) == HEAD_ORDER
        for h in suite.sun_heads:
            assert (h.boresight_hour_angle_deg, h.fov_in_plane_deg, h.fov_out_of_plane_deg,
                    h.quantum_deg, h.noise_deg) == HEADS[h.name]
    # The hand union: consecutive intervals touch or overlap, and span −120°…+122°.
    iv = sorted((b - f, b + f) for b, f, *_ in HEADS.values())
    assert all(iv[k + 1][0] <= iv[k][1] for k in range(len(iv) - 1))
    assert (iv[0][0], max(hi for _, hi in iv)) == (COVER_LO_DEG, COVER_HI_DEG)


def test_attitude_error_is_small(day):
    """Precondition of every edge tolerance below: control holds the body on the orbit frame
    to better than 0.1° on all three axes."""
    _, _, sim, _, _ = day
    assert np.max(np.abs(sim.truth.euler_rad)) / DEG < ATT_MAX_DEG


def test_hour_angle_reference_matches_truth_sun(day):
    """The ephemeris hour angle and the truth's satellite-to-Sun direction agree to the
    parallax R/AU = 0.016° (a check of the reference, not of the sensors)."""
    _, _, sim, theta, _ = day
    s = sim.truth.sun_orbit_frame
    theta_truth = np.arctan2(-s[:, 0], -s[:, 2]) / DEG
    assert np.max(np.abs(_wrap_deg(theta_truth - theta))) < 0.02


def test_each_head_sees_the_sun_where_the_hand_geometry_says(day):
    """Per sample and per head: visible iff |θ − θ_b| ≤ FOV_in (and the out-of-plane angle
    tan β = tan δ / cos α is inside FOV_out), except within EDGE_TOL of an edge.  At the
    solstice δ = 23.4° gives β ≤ 27.1° (DSS) and ≤ 31.5° (CASS) at the in-plane edges,
    inside 32° and 35°, so coverage in hour angle is the same as at equinox."""
    _, _, sim, theta, dec = day
    lit = sim.truth.shadow >= 0.5
    for k, name in enumerate(HEAD_ORDER):
        bore, fov_in, fov_out, _, _ = HEADS[name]
        beta_edge = np.arctan(np.tan(np.abs(dec) * DEG) / np.cos(fov_in * DEG)) / DEG
        assert np.all(beta_edge < fov_out), name
        off = np.abs(_wrap_deg(theta - bore))
        expected = (off <= fov_in) & lit
        ambiguous = np.abs(off - fov_in) < EDGE_TOL_DEG
        got = sim.telemetry.sun.visible[:, k]
        assert np.all(got[~ambiguous] == expected[~ambiguous]), name


def test_eclipse_at_equinox_falls_inside_the_gap(equinox_day):
    """Hand calculation: the satellite is in (pen)umbra while the Sun is within a + b of the
    Earth's centre, a = asin(R_sun/AU) = 0.27°, b = asin(R_E/r) = 8.70°, i.e. 2(a+b) = 17.9°
    of hour angle = 71.7 min centred on midnight (θ = 180°), well inside the 122°…240° gap."""
    sim = equinox_day
    epoch = ephemeris.parse_epoch(EQUINOX_UTC)
    theta, _ = sun_hour_angle_deg(epoch, sim.truth.t_s)
    a = np.arcsin(695_700.0 / 149_597_870.7) / DEG
    b = np.arcsin(6_378.137 / 42_164.17) / DEG
    half_width = a + b
    shadow = sim.truth.shadow < 1.0
    assert shadow.any()
    theta360 = theta[shadow] % 360.0
    assert np.all(np.abs(theta360 - 180.0) <= half_width + 0.05)
    assert np.all((theta360 > COVER_HI_DEG) & (theta360 < COVER_LO_DEG + 360.0))
    minutes = shadow.sum() * DT_S / 60.0
    assert minutes == pytest.approx(2 * half_width / 360.0 * DAY_S / 60.0, abs=1.0)
    assert not np.any(sim.telemetry.sun_visible & shadow)


def test_no_eclipse_at_solstice(solstice_day):
    """|δ| = 23.4° > a + b = 8.97°: the Earth's shadow misses the orbit entirely."""
    assert np.all(solstice_day.truth.shadow == 1.0)


def test_coverage_fraction(day):
    """(a) Fraction of samples with any head seeing the Sun = 242/360 = 0.6722 at both
    seasons (eclipse is inside the gap, test above).  Tolerance: two edges of EDGE_TOL each
    (0.00067) plus the solar day differing from 86400 s by < 30 s (0.00035)."""
    _, _, sim, _, _ = day
    frac = sim.telemetry.sun_visible.mean()
    assert frac == pytest.approx(COVER_DEG / 360.0, abs=0.001)


def test_ground_yaw_fraction(day):
    """(b) Fraction with a ground yaw.  Equinox (|δ| < 0.4°): the Sun is within 10° of the
    yaw axis for |θ| < 10° (noon, inside the coverage) and |θ − 180°| < 10° (midnight,
    inside the gap), so (242 − 20)/360 = 0.6167.  Solstice: sin δ = 0.40 > sin 10°, the Sun
    is never that close, so the fraction equals the coverage, 242/360."""
    name, _, sim, theta, dec = day
    yaw_ok = np.isfinite(sim.telemetry.yaw_rad)
    if name == EQUINOX_UTC:
        assert np.max(np.abs(dec)) < 0.4
        assert COVER_LO_DEG < -MIN_SEP_DEG and MIN_SEP_DEG < COVER_HI_DEG       # noon band
        assert COVER_HI_DEG < 180 - MIN_SEP_DEG and 180 + MIN_SEP_DEG < 360 + COVER_LO_DEG
        expected = (COVER_DEG - 2 * MIN_SEP_DEG) / 360.0
        # The noon band's edges do not depend on the attitude: they sit at ±10° of the
        # geocentric hour angle to within the parallax and the δ < 0.4° shift (< 0.01°).
        lost, regained = transitions(yaw_ok)
        noon = [i for i in np.concatenate([lost, regained]) if abs(theta[i]) < 45]
        assert len(noon) == 2
        for i in noon:
            assert abs(theta[i]) == pytest.approx(MIN_SEP_DEG, abs=0.03)
    else:
        assert np.min(np.abs(dec)) > MIN_SEP_DEG
        expected = COVER_DEG / 360.0
    assert yaw_ok.mean() == pytest.approx(expected, abs=0.0015)
    # Yaw is never produced where no head sees the Sun.
    assert not np.any(yaw_ok & ~sim.telemetry.sun_visible)


def test_gap_position_in_hour_angle_and_local_time(day):
    """(c) Coverage is lost at θ = +122° (the DSS's far edge, 20:08 local apparent solar
    time) and regained at θ = −120° = 240° (cass1's near edge, 04:00), each to EDGE_TOL.
    Clock check: local mean time UTC − 5 h plus Spencer's equation of time, to 1.5 min
    (Spencer's ~1 min error plus EDGE_TOL = 0.5 min)."""
    _, epoch, sim, theta, _ = day
    t = sim.truth.t_s
    lost, regained = transitions(sim.telemetry.sun_visible)
    assert len(lost) == 1 and len(regained) == 1     # one gap in the day (start at θ ≈ −77°)
    th_lost = 0.5 * (theta[lost[0]] + theta[lost[0] + 1])
    th_regained = 0.5 * (theta[regained[0]] + theta[regained[0] + 1])
    assert th_lost == pytest.approx(COVER_HI_DEG, abs=EDGE_TOL_DEG)
    assert th_regained == pytest.approx(COVER_LO_DEG, abs=EDGE_TOL_DEG)
    assert (th_regained - th_lost) % 360.0 == pytest.approx(GAP_DEG, abs=2 * EDGE_TOL_DEG)

    utc_h = epoch.hour + epoch.minute / 60 + t / 3600.0
    apparent_h = (utc_h + LON_DEG / 15.0 + spencer_eot_min(epoch, t) / 60.0) % 24.0
    for i, hand_h in ((lost[0], 12 + COVER_HI_DEG / 15), (regained[0], 12 + COVER_LO_DEG / 15)):
        diff_min = ((apparent_h[i] - hand_h + 12) % 24 - 12) * 60
        assert abs(diff_min) < 1.5


# ------------------------------------------------------------ 2. DSS sees the Sun last


def test_dss_sees_the_sun_last_before_the_gap(day):
    """Paper Section 2.1: 'It is the more accurate DSS that sees the Sun just before the
    loss of coverage.'  At the last covered sample before each gap the DSS is the only head
    seeing the Sun and the one used for yaw; and no other head sees it in the last 60° (4 h)
    before the gap (cass2 ends at θ = 60°, the DSS covers 58°…122°)."""
    _, _, sim, theta, _ = day
    vis = sim.telemetry.sun.visible
    lost, _ = transitions(sim.telemetry.sun_visible)
    assert len(lost) >= 1
    dss = HEAD_ORDER.index("dss")
    for i in lost:
        assert vis[i, dss] and vis[i].sum() == 1
        assert sim.telemetry.yaw_head[i] == dss
        window = (theta > 60 + EDGE_TOL_DEG) & (theta <= theta[i])
        window[i + 1:] = False
        assert np.all(vis[window, dss]) and not np.any(np.delete(vis[window], dss, axis=1))


# ------------------------------------------------------------ 3. quantised outputs


def test_outputs_are_exact_multiples_of_their_quanta(equinox_day):
    tel = equinox_day.telemetry
    assert frac_off_quantum(tel.roll_rad / DEG, 0.01) < 1e-9
    assert frac_off_quantum(tel.pitch_rad / DEG, 0.01) < 1e-9
    assert frac_off_quantum(tel.wheel_speeds_radps / RPM, 0.0163) < 1e-9
    for k, name in enumerate(HEAD_ORDER):
        vis = tel.sun.visible[:, k]
        assert vis.sum() > 10_000, name
        q = HEADS[name][3]
        assert frac_off_quantum(tel.sun.alpha_rad[vis, k] / DEG, q) < 1e-9, name
        assert frac_off_quantum(tel.sun.beta_rad[vis, k] / DEG, q) < 1e-9, name
        assert np.all(np.isnan(tel.sun.alpha_rad[~vis, k]))
        assert np.all(np.isnan(tel.sun.beta_rad[~vis, k]))


# ------------------------------------------------------------ 4. noise statistics


def _check_noise_plus_quantisation(err: np.ndarray, sigma: float, q: float) -> None:
    """err = Q(x + n) − x with n ~ N(0, σ²), σ ≥ q: the quantisation error is then uniform
    and independent (Sheppard; the Gaussian's characteristic function at 2π/q is
    exp(−2π²σ²/q²) ≤ 3e-9), so Var = σ² + q²/12 and μ4 = 3σ⁴ + σ²q²/2 + q⁴/80."""
    n = err.size
    var = sigma**2 + q**2 / 12.0
    mu4 = 3 * sigma**4 + sigma**2 * q**2 / 2 + q**4 / 80
    assert abs(err.mean()) < Z999 * np.sqrt(var / n)
    assert abs(err.var() - var) < variance_bound(n, var, mu4), (err.var(), var)
    # White: lag-1 autocorrelation within its 99.9 % interval.
    r1 = np.corrcoef(err[:-1], err[1:])[0, 1]
    assert abs(r1) < Z999 / np.sqrt(n)


def test_earth_sensor_noise_matches_eq47(equinox_day):
    """Roll and pitch error against the truth: variance (0.01²/12 + 0.01²) deg², which is
    the paper's Eq. 47 R_roll = 3.3e-8 rad²."""
    sim = equinox_day
    assert (0.01**2 / 12 + 0.01**2) * DEG**2 == pytest.approx(3.3e-8, rel=0.02)
    for meas, true in ((sim.telemetry.roll_rad, sim.truth.roll_rad),
                       (sim.telemetry.pitch_rad, sim.truth.pitch_rad)):
        _check_noise_plus_quantisation((meas - true) / DEG, 0.01, 0.01)


def test_tachometer_noise_matches_eq46(equinox_day):
    """Wheel-speed error: variance 0.0163²/12 + (0.0978/3)² rpm² per wheel, the paper's
    Eq. 46 R_tach = 1.2e-5 (rad/s)²."""
    sim = equinox_day
    assert (0.0163**2 / 12 + (0.0978 / 3) ** 2) * RPM**2 == pytest.approx(1.2e-5, rel=0.02)
    err = (sim.telemetry.wheel_speeds_radps - sim.truth.wheel_speeds_radps) / RPM
    assert err.shape[1] == 2
    for w in range(err.shape[1]):
        _check_noise_plus_quantisation(err[:, w], 0.0978 / 3, 0.0163)


def test_dss_error_is_bounded_by_half_quantum_plus_noise(equinox_day):
    """DSS noise (0.0042°) is far below its quantum (0.125°), so the error is not dithered
    and a variance test does not apply: every angle error is within q/2 + 5σ = 0.0835°."""
    sim = equinox_day
    k = HEAD_ORDER.index("dss")
    bore, _, _, q, sigma = HEADS["dss"]
    vis = sim.telemetry.sun.visible[:, k]
    alpha, beta = true_head_angles_deg(sim.truth.sun_body[vis], bore)
    bound = q / 2 + 5 * sigma
    assert np.max(np.abs(sim.telemetry.sun.alpha_rad[vis, k] / DEG - alpha)) < bound
    assert np.max(np.abs(sim.telemetry.sun.beta_rad[vis, k] / DEG - beta)) < bound


@pytest.mark.parametrize("name", ["cass1", "cass2"])
def test_cass_noise_grows_as_one_over_cos_off_boresight(equinox_day, name):
    """CASS error normalised by σ(γ) = 1°/cos γ (γ the angle off the boresight) has unit
    variance, plus the tiny q²cos²γ/(12·1°²); 99.9 % normal interval sqrt(2/n)·3.29.
    (A constant 1° would give ≈ E[cos²γ] ≈ 0.8, far outside.)"""
    sim = equinox_day
    k = HEAD_ORDER.index(name)
    bore, _, _, q, sigma0 = HEADS[name]
    vis = sim.telemetry.sun.visible[:, k]
    s = sim.truth.sun_body[vis]
    alpha, beta = true_head_angles_deg(s, bore)
    cos_gamma = s @ np.array([-np.sin(bore * DEG), 0.0, -np.cos(bore * DEG)])
    sigma = sigma0 / cos_gamma
    n = vis.sum()
    expected = 1.0 + np.mean(q**2 / 12 / sigma**2)
    for meas, true in ((sim.telemetry.sun.alpha_rad[vis, k], alpha),
                       (sim.telemetry.sun.beta_rad[vis, k], beta)):
        z = (meas / DEG - true) / sigma
        assert abs(z.mean()) < Z999 / np.sqrt(n)
        assert abs(z.var() - expected) < Z999 * np.sqrt(2.0 / n) * expected, z.var()


# ------------------------------------------------------------ 5. the noise switch


def test_noise_switch_gives_quantised_truth_and_draws_nothing(equinox_day):
    """Noise off: no generator is touched, and the outputs are the quantised truth.
    Identity is the requirement for two noise-free runs with different streams: nothing
    random may enter, so every byte must agree."""
    truth = equinox_day.truth
    suite = SensorSuite(noise_enabled=False)
    rngs_a, rngs_b = streams(1), streams(2)
    before = {k: g.bit_generator.state for k, g in rngs_a.items()}
    a = make_telemetry(truth, suite, rngs_a)
    b = make_telemetry(truth, suite, rngs_b)
    assert {k: g.bit_generator.state for k, g in rngs_a.items()} == before
    for key, arr in telemetry_arrays(a).items():
        assert bit_identical(arr, telemetry_arrays(b)[key]), key

    def q(x, quantum):
        return np.round(x / quantum) * quantum

    # Angles ≤ 0.1° through deg ↔ rad conversions: ulps of 1e-17; 1e-12° is 1e-10 of a
    # quantum, and a quantum off is 0.01° (measured ≤ 3.5e-18°).
    np.testing.assert_allclose(a.roll_rad / DEG, q(truth.roll_rad / DEG, 0.01), rtol=0,
                               atol=1e-12)
    np.testing.assert_allclose(a.pitch_rad / DEG, q(truth.pitch_rad / DEG, 0.01), rtol=0,
                               atol=1e-12)
    np.testing.assert_allclose(a.wheel_speeds_radps / RPM,
                               q(truth.wheel_speeds_radps / RPM, 0.0163), rtol=0, atol=1e-9)
    for k, name in enumerate(HEAD_ORDER):
        bore, _, _, quantum, _ = HEADS[name]
        vis = a.sun.visible[:, k]
        alpha, beta = true_head_angles_deg(truth.sun_body[vis], bore)
        np.testing.assert_allclose(a.sun.alpha_rad[vis, k] / DEG, q(alpha, quantum), rtol=0,
                                   atol=1e-9, err_msg=name)
        np.testing.assert_allclose(a.sun.beta_rad[vis, k] / DEG, q(beta, quantum), rtol=0,
                                   atol=1e-9, err_msg=name)
    # Visibility is geometric: the same with noise on.
    assert np.array_equal(a.sun.visible, equinox_day.telemetry.sun.visible)


# ------------------------------------------------------------ 6. stream independence


def test_same_seed_is_bit_identical(equinox_day):
    """Identity is the requirement here: a rerun with the same seed on the same machine
    reproduces the telemetry byte for byte."""
    again = _day(EQUINOX_UTC)
    for key, arr in telemetry_arrays(equinox_day.telemetry).items():
        assert bit_identical(arr, telemetry_arrays(again.telemetry)[key]), key


def _sensor_outputs(tel) -> dict[str, np.ndarray]:
    out = {"earth": np.stack([tel.roll_rad, tel.pitch_rad]), "tachometer": tel.wheel_speeds_radps}
    for k, name in enumerate(HEAD_ORDER):
        out[name] = np.stack([tel.sun.alpha_rad[:, k], tel.sun.beta_rad[:, k]])
    return out


@pytest.mark.parametrize("changed, sensors", [
    ("earth", {"earth": {"noise_deg": 0.02}}),
    ("tachometer", {"tachometer": {"noise_3sigma_rpm": 0.2}}),
    ("cass1", {"sun": {"cass1": {"kind": "cass", "boresight_hour_angle_deg": -75.0,
                                 "fov_in_plane_deg": 45.0, "fov_out_of_plane_deg": 35.0,
                                 "quantum_deg": 0.039, "noise_deg": 2.0}}}),
])
def test_changing_one_sensor_leaves_the_others_bit_identical(equinox_day, changed, sensors):
    """Identity is the requirement here: a sensor's parameters must not reach any other
    sensor's stream, nor the truth, so everything else is byte-identical on one machine."""
    base = equinox_day
    other = _day(EQUINOX_UTC, sensors=sensors)
    assert bit_identical(base.truth.q_br, other.truth.q_br)   # same ripple stream
    a, b = _sensor_outputs(base.telemetry), _sensor_outputs(other.telemetry)
    for name in a:
        if name == changed:
            assert not bit_identical(a[name], b[name]), name
        else:
            assert bit_identical(a[name], b[name]), name
    assert bit_identical(base.telemetry.sun.visible, other.telemetry.sun.visible)


def test_a_different_seed_changes_every_sensors_noise(equinox_day):
    """Same truth, sensed with streams(seed) and streams(seed + 1): every sensor's output
    differs (the DSS only where its small noise crosses a quantisation step).  Identity is
    the requirement for the same seed: reruns reproduce every byte."""
    truth, seed = equinox_day.truth, equinox_day.scenario.seed
    suite = SensorSuite()
    a = _sensor_outputs(make_telemetry(truth, suite, streams(seed)))
    b = _sensor_outputs(make_telemetry(truth, suite, streams(seed + 1)))
    c = _sensor_outputs(make_telemetry(truth, suite, streams(seed)))
    for name in a:
        assert bit_identical(a[name], c[name]), name
        assert not np.array_equal(a[name], b[name], equal_nan=True), name
    # And through the runner, the same seed reproduces the telemetry of the fixture.
    for name, arr in _sensor_outputs(equinox_day.telemetry).items():
        assert bit_identical(arr, a[name]), name


@pytest.mark.parametrize("stream", ["earth", "tachometer", *HEAD_ORDER])
def test_each_sensor_draws_only_from_its_own_stream(equinox_day, stream):
    """Replacing one stream's generator changes that sensor alone.  (A parameter change
    cannot reveal two sensors sharing a generator when the number of draws stays the same;
    this can.)  Identity is the requirement for the untouched sensors."""
    truth, seed = equinox_day.truth, equinox_day.scenario.seed
    suite = SensorSuite()
    assert set(suite.stream_names()) == {"earth", "tachometer", *HEAD_ORDER}
    rngs = streams(seed)
    rngs[stream] = np.random.default_rng([seed, 99])
    a = _sensor_outputs(equinox_day.telemetry)
    b = _sensor_outputs(make_telemetry(truth, suite, rngs))
    for name in a:
        assert bit_identical(a[name], b[name]) == (name != stream), name


# ------------------------------------------------------------ 7. ground-yaw geometry


def _direction_error_yaw_bound_deg(eps_deg: float, sep_sin: np.ndarray) -> np.ndarray:
    """Largest azimuth change of a unit vector at angle p from z (sin p = sep_sin) when the
    vector moves by eps: asin(sin eps / sin p)."""
    return np.arcsin(np.minimum(1.0, np.sin(eps_deg * DEG) / sep_sin)) / DEG


@pytest.mark.parametrize("epoch_utc", [EQUINOX_UTC, SOLSTICE_UTC], ids=["equinox", "solstice"])
def test_ground_yaw_with_zero_attitude_is_within_quantisation(spacecraft, orbit, quiet,
                                                             epoch_utc):
    """Torque-free, control off, body on the orbit frame: the truth attitude is 0.  With
    noise off, Earth roll/pitch quantise to exactly 0, and the ground yaw error comes only
    from the Sun angles' quantisation (|δα|, |δβ| ≤ q/2).

    By hand: for |α|, |β| ≤ 45° the direction b + tan α u + tan β y moves by at most 1 rad
    per rad of α or β, so by ≤ q in all; that moves the azimuth by ≤ asin(sin q / sin p),
    p the Sun's angle from the yaw axis.  For the DSS (boresight −x, u = +z) the measured
    direction is ∝ (−1, tan β, ·), whose azimuth is exactly π − β: its yaw error is |δβ| ≤
    q/2 = 0.0625° at any separation (within the brief's 0.0625°/sin p)."""
    env, ctrl = quiet
    epoch = ephemeris.parse_epoch(epoch_utc)
    truth = simulate_truth(spacecraft, orbit, env, ctrl, InitialState(), epoch, DAY_S)
    # Exactly 0 here; 1.3e-19 rad with an FMA build (whose h_z is 2e-17 N m s, not 0).
    assert np.max(np.abs(truth.euler_rad)) < 1e-12
    tel, sep_sin, err, uses = _noise_free_yaw_errors(truth)
    assert np.all(tel.roll_rad == 0.0) and np.all(tel.pitch_rad == 0.0)
    for name, use in uses:
        q = HEADS[name][3]
        assert np.all(err[use] <= _direction_error_yaw_bound_deg(q, sep_sin[use]) + 1e-9), name
        if name == "dss":
            assert np.max(err[use]) <= q / 2 + 1e-9
            assert np.all(err[use] * sep_sin[use] <= q / 2 + 1e-9)


def _noise_free_yaw_errors(truth):
    """Noise-free telemetry of ``truth``, the sine of the Sun's angle from the yaw
    axis, |ground − true yaw| (deg), and each head's samples (each used ≥ 10 000 times)."""
    tel = make_telemetry(truth, SensorSuite(noise_enabled=False), streams(0))
    s = truth.sun_orbit_frame
    sep_sin = np.hypot(s[:, 0], s[:, 1])
    err = np.abs(_wrap_deg((tel.yaw_rad - truth.yaw_rad) / DEG))
    uses = [(name, tel.yaw_head == k) for k, name in enumerate(HEAD_ORDER)]
    for name, use in uses:
        assert use.sum() > 10_000, name
    return tel, sep_sin, err, uses


@pytest.fixture(scope="module")
def yaw_offset_truth(spacecraft, orbit, quiet):
    """A deliberate 2° initial yaw, control and torques off: the wheel momentum stays
    inertially fixed, so yaw and roll trade places each quarter day (both within ±2°)."""
    env, ctrl = quiet
    truth = simulate_truth(spacecraft, orbit, env, ctrl, InitialState(yaw_rad=2.0 * DEG),
                           ephemeris.parse_epoch(EQUINOX_UTC), DAY_S)
    assert truth.yaw_rad[0] == pytest.approx(2.0 * DEG, abs=1e-12)
    assert np.max(np.abs(truth.roll_rad)) > 1.5 * DEG     # the offset does move around
    return truth


def test_ground_yaw_recovers_a_two_degree_offset_noise_off(yaw_offset_truth):
    """Noise off, roll up to 2°: besides the Sun angles (≤ q in direction) the measured
    roll and pitch are each off by ≤ 0.005° (Earth quantum / 2), rotating the de-rotated
    Sun by ≤ 0.01°; the yaw error is ≤ asin(sin(q + 0.01°)/sin p) for every head."""
    truth = yaw_offset_truth
    _, sep_sin, err, uses = _noise_free_yaw_errors(truth)
    for name, use in uses:
        bound = _direction_error_yaw_bound_deg(HEADS[name][3] + 0.01, sep_sin[use])
        assert np.all(err[use] <= bound + 1e-9), name


def test_ground_yaw_recovers_a_two_degree_offset_noise_on(yaw_offset_truth):
    """Noise on: on DSS samples the ground yaw follows the true yaw (−2°…−1.4° there) to
    0.1° (q/2 + 5σ_DSS = 0.084° from β, plus Earth-sensor noise that barely moves a Sun
    near −x); the offset is really seen, not a zero yaw passing the bound."""
    truth = yaw_offset_truth
    tel = make_telemetry(truth, SensorSuite(), streams(20260320))
    use = tel.yaw_head == HEAD_ORDER.index("dss")
    assert use.sum() > 10_000
    err = _wrap_deg((tel.yaw_rad[use] - truth.yaw_rad[use]) / DEG)
    assert np.max(np.abs(err)) < 0.1
    assert np.max(np.abs(truth.yaw_rad[use])) / DEG > 1.3
    assert np.all(np.abs(tel.yaw_rad[use]) / DEG > 1.2)
    assert np.all(np.sign(tel.yaw_rad[use]) == np.sign(truth.yaw_rad[use]))


# ------------------------------------------------------------ 8. constant sensor biases
#
# Convention (sim.sensors): measured = quantise(true + bias + noise), in the sensor's unit.
# With the same random streams the noise draws are the same with and without a bias, so
# where the bias is a whole number of quanta the quantised reading moves by exactly the
# bias; other biases are checked on the mean, where noise σ ≥ q dithers the quantiser.


def _suite(earth=None, tach=None, **head_biases) -> SensorSuite:
    """The default suite with biases: ``head_biases`` maps a head name to its
    (in-plane, out-of-plane) biases in degrees."""
    base = SensorSuite()
    heads = tuple(replace(h, in_plane_bias_deg=head_biases.get(h.name, (0.0, 0.0))[0],
                          out_of_plane_bias_deg=head_biases.get(h.name, (0.0, 0.0))[1])
                  for h in base.sun_heads)
    return replace(base, earth=earth or base.earth, tachometer=tach or base.tachometer,
                   sun_heads=heads)


def _noise_off(suite: SensorSuite) -> SensorSuite:
    return replace(suite, noise_enabled=False)


@pytest.fixture(scope="module")
def zero_attitude_solstice(spacecraft, orbit, quiet):
    """Torque-free, control off, body on the orbit frame (attitude exactly 0) for a day at
    the June solstice, where the Sun is 23.4° out of the orbit plane."""
    env, ctrl = quiet
    truth = simulate_truth(spacecraft, orbit, env, ctrl, InitialState(),
                           ephemeris.parse_epoch(SOLSTICE_UTC), DAY_S)
    # Exactly 0 here; 1.3e-19 rad with an FMA build (whose h_z is 2e-17 N m s, not 0).
    assert np.max(np.abs(truth.euler_rad)) < 1e-12
    return truth


def test_earth_sensor_bias_shifts_the_quantised_reading_by_whole_quanta(equinox_day):
    """Roll bias +0.03° and pitch bias −0.05° (3 and −5 quanta of 0.01°), same noise draws:
    every reading moves by exactly the bias, noise on or off."""
    truth, seed = equinox_day.truth, equinox_day.scenario.seed
    biased = _suite(earth=EarthSensor(roll_bias_deg=0.03, pitch_bias_deg=-0.05))
    for on in (True, False):
        a = make_telemetry(truth, replace(SensorSuite(), noise_enabled=on), streams(seed))
        b = make_telemetry(truth, replace(biased, noise_enabled=on), streams(seed))
        np.testing.assert_allclose((b.roll_rad - a.roll_rad) / DEG, 0.03, rtol=0, atol=1e-9)
        np.testing.assert_allclose((b.pitch_rad - a.pitch_rad) / DEG, -0.05, rtol=0, atol=1e-9)


def test_earth_sensor_bias_is_the_mean_error_with_noise_on(equinox_day):
    """A bias that is not a whole quantum (roll +0.0037°, pitch −0.0061°): σ = q = 0.01°
    dithers the quantiser (Sheppard, residual ≤ exp(−2π²) = 3e-9 of q), so the mean of
    measured − true is the bias, within the 99.9 % interval Z·sqrt((σ² + q²/12)/n)
    (≈ 8e-5° for n = 168 750), far below the bias itself."""
    truth, seed = equinox_day.truth, equinox_day.scenario.seed
    roll_b, pitch_b = 0.0037, -0.0061
    tel = make_telemetry(truth, _suite(earth=EarthSensor(roll_bias_deg=roll_b,
                                                         pitch_bias_deg=pitch_b)), streams(seed))
    for meas, true, bias in ((tel.roll_rad, truth.roll_rad, roll_b),
                             (tel.pitch_rad, truth.pitch_rad, pitch_b)):
        err = (meas - true) / DEG
        tol = Z999 * np.sqrt((0.01**2 + 0.01**2 / 12) / err.size)
        assert tol < abs(bias) / 20
        assert abs(err.mean() - bias) < tol, (err.mean(), bias)
        # The spread is unchanged: a bias is not noise.
        _check_noise_plus_quantisation(err - bias, 0.01, 0.01)


def test_tachometer_bias_shifts_every_wheel_in_rad_per_s(equinox_day):
    """Noise off, bias 3 quanta = 0.0489 rpm: every wheel speed moves by exactly
    0.0489 · 2π/60 = 5.1208e-3 rad/s (hand value).  Noise on, bias 0.005 rpm (under a third
    of a quantum; σ = 0.0326 rpm = 2q dithers it): the mean speed error per wheel is
    0.005 rpm = 5.236e-4 rad/s within Z·sqrt((σ² + q²/12)/n) (≈ 2.6e-4 rpm)."""
    truth, seed = equinox_day.truth, equinox_day.scenario.seed
    a = make_telemetry(truth, _noise_off(SensorSuite()), streams(seed))
    b = make_telemetry(truth, _noise_off(_suite(tach=Tachometer(bias_rpm=3 * 0.0163))),
                       streams(seed))
    shift = b.wheel_speeds_radps - a.wheel_speeds_radps
    assert shift.shape[1] == 2
    np.testing.assert_allclose(shift, 5.1208e-3, rtol=1e-4)
    # A difference of two 574 rad/s readings, ulp 1.1e-13 each (measured 1.4e-13): 1e-10
    # rad/s is 2e-8 of the shift, 900 ulps of the readings.
    np.testing.assert_allclose(shift, 3 * 0.0163 * RPM, rtol=0, atol=1e-10)

    tel = make_telemetry(truth, _suite(tach=Tachometer(bias_rpm=0.005)), streams(seed))
    err = tel.wheel_speeds_radps - truth.wheel_speeds_radps
    sigma, q = 0.0978 / 3, 0.0163
    tol = Z999 * np.sqrt((sigma**2 + q**2 / 12) / err.shape[0])
    assert tol < 0.005 / 10
    for w in range(2):
        assert abs(err[:, w].mean() / RPM - 0.005) < tol, w
        assert err[:, w].mean() == pytest.approx(5.236e-4, rel=0.06)


def test_sun_head_biases_shift_alpha_and_beta_but_not_visibility(equinox_day):
    """Noise off, each head biased by whole quanta on both angles (opposite signs): where a
    head sees the Sun its α and β move by exactly the bias; the field of view is geometric,
    so visibility does not change."""
    truth = equinox_day.truth
    biases = {name: (4 * HEADS[name][3], -2 * HEADS[name][3]) for name in HEAD_ORDER}
    a = make_telemetry(truth, _noise_off(SensorSuite()), streams(0))
    b = make_telemetry(truth, _noise_off(_suite(**biases)), streams(0))
    assert np.array_equal(a.sun.visible, b.sun.visible)
    for k, name in enumerate(HEAD_ORDER):
        vis = a.sun.visible[:, k]
        assert vis.sum() > 10_000
        for got, ref, bias in ((b.sun.alpha_rad, a.sun.alpha_rad, biases[name][0]),
                               (b.sun.beta_rad, a.sun.beta_rad, biases[name][1])):
            np.testing.assert_allclose((got[vis, k] - ref[vis, k]) / DEG, bias, rtol=0,
                                       atol=1e-9, err_msg=name)


def test_dss_out_of_plane_bias_is_a_yaw_error_of_the_same_size(zero_attitude_solstice):
    """The DSS (boresight −x, u = +z) gives the measured direction ∝ (−1, tan β, tan α),
    whose azimuth is π − β; with zero roll and pitch the ground yaw is az(ŝ_R) − (π − β), so
    a β bias Δβ is a yaw error of exactly +Δβ, at any hour angle and season.  Δβ = 0.25°
    (2 quanta), noise off, attitude 0."""
    truth = zero_attitude_solstice
    dss = HEAD_ORDER.index("dss")
    a = make_telemetry(truth, _noise_off(SensorSuite()), streams(0))
    b = make_telemetry(truth, _noise_off(_suite(dss=(0.0, 0.25))), streams(0))
    use = (a.yaw_head == dss) & (b.yaw_head == dss)
    assert use.sum() > 10_000
    np.testing.assert_allclose(_wrap_deg((b.yaw_rad[use] - a.yaw_rad[use]) / DEG), 0.25,
                               rtol=0, atol=1e-9)


def test_dss_in_plane_bias_does_not_move_the_ground_yaw(zero_attitude_solstice, equinox_day):
    """Same geometry: the DSS's α only sets the z component of the measured direction, i.e.
    the Sun's elevation from the yaw axis, never its azimuth.  So with zero roll and pitch an
    in-plane bias (here 1° = 8 quanta) leaves the ground yaw unchanged (to rounding); with
    the attitude under control (|roll|, |pitch| < 0.1°) the de-rotation couples it in only
    through sin(roll) · δ(s_z) ≤ 0.00175 · 0.0175 rad, over a horizontal Sun component
    ≥ sin 58° (the DSS sees θ = 58°…122°): ≤ 3.6e-5 rad = 0.0021° (bound by hand)."""
    dss = HEAD_ORDER.index("dss")
    truth = zero_attitude_solstice
    a = make_telemetry(truth, _noise_off(SensorSuite()), streams(0))
    b = make_telemetry(truth, _noise_off(_suite(dss=(1.0, 0.0))), streams(0))
    use = (a.yaw_head == dss) & (b.yaw_head == dss)
    assert use.sum() > 10_000
    assert np.max(np.abs(b.yaw_rad[use] - a.yaw_rad[use])) < 1e-12  # rounding: 4.4e-16
    # And the readings really did move: α by 1°.
    np.testing.assert_allclose((b.sun.alpha_rad[use, dss] - a.sun.alpha_rad[use, dss]) / DEG,
                               1.0, rtol=0, atol=1e-9)

    truth, seed = equinox_day.truth, equinox_day.scenario.seed
    a = make_telemetry(truth, SensorSuite(), streams(seed))
    b = make_telemetry(truth, _suite(dss=(1.0, 0.0)), streams(seed))
    use = (a.yaw_head == dss) & (b.yaw_head == dss)
    assert use.sum() > 10_000
    assert np.max(np.abs(truth.euler_rad)) / DEG < ATT_MAX_DEG
    assert np.max(np.abs(b.yaw_rad[use] - a.yaw_rad[use])) / DEG < 0.0021


def test_cass_in_plane_bias_gives_the_hand_derived_yaw_error(zero_attitude_solstice):
    """A head at boresight hour angle θ_b sees the Sun ŝ = (−sin θ cos δ, −sin δ, −cos θ cos δ)
    at α = θ − θ_b, tan β = −tan δ / cos α.  The ground's direction b + tan α u + tan β ŷ is
    ∝ (−sin θ, cos α tan β, −cos θ) (since b cos α + u sin α is the boresight at θ), with
    azimuth atan2(cos α tan β, −sin θ).  Perturbing α by Δα at fixed β and differentiating,
    the yaw error (ground − true = −δ azimuth) is

        δψ = tan δ · cos θ_b / (cos α · (sin²θ + tan²δ)) · Δα.

    (For the DSS cos θ_b = 0: no yaw error, the test above.)  cass2 (θ_b = 15°) at the June
    solstice (δ = +23.4°), Δα = +0.195° (5 quanta), noise off, attitude 0: the factor is
    positive, from 1/tan δ = 2.31 at noon (θ = 0, where α = −θ_b) down to 0.63 at the far
    edge (θ = 60°), so the yaw error has the bias's sign and up to 2.3 times its size.
    Tolerance: the neglected second-order term, ≤ Δα · |d ln factor/dθ| ≲ 0.2 %, taken as
    1 %."""
    truth = zero_attitude_solstice
    k = HEAD_ORDER.index("cass2")
    d_alpha = 5 * HEADS["cass2"][3]
    a = make_telemetry(truth, _noise_off(SensorSuite()), streams(0))
    b = make_telemetry(truth, _noise_off(_suite(cass2=(d_alpha, 0.0))), streams(0))
    use = (a.yaw_head == k) & (b.yaw_head == k)
    assert use.sum() > 10_000
    s = truth.sun_orbit_frame[use]
    dec = np.arcsin(-s[:, 1])
    theta = np.arctan2(-s[:, 0], -s[:, 2])
    alpha = theta - HEADS["cass2"][0] * DEG
    assert np.all(dec / DEG > 23.0)
    factor = np.tan(dec) * np.cos(HEADS["cass2"][0] * DEG) / (
        np.cos(alpha) * (np.sin(theta) ** 2 + np.tan(dec) ** 2))
    assert factor.min() == pytest.approx(0.63, abs=0.01)
    assert factor.max() == pytest.approx(1 / np.tan(23.44 * DEG), abs=0.01)
    got = _wrap_deg((b.yaw_rad[use] - a.yaw_rad[use]) / DEG)
    assert np.all(got > 0)
    np.testing.assert_allclose(got, factor * d_alpha, rtol=0.01)


def test_dss_out_of_plane_bias_shifts_the_yaw_error_closed_loop(equinox_day):
    """Closed loop, noise on (same draws), equinox: a DSS β bias of 0.25° (2 quanta) moves
    every DSS ground yaw, and so the mean yaw error, by +0.25°.  Off zero attitude the
    de-rotation tilts the measured direction by the roll and pitch (≤ 0.1°, checked), so
    ∂ψ/∂β departs from 1 by about attitude · tan α ≤ 0.0017 · tan 32° ≈ 1e-3: ≤ 2.5e-4° on
    0.25°; allowed 1e-3°."""
    truth, seed = equinox_day.truth, equinox_day.scenario.seed
    assert np.max(np.abs(truth.euler_rad)) / DEG < ATT_MAX_DEG
    dss = HEAD_ORDER.index("dss")
    a = make_telemetry(truth, SensorSuite(), streams(seed))
    b = make_telemetry(truth, _suite(dss=(0.0, 0.25)), streams(seed))
    use = (a.yaw_head == dss) & (b.yaw_head == dss)
    assert use.sum() > 10_000
    shift = _wrap_deg((b.yaw_rad[use] - a.yaw_rad[use]) / DEG)
    np.testing.assert_allclose(shift, 0.25, rtol=0, atol=1e-3)
    err_a = _wrap_deg((a.yaw_rad[use] - truth.yaw_rad[use]) / DEG)
    err_b = _wrap_deg((b.yaw_rad[use] - truth.yaw_rad[use]) / DEG)
    assert err_b.mean() - err_a.mean() == pytest.approx(0.25, abs=1e-3)


def test_zero_biases_are_bit_identical_to_no_biases(equinox_day):
    """Explicit zero biases (−0.0 too) give the very same bytes as the defaults, noise on
    and off (a zero bias is never added).  Identity is the requirement here."""
    truth, seed = equinox_day.truth, equinox_day.scenario.seed
    zeros = _suite(earth=EarthSensor(roll_bias_deg=0.0, pitch_bias_deg=-0.0),
                   tach=Tachometer(bias_rpm=-0.0), dss=(0.0, -0.0), cass1=(-0.0, 0.0),
                   cass2=(0.0, 0.0))
    for on in (True, False):
        a = make_telemetry(truth, replace(SensorSuite(), noise_enabled=on), streams(seed))
        b = make_telemetry(truth, replace(zeros, noise_enabled=on), streams(seed))
        for key, arr in telemetry_arrays(a).items():
            assert bit_identical(arr, telemetry_arrays(b)[key]), (key, on)
    # And through the scenario: zero keys build the default suite.
    s = Scenario(name="zero-bias", sensors={
        "earth": {"roll_bias_deg": 0.0, "pitch_bias_deg": 0.0},
        "tachometer": {"bias_rpm": 0.0},
        "sun": {"dss": {"in_plane_bias_deg": 0.0, "out_of_plane_bias_deg": 0.0}}})
    assert build_sensors(s) == SensorSuite()


@pytest.mark.parametrize("make", [
    lambda: EarthSensor(roll_bias_deg=np.nan),
    lambda: EarthSensor(pitch_bias_deg=np.inf),
    lambda: Tachometer(bias_rpm=np.nan),
    lambda: replace(SensorSuite().sun_heads[0], in_plane_bias_deg=np.nan),
    lambda: replace(SensorSuite().sun_heads[1], out_of_plane_bias_deg=-np.inf),
])
def test_non_finite_biases_are_rejected(make):
    with pytest.raises(ValueError, match="bias"):
        make()
