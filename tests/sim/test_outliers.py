"""Sensor outliers (sim.sensors' module doc): `outlier_rate`, `outlier_size` per sensor.

An outlier is the reading true + bias + noise + s · size · σ (s = ±1, σ that reading's
noise 1σ) before quantisation, at samples chosen by Bernoulli(rate) per channel.  The
draws come from new streams, SeedSequence(seed, spawn_key=(run, 8, j)) with j the
sensor's place in ("earth", "tachometer", "dss", "cass1", "cass2"): one uniform per
channel and sample, u < rate an outlier, u < rate/2 a positive one.

References, none of them the code's output: the outlier positions are recomputed here
from numpy's SeedSequence children directly; counts are checked against the binomial
law (mean N p, standard deviation √(N p (1 − p)), a 5σ band); magnitudes against
size · σ by hand (σ = 0.01° for the Earth sensor, 0.0978/3 rpm for the tachometer,
0.0042° for the DSS, 1°/cos γ for a CASS with γ the true angle off its boresight).
The noise draws are the same with and without outliers (separate streams), so
reading(with) − reading(without) is the outlier alone, up to one quantum of rounding.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace

import numpy as np
import pytest

from scenarios.config import build
from scenarios.config.loader import ScenarioError, load_scenario
from scenarios.config.schema import Scenario
from scenarios.run.simulate import simulate
from scenarios.run.stream.producer import producer
from sim.sensors import NoiseStream, SensorSuite, draw_ahead
from sim.telemetry import make_telemetry, sense_window

DEG = np.pi / 180.0
RPM = 2.0 * np.pi / 60.0
DAY_S = 86400.0
HEADS = ("dss", "cass1", "cass2")
SENSORS = ("earth", "tachometer", *HEADS)   # build.OUTLIER_SENSORS, written out
OUTLIER_KEY = 8                              # past ripple..cass2 (0-5), dispersion 6, disturbance 7


def _bytes_equal(a, b) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    return a.shape == b.shape and a.dtype == b.dtype and a.tobytes() == b.tobytes()


def _arrays(tel) -> dict[str, np.ndarray]:
    return {"roll": tel.roll_rad, "pitch": tel.pitch_rad, "yaw": tel.yaw_rad,
            "yaw_sigma": tel.yaw_sigma_rad, "yaw_head": tel.yaw_head,
            "tach": tel.wheel_speeds_radps, "visible": tel.sun.visible,
            "alpha": tel.sun.alpha_rad, "beta": tel.sun.beta_rad}


def _with(suite: SensorSuite, rate: dict[str, float], size: dict[str, float] | None = None,
          ) -> SensorSuite:
    """``suite`` with outlier rates (and sizes) by sensor name."""
    size = size or {}

    def spec(name, s):
        if name not in rate:
            return s
        return replace(s, outlier_rate=rate[name], outlier_size=size.get(name, s.outlier_size))
    return replace(suite, earth=spec("earth", suite.earth),
                   tachometer=spec("tachometer", suite.tachometer),
                   sun_heads=tuple(spec(h.name, h) for h in suite.sun_heads))


def _uniforms(seed: int, sensor: str, shape, run: int = 0) -> np.ndarray:
    """The sensor's outlier uniforms, from numpy's SeedSequence directly."""
    ss = np.random.SeedSequence(seed, spawn_key=(run, OUTLIER_KEY, SENSORS.index(sensor)))
    return np.random.default_rng(ss).random(shape)


@pytest.fixture(scope="module")
def day():
    """One equinox day (168 750 samples), every torque, the control and the noise on."""
    return simulate(Scenario(name="outliers", duration_s=DAY_S))


# --------------------------------------------------------------- 1. rate 0 changes nothing


def test_rate_zero_is_bit_identical_to_no_key(day):
    """Explicit `outlier_rate: 0` on every sensor gives the very bytes of a scenario
    without the keys, through the scenario and the streamed sensing, and builds the
    default suite."""
    zero = {"outlier_rate": 0.0, "outlier_size": 7.0}
    s = Scenario(name="outliers", duration_s=DAY_S, sensors={
        "earth": zero, "tachometer": zero, "sun": {h: zero for h in HEADS}})
    got = simulate(s)
    for key, arr in _arrays(day.telemetry).items():
        assert _bytes_equal(arr, _arrays(got.telemetry)[key]), key
    for name in ("roll_rad", "pitch_rad", "yaw_rad", "wheel_speeds_radps"):
        assert _bytes_equal(getattr(day.truth, name), getattr(got.truth, name)), name
    assert build.build_sensors(Scenario(name="x", sensors={
        "earth": {"outlier_rate": 0.0}})) == SensorSuite()
    # "As today", independently: roll and pitch are Q(true + 0.01° z) with z numpy's
    # default_rng(SeedSequence(seed, spawn_key=(0, 1))) normals, (N, 2), in the same
    # operations as the sensor, so bit for bit.
    n = len(day.truth.t_s)
    z = np.random.default_rng(np.random.SeedSequence(day.scenario.seed, spawn_key=(0, 1))
                              ).standard_normal((n, 2))
    e = 0.01 * z
    for k, (true, meas) in enumerate(((day.truth.roll_rad, got.telemetry.roll_rad),
                                      (day.truth.pitch_rad, got.telemetry.pitch_rad))):
        want = np.round((true / DEG + e[:, k]) / 0.01) * 0.01 * DEG
        assert _bytes_equal(meas, want), k


def test_rate_zero_draws_nothing_from_the_outlier_streams():
    """With rate 0 the outlier generators are never drawn from (their state stays that
    of a fresh generator), with rate > 0 only the sensor's own one is."""
    rngs = build.streams(5, 0)
    fresh = {n: rngs[n].outliers.bit_generator.state for n in SENSORS}
    draw_ahead(SensorSuite(), rngs, 1000, 2)
    assert all(rngs[n].outliers.bit_generator.state == fresh[n] for n in SENSORS)
    draw_ahead(_with(SensorSuite(), {"cass1": 0.1}), rngs, 1000, 2)
    moved = [n for n in SENSORS if rngs[n].outliers.bit_generator.state != fresh[n]]
    assert moved == ["cass1"]


def test_noise_streams_are_the_plain_generators():
    """A sensor's NoiseStream draws exactly what numpy's default_rng of its SeedSequence
    child (run, i) draws: outliers move no existing stream."""
    for run in (0, 3):
        rngs = build.streams(11, run)
        for i, name in enumerate(("ripple", *SENSORS)):
            want = np.random.default_rng(np.random.SeedSequence(11, spawn_key=(run, i)))
            assert np.array_equal(rngs[name].standard_normal(16), want.standard_normal(16))
            assert isinstance(rngs[name], NoiseStream) == (name != "ripple")


# ------------------------------------------------------------ 2. where and how large


@pytest.fixture(scope="module")
def outlying(day):
    """The same day sensed again with the same seeds, every sensor at rate 0.001; the
    DSS's size is 100 σ = 0.42° (20 σ = 0.084° is under its 0.125° quantum and could
    round away)."""
    rate = {n: 1e-3 for n in SENSORS}
    suite = _with(SensorSuite(), rate, {"dss": 100.0})
    seed = day.scenario.seed
    plain = make_telemetry(day.truth, SensorSuite(), build.streams(seed))
    return suite, plain, make_telemetry(day.truth, suite, build.streams(seed))


def _channels(tel) -> dict[str, np.ndarray]:
    """Each sensor's readings, (N, 2) or (N, n_wheels), in degrees or rpm."""
    out = {"earth": np.column_stack([tel.roll_rad, tel.pitch_rad]) / DEG,
           "tachometer": tel.wheel_speeds_radps / RPM}
    for k, h in enumerate(HEADS):
        out[h] = np.column_stack([tel.sun.alpha_rad[:, k], tel.sun.beta_rad[:, k]]) / DEG
    return out


def _seen(tel, name: str) -> np.ndarray:
    """Samples where the sensor reads anything (a head: where it sees the Sun)."""
    if name in HEADS:
        return tel.sun.visible[:, HEADS.index(name)]
    return np.ones(len(tel.t_s), dtype=bool)


def test_outliers_sit_where_the_seeded_uniforms_say(day, outlying):
    """Every changed reading is an outlier of the hand-seeded stream and every outlier
    (where the sensor reads) changed the reading: u < rate, from SeedSequence(seed,
    spawn_key=(0, 8, j)).  The other readings are bit for bit the plain ones."""
    suite, plain, got = outlying
    seed, n = day.scenario.seed, len(day.truth.t_s)
    a, b = _channels(plain), _channels(got)
    for name in SENSORS:
        u = _uniforms(seed, name, a[name].shape)
        hit = (u < 1e-3) & _seen(plain, name)[:, None]
        changed = ~np.isclose(a[name], b[name], rtol=0, atol=0, equal_nan=True)
        assert np.array_equal(changed, hit), name
        same = ~hit
        assert _bytes_equal(np.where(same, a[name], 0.0), np.where(same, b[name], 0.0)), name
        assert n > 1e5


def test_outlier_count_is_binomial(day, outlying):
    """Over the samples where each sensor reads (168 750 for the Earth sensor and the
    tachometer, per channel; 28 000–56 000 for a head), the outlier count per sensor is
    within 5σ of N p, σ = √(N p (1 − p)), p = 0.001."""
    _, plain, got = outlying
    a, b = _channels(plain), _channels(got)
    p = 1e-3
    for name in SENSORS:
        seen = np.broadcast_to(_seen(plain, name)[:, None], a[name].shape)
        N = int(seen.sum())
        count = int(np.sum((a[name] != b[name]) & seen))
        mean, sd = N * p, np.sqrt(N * p * (1 - p))
        assert N > 5e4, name
        assert abs(count - mean) < 5 * sd, (name, count, mean, sd)


def _sigma(name: str, truth, suite) -> np.ndarray:
    """Each reading's noise 1σ by hand (deg or rpm), (N, 1)."""
    if name == "earth":
        return np.full((len(truth.t_s), 1), 0.01)
    if name == "tachometer":
        return np.full((len(truth.t_s), 1), 0.0978 / 3)
    head = next(h for h in suite.sun_heads if h.name == name)
    if head.kind == "dss":
        return np.full((len(truth.t_s), 1), 0.0042)
    t = head.boresight_hour_angle_deg * DEG
    cos_off = truth.sun_body @ np.array([-np.sin(t), 0.0, -np.cos(t)])
    return (1.0 / cos_off)[:, None]


@pytest.mark.parametrize("name", SENSORS)
def test_outlier_magnitude_is_size_sigma(day, outlying, name):
    """At the outliers, with-outlier − plain is ±size · σ to within one quantum (the two
    readings round the same noisy value shifted by size · σ); both signs appear, about
    equally often (a fair sign: within 5σ of half)."""
    suite, plain, got = outlying
    quantum = {"earth": 0.01, "tachometer": 0.0163, "dss": 0.125, "cass1": 0.039,
               "cass2": 0.039}[name]
    size = 100.0 if name == "dss" else 20.0
    d = _channels(got)[name] - _channels(plain)[name]
    expect = size * np.broadcast_to(_sigma(name, day.truth, suite), d.shape)
    hit = (d != 0) & ~np.isnan(d)
    assert hit.sum() >= 20
    err = np.abs(d[hit]) - expect[hit]
    assert np.max(np.abs(err)) <= quantum * (1 + 1e-9), (name, np.max(np.abs(err)))
    if name in ("cass1", "cass2"):
        assert np.ptp(expect[hit]) > 1.0   # σ really varies off the boresight
    k, n_hit = int(np.sum(d[hit] > 0)), int(hit.sum())
    assert abs(k - n_hit / 2) < 5 * np.sqrt(n_hit) / 2


# ----------------------------------------------------- 3. seeds, sensors, windows


def test_same_seed_reproduces_and_another_seed_moves_the_outliers():
    s = Scenario(name="outliers", duration_s=7200.0, sensors={"earth": {"outlier_rate": 0.01}})
    a, b = simulate(s), simulate(s)
    for key, arr in _arrays(a.telemetry).items():
        assert _bytes_equal(arr, _arrays(b.telemetry)[key]), key
    # Another seed: another outlier pattern (the noise moves too, so compare positions
    # against each seed's plain run).
    pos = []
    for seed in (1, 2):
        plain = simulate(s.model_copy(update={"seed": seed, "sensors": Scenario(
            name="x").sensors}))
        with_ = simulate(s.model_copy(update={"seed": seed}))
        pos.append(np.flatnonzero(plain.telemetry.roll_rad != with_.telemetry.roll_rad))
    assert len(pos[0]) > 30 and len(pos[1]) > 30
    assert len(np.intersect1d(pos[0], pos[1])) < 5


def test_sensors_draw_outliers_independently(day):
    """Changing one sensor's outliers changes no other sensor's output; at rate 0.5 on
    two sensors the joint outlier frequency is the product of the marginals (within
    5σ of 0.25), as it would not be if they shared a stream."""
    seed = day.scenario.seed
    base = make_telemetry(day.truth, _with(SensorSuite(), {"earth": 0.01}),
                          build.streams(seed))
    other = make_telemetry(day.truth, _with(SensorSuite(), {"earth": 0.02}),
                           build.streams(seed))
    for key in ("tach", "alpha", "beta", "visible"):
        assert _bytes_equal(_arrays(base)[key], _arrays(other)[key]), key
    assert not np.array_equal(base.roll_rad, other.roll_rad)

    plain = make_telemetry(day.truth, SensorSuite(), build.streams(seed))
    half = make_telemetry(day.truth, _with(SensorSuite(), {"earth": 0.5, "tachometer": 0.5}),
                          build.streams(seed))
    e = half.roll_rad != plain.roll_rad
    t = half.wheel_speeds_radps[:, 0] != plain.wheel_speeds_radps[:, 0]
    n = len(e)
    joint = np.mean(e & t)
    assert abs(np.mean(e) - 0.5) < 5 * 0.5 / np.sqrt(n)
    assert abs(joint - 0.25) < 5 * np.sqrt(0.25 * 0.75 / n), joint


def _scenario_with_outliers(duration_s: float) -> Scenario:
    rate = {"outlier_rate": 0.002}
    return Scenario(name="outliers", duration_s=duration_s, sensors={
        "earth": rate, "tachometer": rate, "sun": {h: rate for h in HEADS}})


def test_windows_do_not_move_the_draws():
    """The streamed sensing (``sense_window``, the producer's) of one whole window, of
    two windows and of three uneven ones gives the same bytes, and so does sensing the
    whole truth with the generators directly (the whole-array twin's path): the draws
    never depend on how the samples are split."""
    s = _scenario_with_outliers(4 * 3600.0)
    suite = build.build_sensors(s)
    got = []
    with ThreadPoolExecutor(1) as pool:
        for cuts in ((0, None), (0, 7000, None), (0, 1, 9999, None)):
            rngs = build.streams(s.seed, 0)
            stream = build.truth_stream(s, rngs.pop("ripple"))
            cuts = [stream.n_samples if c is None else c for c in cuts]
            parts = [sense_window(stream, a, b, suite, rngs, pool)
                     for a, b in zip(cuts[:-1], cuts[1:], strict=False)]
            got.append({k: np.concatenate([_arrays(p[1])[k] for p in parts])
                        for k in _arrays(parts[0][1])})
            if len(parts) == 1:
                direct = _arrays(make_telemetry(parts[0][0], suite, build.streams(s.seed, 0)))
    for other in (*got[1:], direct):
        for key, arr in got[0].items():
            assert _bytes_equal(arr, other[key]), key
    # And outliers did happen.
    plain = simulate(s.model_copy(update={"sensors": Scenario(name="x").sensors}))
    assert np.sum(plain.telemetry.roll_rad != got[0]["roll"]) > 10
    assert np.sum(plain.telemetry.wheel_speeds_radps != got[0]["tach"]) > 10


def test_the_producers_window_size_does_not_move_the_telemetry():
    """`dynprop run`'s producer with 1000-sample windows and with one window: the
    telemetry the filter reads (roll, yaw, wheel speeds) is the same bytes."""
    s = _scenario_with_outliers(2 * 3600.0)

    def measured(window_samples):
        rows = [rec.measured for tag, rec in
                (item for item in producer(s, 0, window_samples) if isinstance(item, tuple))
                if tag == "real"]
        return [np.concatenate([getattr(m, f) for m in rows])
                for f in ("roll_rad", "yaw_rad", "speeds_radps")]
    whole, windowed = measured(None), measured(1000)
    for a, b in zip(whole, windowed, strict=True):
        assert _bytes_equal(a, b)


# ------------------------------------------------------------------- 4. validation


@pytest.mark.parametrize("key, value", [
    ("sensors.earth.outlier_rate", "1.5"), ("sensors.earth.outlier_rate", "-0.1"),
    ("sensors.tachometer.outlier_size", "-1"), ("sensors.sun.cass2.outlier_rate", "2"),
])
def test_bad_outlier_keys_give_one_line_naming_the_key(key, value):
    with pytest.raises(ScenarioError) as err:
        load_scenario("goes_next_equinox", [f"{key}={value}"])
    text = str(err.value)
    assert text.startswith(key) and "\n" not in text, text
