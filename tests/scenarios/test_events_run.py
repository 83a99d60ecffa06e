"""Events through `dynprop run` and back through the telemetry readers.

40 minutes of goes_next_equinox flown twice with the same seed: with events (an Earth,
a Sun and a tachometer outage, then a thruster firing and a tab command) and without.
Until the firing the two runs fly the same truth and draw the same noise, so
telemetry.csv must be the run without events' except that each outage's columns are
empty on exactly its samples (t0 ≤ t < t0 + duration, counted here by hand) and
nowhere else; the maneuver column is 1 on exactly the firing's samples; truth.csv
records the firing as its own torque.  The file readers, whole and in blocks, read
the flag back into ``records.Measured``, and screen a flag that is neither 0 nor 1."""

from __future__ import annotations

import contextlib
import io
import json

import numpy as np
import pytest

from scenarios.bridge.coordinates import truth_torques
from scenarios.bridge.inputs import telemetry_inputs
from scenarios.bridge.twin import linear_twin
from scenarios.cli import main
from scenarios.config.loader import load_scenario
from scenarios.files.csvio import read_csv
from scenarios.files.telemetry_file import read_screened
from scenarios.files.telemetry_source import open_source
from scenarios.run.simulate import simulate

DT = 0.512
EARTH, SUN, TACH = (600.1, 300.0), (200.0, 400.0), (1000.0, 100.0)
FIRE, TORQUE = (1500.0, 200.0), (2e-3, 0.0, -1e-3)
EVENTS = f"""\
events:
  - {{kind: sensor_outage, time_s: {EARTH[0]}, duration_s: {EARTH[1]}, sensor: earth}}
  - {{kind: sensor_outage, time_utc: "2026-03-20T12:03:20Z", duration_s: {SUN[1]}, sensor: sun}}
  - {{kind: sensor_outage, time_s: {TACH[0]}, duration_s: {TACH[1]}, sensor: tachometer}}
  - {{kind: thruster, time_s: {FIRE[0]}, duration_s: {FIRE[1]}, torque_Nm: {list(TORQUE)},
     label: momentum dump}}
  - {{kind: trim_tab, time_s: 2200, angle_deg: 19.0}}
"""
COLUMNS = {"earth": ("roll_deg", "pitch_deg"),
           "sun": ("yaw_deg", "yaw_sigma_deg", "sun_head", "dss_alpha_deg", "dss_beta_deg",
                   "cass1_alpha_deg", "cass1_beta_deg", "cass2_alpha_deg", "cass2_beta_deg"),
           "tachometer": ("wheel1_rpm", "wheel2_rpm")}
SPANS = {"earth": EARTH, "sun": SUN, "tachometer": TACH}


def _inside(t: np.ndarray, span: tuple[float, float]) -> np.ndarray:
    return (t >= span[0]) & (t < span[0] + span[1])


def _run(tmp, name: str, events: str):
    path = tmp / f"{name}.yaml"
    path.write_text(f"name: {name}\nduration_s: 2400\n{events}")
    out = tmp / name
    err = io.StringIO()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
        assert main(["run", str(path), "--out", str(out)]) == 0, err.getvalue()
    return out


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("events")
    return _run(tmp, "with_events", EVENTS), _run(tmp, "without", "")


def test_outages_empty_their_columns_on_exactly_their_samples(runs):
    with_ev, without = (read_csv(r / "telemetry.csv") for r in runs)
    t = without["t_s"]
    assert np.array_equal(with_ev["t_s"], t) and len(t) == 4688
    before = t < FIRE[0]        # the same truth and noise until the firing
    out_any = np.zeros(len(t), dtype=bool)
    for sensor, names in COLUMNS.items():
        out = _inside(t, SPANS[sensor])
        out_any |= out
        assert out.sum() > 100
        for name in names:
            a, b = with_ev[name], without[name]
            assert np.all(np.isnan(a[out])), (sensor, name)
            keep = before & ~out
            assert np.array_equal(a[keep], b[keep], equal_nan=True), (sensor, name)
        # The run without the outage did read there: the blanking is the outage's.
        assert np.isfinite(without[names[0]][out]).any(), sensor
    for name in set(without) - {n for names in COLUMNS.values() for n in names}:
        a, b = with_ev[name][before], without[name][before]
        assert np.array_equal(a, b, equal_nan=a.dtype.kind == "f"), name


def test_maneuver_column_is_the_firing_and_only_with_events(runs):
    with_ev, without = (read_csv(r / "telemetry.csv") for r in runs)
    assert "maneuver" not in without
    assert np.array_equal(with_ev["maneuver"], _inside(with_ev["t_s"], FIRE).astype(float))
    assert with_ev["maneuver"].sum() == 391     # samples 2930 (1500.16 s) … 3320


def test_truth_records_the_firing_as_its_own_torque(runs):
    with_ev, without = (read_csv(r / "truth.csv") for r in runs)
    assert not any(c.startswith("thruster_") for c in without)
    inside = _inside(with_ev["t_s"], FIRE)
    assert inside.sum() == 3          # the 64 s rows at 1536, 1600 and 1664 s
    for k, axis in enumerate("xyz"):
        col = with_ev[f"thruster_{axis}_Nm"]
        assert np.all(col[inside] == TORQUE[k]) and not col[~inside].any()


def test_summary_lists_the_events(runs):
    summary = json.loads((runs[0] / "summary.json").read_text())
    assert [(e["kind"], e["t_s"], e["end_s"]) for e in summary["events"]] == [
        ("sensor_outage", 200.0, 600.0), ("sensor_outage", 600.1, 900.1),
        ("sensor_outage", 1000.0, 1100.0), ("thruster", 1500.0, 1700.0),
        ("trim_tab", 2200.0, 2200.0)]
    assert summary["events"][3]["label"] == "momentum dump"
    assert "events" not in json.loads((runs[1] / "summary.json").read_text())


def test_the_twin_is_out_when_the_truth_is(runs):
    """The linear twin's telemetry (its filter's input) has the same outages and flag."""
    s = load_scenario(runs[0] / "scenario.yaml", ["duration_s=2300"])
    sim = simulate(s)
    tt = truth_torques(sim.truth, s.estimator.model_torques, 7.2921e-5)
    _, twin_tel, _ = linear_twin(s, sim.truth, 0, s.estimator.model_torques, tt)
    t = twin_tel.t_s
    earth, tach, sun = (_inside(t, SPANS[k]) for k in ("earth", "tachometer", "sun"))
    assert np.all(np.isnan(twin_tel.roll_rad[earth]))
    assert np.isfinite(twin_tel.roll_rad[~earth]).all()
    assert np.all(np.isnan(twin_tel.wheel_speeds_radps[tach]))
    assert np.isfinite(twin_tel.wheel_speeds_radps[~tach]).all()
    assert np.all(np.isnan(twin_tel.yaw_rad[sun])) and np.all(twin_tel.yaw_head[sun] == -1)
    assert np.array_equal(twin_tel.maneuver, _inside(t, FIRE).astype(float))


def test_readers_carry_the_flag_into_measured(runs, tmp_path):
    """`dynprop estimate`'s readers, whole and in blocks, read the flag; a run without
    events has none (Measured.maneuver None)."""
    s = load_scenario(runs[0] / "scenario.yaml")
    path = runs[0] / "telemetry.csv"
    cols, report = read_screened(path, s)
    flag = _inside(cols["t_s"], FIRE).astype(float)
    assert np.array_equal(cols["maneuver"], flag) and report.count == 0
    assert np.array_equal(telemetry_inputs(s, cols).maneuver, flag)
    spool = open_source(path, s, tmp_path, block_rows=97)
    assert np.array_equal(spool.columns(0, spool.n)["maneuver"], flag)
    plain = load_scenario(runs[1] / "scenario.yaml")
    assert telemetry_inputs(plain, read_screened(runs[1] / "telemetry.csv", plain)[0]) \
        .maneuver is None


def test_a_flag_neither_0_nor_1_is_screened_and_counted(runs, tmp_path):
    s = load_scenario(runs[0] / "scenario.yaml")
    lines = (runs[0] / "telemetry.csv").read_text().splitlines(keepends=True)
    j = lines[1].rstrip("\n").split(",").index("maneuver")

    def edit(row: int, text: str) -> None:
        cells = lines[row + 2].rstrip("\n").split(",")
        cells[j] = text
        lines[row + 2] = ",".join(cells) + "\n"
    edit(10, "2")
    edit(20, "0.5")
    edit(30, "nan")
    bad = tmp_path / "bad.csv"
    bad.write_text("".join(lines))
    cols, report = read_screened(bad, s)
    spool = open_source(bad, s, tmp_path, block_rows=7)
    for summary, values in ((report.summary(), cols["maneuver"]),
                            (spool.screen.summary(), spool.columns(0, spool.n)["maneuver"])):
        reasons = summary["columns"]["maneuver"]["reasons"]
        assert reasons["flag"]["count"] == 2 and reasons["flag"]["first_rows"] == [12, 22]
        assert reasons["non-finite"]["count"] == 1
        assert np.isnan(values[[10, 20, 30]]).all()
        assert np.isfinite(np.delete(values, [10, 20, 30])).all()


@pytest.mark.surface
def test_estimate_reads_a_telemetry_file_with_the_flag(runs, tmp_path):
    err = io.StringIO()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
        rc = main(["estimate", "--scenario", str(runs[0] / "scenario.yaml"),
                   str(runs[0] / "telemetry.csv"), "--out", str(tmp_path / "est")])
    assert rc == 0, err.getvalue()
