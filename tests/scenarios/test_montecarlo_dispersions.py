"""Monte Carlo dispersions: the statistics of the draws, case seeds spawned from the
scenario seed, and validation of the `montecarlo` section (one line, exit 2).

Statistical checks state their tolerance: a sample mean within 4 standard errors,
a sample variance inside its 99.9% χ² interval.  Every draw is seeded, so the
tests are deterministic.
"""

from __future__ import annotations

import json
import math
import zlib
from datetime import timedelta

import numpy as np
import pytest
from scipy import stats

from scenarios.config import build
from scenarios.config.loader import ScenarioError, load_scenario
from scenarios.montecarlo.dispersions import draw_case
from scenarios.run.simulate import simulate
from sim.disturbance import draw
from sim.ephemeris import parse_epoch

from .mc_helpers import (
    assert_one_line,
    chi2_var_interval,
    dispersions_override,
    montecarlo,
    run_cli,
)

# --------------------------------------------------------------------------- 1. dispersions

STAT_DISPERSIONS = {
    "initial_state.yaw_deg": {"distribution": "normal", "sigma": 0.5, "mean": 0.2},
    "spacecraft.wheels.speed_rpm": {"distribution": "uniform", "low": -50, "high": 25},
    "environment.magnetic.residual_dipole_Am2":
        {"distribution": "uniform", "low": [-1, -2, 0.5], "high": [1, 3, 0.75]},
    "initial_state.rate_wrt_orbit_degps":
        {"distribution": "normal", "sigma": [0.001, 0.002, 0.0005], "mean": 0.0001},
    "spacecraft.inertia_kgm2":
        {"distribution": "normal", "sigma": [[67, 10, 5], [10, 19, 8], [5, 8, 69]]},
    "epoch_utc": {"distribution": "uniform", "low": -10, "high": 10},
}
N_DRAWS = 400


@pytest.fixture(scope="module")
def stat_scenario():
    return load_scenario("goes_next_equinox", [dispersions_override(STAT_DISPERSIONS)])


@pytest.fixture(scope="module")
def stat_draws(stat_scenario):
    return [draw_case(stat_scenario, k)[0] for k in range(N_DRAWS)]


def test_normal_scalar_dispersion_has_the_stated_mean_and_variance(stat_scenario, stat_draws):
    nominal = stat_scenario.initial_state.yaw_deg
    x = np.array([v["initial_state.yaw_deg"] for v in stat_draws]) - nominal
    n, sigma, mean = len(x), 0.5, 0.2
    assert abs(x.mean() - mean) <= 4 * sigma / math.sqrt(n)
    lo, hi = chi2_var_interval(n, sigma)
    assert lo <= x.var(ddof=1) <= hi
    # Normal, not anything else with that mean and variance: Kolmogorov–Smirnov at 0.1%.
    assert stats.kstest((x - mean) / sigma, "norm").pvalue > 1e-3


def test_normal_vector_dispersion_per_component(stat_scenario, stat_draws):
    nominal = np.array(stat_scenario.initial_state.rate_wrt_orbit_degps)
    x = np.array([v["initial_state.rate_wrt_orbit_degps"] for v in stat_draws]) - nominal
    sigma, n = np.array([0.001, 0.002, 0.0005]), len(x)
    assert x.shape == (n, 3)
    assert np.all(np.abs(x.mean(axis=0) - 0.0001) <= 4 * sigma / math.sqrt(n))
    lo, hi = chi2_var_interval(n, sigma)
    assert np.all((lo <= x.var(axis=0, ddof=1)) & (x.var(axis=0, ddof=1) <= hi))
    # Components are drawn independently.
    c = np.corrcoef(x.T)[np.triu_indices(3, 1)]
    assert np.all(np.abs(c) <= 4 / math.sqrt(n))


def test_uniform_dispersions_stay_in_bounds_with_the_uniform_mean(stat_scenario, stat_draws):
    speed0 = stat_scenario.spacecraft.wheels.speed_rpm
    speed = np.array([v["spacecraft.wheels.speed_rpm"] for v in stat_draws]) - speed0
    dip0 = np.array(stat_scenario.environment.magnetic.residual_dipole_Am2)
    dip = np.array([v["environment.magnetic.residual_dipole_Am2"] for v in stat_draws]) - dip0
    n = N_DRAWS
    for x, low, high in ((speed, np.array(-50.0), np.array(25.0)),
                         (dip, np.array([-1, -2, 0.5]), np.array([1, 3, 0.75]))):
        # Offsets are recovered by a subtraction: allow its rounding.
        eps = 1e-9 * (np.abs(low) + np.abs(high) + 1)
        assert np.all(x >= low - eps) and np.all(x <= high + eps)
        width = high - low
        assert np.all(np.abs(x.mean(axis=0) - (low + high) / 2)
                      <= 4 * width / math.sqrt(12 * n))
        # They fill the interval: the extremes lie within 2% of its ends (P(not) < 1e-3).
        assert np.all(x.min(axis=0) - low < 0.02 * width)
        assert np.all(high - x.max(axis=0) < 0.02 * width)
    assert stats.kstest((speed + 50) / 75, "uniform").pvalue > 1e-3


def test_inertia_draws_are_symmetric_with_the_sigma_matrix(stat_scenario, stat_draws):
    """Exact symmetry is the requirement: one draw per distinct element, mirrored."""
    nominal = np.array(stat_scenario.spacecraft.inertia_kgm2)
    sigma = np.array(STAT_DISPERSIONS["spacecraft.inertia_kgm2"]["sigma"], dtype=float)
    J = np.array([v["spacecraft.inertia_kgm2"] for v in stat_draws])
    assert J.shape == (N_DRAWS, 3, 3)
    assert np.array_equal(J, J.transpose(0, 2, 1)), "inertia draws must be exactly symmetric"
    d = J - nominal
    iu = np.triu_indices(3)
    lo, hi = chi2_var_interval(N_DRAWS, sigma[iu])
    var = d[:, iu[0], iu[1]].var(axis=0, ddof=1)
    assert np.all((lo <= var) & (var <= hi)), (np.sqrt(var), sigma[iu])
    assert np.all(np.abs(d[:, iu[0], iu[1]].mean(axis=0)) <= 4 * sigma[iu] / math.sqrt(N_DRAWS))
    # The six distinct elements are independent of each other.
    c = np.corrcoef(d[:, iu[0], iu[1]].T)[np.triu_indices(6, 1)]
    assert np.all(np.abs(c) <= 4 / math.sqrt(N_DRAWS))
    # Every draw that validated is a physical inertia: positive definite.
    assert np.all(np.linalg.eigvalsh(J) > 0)


def test_epoch_offsets_are_whole_days_within_bounds(stat_scenario, stat_draws):
    nominal = parse_epoch(stat_scenario.epoch_utc)
    days = []
    for v in stat_draws:
        delta = parse_epoch(v["epoch_utc"]) - nominal
        # Whole days: the time of day (and with it the Sun-gap timing) is the nominal one.
        assert delta % timedelta(days=1) == timedelta(0), v["epoch_utc"]
        days.append(delta.days)
    days = np.array(days)
    assert days.min() >= -10 and days.max() <= 10
    # U(−10, 10) rounded: every whole day from −10 to 10 occurs (the rarest, the ends,
    # with probability 1/40 each: P(missing one in 400) < 1e-4), mean 0.
    assert set(days) == set(range(-10, 11))
    assert abs(days.mean()) <= 4 * math.sqrt(400 / 12 + 1 / 12) / math.sqrt(len(days))


def test_case_draws_do_not_depend_on_other_keys_cases_or_order(stat_scenario, stat_draws):
    """Identity is the requirement here: a case's draws come from its own seeded
    streams, on the same machine."""
    keys = ("initial_state.yaw_deg", "spacecraft.inertia_kgm2")
    subset = {k: STAT_DISPERSIONS[k] for k in keys}
    alone = load_scenario("goes_next_equinox", [dispersions_override(subset)])
    more = load_scenario("goes_next_equinox", [dispersions_override(
        {**STAT_DISPERSIONS, "initial_state.roll_deg": {"distribution": "normal",
                                                        "sigma": 0.05}})])
    reordered = load_scenario("goes_next_equinox", [dispersions_override(
        dict(reversed(list(STAT_DISPERSIONS.items()))))])
    for k in (0, 1, 17, N_DRAWS - 1):
        for key in keys:
            assert draw_case(alone, k)[0][key] == stat_draws[k][key], (k, key)
        assert {key: draw_case(more, k)[0][key] for key in STAT_DISPERSIONS} == stat_draws[k]
        assert draw_case(reordered, k)[0] == stat_draws[k]
    # Drawn in another order, and far past the others: each case is its own.
    for k in (N_DRAWS - 1, 3, 0):
        assert draw_case(stat_scenario, k)[0] == stat_draws[k]
    # Case k's root, the spawn key (k,) its record stores, is the k-th child of the
    # scenario seed whatever the number of cases.
    seed = stat_scenario.seed
    for k in (0, 5, 9):
        state = np.random.SeedSequence(seed, spawn_key=(k,)).generate_state(4)
        for n in (k + 1, 10, 1000):
            assert np.array_equal(np.random.SeedSequence(seed).spawn(n)[k].generate_state(4),
                                  state)


def test_same_seed_same_draws_other_seed_other_draws(stat_scenario, stat_draws):
    """Identity is the requirement for the same seed (same streams, same machine)."""
    same = load_scenario("goes_next_equinox", [dispersions_override(STAT_DISPERSIONS)])
    other = load_scenario("goes_next_equinox", [dispersions_override(STAT_DISPERSIONS),
                                                f"seed={stat_scenario.seed + 1}"])
    for k in range(10):
        assert draw_case(same, k)[0] == stat_draws[k]
        moved = draw_case(other, k)[0]
        for key in STAT_DISPERSIONS:
            if key != "epoch_utc":    # whole days: two seeds may well agree
                assert moved[key] != stat_draws[k][key], (k, key)
    # Different cases of one seed differ too.
    assert len({v["initial_state.yaw_deg"] for v in stat_draws}) == N_DRAWS


def test_draw_case_flies_the_drawn_values_and_keeps_the_estimator(stat_scenario):
    """Identity is the requirement: the scenario flown holds the drawn values."""
    values, flying = draw_case(stat_scenario, 3)
    assert flying.initial_state.yaw_deg == values["initial_state.yaw_deg"]
    assert np.array_equal(np.array(flying.spacecraft.inertia_kgm2),
                          np.array(values["spacecraft.inertia_kgm2"]))
    assert flying.epoch_utc == values["epoch_utc"]
    assert flying.estimator == stat_scenario.estimator
    assert flying.seed == stat_scenario.seed
    assert flying.duration_s == stat_scenario.duration_s


def test_an_unphysical_draw_raises_naming_the_key():
    s = load_scenario("goes_next_equinox", [dispersions_override(
        {"sensors.earth.noise_deg": {"distribution": "normal", "sigma": 1.0, "mean": -5}})])
    with pytest.raises(ScenarioError, match=r"^sensors\.earth\.noise_deg"):
        draw_case(s, 0)


# --------------------------------------------------------------------------- 2. seeds


@pytest.mark.parametrize("seed", [0, 20260320, 2**40 + 7])
def test_case_streams_are_spawned_from_the_scenario_seed(seed):
    """Identity is the requirement: the streams are numpy's SeedSequence children."""
    for k in (0, 1, 7):
        got = build.streams(seed, k)
        assert list(got) == list(build.STREAMS)
        children = np.random.SeedSequence(seed).spawn(k + 1)[k].spawn(len(build.STREAMS))
        for i, name in enumerate(build.STREAMS):
            want = np.random.default_rng(children[i])
            assert np.array_equal(got[name].standard_normal(8), want.standard_normal(8))
            assert np.array_equal(got[name].integers(0, 2**62, 4),
                                  want.integers(0, 2**62, 4))
    # Two streams, or two cases, never share draws.
    first = [tuple(build.streams(seed, k)[n].standard_normal(2)) for k in (0, 1)
             for n in build.STREAMS]
    assert len(set(first)) == len(first)


def test_dispersed_key_draws_from_its_own_child_of_the_case():
    s = load_scenario("goes_next_equinox", [dispersions_override(
        {"initial_state.yaw_deg": {"distribution": "normal", "sigma": 0.5, "mean": 0.2}})])
    key = "initial_state.yaw_deg"
    for k in (0, 4):
        z = np.random.default_rng(np.random.SeedSequence(
            s.seed, spawn_key=(k, len(build.STREAMS), zlib.crc32(key.encode())))
        ).standard_normal()
        # The draw is that stream's first normal: another stream moves it by O(0.5°).
        assert draw_case(s, k)[0][key] == pytest.approx(s.initial_state.yaw_deg
                                                        + (0.2 + 0.5 * z), rel=0, abs=1e-12)


def test_the_disturbance_has_its_own_stream_per_case():
    """Case (run) k's disturbance draws from SeedSequence(seed, spawn_key=(k, 7)): numpy's
    child 7 of case k, one past the dispersions' (k, 6, ·), and made only for a scenario
    that flies one.  STREAMS, and with it DISPERSION_STREAM = 6, are what they were."""
    assert build.STREAMS == ("ripple", "earth", "tachometer", "dss", "cass1", "cass2")
    assert build.DISPERSION_STREAM == 6
    s = load_scenario("goes_next_paper_torques")
    for k in (0, 1, 5):
        want = np.random.default_rng(np.random.SeedSequence(s.seed).spawn(k + 1)[k].spawn(8)[7])
        assert np.array_equal(build.disturbance_generator(s, k).standard_normal(8),
                              want.standard_normal(8))
    assert build.disturbance_generator(load_scenario("goes_next_equinox"), 0) is None


def test_the_disturbance_levels_are_dispersed_like_any_numeric_key():
    """`environment.disturbance.sigma_Nm` and `correlation_time_s` disperse as every
    numeric key does (a 3-vector per component, a number), each from its own key
    stream; the case flies the dispersed levels, drawn from its own stream (k, 7)."""
    sigma_key, tau_key = "environment.disturbance.sigma_Nm", \
        "environment.disturbance.correlation_time_s"
    low, high = np.array([-1e-6, 0.0, -2e-6]), np.array([1e-6, 0.0, 2e-6])
    s = load_scenario("goes_next_paper_torques", ["duration_s=60", dispersions_override({
        sigma_key: {"distribution": "uniform", "low": low.tolist(), "high": high.tolist()},
        tau_key: {"distribution": "normal", "sigma": 1000.0}})])

    def key_stream(k, key):
        return np.random.default_rng(np.random.SeedSequence(
            s.seed, spawn_key=(k, len(build.STREAMS), zlib.crc32(key.encode()))))
    for k in (0, 3):
        values, flying = draw_case(s, k)
        u = key_stream(k, sigma_key).random(3)
        sigma = np.array([5e-6, 0.0, 5e-6]) + low + (high - low) * u
        tau = 21541.0 + 1000.0 * key_stream(k, tau_key).standard_normal()
        np.testing.assert_allclose(values[sigma_key], sigma, rtol=0, atol=1e-20)
        assert values[tau_key] == pytest.approx(tau, rel=1e-15)
        d = build.build_disturbance(flying)
        assert d.sigma_Nm == tuple(values[sigma_key]) and d.correlation_time_s == values[tau_key]
        sim = simulate(flying, run=k)
        want = draw(d, flying.sample_interval_s, len(sim.truth.t_s), np.random.default_rng(
            np.random.SeedSequence(s.seed, spawn_key=(k, 7))))
        assert np.array_equal(sim.truth.torques["disturbance"], want)


# --------------------------------------------------------------------------- 3. validation

BAD_DISPERSIONS = [
    ("unknown", "spacecraft.bogus", {"distribution": "normal", "sigma": 1}),
    ("section", "spacecraft", {"distribution": "normal", "sigma": 1}),
    ("seed", "seed", {"distribution": "normal", "sigma": 1}),
    ("duration", "duration_s", {"distribution": "uniform", "low": -1, "high": 1}),
    ("step", "sample_interval_s", {"distribution": "normal", "sigma": 0.01}),
    ("estimator", "estimator.process_noise.q_x", {"distribution": "normal", "sigma": 1e-8}),
    ("shape-vector-on-scalar", "initial_state.yaw_deg",
     {"distribution": "normal", "sigma": [1, 2, 3]}),
    ("shape-matrix-on-vector", "initial_state.rate_wrt_orbit_degps",
     {"distribution": "normal", "sigma": [[1, 0, 0], [0, 1, 0], [0, 0, 1]]}),
    ("shape-two", "initial_state.rate_wrt_orbit_degps",
     {"distribution": "normal", "sigma": [1, 2]}),
    ("asymmetric", "spacecraft.inertia_kgm2",
     {"distribution": "normal", "sigma": [[1, 2, 3], [0, 1, 0], [0, 0, 1]]}),
    ("asymmetric-uniform", "spacecraft.inertia_kgm2",
     {"distribution": "uniform", "low": [[-1, -2, 0], [0, -1, 0], [0, 0, -1]], "high": 3}),
    ("negative-sigma", "initial_state.yaw_deg", {"distribution": "normal", "sigma": -0.1}),
    ("negative-sigma-component", "initial_state.rate_wrt_orbit_degps",
     {"distribution": "normal", "sigma": [0.1, -0.1, 0.1]}),
    ("low-above-high", "initial_state.yaw_deg", {"distribution": "uniform", "low": 1,
                                                 "high": -1}),
    ("bool", "sensors.noise.enabled", {"distribution": "normal", "sigma": 1}),
    ("string", "environment.shadow_model", {"distribution": "normal", "sigma": 1}),
    ("nan", "initial_state.yaw_deg", {"distribution": "normal", "sigma": ".nan"}),
    ("inf", "initial_state.yaw_deg", {"distribution": "uniform", "low": 0, "high": ".inf"}),
    ("bool-parameter", "initial_state.yaw_deg", {"distribution": "normal", "sigma": True}),
    ("unknown-distribution", "initial_state.yaw_deg",
     {"distribution": "lognormal", "sigma": 1}),
    ("unknown-parameter", "initial_state.yaw_deg",
     {"distribution": "normal", "sigma": 1, "low": 0}),
    ("epoch-vector", "epoch_utc", {"distribution": "uniform", "low": [1, 1, 1], "high": 2}),
]


def _flow(d: dict) -> str:
    """A YAML flow mapping; ".nan"/".inf" stay YAML's special floats."""
    def v(x):
        if isinstance(x, str) and x.startswith("."):
            return x
        return json.dumps(x)
    return "{" + ", ".join(f"{k}: {v(x)}" for k, x in d.items()) + "}"


@pytest.mark.parametrize(("key", "dispersion"), [b[1:] for b in BAD_DISPERSIONS],
                         ids=[b[0] for b in BAD_DISPERSIONS])
def test_bad_dispersion_exits_2_naming_the_key(tmp_path, key, dispersion):
    out = tmp_path / "set"
    rc, stdout, err = montecarlo(out, 2, "--set", f"montecarlo.dispersions={{{key}: "
                                 f"{_flow(dispersion)}}}")
    assert rc == 2, (stdout, err)
    assert_one_line(err)
    assert f"montecarlo.dispersions.{key}" in err, err
    assert not out.exists()
    # `dynprop run --montecarlo-case` refuses it the same way.
    rc, _, err = run_cli("run", "goes_next_equinox", "--montecarlo-case", 0, "--set",
                         f"montecarlo.dispersions={{{key}: {_flow(dispersion)}}}",
                         "--out", out)
    assert rc == 2 and f"montecarlo.dispersions.{key}" in assert_one_line(err)
    assert not out.exists()


@pytest.mark.parametrize("args", [
    ("--runs", "0"), ("--runs", "x"), ("--runs", "-3"), ("--runs", "2.5"),
    ("--runs", "2", "--workers", "0"), ("--runs", "2", "--keep-trajectories", "a"),
    ("--runs", "2", "--keep-trajectories", "-1"),
], ids=["runs-0", "runs-x", "runs-negative", "runs-float", "workers-0", "keep-x",
        "keep-negative"])
def test_bad_arguments_exit_2(tmp_path, args):
    out = tmp_path / "set"
    rc, _, err = run_cli("montecarlo", "goes_next_equinox", *args, "--out", out)
    assert rc == 2
    assert_one_line(err)
    assert not out.exists()


def test_run_montecarlo_case_needs_dispersions_and_a_case_number(tmp_path):
    out = tmp_path / "run"
    rc, _, err = run_cli("run", "torque_free", "--montecarlo-case", 0, "--out", out)
    assert rc == 2 and "montecarlo" in assert_one_line(err)
    rc, _, err = run_cli("run", "goes_next_equinox", "--montecarlo-case", -1, "--out", out)
    assert rc == 2
    assert_one_line(err)
    assert not out.exists()


