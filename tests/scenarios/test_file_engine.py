"""`dynprop estimate` through the run's engine in small windows (issue 44): the
window boundaries fall inside the Sun gap, inside a wheel dropout longer than the
padding, and between jittered tags.

Identity is the requirement on the grid: the filter carries its prior across a
boundary and each window's inputs are derived over padding that reaches the
nearest wheel reading, so the filtered estimate and σ, the Sun gaps and the σ at
their ends are those of the file filtered in one window, bit for bit.  Off the
grid the wheel torque N_w* is resampled to the file's cadence per window
(``preprocess.wheel_torque_at``: its running integral starts at the window's first
sample), which moves it by rounding only; the bound below says how far the
estimate may move for that.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from scenarios.commands import estimate_into
from scenarios.config.loader import load_scenario
from scenarios.files.csvio import read_csv, write_csv

SMALL = 20_000     # samples per window: 4 boundaries in the 13 h run, 2 in its Sun gap


def _estimate(tmp_path, name, s, path, window_samples=None):
    stage = tmp_path / name
    stage.mkdir()
    summary = estimate_into(s, path, None, stage, window_samples)
    return stage, summary


def _telemetry(gap_run):
    cols = read_csv(gap_run / "telemetry.csv")
    return {k: v for k, v in cols.items() if k != "time_utc"}


@pytest.fixture(scope="module")
def holed(gap_run, tmp_path_factory):
    """gap_run's telemetry with every row of 39 000–41 499 removed (a 21 min dropout
    across the boundary at 40 000, inside the Sun gap, longer than the padding) and
    wheel 1 blank in 59 990–60 400 (across the boundary at 60 000)."""
    cols = _telemetry(gap_run)
    n = len(cols["t_s"])
    keep = np.ones(n, bool)
    keep[39_000:41_500] = False
    cols["wheel1_rpm"] = cols["wheel1_rpm"].copy()
    cols["wheel1_rpm"][59_990:60_400] = np.nan
    path = tmp_path_factory.mktemp("holed") / "telemetry.csv"
    write_csv(path, {k: v[keep] for k, v in cols.items()})
    return path


def test_small_windows_on_the_grid_give_the_one_window_filter_bit_for_bit(gap_run, holed,
                                                                          tmp_path):
    s = load_scenario(gap_run / "scenario.yaml")
    one, s1 = _estimate(tmp_path, "one", s, holed)
    many, sn = _estimate(tmp_path, "many", s, holed, SMALL)
    a, b = read_csv(one / "estimate.csv"), read_csv(many / "estimate.csv")
    assert list(a) == list(b)
    for key in a:
        assert np.array_equal(a[key], b[key], equal_nan=True), key
    for key in ("sun_gaps_h", "yaw_sigma_at_gap_end_deg"):
        assert s1[key] == sn[key], key
    # A mean over windows is summed window by window: its last bits follow the order.
    for m, v in s1["nis_mean"].items():
        assert sn["nis_mean"][m] == pytest.approx(v, rel=1e-12)
    da, db = read_csv(one / "daily.csv"), read_csv(many / "daily.csv")
    for key in ("sun_gap_start_h", "sun_gap_end_h", "gap_end_yaw_sigma_deg"):
        assert np.array_equal(da[key], db[key], equal_nan=True), key
    # The dropout is in the summary as the file has it, and the windows did cross it.
    assert sn["telemetry"]["longest_dropout_s"] > 1000
    assert json.loads((many / "summary.json").read_text())["daily"] == "daily.csv"


@pytest.fixture(scope="module")
def jittered(gap_run, tmp_path_factory):
    """gap_run's telemetry with ±50 ms of jitter on every tag but the first, 10% of
    the rows dropped and a 30 min hole across the boundary at 60 000: off the grid."""
    cols = _telemetry(gap_run)
    rng = np.random.default_rng(44)
    n = len(cols["t_s"])
    t = cols["t_s"] + rng.uniform(-0.05, 0.05, n)
    t[0] = cols["t_s"][0]
    keep = rng.random(n) > 0.1
    keep[[0, -1]] = True
    keep[59_000:62_500] = False
    cols["t_s"] = t
    path = tmp_path_factory.mktemp("jitter") / "telemetry.csv"
    write_csv(path, {k: v[keep] for k, v in cols.items()})
    return path


def test_small_windows_off_the_grid_step_across_each_boundary(gap_run, jittered, tmp_path):
    s = load_scenario(gap_run / "scenario.yaml")
    one, s1 = _estimate(tmp_path, "one", s, jittered)
    many, sn = _estimate(tmp_path, "many", s, jittered, SMALL * 9 // 10)
    a, b = read_csv(one / "estimate.csv"), read_csv(many / "estimate.csv")
    assert np.array_equal(a["t_s"], b["t_s"])
    # The gaps are found in time across the boundaries, as in one window.
    assert s1["sun_gaps_h"] == sn["sun_gaps_h"]
    for key in ("yaw", "roll"):
        dev = np.max(np.abs(a[f"{key}_deg"] - b[f"{key}_deg"]) / a[f"sigma_{key}_deg"])
        # Per window by design: the q_w of a dropout bridge is measured on the window's
        # own samples (``preprocess.dropout_wheel_noise_at``), and N_w*'s running
        # integral starts at the window's first sample (rounding); measured 1.3e-6 σ.  A
        # step across a boundary taken wrong (the window's own last step repeated over
        # the 30 min hole) moves it by 3e-3 σ.
        assert dev < 1e-4, (key, dev)


def _late_defect(gap_run, tmp_path, row: int, column: str, value: str):
    """gap_run's telemetry.csv with one cell of a data row near the end replaced."""
    lines = (gap_run / "telemetry.csv").read_text().splitlines(keepends=True)
    head = next(i for i, line in enumerate(lines) if not line.startswith("#"))
    names = lines[head].rstrip("\n").split(",")
    cells = lines[head + 1 + row].rstrip("\n").split(",")
    cells[names.index(column)] = value
    lines[head + 1 + row] = ",".join(cells) + "\n"
    path = tmp_path / "late.csv"
    path.write_text("".join(lines))
    return path, row + 2    # as the messages number rows: the header is row 1


@pytest.mark.parametrize("column,value,says", [
    ("t_s", "100.0", "time tags must increase"),
    ("sun_head", "7", "must be 0 (dss), 1 (cass1) or 2 (cass2)"),
])
def test_a_defect_late_in_the_file_is_one_line_and_nothing_written(gap_run, tmp_path, column,
                                                                    value, says):
    """A file that goes bad near its end (its last window) is refused before anything
    is written: one line, exit 2, no output directory and no stage left beside it."""
    from tests.scenarios.mc_helpers import run_cli
    n = len(read_csv(gap_run / "telemetry.csv", only=["t_s"])["t_s"])
    path, file_row = _late_defect(gap_run, tmp_path, n - 100, column, value)
    out = tmp_path / "out"
    rc, _, err = run_cli("estimate", path, "--scenario", gap_run / "scenario.yaml",
                         "--out", out)
    assert rc == 2 and err.count("\n") == 1 and says in err, err
    if column == "t_s":
        assert f"row {file_row}" in err
    assert not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["late.csv"]
