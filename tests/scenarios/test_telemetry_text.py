"""telemetry.csv reads like telemetry: every number is the shortest text that reads
back to the same double, and a quantised reading is its decimal (5485.0967 rpm,
not 5485.0967000000001 or 5485.096699999999)."""

from __future__ import annotations

from decimal import Decimal

import numpy as np
import pytest

from scenarios.cli import main
from scenarios.config.loader import load_scenario
from scenarios.files.columns import RAD2DEG, RADPS2RPM, as_decimal_reading, decimals_of
from scenarios.files.csvio import read_csv, write_csv
from scenarios.run.simulate import simulate


@pytest.fixture(scope="module")
def one_day(tmp_path_factory):
    """A day of the default scenario: every Sun head sees the Sun at some time, and
    the Sun gap leaves yaw empty."""
    out = tmp_path_factory.mktemp("tel") / "run"
    argv = ["simulate", "goes_next_equinox", "--duration-s", "86400", "--out", str(out)]
    assert main(argv) == 0
    return out


@pytest.fixture(scope="module")
def fields(one_day):
    """Column names and the rows of telemetry.csv as text fields."""
    lines = (one_day / "telemetry.csv").read_text().splitlines()[1:]   # after # epoch_utc
    # Numbers only: the last column is time_utc, text (test_telemetry_reader.py).
    assert lines[0].endswith(",time_utc")
    return lines[0].split(",")[:-1], [line.split(",")[:-1] for line in lines[1:]]


def test_every_number_is_the_shortest_round_trip_text(fields):
    names, rows = fields
    checked = 0
    for row in rows[::7]:
        assert len(row) == len(names)
        for text in row:
            if text:
                assert repr(float(text)) == text, text
                checked += 1
    assert checked > 100_000


@pytest.mark.parametrize(("column", "quantum_key"), [
    ("roll_deg", "earth"), ("pitch_deg", "earth"), ("wheel1_rpm", "tachometer"),
    ("wheel2_rpm", "tachometer"), ("dss_beta_deg", "dss"), ("cass1_alpha_deg", "cass1"),
    ("cass2_beta_deg", "cass2")])
def test_quantised_readings_are_whole_quanta_written_as_decimals(one_day, fields, column,
                                                                  quantum_key):
    s = load_scenario(one_day / "scenario.yaml")
    quantum = {"earth": s.sensors.earth.quantum_deg,
               "tachometer": s.sensors.tachometer.quantum_rpm}.get(quantum_key) \
        or getattr(s.sensors.sun, quantum_key).quantum_deg
    names, rows = fields
    k = names.index(column)
    texts = [r[k] for r in rows[::5] if r[k]]
    assert len(texts) > 100, f"{column} never present in the run"
    q = Decimal(repr(quantum))
    for text in texts:
        # Exact decimal arithmetic: the written reading is an integer number of quanta.
        assert (Decimal(text) / q) == (Decimal(text) / q).to_integral_value(), (column, text)


def test_written_readings_differ_from_the_simulated_ones_by_ulps_only(one_day):
    """Writing the decimal moves a reading by rounding only, never by a quantum:
    the filter reads what the sensor model produced."""
    s = load_scenario(one_day / "scenario.yaml")
    sim = simulate(s)
    written = read_csv(one_day / "telemetry.csv")
    for column, values in (("roll_deg", sim.telemetry.roll_rad * RAD2DEG),
                           ("wheel1_rpm", sim.telemetry.wheel_speeds_radps[:, 0] * RADPS2RPM),
                           ("cass1_alpha_deg", sim.telemetry.sun.alpha_rad[:, 1] * RAD2DEG)):
        # Missing readings stay missing, the same samples exactly.
        np.testing.assert_array_equal(np.isnan(written[column]), np.isnan(values))
        ok = ~np.isnan(values)
        # A deg↔rad or rpm↔rad/s round trip costs a few ulps of the value: 1e-14 relative
        # is ~45 ulps, while one quantum is ≥ 1e-6 relative of these readings.
        np.testing.assert_allclose(written[column][ok], values[ok], rtol=1e-14, atol=1e-15)


def test_the_file_is_smaller_than_with_17_digits(fields):
    _, rows = fields
    texts = [t for row in rows[::20] for t in row if t]
    shortest = sum(map(len, texts))
    seventeen = sum(len(f"{float(t):.17g}") for t in texts)
    assert shortest < 0.7 * seventeen, (shortest, seventeen)


def test_as_decimal_reading_gives_the_nearest_double_to_the_decimal():
    q = 0.0163
    counts = np.arange(336_000, 337_000)
    # The sensor model's path: k·q in rpm, to rad/s and back.
    via_rad = (counts * q) * (2 * np.pi / 60) * (60 / (2 * np.pi))
    snapped = as_decimal_reading(via_rad, q)
    expected = np.array([float(Decimal(int(c)) * Decimal("0.0163")) for c in counts])
    np.testing.assert_array_equal(snapped, expected)   # identity: both are one rounding
    assert np.any(via_rad != expected)                  # the artefact this removes
    assert np.isnan(as_decimal_reading(np.array([np.nan]), q)[0])


def test_a_quantum_without_a_short_decimal_leaves_readings_alone():
    """Identity is the requirement: such readings are passed through untouched."""
    assert decimals_of(0.0163) == 4 and decimals_of(0.125) == 3 and decimals_of(1.0) == 0
    assert decimals_of(1 / 3) is None
    x = np.array([1 / 3, 2 / 3])
    np.testing.assert_array_equal(as_decimal_reading(x, 1 / 3), x)


def test_exact_csv_round_trips_any_double(tmp_path):
    rng = np.random.default_rng(5)
    x = rng.normal(size=(500, 4)) * 10.0 ** rng.integers(-300, 300, size=(500, 4))
    x[3, 2] = np.nan
    x[7, 0] = np.nan   # a missing first field
    x[9, 1] = -0.0
    write_csv(tmp_path / "x.csv", {f"c{k}": x[:, k] for k in range(4)}, exact=True)
    back = read_csv(tmp_path / "x.csv")
    y = np.column_stack([back[f"c{k}"] for k in range(4)])
    np.testing.assert_array_equal(y, x)   # identity is the requirement: a re-read
    assert np.signbit(y[9, 1])


def test_looked_up_readings_give_the_same_bytes_as_formatting_each_value():
    """``write_csv(exact=True, lattices=...)`` looks a quantised column's text up per
    reading level: the bytes must be those of formatting every value with repr,
    for readings on the lattice and for everything that is not (−0.0, NaN, ±inf,
    values between levels, a quantum without a short decimal, a column with more
    levels than the table takes, a column with no reading at all)."""
    from scenarios.files.csvio import EXACT_FMT, _format_block
    rng = np.random.default_rng(11)
    n = 4000
    cols, quanta = [], []
    for q in (0.01, 0.0163, 0.125, 0.039, 1.0, 1 / 3):
        v = as_decimal_reading(rng.normal(0, 40 * q, n), q)
        v[rng.random(n) < 0.1] = np.nan
        v[rng.random(n) < 0.05] = -0.0
        v[rng.random(n) < 0.05] = 0.0
        v[rng.random(n) < 0.02] = rng.normal(0, 1, 1)   # off the lattice
        v[:3] = [np.inf, -np.inf, 5 * q + 1e-13]
        cols.append(v)
        quanta.append(q)
    cols.append(as_decimal_reading(rng.uniform(-1e4, 1e4, n), 0.01))   # 2e6 levels
    quanta.append(0.01)
    cols.append(np.full(n, np.nan))
    quanta.append(0.01)
    cols.append(rng.normal(0, 1, n))   # not quantised: no lattice
    quanta.append(None)
    block = np.column_stack(cols)
    plain = _format_block(block, EXACT_FMT)
    assert _format_block(block, EXACT_FMT, tuple(quanta)) == plain
    assert "-0.0" in plain and "inf" in plain
