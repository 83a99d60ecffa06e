"""`dynprop estimate` on what `dynprop run` writes at its default output cadence
(issue 29 item 5): the run's own truth.csv (every 64 s) is compared at the rows
both have, estimate's files keep the scenario's output cadence, and `--set`
overrides the scenario as `run`'s does (after `--tuned-from`)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from scenarios.files.csvio import read_csv

from .test_cli_run import GAP_EPOCH, run_cli

# Whole commands checked for their wiring: the compiled pass runs them (conftest).
pytestmark = pytest.mark.surface

DT = 0.512
ROW_S = 64.0                       # output.interval_s by default: 125 samples
SIX_H = 21600


def _run(tmp_path_factory, name: str, *argv: str) -> Path:
    out = tmp_path_factory.mktemp(name) / "run"
    rc, _, err = run_cli("run", "goes_next_equinox", *argv, "--out", str(out))
    assert rc == 0, err
    return out


@pytest.fixture(scope="module")
def gap_run(tmp_path_factory) -> Path:
    """13 h holding the whole night Sun gap and its end, default output cadence."""
    return _run(tmp_path_factory, "fitgap", "--duration-s", "46800", "--set", GAP_EPOCH)


def _estimate(out: Path, run: Path, *extra: str, telemetry: Path | None = None):
    return run_cli("estimate", str(telemetry or run / "telemetry.csv"), "--scenario",
                   str(run / "scenario.yaml"), "--out", str(out), *extra)


def _summary(d: Path) -> dict:
    return json.loads((d / "summary.json").read_text())


def _rms(a) -> float:
    return float(np.sqrt(np.mean(np.square(a, dtype=float))))


def test_a_runs_truth_is_compared_at_the_rows_both_have(run6, tmp_path):
    """The run's truth.csv, every 64 s, against the filter at 0.512 s: accepted, and the
    errors are those at the 64 s rows.  The same filter on the same telemetry gives the
    run's estimate.csv byte for byte, so the errors are the run's own at those rows
    (its comparison.npz, float32: ~6e-8 relative per value; truth.csv's 10 digits move
    an error by ≤ 5e-10 of the value, 1e-7 of h's errors): RMS to 1e-6 relative."""
    out = tmp_path / "est"
    rc, stdout, err = _estimate(out, run6, "--truth", str(run6 / "truth.csv"))
    assert rc == 0, err
    n_rows = math.ceil(SIX_H / DT / (ROW_S / DT))    # rows 0, 125, 250, … of 42188 samples
    s = _summary(out)
    tel = s["telemetry"]
    assert tel["truth_rows"] == tel["compared_rows"] == n_rows
    assert tel["compared_cadence_s"] == pytest.approx(ROW_S)
    assert f"errors on the {n_rows} samples the truth has a row for, every 64 s" in stdout
    assert (out / "estimate.csv").read_bytes() == (run6 / "estimate.csv").read_bytes()
    c = np.load(run6 / "comparison.npz")
    assert len(c["t_s"]) == n_rows
    for key, k, scale in (("yaw_error_rms_deg", 2, 1.0), ("roll_error_rms_deg", 0, 1.0),
                          ("h_error_rms_Nms", 4, 1.0)):
        assert s[key] == pytest.approx(_rms(c["err_real"][:, k]) * scale, rel=1e-6), key
    # NEES on every common row, against the same covariance: near the run's, whose rows
    # are every 10th sample (the χ²(9) mean of 338 values has a 2.5% spread; the
    # filter here is conservative, NEES ~2.6, so 25% is a loose but real bound).
    assert s["nees_mean"] == pytest.approx(_summary(run6)["nees_mean"], rel=0.25)


def test_no_gap_end_is_no_verdict(run6, tmp_path):
    """6 h hold no Sun-gap end: nothing to judge there, so null (never true) and the
    console says it was not tested rather than printing "none"."""
    out = tmp_path / "est"
    rc, stdout, err = _estimate(out, run6, "--truth", str(run6 / "truth.csv"))
    assert rc == 0, err
    s = _summary(out)
    assert s["yaw_error_at_gap_end_deg"] == [] and s["yaw_sigma_at_gap_end_deg"] == []
    assert s["yaw_within_3sigma_at_gap_ends"] is None
    assert "Sun-gap-end yaw not tested (no Sun-gap end in the run)" in stdout
    assert "none" not in stdout


def test_the_files_keep_the_output_cadence(run6, tmp_path):
    """estimate.csv and smoothed.csv: a row every output.interval_s (64 s), as the
    run's; `--set output.interval_s=0.512` gives every sample again.  The summary's
    figures stay full rate: the filter's σ at the end is the same either way."""
    out = tmp_path / "est"
    rc, _, err = _estimate(out, run6)
    assert rc == 0, err
    n_samples = round(SIX_H / DT)
    for name in ("estimate.csv", "smoothed.csv"):
        t = read_csv(out / name)["t_s"]
        assert len(t) == math.ceil(n_samples / 125), name
        assert np.allclose(t, ROW_S * np.arange(len(t)), rtol=0, atol=1e-6), name
    assert _summary(out)["output_interval_s"] == pytest.approx(ROW_S)
    full = tmp_path / "full"
    rc, _, err = _estimate(full, run6, "--set", f"output.interval_s={DT}")
    assert rc == 0, err
    assert len(read_csv(full / "smoothed.csv")["t_s"]) == n_samples
    assert _summary(full)["nis_mean"] == _summary(out)["nis_mean"]


def test_a_longer_dropout_warns_and_set_raises_the_level(run6, tmp_path):
    """A 2 h hole is over estimator.max_gap_s (1 h): filtered across, with a warning
    naming the key; `--set estimator.max_gap_s=7300` raises the level, and the
    estimate is the same."""
    lines = (run6 / "telemetry.csv").read_text().splitlines(keepends=True)
    head = [r for r in lines if r.startswith("#")] + [lines[sum(r.startswith("#")
                                                             for r in lines)]]
    rows = lines[len(head):]
    keep = [r for r in rows if not 7200.0 < float(r.split(",", 1)[0]) < 14400.0]
    path = tmp_path / "hole.csv"
    path.write_text("".join(head) + "".join(keep))
    rc, out, err = _estimate(tmp_path / "warned", run6, telemetry=path)
    assert rc == 0, err
    warned = _summary(tmp_path / "warned")
    assert warned["telemetry"]["longest_dropout_s"] == pytest.approx(7200.0, abs=2 * DT)
    assert [w["check"] for w in warned["warnings"]].count("telemetry_gaps") == 1
    assert "longer than estimator.max_gap_s" in out
    rc, out, err = _estimate(tmp_path / "ok", run6, "--set", "estimator.max_gap_s=7300",
                             telemetry=path)
    assert rc == 0, err
    ok = _summary(tmp_path / "ok")
    assert "telemetry_gaps" not in [w["check"] for w in ok["warnings"]]
    assert ok["yaw_error_rms_deg"] == warned["yaw_error_rms_deg"]


def test_set_wins_over_tuned_from(run6, tmp_path):
    """`--tuned-from` sets the process noise, `--set` after it overrides one key of it."""
    rc, _, err = run_cli("tune", str(run6), "--params", "q_x,q_z,q_w", "--out",
                         str(tmp_path / "tune"))
    assert rc == 0, err
    tuned = json.loads((tmp_path / "tune" / "tune.json").read_text())
    out = tmp_path / "est"
    rc, _, err = _estimate(out, run6, "--tuned-from", str(tmp_path / "tune"), "--set",
                           "estimator.process_noise.q_x=3e-11")
    assert rc == 0, err
    q = yaml.safe_load((out / "scenario.yaml").read_text())["estimator"]["process_noise"]
    assert q["q_x"] == pytest.approx(3e-11)
    assert q["q_w"] == tuned["tuned_process_noise"]["q_w"] != 5e-10   # tuned, not the scenario's
    assert _summary(out)["process_noise"]["source"] == "tuned"


def _truth_without(run: Path, path: Path, drop) -> Path:
    lines = (run / "truth.csv").read_text().splitlines(keepends=True)
    path.write_text(lines[0] + "".join(r for r in lines[1:]
                                       if not drop(float(r.split(",", 1)[0]))))
    return path


def test_gap_end_between_truth_rows(gap_run, tmp_path):
    """The gap end (about 40037.9 s) falls between 64 s truth rows: judged at the last
    row before it, inside the gap, where the filter's yaw σ is that of the end within
    1%; there the error is the run's own gap-end error (full rate, from doubles) to
    0.2 σ (the module's bound: ~2% of σ² of change from that row to the end).  With
    no truth row in the gap's last 3 hours the end is not tested: null, no verdict."""
    run = _summary(gap_run)
    (b_h,) = [end for _, end in run["sun_gaps_h"]]
    out = tmp_path / "est"
    rc, stdout, err = _estimate(out, gap_run, "--truth", str(gap_run / "truth.csv"))
    assert rc == 0, err
    s = _summary(out)
    (at,) = s["telemetry"]["gap_end_compared_at_s"]
    assert at == ROW_S * math.floor(b_h * 3600 / ROW_S) < b_h * 3600
    (e,), (sig,) = s["yaw_error_at_gap_end_deg"], s["yaw_sigma_at_gap_end_deg"]
    assert sig == run["yaw_sigma_at_gap_end_deg"][0]
    assert abs(e - run["yaw_error_at_gap_end_deg"][0]) <= 0.2 * sig
    assert s["yaw_within_3sigma_at_gap_ends"] is True and "within 3 sigma" in stdout

    truth = _truth_without(gap_run, tmp_path / "sparse.csv",
                           lambda t: b_h * 3600 - 3 * 3600 < t < b_h * 3600 + 3600)
    out = tmp_path / "untested"
    rc, stdout, err = _estimate(out, gap_run, "--truth", str(truth))
    assert rc == 0, err
    s = _summary(out)
    assert s["yaw_error_at_gap_end_deg"] == [None]
    assert s["telemetry"]["gap_end_compared_at_s"] == [None]
    assert s["yaw_within_3sigma_at_gap_ends"] is None
    assert s["yaw_sigma_at_gap_end_deg"] == run["yaw_sigma_at_gap_end_deg"]
    assert ("Sun-gap-end yaw not tested (no truth row close enough to any Sun-gap end)"
            in stdout)


def test_no_common_row_says_how_to_get_one(run6, tmp_path):
    """A truth whose times are all off the filter's grid (0.3 s late, far beyond the
    5e-10 its 10 digits allow) has no row to compare: one line, exit 2, naming what
    writes a truth that works."""
    lines = (run6 / "truth.csv").read_text().splitlines(keepends=True)
    shifted = [f"{float(r.split(',', 1)[0]) + 0.3!r},{r.split(',', 1)[1]}" for r in lines[1:]]
    path = tmp_path / "late.csv"
    path.write_text(lines[0] + "".join(shifted))
    rc, _, err = _estimate(tmp_path / "est", run6, "--truth", str(path))
    assert rc == 2 and len(err.strip().splitlines()) == 1, err
    assert "no row at a time of the telemetry's filter grid" in err
    assert "dynprop simulate" in err and "output.interval_s" in err
    assert not (tmp_path / "est").exists()
