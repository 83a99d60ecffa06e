"""Issue 29 item 7: the messages a new user meets in the first hour say what is wrong
in the user's terms, name the file (and the row, the key, the value) it is about,
and never blame a file or an option that is not involved."""

from __future__ import annotations

import builtins
import errno
import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from scenarios.config.loader import ScenarioError, load_scenario
from scenarios.files.csvio import write_csv
from scenarios.files.rundir import RunDirError, check_out_dir, foreign_files, staged_run_dir
from scenarios.files.telemetry_file import on_grid, run_telemetry

from .mc_helpers import run_cli

DT = 0.512


def one_error(err: str) -> str:
    """The single problem the CLI printed (no traceback, no second line)."""
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("dynprop: error: "), err
    return lines[0].removeprefix("dynprop: error: ")


def telemetry_columns(t):
    return {"t_s": t, "roll_deg": 0 * t, "yaw_deg": 0 * t, "wheel1_rpm": 5485 + 0 * t,
            "wheel2_rpm": 5485 + 0 * t}


def estimate(tmp_path, telemetry: Path):
    out = tmp_path / "est"
    rc, stdout, err = run_cli("estimate", telemetry, "--scenario", "goes_next_equinox",
                              "--out", out)
    assert not out.exists()
    return rc, stdout, err


# --------------------------------------------------------------------------- CSV files


def test_a_row_with_too_few_values_names_the_file_and_row_not_numpys_usecols(tmp_path):
    """NumPy's own message counts rows from the first data row and ends "use `usecols`
    to select a subset", an argument of its API; the file's row 4 (the header being
    row 1) is the one with a value missing."""
    path = tmp_path / "tel.csv"
    path.write_text("t_s,roll_deg,yaw_deg,wheel1_rpm,wheel2_rpm\n0,0,0,5485,5485\n"
                    "0.512,0,0,5485,5485\n1.024,0,0,5485\n")
    rc, stdout, err = estimate(tmp_path, path)
    assert rc == 2 and stdout == ""
    assert one_error(err) == (f"{path}: row 4 has 4 values, but the header (row 1) names 5 "
                              "columns")


def test_a_value_that_is_not_a_number_names_its_row_and_column(tmp_path):
    path = tmp_path / "tel.csv"
    path.write_text("t_s,roll_deg,yaw_deg,wheel1_rpm,wheel2_rpm\n0,0,0,5485,5485\n"
                    "0.512,0,O.1,5485,5485\n")
    rc, _, err = estimate(tmp_path, path)
    assert rc == 2
    assert one_error(err) == f"{path}: row 3, column yaw_deg: 'O.1' is not a number"


def test_an_empty_telemetry_file_is_one_line(tmp_path):
    """It used to be five lines, one per required column "missing"."""
    path = tmp_path / "tel.csv"
    path.write_text("")
    rc, _, err = estimate(tmp_path, path)
    assert rc == 2
    assert one_error(err) == f"{path}: the file is empty (no header)"


# --------------------------------------------------------------------------- full disk


def test_a_full_disk_names_the_file_being_written(tmp_path, monkeypatch):
    """A write() that fails on a full disk raises OSError without a file name; the
    message used to be "dynprop: error: : No space left on device".  It must name the
    file as the user will know it: inside --out, not inside the hidden staging
    directory, which is gone by the time the message is read."""
    from scenarios.files import csvio

    def full(*args, **kwargs):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(csvio, "_format_block", full)
    out = tmp_path / "run"
    rc, _, err = run_cli("simulate", "goes_next_equinox", "--duration-s", "600", "--out", out)
    assert rc == 2
    line = one_error(err)
    written, why = line.split(": ", 1)
    assert Path(written).parent == out and written.endswith(".csv"), line
    assert why.startswith(os.strerror(errno.ENOSPC)) and "--out" in why
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_a_write_error_without_a_file_name_names_the_output_directory(tmp_path, monkeypatch):
    from scenarios import commands

    def full(scenario, stage):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(commands, "simulate_to_directory", full)
    out = tmp_path / "run"
    rc, _, err = run_cli("simulate", "goes_next_equinox", "--duration-s", "600", "--out", out)
    assert rc == 2
    assert one_error(err).startswith(f"writing {out}: {os.strerror(errno.ENOSPC)}")


def test_a_staging_directory_in_a_file_name_is_named_by_its_run_directory(tmp_path,
                                                                          monkeypatch):
    from scenarios import commands

    def denied(scenario, stage):
        raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), str(stage / "truth.csv"))

    monkeypatch.setattr(commands, "simulate_to_directory", denied)
    out = tmp_path / "run"
    rc, _, err = run_cli("simulate", "goes_next_equinox", "--duration-s", "600", "--out", out)
    assert rc == 2
    assert one_error(err) == f"{out / 'truth.csv'}: {os.strerror(errno.EACCES)}"


# --------------------------------------------------------------------------- trim, plot


def test_trim_names_its_own_directory_not_an_out_it_does_not_have(run6, tmp_path):
    run = tmp_path / "run"
    shutil.copytree(run6, run)
    (run / "trim").write_text("in the way")
    rc, _, err = run_cli("trim", run)
    assert rc == 2
    line = one_error(err)
    assert "--out" not in line and "--force" not in line
    assert line == f"{run / 'trim'}: exists and is not a directory"


def _read_only(monkeypatch, root: Path) -> None:
    """Every write under ``root`` fails as on a read-only mount: EROFS, naming the path,
    whether the file exists or not (unlink of a file that is not there included)."""
    root_text = str(root.resolve())

    def under(path) -> bool:
        return isinstance(path, str | os.PathLike) and \
            os.path.abspath(os.fspath(path)).startswith(root_text)

    def refuse(path):
        raise OSError(errno.EROFS, os.strerror(errno.EROFS), os.fspath(path))

    for name in ("unlink", "remove", "mkdir", "rmdir", "rename", "replace"):
        real = getattr(os, name)

        def fake(path, *args, _real=real, **kwargs):
            if under(path):
                refuse(path)
            return _real(path, *args, **kwargs)
        monkeypatch.setattr(os, name, fake)
    real_os_open, real_open = os.open, builtins.open
    writing = os.O_WRONLY | os.O_RDWR | os.O_CREAT

    def fake_os_open(path, flags, *args, **kwargs):
        if under(path) and flags & writing:
            refuse(path)
        return real_os_open(path, flags, *args, **kwargs)

    def fake_open(file, mode="r", *args, **kwargs):
        if under(file) and any(c in mode for c in "wax+"):
            refuse(file)
        return real_open(file, mode, *args, **kwargs)
    monkeypatch.setattr(os, "open", fake_os_open)
    monkeypatch.setattr(builtins, "open", fake_open)


def test_plot_on_a_read_only_run_names_the_directory_it_cannot_write(run6, tmp_path,
                                                                     monkeypatch):
    """It used to name plots/trim_loop.png, a figure this run never had (the first
    file the drawing touched: a stale figure it removes)."""
    run = tmp_path / "run"
    shutil.copytree(run6, run)
    before = {p: p.read_bytes() for p in run.rglob("*") if p.is_file()}
    _read_only(monkeypatch, run)
    rc, _, err = run_cli("plot", run)
    monkeypatch.undo()
    assert rc == 2
    line = one_error(err)
    assert "trim_loop" not in line
    assert line == f"{run / 'plots'}: cannot write the figures there " \
                   f"({os.strerror(errno.EROFS)})"
    assert {p: p.read_bytes() for p in run.rglob("*") if p.is_file()} == before


# --------------------------------------------------------------------------- telemetry of a run


def _estimate_dir(tmp_path: Path, recorded: str) -> Path:
    """An `estimate` directory as trim and tune read it: its scenario and the
    telemetry file its summary.json records."""
    est = tmp_path / "est"
    est.mkdir()
    (est / "scenario.yaml").write_text(str(load_scenario("goes_next_equinox")))
    (est / "summary.json").write_text(json.dumps({"telemetry": {"file": recorded}}))
    return est


def test_an_estimate_directory_finds_its_telemetry_from_any_working_directory(
        tmp_path, monkeypatch):
    """A recorded relative path is relative to the estimate directory, not to the
    directory the user happens to be in (which gave "a run longer than 2 days ...")."""
    tel = tmp_path / "data" / "telemetry.csv"
    tel.parent.mkdir()
    write_csv(tel, telemetry_columns(np.arange(4) * DT), exact=True)
    est = _estimate_dir(tmp_path, "../data/telemetry.csv")
    elsewhere = tmp_path / "a" / "b"   # where ../data/telemetry.csv is not
    elsewhere.mkdir(parents=True)
    monkeypatch.chdir(elsewhere)
    assert run_telemetry(est).resolve() == tel.resolve()
    (est / "summary.json").write_text(json.dumps({"telemetry": {"file": str(tel)}}))
    assert run_telemetry(est) == tel


def test_an_estimate_whose_telemetry_is_gone_says_which_file(tmp_path):
    est = _estimate_dir(tmp_path, "../data/telemetry.csv")
    rc, _, err = run_cli("trim", est)
    assert rc == 2
    line = one_error(err)
    assert "2 days" not in line and "output.telemetry" not in line
    assert f"the telemetry file {est / '../data/telemetry.csv'} this estimate read is no " \
           "longer there" in line
    assert line.endswith("give it with --telemetry FILE")


def test_a_run_whose_telemetry_was_deleted_does_not_blame_its_length(run6, tmp_path):
    run = tmp_path / "run"
    shutil.copytree(run6, run)
    (run / "telemetry.csv").unlink()
    rc, _, err = run_cli("trim", run)
    assert rc == 2
    line = one_error(err)
    assert "2 days" not in line
    assert line.startswith(f"{run}: its telemetry.csv is no longer there")
    with pytest.raises(RunDirError, match="no longer there"):
        run_telemetry(run)


def test_a_long_run_without_telemetry_says_why_it_has_none(tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    (run / "scenario.yaml").write_text(str(load_scenario("goes_next_equinox",
                                                         ["duration_s=259200"])))
    assert run_telemetry(run) is None
    rc, _, err = run_cli("trim", run)
    assert rc == 2
    assert "output.telemetry: true" in one_error(err)


# --------------------------------------------------------------------------- cadence


def test_a_cadence_of_two_steps_is_not_counted_as_dropouts():
    """A 1.024 s file misses every other 0.512 s filter step: that is its cadence,
    not 84,375 dropouts.  A 10 s hole in it is one dropout of 10 − 1.024 s."""
    t = np.r_[np.arange(0, 100, 1.024), 110.592 + np.arange(0, 50, 1.024)]
    grid = on_grid(telemetry_columns(t), DT, 3600.0)
    stats = grid.stats(DT)
    assert stats["cadence_s"] == pytest.approx(1.024)
    assert stats["dropouts"] == 1
    hole = 110.592 - t[t < 100][-1]
    assert stats["longest_dropout_s"] == pytest.approx(hole - 1.024)
    assert stats["missing_steps"] == stats["filter_steps"] - len(t)
    assert stats["cadence_note"].startswith(
        "telemetry cadence 1.024 s is not the filter's 0.512 s step: ")


def test_the_filters_own_cadence_counts_each_hole_as_a_dropout():
    t = np.delete(np.arange(200) * DT, [10, 50, 51, 52])
    stats = on_grid(telemetry_columns(t), DT, 3600.0).stats(DT)
    assert stats["cadence_note"] is None
    assert stats["dropouts"] == 2 and stats["missing_steps"] == 4
    assert stats["longest_dropout_s"] == pytest.approx(3 * DT)


# --------------------------------------------------------------------------- scenario values


# (the YAML of a bad key, its key path, what the message says, the value echoed)
BAD_VALUES = [
    ("spacecraft: {inertia_kgm2: 5}", "spacecraft.inertia_kgm2",
     "must be a 3×3 matrix, a list of 3 lists of 3 numbers", "5"),
    ("spacecraft: {inertia_kgm2: [1, 2, 3]}", "spacecraft.inertia_kgm2",
     "must be a 3×3 matrix, a list of 3 lists of 3 numbers", "[1, 2, 3]"),
    ("initial_state: {rate_wrt_orbit_degps: [0, 1]}", "initial_state.rate_wrt_orbit_degps",
     "must be a list of 3 numbers", "[0, 1]"),
    ("initial_state: {rate_wrt_orbit_degps: [0, 1, 2, 3]}",
     "initial_state.rate_wrt_orbit_degps", "must be a list of 3 numbers", "[0, 1, 2, 3]"),
    ("initial_state: {rate_wrt_orbit_degps: [0, x, 2]}", "initial_state.rate_wrt_orbit_degps",
     "must be a list of 3 numbers", "[0, x, 2]"),
    ("orbit: {longitude_deg: east}", "orbit.longitude_deg", "must be a number", "east"),
    ("orbit: {longitude_deg: true}", "orbit.longitude_deg", "must be a number", "true"),
    ("seed: 1.5", "seed", "must be a whole number", "1.5"),
    ("seed: -1", "seed", "must be at least 0", "-1"),
    ("control: {enabled: 1}", "control.enabled", "must be true or false", "1"),
    ("control: 5", "control", "must be a section, a mapping of keys, each key: value", "5"),
    ("montecarlo: {dispersions: [1]}", "montecarlo.dispersions",
     "must be a mapping of keys, each key: value", "[1]"),
    ("estimator: {filters: paper}", "estimator.filters", "must be a list", "paper"),
    ("estimator: {filters: []}", "estimator.filters", "must have at least 1 item", "[]"),
    ("spacecraft: {configuration: spare}", "spacecraft.configuration",
     "must be 'nominal' or 'backup'", "spare"),
    ("output: {telemetry: maybe}", "output.telemetry", "must be 'auto', true or false",
     "maybe"),
    ("spacecraft: {wheels: {cant_deg: 90}}", "spacecraft.wheels.cant_deg",
     "must be less than 90", "90"),
    ("epoch_utc: 2026", "epoch_utc", "must be text (quote it if it looks like a number)",
     "2026"),
]


@pytest.mark.parametrize("text, key, says, value", BAD_VALUES,
                         ids=[f"{k}={v}" for _, k, _, v in BAD_VALUES])
def test_a_bad_value_is_said_in_the_keys_terms_with_the_value_and_its_line(
        tmp_path, text, key, says, value):
    """pydantic's "Input should be a valid tuple" is Python; the message says what
    the key holds (a list of 3 numbers), echoes what was given and where."""
    path = tmp_path / "s.yaml"
    path.write_text(f"name: x\n{text}\n")
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    assert info.value.problems == [f"{key}: {says}, got {value} ({path}:2)"]


def test_a_missing_key_names_the_file(tmp_path):
    path = tmp_path / "s.yaml"
    path.write_text("seed: 1\n")
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    assert info.value.problems == [f"name: required key is missing ({path})"]


def test_a_bad_set_value_names_the_set_not_the_file(tmp_path):
    with pytest.raises(ScenarioError) as info:
        load_scenario("goes_next_equinox", ["spacecraft.inertia_kgm2=[1, 2]",
                                            "control={enabled: x}"])
    assert info.value.problems == [
        "spacecraft.inertia_kgm2: must be a 3×3 matrix, a list of 3 lists of 3 numbers "
        "(--set spacecraft.inertia_kgm2=[1, 2])",
        "control.enabled: must be true or false, got x (--set control={enabled: x})"]


# --------------------------------------------------------------------------- --force


def test_force_refuses_a_directory_holding_files_dynprop_did_not_write(tmp_path):
    """`--force` used to delete the whole directory, the user's files with it."""
    out = tmp_path / "run"
    rc, _, err = run_cli("simulate", "goes_next_equinox", "--duration-s", "600", "--out", out)
    assert rc == 0, err
    (out / "notes.txt").write_text("mine")
    (out / "plots").mkdir()   # as `dynprop plot` makes it
    (out / "plots" / "sketch.svg").write_text("mine")
    (out / "mine").mkdir()
    before = sorted(p.relative_to(out) for p in out.rglob("*"))
    rc, _, err = run_cli("simulate", "goes_next_equinox", "--duration-s", "600", "--out", out,
                         "--force")
    assert rc == 2
    line = one_error(err)
    assert line.startswith(f"--out {out}: holds mine/, notes.txt, plots/sketch.svg, which "
                           "dynprop did not write")
    assert sorted(p.relative_to(out) for p in out.rglob("*")) == before
    # Without them, --force replaces the run.
    for p in (out / "notes.txt", out / "plots" / "sketch.svg"):
        p.unlink()
    (out / "mine").rmdir()
    (out / "plots" / "truth.png").write_text("drawn by dynprop plot")
    rc, _, err = run_cli("simulate", "goes_next_equinox", "--duration-s", "900", "--out", out,
                         "--force")
    assert rc == 0, err
    assert "duration_s: 900.0" in (out / "scenario.yaml").read_text()


def test_what_dynprop_writes_is_its_own_and_a_second_force_takes_anything(tmp_path):
    out = tmp_path / "d"
    (out / "cases").mkdir(parents=True)
    (out / "trim" / "verify" / "plots").mkdir(parents=True)
    for name in ("scenario.yaml", "summary.json", "estimate_ekf.csv", "montecarlo.json",
                 "report.md", "tune.json", "cases/case-00012.full.npz", "trim/trim.json",
                 "trim/verify/truth.csv", "trim/verify/plots/errors.png",
                 ".montecarlo.json.ab12cd_z"):
        (out / name).write_text("x")
    assert foreign_files(out) == []
    check_out_dir(out, force=True)
    (out / "cases" / "my.csv").write_text("x")
    (out / "truth (copy).csv").write_text("x")
    assert foreign_files(out) == ["cases/my.csv", "truth (copy).csv"]
    with pytest.raises(RunDirError):
        check_out_dir(out, force=True)
    with staged_run_dir(out, force=2) as stage:
        (stage / "summary.json").write_text("{}")
    assert [p.name for p in out.iterdir()] == ["summary.json"]


def test_montecarlo_force_keeps_a_directory_of_the_users_files(tmp_path):
    from scenarios.montecarlo.store import SetDirectory
    out = tmp_path / "set"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    with pytest.raises(RunDirError, match="notes.txt, which dynprop did not write"):
        SetDirectory(out).open(load_scenario("goes_next_equinox"), force=True)
    assert (out / "notes.txt").read_text() == "mine"


# --------------------------------------------------------------------------- --runs


def test_fewer_runs_than_the_set_holds_keeps_every_case_in_the_summary(tmp_path,
                                                                       monkeypatch):
    """`--runs 1` on a set of 2 used to rewrite montecarlo.json for case 0 alone."""
    from scenarios.montecarlo import runset
    monkeypatch.setattr(runset, "draw_figures", lambda *a, **k: None)
    out = tmp_path / "set"
    argv = ("montecarlo", "goes_next_equinox", "--duration-s", "600", "--workers", "1",
            "--out", out)
    rc, _, err = run_cli(*argv, "--runs", "2")
    assert rc == 0, err
    rc, stdout, err = run_cli(*argv, "--runs", "1")
    assert rc == 0, err
    assert err == (f"dynprop: note: the set in {out} holds 2 cases; --runs 1 adds none, and "
                   "montecarlo.json summarizes all 2 (a smaller set needs another --out)\n")
    assert ": resumed set, ran 0 of 2 cases (2 already stored)" in stdout
    summary = json.loads((out / "montecarlo.json").read_text())
    assert summary["runs_ok"] == 2 and summary["runs_missing"] == 0
