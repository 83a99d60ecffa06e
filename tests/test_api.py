"""`import dynprop` (issue 17): the API runs the CLI's code and writes its files.

Identity is the requirement: the same scenario and seed give byte-identical run
directories whether written by `dynprop run` or by ``dynprop.run(...).save``, and the
numbers and messages the API returns are the ones the CLI prints."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

import dynprop
from tests.scenarios.test_cli_run import run_cli

SHORT = 21600.0


def _files(d: Path) -> dict[str, bytes]:
    return {str(p.relative_to(d)): p.read_bytes() for p in sorted(d.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def both(run6, tmp_path_factory):
    """The CLI's 6 h run (the session's ``run6``: `dynprop run goes_next_equinox
    --duration-s 21600`), the same through the API, and a folder for the API's files."""
    r = dynprop.run(dynprop.load_scenario("goes_next_equinox", duration_s=SHORT))
    return run6, tmp_path_factory.mktemp("api"), r


def test_run_gives_the_clis_summary_and_saves_its_files_byte_for_byte(both):
    cli_dir, base, r = both
    cli = json.loads((cli_dir / "summary.json").read_text())
    assert r.summary["yaw_error_rms_deg"] == cli["yaw_error_rms_deg"]
    r.save(base / "api")
    mine, theirs = _files(base / "api"), _files(cli_dir)
    assert mine.keys() == theirs.keys()
    for name in theirs:
        assert mine[name] == theirs[name], name


def test_open_run_reads_back_the_same_tables(both):
    cli_dir, _, r = both
    again = dynprop.open_run(cli_dir)
    assert isinstance(again, dynprop.RunResult)
    assert again.estimate.index.name == "t_s"
    np.testing.assert_array_equal(again.estimate.to_numpy(), r.estimate.to_numpy())
    assert list(again.estimate.columns) == list(r.estimate.columns)
    e = r.errors()
    assert list(e.columns)[:3] == ["roll_deg", "roll_rate_degps", "yaw_deg"]
    # The errors are the estimate less the truth the figures are drawn from.
    assert float(e["yaw_deg"].abs().max()) > 0
    fig = r.figure("errors")
    assert fig.axes and "goes_next_equinox" in fig._suptitle.get_text()


def test_a_bad_key_raises_the_clis_message(tmp_path):
    with pytest.raises(dynprop.ScenarioError) as info:
        dynprop.load_scenario("goes_next_equinox", nmae=1)
    rc, _, err = run_cli("simulate", "goes_next_equinox", "--set", "nmae=1",
                         "--out", str(tmp_path / "x"))
    assert rc == 2
    assert err.splitlines() == [f"dynprop: error: {line}" for line in
                                str(info.value).splitlines()]
    assert "did you mean 'name'" in str(info.value)


def test_printing_a_scenario_shows_its_resolved_yaml():
    s = dynprop.load_scenario("goes_next_equinox",
                              set={"spacecraft.wheels.speed_rpm": 5000.0})
    text = str(s)
    assert "speed_rpm: 5000.0" in text and text.startswith("name: goes_next_equinox")


def test_simulate_and_reports_match_the_cli(tmp_path):
    s = dynprop.load_scenario("goes_next_equinox", duration_s=600.0)
    sim = dynprop.simulate(s)
    sim.save(tmp_path / "api")
    rc, _, err = run_cli("simulate", "goes_next_equinox", "--duration-s", "600",
                         "--out", str(tmp_path / "cli"))
    assert rc == 0, err
    assert _files(tmp_path / "api") == _files(tmp_path / "cli")
    assert len(sim.truth) == len(sim.telemetry) == 1172
    for name, fn in (("covariance", dynprop.covariance),
                     ("observability", dynprop.observability)):
        rc, out, _ = run_cli(name, "goes_next_equinox")
        assert rc == 0 and out == str(fn("goes_next_equinox")) + "\n"


def test_montecarlo_cases_are_the_clis(tmp_path):
    s = dynprop.load_scenario("goes_next_equinox", duration_s=3600.0)
    mc = dynprop.montecarlo(s, runs=2, workers=1)
    rc, _, err = run_cli("montecarlo", "goes_next_equinox", "--duration-s", "3600",
                         "--runs", "2", "--workers", "1", "--out", str(tmp_path / "cli"))
    assert rc == 0, err
    assert mc.summary["runs_ok"] == 2 and list(mc.cases.index) == [0, 1]
    for k in (0, 1):
        name = f"cases/case-0000{k}.json"
        assert (mc.path / name).read_bytes() == (tmp_path / "cli" / name).read_bytes()
    assert mc.figure("mc_nees").axes
    mc.save(tmp_path / "api")
    assert isinstance(dynprop.open_run(tmp_path / "api"), dynprop.MonteCarloResult)


def test_linearization_returns_the_report(tmp_path):
    lin = dynprop.linearization(dynprop.load_scenario("goes_next_equinox", duration_s=3600.0))
    assert lin.verdict and lin.markdown.startswith("#")
    lin.save(tmp_path / "lin")
    assert json.loads((tmp_path / "lin" / "report.json").read_text())["verdict"] == lin.verdict


def _data_lines(path: Path) -> list[str]:
    """An AEM/APM from its first META_START/EPOCH on: what does not name where or when
    it was written (the header's directory comment and CREATION_DATE do)."""
    lines = path.read_text().splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith(("META_START",
                                                                       "OBJECT_NAME")))
    return lines[start:]


def test_export_writes_the_clis_message_and_compares_as_it_does(both, tmp_path):
    cli_dir, _, r = both
    rc, out, err = run_cli("export", str(cli_dir), "--format", "aem", "--what", "truth",
                           "--out", str(tmp_path / "cli.aem"))
    assert rc == 0, err
    e = r.export(what="truth", out=tmp_path / "api.aem", truth=tmp_path / "cli.aem")
    assert isinstance(e, dynprop.ExportResult)
    assert (e.path, e.format, e.what, e.frame, e.rows) == (tmp_path / "api.aem", "aem", "truth",
                                                           "EME2000", 338)
    assert _data_lines(e.path) == _data_lines(tmp_path / "cli.aem")
    assert e.segments == [("2026-03-20T12:00:00.000000", "2026-03-20T17:59:28.000000", 338)]
    assert e.comparison["compared"] == 338 and e.comparison["angle_max_deg"] < 1e-9
    # Into the directory by default (a copy: the CLI's directory is compared whole above).
    copy = Path(shutil.copytree(cli_dir, tmp_path / "copy"))
    apm = dynprop.export(copy, format="apm", what="truth", frame="orbit",
                         at="2026-03-20T13:00:00Z")
    assert apm.path == copy / "truth.apm" and apm.epoch == "2026-03-20T13:00:00.000000"
    rc, _, err = run_cli("export", str(copy), "--format", "apm", "--what", "truth", "--frame",
                         "orbit", "--at", "3600", "--out", str(tmp_path / "cli.apm"))
    assert rc == 0, err
    assert _data_lines(apm.path) == _data_lines(tmp_path / "cli.apm")
    with pytest.raises(dynprop.ExportError) as info:
        dynprop.export(copy, at=60)
    rc, _, err = run_cli("export", str(copy), "--format", "aem", "--at", "60")
    assert rc == 2 and err == f"dynprop: error: {info.value}\n"
