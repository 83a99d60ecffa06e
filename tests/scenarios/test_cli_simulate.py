"""`dynprop simulate`, `scenarios` and `plot` end to end through ``scenarios.cli.main``
(docs/outputs.md: CLI, exit codes, run directory, truth.csv and telemetry.csv)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from scenarios.cli import main
from scenarios.config.loader import bundled_names, load_scenario
from scenarios.files.csvio import read_csv

DT = 0.512
RUN_FILES = {"scenario.yaml", "truth.csv", "telemetry.csv"}
TRUTH_COLUMNS = ("t_s", "yaw_deg", "roll_deg", "pitch_deg", "wx_radps", "wy_radps", "wz_radps",
                 "wheel1_rpm", "wheel2_rpm", "h_Nms", "H_Nms", "sun_visible", "eclipse")
TELEMETRY_COLUMNS = ("t_s", "roll_deg", "pitch_deg", "yaw_deg", "wheel1_rpm", "wheel2_rpm")
# Around 16:25Z on the equinox the Sun passes within 10° of the yaw axis (local noon):
# a 300 s run there has Sun-sensor yaw for a while, then none.
NOON_GAP_EPOCH = "epoch_utc=2026-03-20T16:25:00Z"


def simulate(out: Path, *extra: str, scenario: str = "goes_next_equinox",
             duration: str = "60") -> int:
    return main(["simulate", scenario, "--duration-s", duration, "--out", str(out), *extra])


def header(path: Path) -> list[str]:
    with open(path) as fh:
        return next(line for line in fh if not line.startswith("#")).rstrip("\n").split(",")


def column_text(path: Path, name: str) -> list[str]:
    """The raw text of one column, header excluded."""
    lines = [line for line in path.read_text().splitlines() if not line.startswith("#")]
    k = lines[0].split(",").index(name)
    return [line.split(",")[k] for line in lines[1:]]


def assert_one_line(err: str) -> str:
    assert err.endswith("\n") and err.count("\n") == 1, f"stderr is not one line: {err!r}"
    assert "Traceback" not in err
    return err


@pytest.fixture(scope="module")
def run60(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("cli") / "run"
    assert simulate(out) == 0
    return out


# --------------------------------------------------------------------------- the run directory


def test_simulate_writes_exactly_the_three_files(run60):
    assert {p.name for p in run60.iterdir()} == RUN_FILES
    assert not [p for p in run60.parent.iterdir() if p.name.startswith(".")]  # no staging left


def test_truth_csv_has_the_design_columns_and_one_row_per_sample(run60):
    names = header(run60 / "truth.csv")
    assert set(TRUTH_COLUMNS) <= set(names)
    assert names[0] == "t_s"
    sources = {n[:-5] for n in names if n.endswith("_x_Nm")}
    assert {"gravity_gradient", "solar", "magnetic"} <= sources
    for s in sources:
        assert {f"{s}_y_Nm", f"{s}_z_Nm"} <= set(names)
    truth = read_csv(run60 / "truth.csv")
    n = math.floor(60 / DT) + 1
    assert len(truth["t_s"]) == n == 118
    # %.10g of k·0.512 s (at most 5 significant digits here) reads back to the double
    # k·0.512 up to its last bit: 1e-9 s absolute is 1e-11 of a minute.
    np.testing.assert_allclose(truth["t_s"], np.arange(n) * DT, rtol=0, atol=1e-9)
    for name in names:
        assert np.all(np.isfinite(truth[name])), f"truth column {name} has missing values"
    # the GOES-Next start: wheels at 5485 rpm, H ≈ −124.2 N m s
    assert truth["wheel1_rpm"][0] == pytest.approx(5485)
    assert truth["H_Nms"][0] == pytest.approx(-124.2, abs=0.05)
    assert set(np.unique(truth["sun_visible"])) <= {0.0, 1.0}


def test_telemetry_csv_has_the_design_columns(run60):
    names = header(run60 / "telemetry.csv")
    assert names[:len(TELEMETRY_COLUMNS)] == list(TELEMETRY_COLUMNS)
    tel = read_csv(run60 / "telemetry.csv")
    assert len(tel["t_s"]) == math.floor(60 / DT) + 1
    # Exact: both files hold the decimal k·0.512, which both formats write in full.
    np.testing.assert_array_equal(tel["t_s"], read_csv(run60 / "truth.csv")["t_s"])
    # Earth-sensor angles are quantised to 0.01°
    np.testing.assert_allclose(tel["roll_deg"] / 0.01, np.round(tel["roll_deg"] / 0.01),
                               atol=1e-6)


def test_missing_yaw_is_an_empty_field_not_nan(tmp_path):
    out = tmp_path / "run"
    assert simulate(out, "--set", NOON_GAP_EPOCH, duration="300") == 0
    path = out / "telemetry.csv"
    assert "nan" not in path.read_text().lower()
    yaw = column_text(path, "yaw_deg")
    assert len(yaw) == math.floor(300 / DT) + 1
    missing = [v == "" for v in yaw]
    assert any(missing) and not all(missing), "the run should have yaw, then a gap"
    for v in yaw:
        if v:
            float(v)
    # the other required columns are never empty
    for name in ("t_s", "roll_deg", "pitch_deg", "wheel1_rpm", "wheel2_rpm"):
        assert all(column_text(path, name))


def test_scenario_yaml_is_the_resolved_scenario(run60):
    s = load_scenario(run60 / "scenario.yaml")
    assert s.name == "goes_next_equinox"
    assert s.duration_s == 60
    # The file records the version; loading ignores it (so a rerun equals the original).
    assert "dynprop_version: " in (run60 / "scenario.yaml").read_text()
    assert s.dynprop_version is None
    text = (run60 / "scenario.yaml").read_text()
    assert "speed_rpm: 5485" in text  # defaults are filled in


def test_torque_free_run_has_no_torques(tmp_path):
    """Exact zeros are the requirement: each torque is switched off by a coefficient
    of 0.0 (gravity gradient, solar, magnetic), a zero command (control) or a zero
    input (wheel input, ripple), so it is 0 (or −0) in any arithmetic."""
    out = tmp_path / "run"
    assert simulate(out, scenario="torque_free") == 0
    truth = read_csv(out / "truth.csv")
    for name, values in truth.items():
        if name.endswith("_Nm"):
            assert np.all(values == 0), f"{name} is not zero in a torque-free run"


# --------------------------------------------------------------------------- reproducibility


def test_same_seed_gives_byte_identical_files(tmp_path, run60):
    """Identity is the requirement here: a rerun on the same machine."""
    again = tmp_path / "again"
    assert simulate(again) == 0
    for name in ("truth.csv", "telemetry.csv"):
        assert (again / name).read_bytes() == (run60 / name).read_bytes(), name


def test_different_seed_gives_different_telemetry(tmp_path, run60):
    other = tmp_path / "other"
    assert simulate(other, "--seed", "1") == 0
    assert (other / "telemetry.csv").read_bytes() != (run60 / "telemetry.csv").read_bytes()
    assert load_scenario(other / "scenario.yaml").seed == 1


def test_changing_one_sensor_leaves_the_other_sensors_noise_alone(tmp_path, run60):
    """Identity is the requirement here: each sensor draws from its own stream, so
    another sensor's setting must not change a bit of the others' readings."""
    other = tmp_path / "earth"
    assert simulate(other, "--set", "sensors.earth.noise_deg=0.02") == 0
    base, changed = run60 / "telemetry.csv", other / "telemetry.csv"
    # the truth does not see the sensors at all
    assert (other / "truth.csv").read_bytes() == (run60 / "truth.csv").read_bytes()
    assert column_text(changed, "roll_deg") != column_text(base, "roll_deg")
    # the tachometers and the raw Sun-sensor angles draw from their own streams
    sun_columns = [n for n in header(base) if n.endswith(("_alpha_deg", "_beta_deg"))]
    assert sun_columns
    for name in ("wheel1_rpm", "wheel2_rpm", *sun_columns):
        assert column_text(changed, name) == column_text(base, name), name


def test_changing_the_tachometer_leaves_the_earth_sensor_alone(tmp_path, run60):
    """Identity is the requirement here, as for the Earth sensor above."""
    other = tmp_path / "tach"
    assert simulate(other, "--set", "sensors.tachometer.noise_3sigma_rpm=0.2") == 0
    base, changed = run60 / "telemetry.csv", other / "telemetry.csv"
    assert column_text(changed, "wheel1_rpm") != column_text(base, "wheel1_rpm")
    for name in ("roll_deg", "pitch_deg", "yaw_deg"):
        assert column_text(changed, name) == column_text(base, name), name


# --------------------------------------------------------------------------- bad input

# (id, extra argv after `simulate`, text the single stderr line must contain)
BAD_CLI = [
    ("unknown-scenario", ["no_such_scenario"], "scenario no_such_scenario"),
    ("missing-file", ["does/not/exist.yaml"], "does/not/exist.yaml"),
    ("unknown-set-path", ["goes_next_equinox", "--set", "spacecraft.bogus=1"],
     "spacecraft.bogus"),
    ("set-without-equals", ["goes_next_equinox", "--set", "seed"], "--set seed"),
    ("set-inside-a-value", ["goes_next_equinox", "--set", "duration_s.x=1"], "duration_s"),
    ("set-seed-abc", ["goes_next_equinox", "--set", "seed=abc"], "seed"),
    ("seed-abc", ["goes_next_equinox", "--seed", "abc"], "seed"),
    ("seed-negative", ["goes_next_equinox", "--seed=-3"], "seed"),
    ("duration-negative", ["goes_next_equinox", "--duration-s", "-5"], "duration_s"),
    ("duration-text", ["goes_next_equinox", "--duration-s", "long"], "duration_s"),
    ("duration-nan", ["goes_next_equinox", "--duration-s", ".nan"], "duration_s"),
    ("duration-too-long", ["goes_next_equinox", "--duration-s", "31536000"], "duration_s"),
    ("sample-interval-zero", ["goes_next_equinox", "--set", "sample_interval_s=0"],
     "sample_interval_s"),
    ("inertia-triangle", ["goes_next_equinox", "--set",
                          "spacecraft.inertia_kgm2=[[1,0,0],[0,1,0],[0,0,3]]"],
     "spacecraft.inertia_kgm2"),
    ("epoch-garbage", ["goes_next_equinox", "--set", "epoch_utc=soon"], "epoch_utc"),
    ("epoch-out-of-range", ["goes_next_equinox", "--set", "epoch_utc=2100-01-01T00:00:00Z"],
     "epoch_utc"),
    ("cant-90", ["goes_next_equinox", "--set", "spacecraft.wheels.cant_deg=90"],
     "spacecraft.wheels.cant_deg"),
    ("wheel-speed-zero", ["goes_next_equinox", "--set", "spacecraft.wheels.speed_rpm=0"],
     "spacecraft.wheels.speed_rpm"),
]


@pytest.mark.parametrize(("argv", "needle"), [c[1:] for c in BAD_CLI],
                         ids=[c[0] for c in BAD_CLI])
def test_bad_input_exits_2_with_one_line_and_writes_nothing(tmp_path, capsys, argv, needle):
    out = tmp_path / "runs" / "run"
    assert main(["simulate", *argv, "--out", str(out)]) == 2
    captured = capsys.readouterr()
    err = assert_one_line(captured.err)
    assert needle in err
    assert err.startswith("dynprop: error: ")
    assert captured.out == ""
    assert list(tmp_path.iterdir()) == [], "bad input created a directory"


def test_bad_scenario_file_exits_2_naming_the_key_path(tmp_path, capsys):
    scenario = tmp_path / "mine.yaml"
    scenario.write_text("name: mine\nspacecraft:\n  wheels:\n    bogus: 1\n")
    out = tmp_path / "run"
    assert main(["simulate", str(scenario), "--out", str(out)]) == 2
    err = assert_one_line(capsys.readouterr().err)
    assert "spacecraft.wheels.bogus" in err
    assert not out.exists()


@pytest.mark.parametrize("argv", [
    ["simulate", "goes_next_equinox"],                    # --out is required
    ["simulate", "--out", "x"],                           # SCENARIO is required
    ["simulate", "goes_next_equinox", "--out", "x", "--bogus"],
    ["no-such-command"],
    [],
], ids=["no-out", "no-scenario", "unknown-option", "unknown-command", "no-command"])
def test_argument_errors_exit_2_with_one_line(tmp_path, monkeypatch, capsys, argv):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as exc_info:
        main(argv)
    assert exc_info.value.code == 2
    captured = capsys.readouterr()
    assert_one_line(captured.err)
    assert captured.out == ""
    assert list(tmp_path.iterdir()) == []


def test_duration_accepts_exponent_notation(tmp_path, capsys):
    assert simulate(tmp_path / "run", duration="6e1") == 0


# --------------------------------------------------------------------------- --out handling


def test_existing_non_empty_out_is_refused_and_left_untouched(tmp_path, capsys):
    out = tmp_path / "run"
    out.mkdir()
    (out / "notes.txt").write_text("keep me")
    assert simulate(out) == 2
    err = assert_one_line(capsys.readouterr().err)
    assert "--out" in err and "--force" in err
    assert [p.name for p in out.iterdir()] == ["notes.txt"]
    assert (out / "notes.txt").read_text() == "keep me"
    assert [p.name for p in tmp_path.iterdir()] == ["run"]


def test_force_replaces_an_existing_run(tmp_path, capsys):
    out = tmp_path / "run"
    out.mkdir()
    (out / "truth.csv").write_text("old")
    assert simulate(out, "--force") == 0
    assert {p.name for p in out.iterdir()} == RUN_FILES
    assert [p.name for p in tmp_path.iterdir()] == ["run"]  # no staging or backup left


def test_force_keeps_files_dynprop_did_not_write_unless_given_twice(tmp_path, capsys):
    """--force replaces a directory of dynprop's own files only; a user's notes stop
    it (named), and a second --force is the explicit "replace whatever is there"."""
    out = tmp_path / "run"
    out.mkdir()
    (out / "truth.csv").write_text("old")
    (out / "notes.txt").write_text("mine")
    assert simulate(out, "--force") == 2
    err = capsys.readouterr().err
    assert "notes.txt" in err and "--force --force" in err and len(err.splitlines()) == 1
    assert (out / "notes.txt").read_text() == "mine" and (out / "truth.csv").read_text() == "old"
    assert simulate(out, "--force", "--force") == 0
    assert {p.name for p in out.iterdir()} == RUN_FILES


def test_existing_empty_out_is_used(tmp_path):
    out = tmp_path / "run"
    out.mkdir()
    assert simulate(out) == 0
    assert {p.name for p in out.iterdir()} == RUN_FILES


def test_out_that_is_a_file_is_refused(tmp_path, capsys):
    out = tmp_path / "run"
    out.write_text("not a directory")
    assert simulate(out, "--force") == 2
    assert "--out" in assert_one_line(capsys.readouterr().err)
    assert out.read_text() == "not a directory"


# --------------------------------------------------------------------------- interrupts, errors


def _interrupt_on_call(monkeypatch, which: int) -> list[str]:
    """Make the simulation writer's ``write_csv`` write half a file, then raise
    KeyboardInterrupt, on its ``which``-th call (1 = truth.csv, 2 = telemetry.csv)."""
    import scenarios.files.simulation as runner
    real = runner.write_csv
    calls: list[str] = []

    def interrupted(path, columns, *args, **kwargs):
        calls.append(Path(path).name)
        if len(calls) < which:
            return real(path, columns, *args, **kwargs)
        with open(path, "w") as fh:
            fh.write(",".join(columns) + "\n0,")
        raise KeyboardInterrupt

    monkeypatch.setattr(runner, "write_csv", interrupted)
    return calls


@pytest.mark.parametrize("which", [1, 2], ids=["during-truth", "during-telemetry"])
def test_interrupt_returns_130_and_leaves_nothing(tmp_path, monkeypatch, capsys, which):
    calls = _interrupt_on_call(monkeypatch, which)
    out = tmp_path / "run"
    assert simulate(out) == 130
    assert len(calls) == which
    assert_one_line(capsys.readouterr().err)
    assert not out.exists()
    assert list(tmp_path.iterdir()) == [], "a staging directory was left behind"


def test_interrupt_with_force_keeps_the_previous_run(tmp_path, monkeypatch, capsys):
    out = tmp_path / "run"
    out.mkdir()
    (out / "truth.csv").write_text("previous")
    _interrupt_on_call(monkeypatch, 2)
    assert simulate(out, "--force") == 130
    assert [p.name for p in out.iterdir()] == ["truth.csv"]
    assert (out / "truth.csv").read_text() == "previous"
    assert [p.name for p in tmp_path.iterdir()] == ["run"]


def test_interrupt_leaves_no_parent_directories(tmp_path, monkeypatch, capsys):
    _interrupt_on_call(monkeypatch, 1)
    assert simulate(tmp_path / "a" / "b" / "run") == 130
    assert list(tmp_path.iterdir()) == []


def test_internal_error_exits_1_with_one_line(tmp_path, monkeypatch, capsys):
    import scenarios.commands as runner

    def broken(*args, **kwargs):
        raise RuntimeError("integrator exploded")

    monkeypatch.delenv("DYNPROP_DEBUG", raising=False)
    monkeypatch.setattr(runner, "simulate", broken)
    out = tmp_path / "run"
    assert simulate(out) == 1
    err = assert_one_line(capsys.readouterr().err)
    assert "integrator exploded" in err
    assert list(tmp_path.iterdir()) == []


# Valid, and as far from the nominal as the schema allows: roll at its −90° limit
# (the 3-1-2 singularity), yaw and pitch on ±180°, and a 2°/s tumble about x and z.
STRESS_START = ("initial_state={yaw_deg: -180, roll_deg: -89.99, pitch_deg: 180, "
                "rate_wrt_orbit_degps: [2.0, 0.0, -2.0]}")


def test_a_valid_stress_scenario_writes_finite_truth(tmp_path, capsys):
    """A scenario the schema accepts must run (exit 0) and write finite numbers, even
    at the edge of every attitude range and with a tumble; the wheels (no speed limit
    in the model) and the Sun sensors see it all."""
    out = tmp_path / "run"
    assert simulate(out, "--set", STRESS_START, duration="1200") == 0, capsys.readouterr().err
    truth = read_csv(out / "truth.csv")
    for name, values in truth.items():
        assert np.all(np.isfinite(values)), name
    # The run really goes where it should: through the singular roll and the ±180° wrap,
    # with the Sun both in and out of the heads' fields of view.
    assert np.abs(truth["roll_deg"]).max() >= 89.98
    assert np.ptp(truth["yaw_deg"]) > 180 and np.ptp(truth["pitch_deg"]) > 180
    assert set(np.unique(truth["sun_visible"])) == {0.0, 1.0}
    tel = read_csv(out / "telemetry.csv")
    for name in ("t_s", "roll_deg", "pitch_deg", "wheel1_rpm", "wheel2_rpm"):
        assert np.all(np.isfinite(tel[name])), name
    assert np.isfinite(tel["yaw_deg"]).any()       # the ground yaw was solved at times


# --------------------------------------------------------------------------- other commands


def test_scenarios_lists_every_bundled_scenario_with_its_description(capsys):
    assert main(["scenarios"]) == 0
    captured = capsys.readouterr()
    assert captured.err == ""
    lines = captured.out.splitlines()
    names = bundled_names()
    assert len(lines) == len(names)
    for line, name in zip(lines, names, strict=True):
        listed, _, description = line.partition(" ")
        assert listed == name
        assert description.strip() == load_scenario(name).description


def test_plot_writes_both_figures(tmp_path, capsys):
    out = tmp_path / "run"
    assert simulate(out, "--set", NOON_GAP_EPOCH, duration="120") == 0
    capsys.readouterr()
    assert main(["plot", str(out)]) == 0
    for name in ("truth.png", "telemetry.png"):
        png = out / "plots" / name
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert png.stat().st_size > 20_000, f"{name} looks empty"
    assert {p.name for p in (out / "plots").iterdir()} == {"truth.png", "telemetry.png"}
    assert capsys.readouterr().err == ""


@pytest.mark.parametrize("kind", ["empty-dir", "missing-dir", "partial-run"])
def test_plot_on_a_non_run_directory_exits_2(tmp_path, capsys, kind):
    target = tmp_path / "target"
    if kind != "missing-dir":
        target.mkdir()
    if kind == "partial-run":
        (target / "scenario.yaml").write_text("name: x\n")
    assert main(["plot", str(target)]) == 2
    err = assert_one_line(capsys.readouterr().err)
    assert str(target) in err
    assert not (target / "plots").exists()


# --------------------------------------------------------------------------- progress


def test_without_a_tty_only_the_summary_line_is_printed(tmp_path, capsys):
    out = tmp_path / "run"
    assert simulate(out) == 0
    captured = capsys.readouterr()
    assert captured.err == ""
    lines = captured.out.splitlines()
    assert len(lines) == 1
    assert lines[0].startswith("goes_next_equinox:")
    assert str(out) in lines[0]


def test_unstable_closed_loop_is_refused_not_written(tmp_path, capsys):
    """Gains the schema accepts but that destabilise the sampled loop must not
    produce a NaN truth file: one line, exit 1, nothing written."""
    out = tmp_path / "run"
    # Positive feedback on the yaw momentum: diverges within seconds.
    rc = simulate(out, "--set", "control.yaw_momentum_gain_per_s=5", duration="600")
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 1 and len(err) == 1 and "non-finite" in err[0]
    assert not out.exists()
