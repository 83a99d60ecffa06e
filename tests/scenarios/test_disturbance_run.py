"""`environment.disturbance` in scenario runs: its own seeded stream, nothing else
moved by it (a scenario without one flies and writes what it did before), its
truth.csv columns, and `estimate --truth` reading them (the run's errors again)."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml

from scenarios.config import build
from scenarios.config.loader import load_scenario, validate
from scenarios.config.schema import resolved_yaml
from scenarios.files.csvio import read_csv, write_csv
from scenarios.run.simulate import simulate
from scenarios.run.stream.directory import stream_to_directory
from sim.disturbance import draw
from sim.telemetry import make_telemetry

from .test_cli_run import CSV_REL, DT, run_cli, run_dir

SHORT = "duration_s=600"
GM_ON = ["environment.disturbance.kind=gauss_markov", "environment.disturbance.sigma_Nm="
         "[2e-5,1e-5,3e-5]", "environment.disturbance.correlation_time_s=300"]


def _stream_7(seed: int, run: int) -> np.random.Generator:
    """The disturbance's stream as the brief specifies it, spelled out independently of
    ``build``: SeedSequence(seed, spawn_key=(run, 7))."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(run, 7)))


def _same_simulation(a, b) -> None:
    for name in ("t_s", "q_br", "w_bn_radps", "wheel_speeds_radps", "h_Nms", "H_Nms",
                 "shadow", "final_state"):
        assert np.array_equal(getattr(a.truth, name), getattr(b.truth, name)), name
    assert list(a.truth.torques) == list(b.truth.torques)
    for name in a.truth.torques:
        assert np.array_equal(a.truth.torques[name], b.truth.torques[name]), name
    for name in ("roll_rad", "pitch_rad", "yaw_rad", "wheel_speeds_radps"):
        assert np.array_equal(getattr(a.telemetry, name), getattr(b.telemetry, name),
                              equal_nan=True), name


@pytest.fixture(scope="module")
def plain():
    return simulate(load_scenario("goes_next_equinox", [SHORT]))


def test_kind_none_flies_and_writes_what_a_scenario_without_the_key_does(plain):
    """`kind: none`, its levels set or not, draws nothing: the truth and telemetry of a
    file that never names the key, bit for bit; no disturbance source, external zero.
    The resolved YAML of a scenario with the section at its defaults is the text of
    one without it (run directories and Monte Carlo digests unchanged); with levels
    set it writes the section and loads back to the same scenario."""
    s_plain = load_scenario("goes_next_equinox", [SHORT])
    for extra in ([], ["environment.disturbance.sigma_Nm=[1,1,1]"]):
        s = load_scenario("goes_next_equinox", [SHORT, "environment.disturbance.kind=none",
                                                *extra])
        assert build.disturbance_generator(s, 0) is None
        sim = simulate(s)
        _same_simulation(plain, sim)
        assert "disturbance" not in sim.truth.torques
        assert not np.any(sim.truth.torques["external"])
    assert "disturbance" not in resolved_yaml(s_plain)
    s_levels = load_scenario("goes_next_equinox", [SHORT, "environment.disturbance.q_Nm2s="
                                                   "[1e-9,0,0]"])
    text = resolved_yaml(s_levels)
    assert yaml.safe_load(text)["environment"]["disturbance"]["q_Nm2s"] == [1e-9, 0.0, 0.0]
    assert validate(yaml.safe_load(text)).model_copy(update={"dynprop_version": None}) \
        == s_levels


def test_a_disturbance_draws_from_its_own_stream_and_moves_no_other(plain):
    """With a disturbance: it is the first draw of stream (0, 7) and nothing else; the
    ripple (stream 0 of STREAMS) is the plain run's bit for bit; and the telemetry is
    the truth sensed with fresh sensor streams, so no sensor generator lost a draw to
    it (the readings differ from the plain run's only through the dynamics)."""
    s = load_scenario("goes_next_equinox", [SHORT, *GM_ON])
    sim = simulate(s)
    n = len(sim.truth.t_s)
    assert np.array_equal(sim.truth.torques["disturbance"],
                          draw(build.build_disturbance(s), DT, n, _stream_7(s.seed, 0)))
    assert list(sim.truth.torques)[-2:] == ["external", "disturbance"]
    assert not np.any(sim.truth.torques["external"])
    assert np.array_equal(sim.truth.torques["wheel_ripple"],
                          plain.truth.torques["wheel_ripple"])
    fresh = make_telemetry(sim.truth, sim.suite, build.streams(s.seed, 0),
                           s.sensors.sun.min_sun_separation_deg)
    for name in ("roll_rad", "pitch_rad", "yaw_rad", "wheel_speeds_radps"):
        assert np.array_equal(getattr(sim.telemetry, name), getattr(fresh, name),
                              equal_nan=True), name
    # It acts: the attitude is not the plain run's.
    assert not np.array_equal(sim.truth.q_br, plain.truth.q_br)


def test_the_noise_switch_turns_the_disturbance_off():
    """`sensors.noise.enabled: false` turns every random draw off, the disturbance too:
    the run is the noiseless run without one."""
    off = ["sensors.noise.enabled=false"]
    s = load_scenario("goes_next_equinox", [SHORT, *GM_ON, *off])
    assert not build.build_disturbance(s).enabled
    assert build.disturbance_generator(s, 0) is None
    _same_simulation(simulate(load_scenario("goes_next_equinox", [SHORT, *off])), simulate(s))


def test_a_streamed_run_continues_the_disturbance_across_windows(tmp_path):
    """`dynprop run` in windows (the producer in its own process) writes the truth,
    telemetry and estimate of one window byte for byte: the disturbance's generator and
    Gauss–Markov state cross the window boundaries (2 h in windows of 5000 samples)."""
    s = load_scenario("goes_next_paper_torques", ["duration_s=7200", "output.interval_s=0.512",
                                                  "output.telemetry=true"])
    one, many = tmp_path / "one", tmp_path / "many"
    one.mkdir()
    many.mkdir()
    stream_to_directory(s, one, progress=False)
    stream_to_directory(s, many, window_samples=5000, processes=2, progress=False)
    for name in ("truth.csv", "telemetry.csv", "estimate.csv"):
        assert (one / name).read_bytes() == (many / name).read_bytes(), name


# --------------------------------------------------------------------------- the CLI


@pytest.fixture(scope="module")
def torques_run(tmp_path_factory):
    """`dynprop run goes_next_paper_torques --duration-s 21600`, every sample kept."""
    return run_dir(tmp_path_factory, "paper-torques", "goes_next_paper_torques", 21600)[0]


def test_truth_csv_holds_the_held_disturbance(torques_run):
    """truth.csv's disturbance columns are the torque held over each step: the draw of
    the Eq. 45 Gauss–Markov (σ = 5e-6 N m roll and yaw, τ = 21541 s) from stream
    (0, 7), to the file's 10 digits."""
    truth = read_csv(torques_run / "truth.csv")
    s = load_scenario(torques_run / "scenario.yaml")
    d = build.build_disturbance(s)
    assert (d.kind, d.sigma_Nm, d.correlation_time_s) == ("gauss_markov", (5e-6, 0.0, 5e-6),
                                                          21541.0)
    cols = [f"disturbance_{a}_Nm" for a in "xyz"]
    header = (torques_run / "truth.csv").read_text().split("\n", 1)[0].split(",")
    assert header[-6:] == [f"external_{a}_Nm" for a in "xyz"] + cols
    want = draw(d, DT, len(truth["t_s"]), _stream_7(s.seed, 0))
    got = np.column_stack([truth[c] for c in cols])
    np.testing.assert_allclose(got, want, rtol=CSV_REL, atol=0)
    assert np.all(got[:, 1] == 0) and np.std(got[:, 0]) > 1e-6


def test_estimate_with_truth_reads_the_disturbance(torques_run, tmp_path):
    """`estimate --truth` on the run's own files gives the run's error figures (within
    the 10-digit file's precision, as test_estimate's), since it adds the disturbance
    columns to the external torque as the run did; without them, for a scenario that
    flies one, it refuses, naming the missing columns (exit 2)."""
    out = tmp_path / "est"
    rc, _, err = run_cli("estimate", str(torques_run / "telemetry.csv"), "--scenario",
                         str(torques_run / "scenario.yaml"), "--truth",
                         str(torques_run / "truth.csv"), "--out", str(out))
    assert rc == 0, err
    ours = json.loads((out / "summary.json").read_text())
    run = json.loads((torques_run / "summary.json").read_text())
    for key in ("yaw_error_rms_deg", "roll_error_rms_deg", "h_error_rms_Nms",
                "yaw_error_rms_smoothed_deg", "nees_mean"):
        assert ours[key] == pytest.approx(run[key], rel=1e-6), key
    for name, v in run["nees_mean_per_state"].items():
        # The torque states' "truth" is the fit of the external torque, the
        # disturbance in it: without it their NEES would move by far more than 1e-5.
        assert ours["nees_mean_per_state"][name] == pytest.approx(v, rel=1e-5), name
    cols = read_csv(torques_run / "truth.csv")
    for a in "xyz":
        del cols[f"disturbance_{a}_Nm"]
    stripped = tmp_path / "truth.csv"
    write_csv(stripped, cols)
    rc, _, err = run_cli("estimate", str(torques_run / "telemetry.csv"), "--scenario",
                         str(torques_run / "scenario.yaml"), "--truth", str(stripped),
                         "--out", str(tmp_path / "est2"))
    assert rc == 2
    assert [line.removeprefix("dynprop: error: ") for line in err.splitlines()] == \
        [f"{stripped}: missing column disturbance_{a}_Nm" for a in "xyz"]
