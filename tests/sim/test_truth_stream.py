"""The truth a window at a time (``TruthStream``): identity with the whole run is the
requirement, on one machine.  Windows of uneven lengths (1 sample, less than a
chunk, more than a chunk, across the eclipse and the Sun-node and shadow-grid
boundaries) concatenate to the very arrays one window gives, and so does their
telemetry with the generators carried along."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from datetime import UTC, datetime

import numpy as np
import pytest

from sim.control import Control
from sim.environment import Environment
from sim.frames import GeoOrbit
from sim.history import OPTIONAL_TORQUES, TORQUE_SOURCES
from sim.sensors import SensorSuite, draw_ahead, drawn_rows
from sim.spacecraft import goes_next
from sim.telemetry import TelemetryRows, make_telemetry
from sim.truth import InitialState, TruthResult, TruthStream

# 03:30 UTC on the equinox: local midnight at 75° W (the eclipse, ~70 min) falls
# 1.5 h into the 3 h run.
EPOCH = datetime(2026, 3, 20, 3, 30, 0, tzinfo=UTC)
CUTS = [1, 1000, 1063, 5160, 9000, 9001, 14000]   # window ends before the run's end


def _stream(rng_seed=1):
    return TruthStream(goes_next(), GeoOrbit(), Environment(), Control(),
                       InitialState(yaw_rad=1e-3, roll_rad=5e-4), EPOCH, 3 * 3600.0,
                       rng=np.random.default_rng(rng_seed))


def _concat(parts: list[TruthResult]) -> TruthResult:
    kw = {}
    for f in dataclasses.fields(TruthResult):
        v = [getattr(p, f.name) for p in parts]
        if f.name == "torques":
            kw[f.name] = {k: np.concatenate([p[k] for p in v]) for k in v[0]}
        elif f.name == "final_state":
            kw[f.name] = v[-1]
        elif isinstance(v[0], np.ndarray):
            kw[f.name] = np.concatenate(v)
        else:
            kw[f.name] = v[0]
    return TruthResult(**kw)


def _equal_fields(a, b) -> list[str]:
    bad = []
    for f in dataclasses.fields(a):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if isinstance(x, Mapping):
            bad += [k for k in x if not np.array_equal(x[k], y[k])]
        elif isinstance(x, np.ndarray) and not np.array_equal(x, y, equal_nan=True):
            bad.append(f.name)
        elif dataclasses.is_dataclass(x):
            bad += _equal_fields(x, y)
    return bad


@pytest.fixture(scope="module")
def whole_and_windows():
    whole_stream = _stream()
    whole = whole_stream.window(0, whole_stream.n_samples)
    stream = _stream()
    bounds = [0, *CUTS, stream.n_samples]
    parts = [stream.window(a, b) for a, b in zip(bounds[:-1], bounds[1:], strict=True)]
    return whole, parts


def test_windows_concatenate_to_the_whole_run(whole_and_windows):
    whole, parts = whole_and_windows
    assert np.any(whole.shadow < 1.0) and np.any(whole.shadow == 0.0)   # umbra inside
    assert _equal_fields(whole, _concat(parts)) == []


def test_telemetry_of_the_windows_is_the_whole_runs(whole_and_windows):
    whole, parts = whole_and_windows
    suite = SensorSuite()

    def rngs():
        return {name: np.random.default_rng(k) for k, name in enumerate(suite.stream_names())}

    one = make_telemetry(whole, suite, rngs())
    carried = rngs()
    pieces = [make_telemetry(p, suite, carried) for p in parts]
    _assert_same_telemetry(one, pieces)
    # Drawn ahead a window at a time (stream.producer, in a thread), and read a
    # second time by another sensing of the same window (the linear twin's).
    carried = rngs()
    ahead = [draw_ahead(suite, carried, len(p.t_s), 2) for p in parts]
    for _ in range(2):
        _assert_same_telemetry(one, [make_telemetry(p, suite, d)
                                     for p, d in zip(parts, ahead, strict=True)])


def test_drawn_normals_must_match_the_sensor():
    suite = SensorSuite()
    drawn = draw_ahead(suite, {n: np.random.default_rng(0) for n in suite.stream_names()},
                       10, 2)
    with pytest.raises(ValueError, match="drawn"):
        drawn["earth"].standard_normal((11, 2))


def test_torques_on_chosen_rows_are_the_whole_arrays_rows():
    """The wheel reactions are formed only when read (truth.csv's rows)."""
    whole = _stream().window(0, 3000)
    rows = np.arange(3, len(whole.t_s), 125)
    picked = whole.torques.rows(rows)   # before anything formed the whole reactions
    # No disturbance in this run: the sources that are always there.
    always = [s for s in TORQUE_SOURCES if s not in OPTIONAL_TORQUES]
    assert list(picked) == list(whole.torques) == always
    for name in whole.torques:
        assert np.array_equal(picked[name], whole.torques[name][rows]), name
    assert np.any(picked["wheel_control"] != 0) and np.any(picked["wheel_ripple"] != 0)


def _assert_same_telemetry(one, pieces):
    for f in dataclasses.fields(one):
        x = getattr(one, f.name)
        if dataclasses.is_dataclass(x):
            for g in dataclasses.fields(x):
                y = np.concatenate([getattr(getattr(p, f.name), g.name) for p in pieces])
                assert np.array_equal(getattr(x, g.name), y, equal_nan=True), g.name
        elif x is None:     # the maneuver flag of a run without events
            assert all(getattr(p, f.name) is None for p in pieces), f.name
        else:
            y = np.concatenate([getattr(p, f.name) for p in pieces])
            assert np.array_equal(x, y, equal_nan=True), f.name


def test_windows_must_be_contiguous():
    stream = _stream()
    stream.window(0, 10)
    with pytest.raises(ValueError, match="contiguous"):
        stream.window(11, 20)
    with pytest.raises(ValueError, match="contiguous"):
        stream.window(10, stream.n_samples + 1)


def test_sensing_behind_the_rollout_gives_the_whole_runs_truth_and_telemetry(whole_and_windows):
    """``window(sense=...)``: inputs formed a piece at a time, rolled out in a second
    thread, each piece sensed as it is done; pieces of 1063 samples (not a multiple
    of the chunk) cross the eclipse and the Sun-node and shadow-grid boundaries."""
    whole, _ = whole_and_windows
    suite = SensorSuite()

    def rngs():
        return {name: np.random.default_rng(k) for k, name in enumerate(suite.stream_names())}
    carried = rngs()
    stream = _stream()
    spans = []
    # Also sensed a second time, from the same draws made ahead, straight into the
    # window's arrays (sense_window's way): uninitialised memory must not show through.
    n_wheels = stream.spacecraft.n_wheels
    drawn = draw_ahead(suite, rngs(), stream.n_samples, n_wheels)
    gathered = TelemetryRows(stream.n_samples, len(suite.sun_heads), n_wheels)
    for a in (gathered.window.roll_rad, gathered.window.sun.alpha_rad):
        a.fill(7.0)

    def sense(rows, lo, hi):
        spans.append((lo, hi))
        assert np.array_equal(rows.t_s, whole.t_s[lo:hi])
        into = gathered.rows(lo, hi)
        assert make_telemetry(rows, suite, drawn_rows(drawn, lo, hi), out=into) is into
        return make_telemetry(rows, suite, carried)
    truth, pieces = stream.window(0, stream.n_samples, sense=sense, piece=1063)
    assert _equal_fields(whole, truth) == []
    assert spans[0] == (0, 1063) and spans[-1][1] == stream.n_samples
    one = make_telemetry(whole, suite, rngs())
    _assert_same_telemetry(one, pieces)
    _assert_same_telemetry(one, [gathered.telemetry()])
    assert stream.next_start == stream.n_samples


def test_an_unstable_loop_stops_the_sensing_and_says_when():
    """Positive feedback on h diverges at 12.8 s: the pieces before it are sensed,
    none after, and the error names the same time as without sensing."""
    def stream():
        return TruthStream(goes_next(), GeoOrbit(), Environment(),
                           Control(yaw_momentum_gain_per_s=5.0), InitialState(yaw_rad=1e-3),
                           EPOCH, 3600.0, rng=np.random.default_rng(1))
    with pytest.raises(FloatingPointError) as plain:
        stream().window(0, 7032)
    seen = []
    with pytest.raises(FloatingPointError) as piecewise:
        stream().window(0, 7032, sense=lambda rows, lo, hi: seen.append(
            np.all(np.isfinite(rows.q_br)) and np.all(np.isfinite(rows.w_bn_radps))), piece=10)
    assert "non-finite at t = 12.8 s" in str(plain.value)
    assert str(piecewise.value) == str(plain.value)
    assert len(seen) == 2 and all(seen)   # samples 0-19 sensed, nothing non-finite


def test_an_error_in_the_sensing_comes_out():
    stream = _stream()

    def sense(rows, lo, hi):
        raise RuntimeError("sensor model broke")
    with pytest.raises(RuntimeError, match="sensor model broke"):
        stream.window(0, 5000, sense=sense, piece=1000)
