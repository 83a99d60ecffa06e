"""`estimator.filters: [paper, ekf]` in a streamed `dynprop run`: the EKF continues
across window boundaries exactly, the paper filter's outputs do not change by
running a second filter beside it, and every new file, key and column is
documented."""

from __future__ import annotations

import json

import numpy as np
import pytest

from .test_outputs_doc import _spans, csv_columns, json_keys, undocumented
from .test_stream import _run

GAP_EPOCH = "epoch_utc=2026-03-20T22:00:00Z"   # the night Sun gap 3.25–11.1 h in
FULL = ["duration_s=46800", GAP_EPOCH, "output.interval_s=0.512"]
BOTH = "estimator.filters=[paper, ekf]"


@pytest.fixture(scope="module")
def runs(gap_run, tmp_path_factory):
    """The paper filter alone (the session's ``gap_run``, FULL's settings), and with the
    EKF beside it in one window and in two."""
    return {"paper": (gap_run, json.loads((gap_run / "summary.json").read_text())),
            "one": _run(tmp_path_factory, "one", [*FULL, BOTH]),
            "many": _run(tmp_path_factory, "many", [*FULL, BOTH], window_samples=45_000,
                         processes=2)}


def test_the_ekf_continues_across_windows_exactly(runs):
    one, many = runs["one"][0], runs["many"][0]
    assert (one / "estimate_ekf.csv").read_bytes() == (many / "estimate_ekf.csv").read_bytes()


def test_a_second_filter_changes_nothing_of_the_papers(runs):
    paper, both = runs["paper"][0], runs["one"][0]
    for name in ("estimate.csv", "truth.csv", "telemetry.csv"):
        assert (paper / name).read_bytes() == (both / name).read_bytes()
    a, b = runs["paper"][1], runs["one"][1]
    for key in ("yaw_error_rms_deg", "yaw_error_at_gap_end_deg", "nees_mean"):
        assert a[key] == b[key]
    assert a["filters"] == ["paper"] and b["filters"] == ["paper", "ekf"]


def test_the_ekf_summary_near_earth_pointing(runs):
    s = runs["one"][1]
    e = s["ekf"]
    assert len(e["yaw_error_at_gap_end_deg"]) == 1
    assert e["yaw_within_3sigma_at_gap_ends"]
    # Near Earth pointing the two filters' σ at the gap end agree within 20% (issue 16).
    np.testing.assert_allclose(e["yaw_sigma_at_gap_end_deg"], s["yaw_sigma_at_gap_end_deg"],
                               rtol=0.2)
    # Its innovations are the paper filter's where both measure (yaw's NIS is small in
    # both: the DSS variance is inflated for its correlated quantization), and pitch's,
    # which only the EKF uses, are consistent.
    for m in ("roll", "yaw", "h"):
        assert e["nis_mean"][m] == pytest.approx(s["nis_mean"][m], rel=0.1)
    assert 0.5 < e["nis_mean"]["pitch"] < 2.0


def test_new_files_keys_and_columns_are_documented(runs):
    out, summary = runs["one"]
    spans = _spans()
    assert not undocumented(csv_columns(out / "estimate_ekf.csv"), spans)
    assert not undocumented(sorted(json_keys(summary)), spans)
    with np.load(out / "comparison.npz") as c:
        assert {"err_ekf", "sigma_ekf"} <= set(c.files)
        assert not undocumented(sorted(c.files), spans)
    assert json.loads((out / "summary.json").read_text())["ekf"]["backend"]


def test_estimate_on_the_runs_telemetry_reproduces_the_ekf(runs, tmp_path):
    """`dynprop estimate` with the run's scenario runs the EKF too, on the file's
    doubles: the same estimate_ekf.csv, byte for byte (every sample written by both)."""
    from .test_cli_run import run_cli
    one = runs["one"][0]
    rc, _, err = run_cli("estimate", str(one / "telemetry.csv"), "--scenario",
                         str(one / "scenario.yaml"), "--out", str(tmp_path / "est"))
    assert rc == 0, err
    assert (tmp_path / "est" / "estimate_ekf.csv").read_bytes() == \
        (one / "estimate_ekf.csv").read_bytes()
    summary = json.loads((tmp_path / "est" / "summary.json").read_text())
    assert summary["filters"] == ["paper", "ekf"] and summary["ekf"]["nees_mean"] is None
    # Without the Earth sensor's pitch the EKF cannot run: one line, exit 2.
    text = [line for line in (one / "telemetry.csv").read_text().splitlines()
            if not line.startswith("#")]
    head = text[0].split(",")
    k = head.index("pitch_deg")
    rows = [",".join(c for i, c in enumerate(line.split(",")) if i != k) for line in text]
    (tmp_path / "nopitch.csv").write_text("\n".join(rows) + "\n")
    rc, _, err = run_cli("estimate", str(tmp_path / "nopitch.csv"), "--scenario",
                         str(one / "scenario.yaml"), "--out", str(tmp_path / "never"))
    assert rc == 2 and err.count("\n") == 1 and "pitch_deg" in err
    assert not (tmp_path / "never").exists()
