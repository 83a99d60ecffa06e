"""`dynprop trim` on simulated telemetry: κ̂ against the κ the truth flies (noise-free
and noisy), the known torques against the truth's own, a magnetic torque at the
orbit rate that must not pass for solar, the bundled mistrimmed case end to end
with --verify, and bad batches."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml

from scenarios.config.loader import load_scenario
from scenarios.files.columns import telemetry_columns
from scenarios.run.simulate import simulate
from scenarios.trim.batch import (
    choose_batch,
    estimate_kappa,
    known_torques,
    solar_unit_torque,
    true_kappa_Nm,
)

from .test_cli_run import run_cli

DAY = 86400.0
MISTRIM = "environment.solar.trim_tab_deg=16"   # κ = 5e-5 − 2.5e-6 · 16 = +1e-5 N m
# A commanded dipole at the orbit period, x and z: a magnetic roll/yaw torque of
# ~5e-7 N m turning at the orbit rate, the shape of a solar torque.
MAGNETIC_ONLY = ("environment.solar.enabled=false",
                 "environment.magnetic.profile_amplitude_Am2=[5, 0, 5]")


def _kappa(overrides, days=1.0, to_s=None):
    s = load_scenario("goes_next_equinox", [*overrides, f"duration_s={days * DAY}"])
    sim = simulate(s)
    cols = telemetry_columns(sim.telemetry, sim.suite)
    r = estimate_kappa(s, cols, choose_batch(cols["t_s"], s.sample_interval_s, None, to_s))
    return s, sim, r


@pytest.mark.parametrize("noise", ["true", "false"])
def test_kappa_matches_the_flown_imbalance(noise):
    s, _, r = _kappa([MISTRIM, f"sensors.noise.enabled={noise}"])
    k = true_kappa_Nm(s)
    assert k == pytest.approx(1e-5)
    assert abs(r.fit.kappa_Nm - k) <= 3 * r.fit.sigma_Nm
    # One day: σ ≈ 1e-7 N m, and the error well inside 1% of κ.
    assert r.fit.sigma_Nm < 1.5e-7
    assert abs(r.fit.kappa_Nm - k) < 0.01 * k
    assert r.rec.move and r.rec.trim_tab_deg_new == pytest.approx(20.0, abs=3 * r.rec.sigma_deg)


def test_known_torques_are_the_truths_torquer_profile_and_gravity_gradient():
    s = load_scenario("goes_next_equinox", [MISTRIM, "duration_s=21600",
                                            "environment.magnetic.profile_amplitude_Am2=[2, 0, 2]"])
    sim = simulate(s)
    tr, cols = sim.truth, telemetry_columns(sim.telemetry, sim.suite)
    speeds = np.column_stack([cols["wheel1_rpm"], cols["wheel2_rpm"]]) * np.pi / 30
    got = known_torques(s, cols["t_s"], speeds, np.radians(cols["roll_deg"]),
                        np.radians(cols["pitch_deg"]))
    # The truth's torquer and gravity gradient, and the profile's torque: its magnetic
    # torque less that of the same run without the profile (the residual dipole's).
    s0 = load_scenario("goes_next_equinox", [MISTRIM, "duration_s=21600"])
    tr0 = simulate(s0).truth
    profile = tr.torques["magnetic"] - tr0.torques["magnetic"]
    want = (tr.torques["magnetic_control"] + tr.torques["gravity_gradient"] + profile)[:, [0, 2]]
    # Five-minute means, as the filter integrates them: the measured roll's white
    # noise (0.01°, 7e-9 N m of gravity gradient) averages out; what is left is
    # Earth pointing in place of the true attitude, a percent of torques of ~1e-6 N m.
    k = len(got) // 586 * 586

    def means(a):
        return a[:k].reshape(-1, 586, 2).mean(axis=1)
    rms = np.sqrt(np.mean(means(want) ** 2, axis=0))
    err = np.sqrt(np.mean((means(got) - means(want)) ** 2, axis=0))
    assert np.all(err < 0.02 * rms), (err, rms)


def test_the_solar_shape_times_kappa_is_the_truths_solar_torque():
    s, sim, r = _kappa([MISTRIM], days=0.5, to_s=0.5 * DAY)
    t, shape, _ = solar_unit_torque(s, r.batch, every=1)
    solar = sim.truth.torques["solar"][:len(t)][:, [0, 2]]
    # Earth pointing in place of the true attitude (a few tenths of a degree here).
    err = np.sqrt(np.mean((true_kappa_Nm(s) * shape - solar) ** 2))
    assert err < 0.01 * np.sqrt(np.mean(solar**2))


def test_a_magnetic_torque_at_the_orbit_rate_is_not_taken_for_solar():
    _, sim, r = _kappa(MAGNETIC_ONLY)
    magnetic = sim.truth.torques["magnetic"][:, [0, 2]]
    assert np.ptp(magnetic) > 5e-7      # the disturbance this guards against is there
    assert abs(r.fit.kappa_Nm) <= 3 * r.fit.sigma_Nm
    assert abs(r.fit.kappa_Nm) < 3e-7
    assert not r.rec.move


@pytest.fixture(scope="module")
def mistrimmed(tmp_path_factory) -> tuple[Path, dict, str]:
    """The bundled case, as the issue runs it: two days, then trim --verify."""
    out = tmp_path_factory.mktemp("trim") / "run"
    rc, _, err = run_cli("run", "goes_next_mistrimmed", "--out", str(out))
    assert rc == 0, err
    rc, stdout, err = run_cli("trim", str(out), "--verify")
    assert rc == 0, err
    return out, json.loads((out / "trim" / "trim.json").read_text()), stdout


def test_mistrimmed_recommends_full_trim_within_3_sigma_of_under_0_1_deg(mistrimmed):
    out, d, stdout = mistrimmed
    rec, truth = d["recommendation"], d["truth"]
    assert truth["full_trim_tab_deg"] == pytest.approx(20.0)
    assert abs(rec["trim_tab_deg_new"] - truth["full_trim_tab_deg"]) <= 3 * rec["sigma_deg"]
    assert rec["sigma_deg"] <= 0.1
    assert d["kappa_sigma_Nm"] <= 2.5e-7
    assert {p.name for p in (out / "trim").iterdir()} == {"trim.json", "trim.md", "trim.png",
                                                           "verify"}
    assert "move the tab 16.000 -> 20.0" in stdout


def test_verify_shows_the_residual_falling_20_times(mistrimmed):
    _, d, _ = mistrimmed
    v = d["verify"]
    assert v["before"]["kappa_true_Nm"] == pytest.approx(1e-5)
    assert v["residual_fall"] >= 20
    # The filter's periodic torque state follows the imbalance down.
    assert v["after"]["periodic_Nm"] < v["before"]["periodic_Nm"] / 20
    assert abs(v["after"]["kappa_Nm"]) <= 3 * v["after"]["kappa_sigma_Nm"] + \
        abs(v["after"]["kappa_true_Nm"])


def test_a_short_batch_and_one_with_no_sunlit_time_exit_2(mistrimmed, capsys):
    out, _, _ = mistrimmed
    before = (out / "trim" / "trim.json").read_bytes()
    rc, stdout, err = run_cli("trim", str(out), "--to-s", "10000")
    assert rc == 2 and stdout == ""
    assert err.count("\n") == 1 and "shorter than a quarter orbit" in err
    # 16.8–17.5 h after 12:00 UTC on the equinox the satellite is in the Earth's shadow.
    rc, _, err = run_cli("trim", str(out), "--from-s", "60480", "--to-s", "63000")
    assert rc == 2
    assert err.count("\n") == 2 and "no sunlit time" in err
    rc, _, err = run_cli("trim", str(out.parent / "nowhere"))
    assert rc == 2 and err.count("\n") == 1
    assert (out / "trim" / "trim.json").read_bytes() == before   # nothing was touched


def test_trim_on_jittered_telemetry_with_a_gap_recommends_the_tab_and_reads_columns(
        mistrimmed, tmp_path):
    """The mistrimmed run's telemetry as a ground system might deliver it: 1.0 s ± 20 ms
    tags, a 2 h gap (``resample``: the sample nearest each tag), the roll column named
    ES_ROLL and the wheels in rad/s, read with `estimate`'s --column and --unit (before
    issue 43 trim had neither, and refused the file: "needs telemetry on the scenario's
    grid").  Beside a copy of the run's scenario.yaml only (no truth), `trim` steps
    each sample over its own interval and recommends a tab within its 3σ of the full
    trim the scenario's own tab law gives, untrimmed / effectiveness = 5e-5 / 2.5e-6 =
    20° (read from the YAML here, not from trim.json); σ stays near the grid's 0.03°.
    Measured 19.9997° ± 0.030°.  ~3 s compiled."""
    from .resample import resample
    out, _, _ = mistrimmed
    run = tmp_path / "run"
    run.mkdir()
    shutil.copy(out / "scenario.yaml", run)
    cols = resample(out / "telemetry.csv", tmp_path / "j.csv", gap=(100800.0, 108000.0))
    text = (tmp_path / "j.csv").read_text().splitlines()
    header = text[0].split(",")
    assert header[1] == "roll_deg" and header[4:6] == ["wheel1_rpm", "wheel2_rpm"]
    header[1] = "ES_ROLL"
    rows = [line.split(",") for line in text[1:]]
    for r in rows:   # the wheels in rad/s
        for j in (4, 5):
            r[j] = repr(float(r[j]) * np.pi / 30)
    (tmp_path / "renamed.csv").write_text("\n".join(
        [",".join(header), *(",".join(r) for r in rows)]) + "\n")
    rc, stdout, err = run_cli("trim", str(run), "--telemetry", str(tmp_path / "renamed.csv"),
                              "--column", "roll=ES_ROLL", "--unit", "wheels=rad/s")
    assert rc == 0, err
    d = json.loads((run / "trim" / "trim.json").read_text())
    solar = yaml.safe_load((out / "scenario.yaml").read_text())["environment"]["solar"]
    full = solar["untrimmed_torque_Nm"] / solar["tab_effectiveness_Nm_per_deg"]
    rec = d["recommendation"]
    assert full == pytest.approx(20.0) and rec["move"]
    assert abs(rec["trim_tab_deg_new"] - full) <= 3 * rec["sigma_deg"], rec
    assert rec["sigma_deg"] <= 0.05
    assert d["truth"] is None
    assert d["batch"]["from_s"] >= cols["t_s"][0] and d["batch"]["to_s"] <= cols["t_s"][-1]


def test_every_trim_json_key_is_documented(mistrimmed):
    from .test_outputs_doc import _spans, json_keys, undocumented
    _, d, _ = mistrimmed
    assert d["verify"] is not None
    assert not undocumented(sorted(json_keys(d)), _spans())


@pytest.mark.surface
def test_the_trim_page_shows_each_number_with_its_documented_unit(mistrimmed, tmp_path):
    """`dynprop report` on the trim directory: every number that names trim.json is
    the file's (test_report.check_numbers), and each row of a key, its value and its
    unit shows the unit docs/outputs.md gives the key's innermost documented name:
    the tab effectiveness, the scenario's own 2.5e-6, in N m/° (a suffix rule taken
    after ``_deg`` showed it in °), κ̂ and the torques in N m, the tab in °."""
    from .test_report import check_numbers
    from .test_report_units import UNIT_NOT_IN_NAME, documented_units, innermost_name, shown_units
    out, d, _ = mistrimmed
    # A copy (trim/ and the run's scenario.yaml above it): the other tests read trim/.
    page = tmp_path / "trim"
    shutil.copytree(out / "trim", page)
    shutil.copy(out / "scenario.yaml", tmp_path)
    rc, _, err = run_cli("report", str(page))
    assert rc == 0, err
    assert check_numbers(page / "report.html") > 20
    shown = shown_units(page / "report.html")
    key = "recommendation.tab_effectiveness_Nm_per_deg"
    scenario = yaml.safe_load((out / "scenario.yaml").read_text())
    assert d["recommendation"]["tab_effectiveness_Nm_per_deg"] == \
        scenario["environment"]["solar"]["tab_effectiveness_Nm_per_deg"]
    assert shown[key] == "N m/°"
    documented = documented_units()
    checked = {k: (unit, documented[innermost_name(k)]) for k, unit in shown.items()
               if innermost_name(k) in documented and innermost_name(k) not in UNIT_NOT_IN_NAME}
    assert {key, "recommendation.sigma_deg", "recommendation.residual_after_Nm",
            "out_of_phase.amplitude_Nm", "truth.kappa_Nm"} <= set(checked)
    assert {k: v for k, v in checked.items() if v[0] != v[1]} == {}
