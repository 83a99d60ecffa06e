"""`dynprop.estimate`, `dynprop.trim` and where a result's review page goes (issue 43,
item 6).

Identity with the command line is the requirement: ``dynprop.estimate(...).save(DIR)``
holds byte for byte what `dynprop estimate ... --out DIR` writes, and ``dynprop.trim``
what `dynprop trim RUN_DIR` writes into RUN_DIR/trim/, from the session's 6 h run
(``run6``: its telemetry.csv, truth.csv and scenario.yaml)."""

from __future__ import annotations

import json
import shutil
import tempfile
from pathlib import Path

import pytest

import dynprop
from dynprop.results import RunResult
from tests.scenarios.test_cli_run import run_cli


def _files(d: Path) -> dict[str, bytes]:
    return {str(p.relative_to(d)): p.read_bytes() for p in sorted(d.rglob("*")) if p.is_file()}


def _same_files(mine: Path, theirs: Path) -> None:
    a, b = _files(mine), _files(theirs)
    assert a.keys() == b.keys()
    for name in b:
        assert a[name] == b[name], name


def test_estimate_saves_the_clis_directory_byte_for_byte(run6, tmp_path):
    # A --set and a --unit (the file's own unit, so the numbers stay the run's) go
    # through the keywords as the CLI's options do.
    rc, _, err = run_cli("estimate", str(run6 / "telemetry.csv"), "--scenario",
                         str(run6 / "scenario.yaml"), "--truth", str(run6 / "truth.csv"),
                         "--set", "output.interval_s=128", "--unit", "roll=deg",
                         "--out", str(tmp_path / "cli"))
    assert rc == 0, err
    e = dynprop.estimate(run6 / "telemetry.csv", run6 / "scenario.yaml",
                         truth=run6 / "truth.csv", units={"roll": "deg"},
                         set={"output.interval_s": 128})
    assert isinstance(e, dynprop.RunResult)
    # The rows at the overridden cadence: the override reached the scenario.
    assert float(e.estimate.index[1] - e.estimate.index[0]) == 128.0
    e.save(tmp_path / "api")
    _same_files(tmp_path / "api", tmp_path / "cli")


def test_trim_writes_the_clis_trim_directory_and_leaves_the_run_alone(run6, tmp_path):
    copy = Path(shutil.copytree(run6, tmp_path / "run"))
    rc, _, err = run_cli("trim", str(copy), "--verify")
    assert rc == 0, err
    before = _files(run6)
    t = dynprop.trim(run6, verify=True)
    assert _files(run6) == before and not (run6 / "trim").exists()
    assert t.summary == json.loads((copy / "trim" / "trim.json").read_text())
    assert t.verify.summary["duration_s"] == t.summary["batch"]["to_s"]
    t.save(tmp_path / "api")
    _same_files(tmp_path / "api", copy / "trim")


def test_trim_refuses_with_the_clis_message_naming_the_users_directory(run6, tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    shutil.copy(run6 / "scenario.yaml", run)   # a run whose telemetry.csv is gone
    rc, _, err = run_cli("trim", str(run))
    assert rc == 2
    with pytest.raises(ValueError) as info:
        dynprop.trim(run)
    assert err == f"dynprop: error: {info.value}\n"
    assert not (run / "trim").exists()


def _owned_copy(run6, tmp_path) -> RunResult:
    """A result that owns its temporary directory, as one ``dynprop.run`` returns:
    the session's run copied there (no new simulation)."""
    owner = Path(tempfile.mkdtemp(dir=tmp_path))
    shutil.copytree(run6, owner / "run")
    return RunResult(owner / "run", owner)


def test_report_after_save_goes_into_the_saved_directory(run6, tmp_path):
    r = _owned_copy(run6, tmp_path)
    saved = r.save(tmp_path / "saved")
    page = r.report()
    assert page == saved / "report.html" and page.is_file()
    assert not (r.path / "report.html").exists()
    # The page's "reproduce with" names the directory it sits in.
    assert f"dynprop run {saved}/scenario.yaml" in page.read_text()


def test_save_after_report_keeps_the_page_and_names_the_saved_directory(run6, tmp_path):
    r = _owned_copy(run6, tmp_path)
    dynprop.report(r, yaw_requirement_deg=0.1)
    saved = r.save(tmp_path / "saved")
    text = (saved / "report.html").read_text()
    assert f"dynprop run {saved}/scenario.yaml" in text
    assert str(r.path) not in text
