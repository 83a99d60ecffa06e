"""The estimator's sensor-bias keys (`estimator.bias_states`, `estimator.outlier_gate_chi2`),
``build.bias_model`` and ``build.truth_biases_rad`` against a simulated run.

References: the walk density by hand (a random walk of density q grows to variance q t,
so 1σ of w degrees after an hour is q = (w π/180)²/3600 rad²/s); the truth's biases
against what the ground yaw of a simulated day really does when the sensors carry them
(noise off, biases whole quanta, so every reading moves by exactly its bias and the
ground yaw's shift is the biases' effect alone); the per-sample sensitivities of
``sim.sensors.ground_yaw_sensitivity`` were derived by hand (its docstring) and are
checked here against that run, sample by sample.
"""

from __future__ import annotations

import numpy as np
import pytest

from scenarios.config import build
from scenarios.config.loader import ScenarioError, load_scenario
from scenarios.config.schema import Scenario
from scenarios.run.simulate import simulate
from sim.sensors import ground_yaw_sensitivity

DEG = np.pi / 180.0
NAMES = ("earth_roll", "dss_yaw", "cass1_yaw", "cass2_yaw")


def _wrap(x):
    return (np.asarray(x) + np.pi) % (2 * np.pi) - np.pi


# ------------------------------------------------------------------ 1. keys and defaults


def test_defaults_are_off():
    s = Scenario(name="x")
    b = s.estimator.bias_states
    assert [getattr(b, n).model for n in NAMES] == ["off"] * 4
    assert [getattr(b, n).sigma_deg for n in NAMES] == [0.01, 0.01, 0.05, 0.05]
    assert [getattr(b, n).walk_deg_per_sqrt_h for n in NAMES] == [0.0] * 4
    assert s.estimator.outlier_gate_chi2 is None
    assert build.bias_model(s) is None
    assert build.truth_biases_rad(s) == dict.fromkeys(NAMES, 0.0)


YAML = """\
name: biased
estimator:
  bias_states:
    earth_roll: {model: constant, sigma_deg: 0.02, walk_deg_per_sqrt_h: 0.0}
    dss_yaw:    {model: random_walk, sigma_deg: 0.01, walk_deg_per_sqrt_h: 0.003}
    cass1_yaw:  {model: off, sigma_deg: 0.05, walk_deg_per_sqrt_h: 0.0}
    cass2_yaw:  {model: constant}
  outlier_gate_chi2: 25
"""


def test_yaml_loads_and_gives_the_filters_bias_model(tmp_path):
    """The issue's YAML (with `off` unquoted, which YAML 1.1 reads as false) loads, and
    ``bias_model`` passes the states that are on, in order, in rad and rad²/s."""
    path = tmp_path / "s.yaml"
    path.write_text(YAML)
    s = load_scenario(path)
    b = s.estimator.bias_states
    assert (b.earth_roll.model, b.dss_yaw.model, b.cass1_yaw.model, b.cass2_yaw.model) == \
        ("constant", "random_walk", "off", "constant")
    assert b.cass2_yaw.sigma_deg == 0.05   # a CASS's own default
    assert s.estimator.outlier_gate_chi2 == 25.0
    m = build.bias_model(s)
    assert m.names == ("earth_roll", "dss_yaw", "cass2_yaw")
    np.testing.assert_allclose(m.sigma0_rad, np.array([0.02, 0.01, 0.05]) * np.pi / 180,
                               rtol=1e-15)
    # 0.003°/√h: variance (0.003 π/180)² rad² after 3600 s.
    q = m.walk_rad2ps[1]
    assert q * 3600.0 == pytest.approx((0.003 * np.pi / 180) ** 2, rel=1e-12)
    assert q == pytest.approx(7.615435e-13, rel=1e-6)
    assert m.walk_rad2ps[0] == 0.0 and m.walk_rad2ps[2] == 0.0
    # An unquoted `off` everywhere is the default.
    path.write_text("name: x\nestimator:\n  bias_states:\n    dss_yaw: {model: off}\n")
    assert load_scenario(path) == Scenario(name="x")


@pytest.mark.parametrize("setting, key", [
    ("estimator.bias_states.earth_roll.sigma_deg=0", "estimator.bias_states.earth_roll.sigma_deg"),
    ("estimator.bias_states.cass1_yaw.sigma_deg=-0.1", "estimator.bias_states.cass1_yaw.sigma_deg"),
    ("estimator.bias_states.dss_yaw.walk_deg_per_sqrt_h=-1",
     "estimator.bias_states.dss_yaw.walk_deg_per_sqrt_h"),
    ("estimator.bias_states.dss_yaw={model: random_walk}",
     "estimator.bias_states.dss_yaw.walk_deg_per_sqrt_h"),
    ("estimator.bias_states.cass2_yaw={model: constant, walk_deg_per_sqrt_h: 0.1}",
     "estimator.bias_states.cass2_yaw.walk_deg_per_sqrt_h"),
    ("estimator.bias_states.earth_roll.model=fixed", "estimator.bias_states.earth_roll.model"),
    ("estimator.outlier_gate_chi2=0", "estimator.outlier_gate_chi2"),
    ("estimator.outlier_gate_chi2=-9", "estimator.outlier_gate_chi2"),
])
def test_bad_values_give_one_line_naming_the_field(setting, key):
    with pytest.raises(ScenarioError) as err:
        load_scenario("goes_next_equinox", [setting])
    text = str(err.value)
    assert text.startswith(key + ":") and "\n" not in text, text


def test_the_walk_messages_say_what_to_do():
    for setting, words in (("{model: random_walk}", "must be > 0 with model 'random_walk'"),
                           ("{model: constant, walk_deg_per_sqrt_h: 0.1}",
                            "must be 0 with model 'constant'")):
        with pytest.raises(ScenarioError, match=words):
            load_scenario("goes_next_equinox", [f"estimator.bias_states.dss_yaw={setting}"])
    # A random walk with a walk, and a constant without, are fine.
    load_scenario("goes_next_equinox", [
        "estimator.bias_states.dss_yaw={model: random_walk, walk_deg_per_sqrt_h: 0.01}",
        "estimator.bias_states.earth_roll={model: constant}"])


# ------------------------------------------------- 2. the truth's biases, as the filter's

# Whole quanta (Earth sensor 0.01°, DSS 0.125°, CASS 0.039°), so that with the noise off
# every reading moves by exactly its bias.
ROLL_B, DSS_B, DSS_A, CASS_B = 0.05, 0.25, 1.0, 0.039


@pytest.fixture(scope="module")
def biased_day():
    """One equinox day, control on, noise off: without and with the biases."""
    base = dict(name="bias", duration_s=86400.0)
    off = {"noise": {"enabled": False}}
    biases = {"noise": {"enabled": False}, "earth": {"roll_bias_deg": ROLL_B},
              "sun": {"dss": {"out_of_plane_bias_deg": DSS_B, "in_plane_bias_deg": DSS_A},
                      "cass1": {"out_of_plane_bias_deg": CASS_B},
                      "cass2": {"out_of_plane_bias_deg": -CASS_B}}}
    plain = simulate(Scenario(**base, sensors=off))
    s = Scenario(**base, sensors=biases)
    biased = simulate(s)
    assert np.array_equal(plain.truth.euler_rad, biased.truth.euler_rad)   # sensors only
    return s, plain, biased


def test_earth_roll_bias_is_the_roll_bias(biased_day):
    s, plain, biased = biased_day
    got = build.truth_biases_rad(s)
    assert got["earth_roll"] == ROLL_B * DEG
    np.testing.assert_allclose(biased.telemetry.roll_rad - plain.telemetry.roll_rad,
                               ROLL_B * DEG, rtol=0, atol=1e-12)


def test_dss_yaw_bias_is_the_mean_ground_yaw_error_it_adds(biased_day):
    """Where the DSS gives the yaw (θ ≈ 58°…122°), the mean ground-yaw error with the
    biases minus without is ``truth_biases_rad``'s dss_yaw = +β bias = +0.25° (the α
    bias of 1° adds nothing to first order).  The roll bias leaks in as roll · cot θ,
    ±0.031° at the field's edges, averaging to 1e-6° over the symmetric span; what is
    left is second order, the ground de-rotating the 1° α shift by the 0.05° roll bias:
    about 0.05° · π/180 · 1° = 8.7e-4° (measured 9.8e-4°).  Tolerance 2e-3°; a sign
    error would be 0.5° off, a missed β bias 0.25°."""
    s, plain, biased = biased_day
    dss = 0
    use = (plain.telemetry.yaw_head == dss) & (biased.telemetry.yaw_head == dss)
    assert use.sum() > 20_000
    truth = plain.truth.yaw_rad[use]
    err_plain = _wrap(plain.telemetry.yaw_rad[use] - truth)
    err_biased = _wrap(biased.telemetry.yaw_rad[use] - truth)
    shift = np.mean(err_biased) - np.mean(err_plain)
    want = build.truth_biases_rad(s)["dss_yaw"]
    assert want == pytest.approx(DSS_B * DEG, rel=1e-12)
    assert abs(shift - want) / DEG < 2e-3, (shift / DEG, want / DEG)


@pytest.mark.parametrize("k, name, beta_bias", [(0, "dss", DSS_B), (1, "cass1", CASS_B),
                                                (2, "cass2", -CASS_B)])
def test_every_ground_yaw_moves_as_the_sensitivities_say(biased_day, k, name, beta_bias):
    """Sample by sample, where head ``name`` gives the yaw, the ground yaw's shift is
    Σ ∂ψ/∂(bias) · bias over the head's α and β biases and the roll bias, evaluated at
    the Sun's true hour angle and declination (truth's Sun in the orbit frame).
    Tolerance: the first-order formula is evaluated at zero attitude; the truth flies
    within 0.1° (1.7e-3 rad) of it and the biases are up to 1° (0.017 rad) — so the
    second-order terms are about (attitude + bias) · |∂ ln factor/∂θ| · shift: with
    |cot θ| ≤ 6 at the 10° separation limit, ≤ 0.11 · shift for a CASS near noon; 12 % of
    the shift plus 2e-4° absolute."""
    s, plain, biased = biased_day
    use = (plain.telemetry.yaw_head == k) & (biased.telemetry.yaw_head == k)
    assert use.sum() > 5000
    sr = plain.truth.sun_orbit_frame[use]
    dec = np.arcsin(-sr[:, 1])
    theta = np.arctan2(-sr[:, 0], -sr[:, 2])
    head = build.build_sensors(s).sun_heads[k]
    f = ground_yaw_sensitivity(head, theta, dec)
    alpha_bias = DSS_A if name == "dss" else 0.0
    want = (f["in_plane"] * alpha_bias + f["out_of_plane"] * beta_bias
            + f["roll"] * ROLL_B)
    got = _wrap(biased.telemetry.yaw_rad[use] - plain.telemetry.yaw_rad[use]) / DEG
    np.testing.assert_allclose(got, want, rtol=0.12, atol=2e-4)


@pytest.mark.parametrize("k, name", [(1, "cass1"), (2, "cass2")])
def test_cass_yaw_bias_is_the_shift_on_the_boresight(biased_day, k, name):
    """A CASS's yaw shift depends on where the Sun is in its field; ``truth_biases_rad``
    gives it on the boresight.  The samples whose Sun is within 1° of the boresight hour
    angle have a mean shift equal to it, within their own spread (max − min of the
    shift over those samples, plus 5 %)."""
    s, plain, biased = biased_day
    head = build.build_sensors(s).sun_heads[k]
    sr = plain.truth.sun_orbit_frame
    theta = np.arctan2(-sr[:, 0], -sr[:, 2])
    near = np.abs(_wrap(theta - head.boresight_hour_angle_deg * DEG)) < 1.0 * DEG
    use = near & (plain.telemetry.yaw_head == k) & (biased.telemetry.yaw_head == k)
    assert use.sum() > 100
    shift = _wrap(biased.telemetry.yaw_rad[use] - plain.telemetry.yaw_rad[use])
    want = build.truth_biases_rad(s)[f"{name}_yaw"]
    # By hand at equinox (δ ≈ 0) on the boresight: β / sin θ_b + roll · cot θ_b.
    tb = head.boresight_hour_angle_deg * DEG
    hand = (CASS_B if name == "cass1" else -CASS_B) / np.sin(tb) + ROLL_B / np.tan(tb)
    assert want / DEG == pytest.approx(hand, rel=0.01)
    assert abs(np.mean(shift) - want) <= np.ptp(shift) + 0.05 * abs(want), \
        (np.mean(shift) / DEG, want / DEG, np.ptp(shift) / DEG)
