"""Bad input shows every problem, each on its own line with its key path, and the
likely fix; exit status 2, no traceback, nothing written.

The four files of issue 12's acceptance list are here verbatim, run through the
real CLI entry point.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from scenarios.cli import main
from scenarios.config.loader import ScenarioError, load_scenario, validate
from scenarios.config.suggestions import MAX_PROBLEM_LINES, closest
from scenarios.files.csvio import write_csv


def run_cli(capsys, *argv: str) -> tuple[int, str, str]:
    rc = main(list(argv))
    captured = capsys.readouterr()
    return rc, captured.out, captured.err


def error_lines(err: str) -> list[str]:
    """The problems the CLI printed, without its ``dynprop: error: `` prefix; every
    line of stderr must carry the prefix (no traceback, no stray output)."""
    lines = err.splitlines()
    assert lines, "nothing printed"
    assert all(line.startswith("dynprop: error: ") for line in lines), err
    assert "Traceback" not in err
    return [line.removeprefix("dynprop: error: ") for line in lines]


def check_refused(capsys, tmp_path: Path, text: str, command: str = "run") -> list[str]:
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    out = tmp_path / "out"
    rc, stdout, err = run_cli(capsys, command, str(path), "--out", str(out))
    assert rc == 2, err
    assert stdout == ""
    assert not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.yaml"]  # no staging left
    return error_lines(err)


def test_a_misspelt_required_key_is_named_with_the_key_it_meant(capsys, tmp_path):
    """Issue 12: a file holding only ``nmae: typo`` used to say only that ``name`` was
    missing; the typo itself must be named, with the fix."""
    lines = check_refused(capsys, tmp_path, "nmae: typo\n")
    path = tmp_path / "bad.yaml"
    assert f"nmae: unknown key; did you mean 'name'? ({path}:1)" in lines
    assert f"name: required key is missing ({path})" in lines
    assert len(lines) == 2


def test_a_key_without_its_unit_suffix_suggests_the_suffixed_key(capsys, tmp_path):
    lines = check_refused(capsys, tmp_path,
                          "name: x\nspacecraft: {inertia: [[1,0,0],[0,1,0],[0,0,1]]}\n",
                          command="simulate")
    assert lines == ["spacecraft.inertia: unknown key; did you mean 'inertia_kgm2'? "
                     f"({tmp_path / 'bad.yaml'}:2)"]


def test_two_bad_values_are_both_shown(capsys, tmp_path):
    lines = check_refused(capsys, tmp_path, "name: x\nduration_s: -5\nsample_interval_s: 0\n")
    assert len(lines) == 2
    assert lines[0].startswith("duration_s: ") and "greater than 0" in lines[0]
    assert lines[1].startswith("sample_interval_s: ") and "greater than 0" in lines[1]


def test_a_misspelt_telemetry_column_is_named_with_the_column_it_meant(
        capsys, tmp_path):
    t = np.arange(10) * 0.512
    path = tmp_path / "telemetry.csv"
    write_csv(path, {"t_s": t, "rol_deg": 0 * t, "pitch_deg": 0 * t, "yaw_deg": 0 * t,
                     "wheel1_rpm": 5485 + 0 * t, "wheel_2rpm": 5485 + 0 * t}, exact=True)
    out = tmp_path / "est"
    rc, stdout, err = run_cli(capsys, "estimate", str(path), "--scenario",
                              "goes_next_equinox", "--out", str(out))
    assert rc == 2 and stdout == "" and not out.exists()
    lines = error_lines(err)
    assert lines == [f"{path}: unknown column rol_deg; did you mean 'roll_deg'?",
                     f"{path}: unknown column wheel_2rpm; did you mean 'wheel2_rpm'?"]


def test_a_missing_telemetry_column_with_no_look_alike_is_named(capsys, tmp_path):
    t = np.arange(10) * 0.512
    path = tmp_path / "telemetry.csv"
    # pitch_deg is optional (the paper's filter does not use it); wheel2_rpm is not.
    write_csv(path, {"t_s": t, "roll_deg": 0 * t, "yaw_deg": 0 * t, "wheel1_rpm": 5485 + 0 * t,
                     "comment": 0 * t}, exact=True)
    out = tmp_path / "est"
    rc, _, err = run_cli(capsys, "estimate", str(path), "--scenario", "goes_next_equinox",
                         "--out", str(out))
    assert rc == 2 and not out.exists()
    assert error_lines(err) == [f"{path}: missing column wheel2_rpm"]


def test_every_problem_in_set_overrides_is_shown_with_its_fix(capsys, tmp_path):
    out = tmp_path / "out"
    rc, _, err = run_cli(capsys, "run", "goes_next_equinox", "--out", str(out),
                         "--set", "spacecraft.wheels.sped_rpm=5000",
                         "--set", "environment.solr.enabled=false",
                         "--set", "seed=abc", "--set", "control..enabled=1")
    assert rc == 2 and not out.exists()
    lines = error_lines(err)
    assert "spacecraft.wheels.sped_rpm: unknown key; did you mean 'speed_rpm'? " \
        "(--set spacecraft.wheels.sped_rpm=5000)" in lines
    assert "environment.solr: unknown key; did you mean 'solar'? " \
        "(--set environment.solr.enabled=false)" in lines
    assert "seed: must be a whole number (--set seed=abc)" in lines
    assert any(line.startswith("--set control..enabled=1: ") for line in lines)
    assert len(lines) == 4


@pytest.mark.parametrize("duration", ["0", "-1", "0.1"])
def test_a_run_shorter_than_one_step_is_refused(capsys, tmp_path, duration):
    """Issue 12: ``--duration-s 0`` wrote one-row files.  Anything shorter than one
    sample interval has no step to propagate over."""
    out = tmp_path / "out"
    rc, _, err = run_cli(capsys, "run", "goes_next_equinox", "--duration-s", duration,
                         "--out", str(out))
    assert rc == 2 and not out.exists()
    [line] = error_lines(err)
    assert line.startswith("duration_s: ")


@pytest.mark.parametrize("fields, line", [
    ("kind: gauss_markov, sigma_Nm: [5e-6, -1e-6, 5e-6]",
     "environment.disturbance.sigma_Nm: must not be negative, got [5.0e-06, -1.0e-06, "
     "5.0e-06]"),
    ("kind: white, q_Nm2s: [0, 0, -1e-9]",
     "environment.disturbance.q_Nm2s: must not be negative, got [0, 0, -1.0e-09]"),
    ("kind: gauss_markov, correlation_time_s: 0",
     "environment.disturbance.correlation_time_s: must be greater than 0, got 0"),
    ("kind: gauss_markov, correlation_time_s: .nan",
     "environment.disturbance.correlation_time_s: must be a finite number (not .nan or "
     ".inf), got .nan"),
    ("kind: gauss_markov, sigma_Nm: [5e-6, .nan, 5e-6]",
     "environment.disturbance.sigma_Nm: must be a list of 3 finite numbers, got "
     "[5.0e-06, .nan, 5.0e-06]"),
    ("kind: gauss_markov, correlaton_time_s: 100",
     "environment.disturbance.correlaton_time_s: unknown key; did you mean "
     "'correlation_time_s'?"),
    ("kind: markov",
     "environment.disturbance.kind: must be 'none', 'white' or 'gauss_markov', got markov"),
])
def test_a_bad_disturbance_value_is_one_line_naming_the_field(capsys, tmp_path, fields, line):
    lines = check_refused(capsys, tmp_path,
                          f"name: x\nenvironment:\n  disturbance: {{{fields}}}\n")
    assert lines == [f"{line} ({tmp_path / 'bad.yaml'}:3)"]


def test_a_misspelt_dispersed_key_names_the_scenario_key_it_meant():
    raw = {"name": "x", "duration_s": 0.1, "montecarlo": {"dispersions": {
        "spacecraft.wheels.sped_rpm": {"distribution": "normal", "sigma": 1.0},
        "seed": {"distribution": "normal", "sigma": 1.0}}}}
    with pytest.raises(ScenarioError) as exc_info:
        validate(raw)
    assert exc_info.value.problems == [
        "duration_s: 0.1 s is shorter than one sample_interval_s (0.512 s)",
        "montecarlo.dispersions.spacecraft.wheels.sped_rpm: no such scenario key; "
        "did you mean 'spacecraft.wheels.speed_rpm'?",
        "montecarlo.dispersions.seed: cannot be dispersed (the filter is designed from the "
        "nominal scenario, and every case shares name, seed, length and step)"]


def test_a_misspelt_distribution_parameter_is_named():
    raw = {"name": "x", "montecarlo": {"dispersions": {
        "initial_state.yaw_deg": {"distribution": "normal", "sgma": 1.0}}}}
    with pytest.raises(ScenarioError) as exc_info:
        validate(raw)
    assert "montecarlo.dispersions.initial_state.yaw_deg.sgma: unknown key; did you mean " \
        "'sigma'?" in exc_info.value.problems


def test_a_bad_vector_is_one_problem_naming_the_element():
    with pytest.raises(ScenarioError) as exc_info:
        validate({"name": "x", "spacecraft": {"inertia_kgm2": [[1, 0], [0, 1]]}})
    [line] = exc_info.value.problems
    assert line == ("spacecraft.inertia_kgm2: must be a 3×3 matrix, a list of 3 lists of 3 "
                    "numbers, got [[1, 0], [0, 1]]")


def test_many_problems_are_capped_with_a_count_of_the_rest(tmp_path):
    text = "name: x\n" + "".join(f"bogus{k}: 1\n" for k in range(25))
    (tmp_path / "s.yaml").write_text(text)
    with pytest.raises(ScenarioError) as exc_info:
        load_scenario(tmp_path / "s.yaml")
    lines = exc_info.value.problems
    assert len(lines) == MAX_PROBLEM_LINES
    assert lines[-1] == f"... and {25 - (MAX_PROBLEM_LINES - 1)} more problems"


def test_closest_suggests_only_plausible_keys():
    keys = ["name", "seed", "duration_s", "sample_interval_s", "spacecraft"]
    assert closest("nmae", keys) == "name"
    assert closest("duration", keys) == "duration_s"
    assert closest("sampel_interval_s", keys) == "sample_interval_s"
    assert closest("banana", keys) is None
    assert closest("s", keys) is None


def test_a_mistyped_scenario_name_names_the_bundled_one_it_meant(capsys, tmp_path):
    out = tmp_path / "out"
    rc, _, err = run_cli(capsys, "run", "goes_next_equinx", "--out", str(out))
    assert rc == 2 and not out.exists()
    [line] = error_lines(err)
    # The name offered is a bundled file's (the package's own folder, read here).
    bundled = {p.stem for p in (Path(__file__).parents[2] / "scenarios" / "bundled")
               .glob("*.yaml")}
    assert "goes_next_equinox" in bundled
    assert line.startswith("scenario goes_next_equinx: ")
    assert "did you mean 'goes_next_equinox'?" in line


@pytest.mark.parametrize("value, what", [("-5", "greater than 0"), ("abc", "a number")])
def test_a_bad_duration_s_names_the_option_as_typed(capsys, tmp_path, value, what):
    out = tmp_path / "out"
    rc, _, err = run_cli(capsys, "run", "goes_next_equinox", "--duration-s", value,
                         "--out", str(out))
    assert rc == 2 and not out.exists()
    [line] = error_lines(err)
    # The option the user typed, not a --set they never wrote.
    assert f"(--duration-s {value})" in line and "--set" not in line
    assert f"must be {what}" in line
