"""`dynprop report` (issue 32): the page's numbers against the files they come from,
its verdicts, bad input, `run --report` and the API.  The page in a real browser:
test_report_browser.py."""

from __future__ import annotations

import json
import math
import re
import shutil
import subprocess
import sys
from html.parser import HTMLParser
from pathlib import Path

import pandas as pd
import pytest

from scenarios.review import verdict
from scenarios.review.cells import lookup

DYNPROP = str(Path(sys.executable).with_name("dynprop"))
pytestmark = pytest.mark.surface


def dynprop(*args, cwd=None):
    return subprocess.run([DYNPROP, *map(str, args)], capture_output=True, text=True,
                          cwd=cwd, timeout=900)


class _Numbers(HTMLParser):
    """Every element carrying data-source, with its text; and every verdict."""

    def __init__(self):
        super().__init__()
        self.cells, self.verdicts, self._open = [], [], []

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if "data-source" in a:
            self._open.append([a, ""])
        if "data-verdict" in a:
            self.verdicts.append((a["data-verdict"], a["data-status"]))

    def handle_data(self, data):
        for item in self._open:
            item[1] += data

    def handle_endtag(self, tag):
        if self._open and tag in ("td", "span"):
            a, text = self._open.pop()
            self.cells.append((a, text.strip()))


def numbers_of(page: Path) -> _Numbers:
    p = _Numbers()
    p.feed(page.read_text())
    return p


def shown_value(text: str):
    """The number (or yes/no, or nothing) a cell's text shows, without its unit."""
    if text in ("yes", "no"):
        return text == "yes"
    if text == "—":
        return None
    m = re.match(r"^([-+]?(?:\d+\.?\d*|\.\d+)(?:e[-+]?\d+)?)", text)
    return float(m.group(1)) if m else text


def check_cell(attrs: dict, text: str, files: dict) -> None:
    """The cell's full value is the file's, and its text shows that value rounded."""
    source, key = attrs["data-source"], attrs["data-key"]
    raw = json.loads(attrs["data-value"])
    if source.endswith(".csv"):
        row, column = key.split(":")
        truth = files[source].loc[int(row), column]
        truth = None if pd.isna(truth) else float(truth)
        assert (raw is None and truth is None) or raw == truth, (source, key, raw, truth)
    else:
        truth = lookup(files[source], key)
        assert raw == truth, (source, key, raw, truth)
    shown = shown_value(text)
    if isinstance(truth, bool) or truth is None:
        assert shown == truth, (key, text, truth)
    elif isinstance(truth, int | float):
        # Four significant digits: within half a unit of the fourth.
        assert math.isclose(shown, truth, rel_tol=5.01e-4, abs_tol=0), (key, text, truth)
    else:
        assert text == str(truth), (key, text, truth)


def _load(path: Path):
    if path.suffix == ".csv":
        return pd.read_csv(path)
    if path.suffix == ".yaml":
        import yaml
        return yaml.safe_load(path.read_text())
    return json.loads(path.read_text())


def check_numbers(page: Path) -> int:
    """Every cell of ``page`` that names its file against that file (beside the page,
    or in its parent run directory for a trim/, tune/ or batch/ page); the number of
    cells checked."""
    p = numbers_of(page)
    files = {}
    for attrs, text in p.cells:
        name = attrs["data-source"]
        if name not in files:
            where = page.parent / name
            files[name] = _load(where if where.is_file() else page.parent.parent / name)
        check_cell(attrs, text, files)
    return len(p.cells)


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    """Three days with the EKF: daily.csv with three rows (the season figure), both
    filters' verdicts."""
    out = tmp_path_factory.mktemp("report") / "run"
    done = dynprop("run", "goes_next_equinox", "--duration-s", 3 * 86400, "--set",
                   "estimator.filters=[paper, ekf]", "--set", "report.yaw_requirement_deg=0.05",
                   "--out", out, "--report")
    assert done.returncode == 0, done.stderr
    return out


def test_every_number_on_the_page_is_the_files_value(run_dir):
    page = run_dir / "report.html"
    summary = json.loads((run_dir / "summary.json").read_text())
    files = {"summary.json": summary, "daily.csv": pd.read_csv(run_dir / "daily.csv")}
    assert check_numbers(page) > 150
    p = numbers_of(page)
    keys = {a["data-key"] for a, _ in p.cells if a["data-source"] != "scenario.yaml"}
    # Every scalar of summary.json is on the page, and every cell of daily.csv.
    from scenarios.review.cells import flatten
    assert {k for k, _ in flatten(summary) if not k.startswith(("checks", "warnings"))} <= keys
    daily = files["daily.csv"]
    assert len(daily) == 3
    assert {f"{r}:{c}" for r in range(len(daily)) for c in daily.columns} <= keys
    assert {f"yaw_error_at_gap_end_deg[{i}]" for i in range(len(
        summary["yaw_error_at_gap_end_deg"]))} <= keys


def test_the_verdicts_are_the_runs_own_and_the_requirement_is_judged(run_dir):
    summary = json.loads((run_dir / "summary.json").read_text())
    daily = pd.read_csv(run_dir / "daily.csv")
    verdicts = dict(numbers_of(run_dir / "report.html").verdicts)
    assert verdicts["Filter σ"] == ("met" if summary["checks"][
        "gap_end_yaw_within_3sigma"]["passed"] else "not met")
    assert verdicts["EKF σ"] == ("met" if summary["checks"][
        "ekf_gap_end_yaw_within_3sigma"]["passed"] else "not met")
    worst_end = max(abs(e) for e in summary["yaw_error_at_gap_end_deg"])
    assert verdicts["Paper, Eq. 56"] == ("met" if worst_end <= 0.12 else "not met")
    ok = 3 * daily["yaw_error_rms_deg"].max() <= 0.05 and worst_end <= 0.05
    assert verdicts["Requirement (3σ over 24 h)"] == ("met" if ok else "not met")


def _summary(ends=(0.01, -0.02), sigmas=(0.04, 0.04), passed=True):
    return {"yaw_error_at_gap_end_deg": list(ends), "yaw_sigma_at_gap_end_deg": list(sigmas),
            "checks": {"gap_end_yaw_within_3sigma": {"passed": passed, "detail": "d"}}}


def test_verdicts_are_met_not_met_or_not_tested_never_met_on_nothing():
    assert verdict.against_filter(_summary()).status == "met"
    assert verdict.against_filter(_summary(passed=False)).status == "not met"
    assert verdict.against_filter(_summary(passed=None)).status == "not tested"
    assert verdict.against_filter({"checks": {}}).status == "not tested"
    assert verdict.against_paper(_summary()).status == "met"
    assert verdict.against_paper(_summary(ends=(0.01, -0.121))).status == "not met"
    assert verdict.against_paper(_summary(ends=(), sigmas=())).status == "not tested"
    day = [(0, None, 0.01)]
    assert verdict.against_requirement(_summary(), None, day).status == "not tested"
    assert verdict.against_requirement(_summary(), 0.03, day).status == "met"
    # 3 × 0.011 = 0.033 > 0.033 - ε: the day's 3σ is beyond the line.
    assert verdict.against_requirement(_summary(), 0.0329, [(0, None, 0.011)]).status == \
        "not met"
    # A gap end beyond it fails the day that holds it, whatever the RMS.
    assert verdict.against_requirement(_summary(ends=(0.031,)), 0.03, day).status == "not met"
    assert verdict.against_requirement(_summary(ends=(), sigmas=()), 0.03, []).status == \
        "not tested"


def test_run_report_leaves_the_run_itself_unchanged(run_dir, tmp_path):
    """`run --report` adds report.html and nothing else: every other file is the
    bytes a run without it writes."""
    other = tmp_path / "plain"
    done = dynprop("run", run_dir / "scenario.yaml", "--out", other)
    assert done.returncode == 0, done.stderr
    names = sorted(p.relative_to(run_dir).as_posix() for p in run_dir.rglob("*") if p.is_file())
    assert "report.html" in names
    plain = sorted(p.relative_to(other).as_posix() for p in other.rglob("*") if p.is_file())
    assert plain == [n for n in names if n != "report.html"]
    for name in ("summary.json", "estimate.csv", "daily.csv", "comparison.npz"):
        assert (run_dir / name).read_bytes() == (other / name).read_bytes(), name


def test_the_api_writes_the_same_page(run_dir, tmp_path, monkeypatch):
    import dynprop as dp
    copy = tmp_path / "copy"
    shutil.copytree(run_dir, copy)
    (copy / "report.html").unlink()
    monkeypatch.setenv("SOURCE_DATE_EPOCH", "1790000000")
    path = dp.report(copy, yaw_requirement_deg=0.05)
    assert path == copy / "report.html"
    first = path.read_text()
    assert dp.open_run(copy).report(0.05).read_text() == first
    done = dynprop("report", copy, "--yaw-requirement-deg", "0.05")
    assert done.returncode == 0, done.stderr
    # The same page but for the command line it records.
    strip = re.compile(r"command line</td><td>[^<]*</td>")
    assert strip.sub("", path.read_text()) == strip.sub("", first)
    assert "2026-09-21T" in first   # SOURCE_DATE_EPOCH fixes the page's date


def _bad(tmp_path: Path, run_dir: Path, name: str) -> Path:
    d = tmp_path / name
    d.mkdir()
    for f in ("scenario.yaml", "summary.json", "comparison.npz", "estimate.csv"):
        shutil.copy(run_dir / f, d / f)
    return d


@pytest.mark.parametrize("case, expected", [
    ("empty", "not a directory dynprop wrote"),
    ("no_summary", "summary.json: missing: the run did not finish"),
    ("half_summary", "summary.json: not valid JSON (line"),
    ("foreign_summary", "summary.json: no key 'scenario'"),
    ("half_npz", "comparison.npz: not a readable .npz"),
    ("no_npz", "comparison.npz: missing (beside summary.json)"),
    ("file", "not a directory (give the directory"),
    ("bad_requirement", "--yaw-requirement-deg: -1 must be a positive"),
])
def test_bad_input_gets_one_line_exit_2_and_nothing_written(run_dir, tmp_path, case, expected):
    d = _bad(tmp_path, run_dir, case)
    extra = []
    if case == "empty":
        for p in d.iterdir():
            p.unlink()
        (d / "notes.txt").write_text("mine")
    elif case == "no_summary":
        (d / "summary.json").unlink()
    elif case == "half_summary":
        text = (d / "summary.json").read_text()
        (d / "summary.json").write_text(text[:len(text) // 2])
    elif case == "foreign_summary":
        (d / "summary.json").write_text('{"mine": 1}')
    elif case == "half_npz":
        data = (d / "comparison.npz").read_bytes()
        (d / "comparison.npz").write_bytes(data[:len(data) // 2])
    elif case == "no_npz":
        (d / "comparison.npz").unlink()
    elif case == "bad_requirement":
        extra = ["--yaw-requirement-deg", "-1"]
    (d / "report.html").write_text("the previous page")
    before = {p.name: p.read_bytes() for p in d.iterdir()}
    target = d / "summary.json" if case == "file" else d
    done = dynprop("report", target, *extra)
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and expected in lines[0], done.stderr
    assert "Traceback" not in done.stderr
    assert {p.name: p.read_bytes() for p in d.iterdir()} == before
