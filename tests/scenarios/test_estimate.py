"""`dynprop estimate` on telemetry as a ground system delivers it: dropouts, other
cadences, no pitch column; with `--truth`, the errors and summary `run` computes;
and a directory `dynprop plot` redraws."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from scenarios.files.csvio import read_csv

from .test_cli_run import run_cli

DT = 0.512
STATES = ("roll_deg", "roll_rate_degps", "yaw_deg", "yaw_rate_degps", "h_Nms", "N_px_Nm",
          "N_pz_Nm", "N_cx_Nm", "N_cz_Nm")
# truth.csv holds 10 significant digits: errors recomputed from it agree with the
# run's (computed from doubles) to ~5e-10 of the values that enter them.
CSV_REL = 5e-10


def _rows(run: Path) -> tuple[str, list[str]]:
    lines = [line for line in (run / "telemetry.csv").read_text().splitlines(keepends=True)
             if not line.startswith("#")]   # the epoch comment: a file is read without it
    return lines[0], lines[1:]


def _t(line: str) -> float:
    return float(line.split(",", 1)[0])


def _with_dropouts(run: Path, path: Path) -> Path:
    """The done-when file: every 10th row removed, and a 10-minute dropout in a lit
    period (2 h into the run, before the night gap)."""
    head, rows = _rows(run)
    keep = [r for i, r in enumerate(rows) if i % 10 != 9
            and not 7200.0 <= _t(r) < 7800.0]
    path.write_text(head + "".join(keep))
    return path


def _estimate(tmp_path: Path, telemetry: Path, run: Path, *extra: str):
    out = tmp_path / "est"
    rc, stdout, err = run_cli("estimate", str(telemetry), "--scenario",
                              str(run / "scenario.yaml"), "--out", str(out), *extra)
    assert rc == 0, err
    return out, stdout


@pytest.fixture(scope="module")
def dropout_estimate(gap_run, tmp_path_factory):
    tmp = tmp_path_factory.mktemp("dropouts")
    path = _with_dropouts(gap_run, tmp / "telemetry.csv")
    return _estimate(tmp, path, gap_run, "--truth", str(gap_run / "truth.csv"))


def test_dropouts_match_the_run_within_the_filters_sigma(gap_run, dropout_estimate):
    """With 10% of the rows gone and a 10-minute hole, the estimate differs from the
    run's (all rows) by what the missing data were worth: the difference of two
    estimates of the same state, one with a subset of the data, has variance
    σ²_subset − σ²_all ≤ σ²_subset, so |difference|/σ_subset is at most N(0, 1)-like.
    Asserted: RMS ≤ 1 and max ≤ 5 over the run, for every state."""
    out, _ = dropout_estimate
    full, sparse = read_csv(gap_run / "estimate.csv"), read_csv(out / "estimate.csv")
    assert np.array_equal(sparse["t_s"], full["t_s"])  # a row at every filter step
    for name in STATES:
        z = (sparse[name] - full[name]) / sparse[f"sigma_{name}"]
        assert np.sqrt(np.mean(z**2)) <= 1.0, name
        assert np.max(np.abs(z)) <= 5.0, name
    # Across the 10-minute hole the covariance grows, and shrinks again after it.
    sig = sparse["sigma_h_Nms"]
    before, inside, after = (sig[np.searchsorted(sparse["t_s"], t)] for t in
                             (7199.0, 7790.0, 8400.0))
    assert inside > 10 * before and after < 2 * before


def test_dropout_summary_says_what_the_telemetry_held(gap_run, dropout_estimate):
    out, stdout = dropout_estimate
    s = json.loads((out / "summary.json").read_text())
    tel = s["telemetry"]
    n = len(_rows(gap_run)[1])
    assert tel["filter_steps"] == n
    missing_hole = round(600 / DT)
    assert tel["rows"] == tel["filter_steps"] - tel["missing_steps"]
    assert tel["missing_steps"] == pytest.approx(n / 10 + missing_hole * 0.9, abs=2)
    assert tel["longest_dropout_s"] == pytest.approx(600, abs=2 * DT)
    assert "dropouts" in stdout and "wrote" in stdout and "estimate.csv" in stdout


def test_truth_gives_the_runs_summary(gap_run, tmp_path):
    """`estimate --truth` on the run's own telemetry: every figure `run` computes
    without the linear twin, recomputed from truth.csv (10 digits) instead of the
    run's doubles; the linear-twin figures are null."""
    out, _ = _estimate(tmp_path, gap_run / "telemetry.csv", gap_run,
                       "--truth", str(gap_run / "truth.csv"))
    ours = json.loads((out / "summary.json").read_text())
    run = json.loads((gap_run / "summary.json").read_text())
    assert set(ours) - {"telemetry"} == set(run)
    assert ours["truth"] and not ours["linear_twin"] and run["linear_twin"]
    for key in ("yaw_error_rms_linear_deg", "yaw_error_linear_at_gap_end_deg",
                "nonlinear_vs_linear", "nees_mean_linear", "nees_fraction_inside_95_linear",
                "nis_mean_linear"):
        assert ours[key] is None, key
    for key in ("yaw_error_rms_deg", "roll_error_rms_deg", "h_error_rms_Nms",
                "yaw_error_rms_smoothed_deg", "nees_mean", "nees_fraction_inside_95"):
        # An RMS or mean of errors ~1e-3 of the values whose 5e-10 they carry: 1e-6.
        assert ours[key] == pytest.approx(run[key], rel=1e-6), key
    assert ours["yaw_error_at_gap_end_deg"] == pytest.approx(run["yaw_error_at_gap_end_deg"],
                                                             rel=1e-6)
    for name, v in run["nees_mean_per_state"].items():
        assert ours["nees_mean_per_state"][name] == pytest.approx(v, rel=1e-5), name
    # The filter itself saw the same doubles: its own figures are identical.
    for key in ("yaw_sigma_at_gap_end_deg", "sun_gaps_h", "nis_mean",
                "analytic_sigma_yaw_deg"):
        assert ours[key] == run[key], key


def test_without_truth_the_error_figures_are_null_and_plot_redraws(gap_run, tmp_path):
    """No truth: the filter's own figures only; `dynprop plot` on the directory
    redraws exactly the files estimate drew."""
    head, rows = _rows(gap_run)
    k = head.rstrip("\n").split(",").index("pitch_deg")
    drop_pitch = "".join(",".join(f for i, f in enumerate(line.rstrip("\n").split(","))
                                  if i != k) + "\n" for line in [head, *rows])
    path = tmp_path / "no_pitch.csv"
    path.write_text(drop_pitch)
    out, stdout = _estimate(tmp_path, path, gap_run)
    s = json.loads((out / "summary.json").read_text())
    assert s["truth"] is False and s["yaw_error_rms_deg"] is None and s["nees_mean"] is None
    assert s["nis_mean"]["roll"] > 0 and len(s["yaw_sigma_at_gap_end_deg"]) == 1
    assert {p.name for p in out.iterdir()} == {"scenario.yaml", "estimate.csv", "smoothed.csv",
                                                "summary.json", "comparison.npz", "daily.csv",
                                                "plots"}
    drawn = {p.name: p.stat().st_mtime_ns for p in (out / "plots").iterdir()}
    assert drawn
    rc, plotted, err = run_cli("plot", str(out))
    assert rc == 0, err
    assert {Path(p).name for p in plotted.split()} == set(drawn)


def test_a_coarser_cadence_is_every_other_sample_missing(gap_run, tmp_path):
    """1.024 s telemetry (every other row): accepted, estimated on the 0.512 s grid,
    and within the filter's σ of the full-rate run."""
    head, rows = _rows(gap_run)
    path = tmp_path / "slow.csv"
    path.write_text(head + "".join(rows[::2]))
    out, _ = _estimate(tmp_path, path, gap_run)
    full, slow = read_csv(gap_run / "estimate.csv"), read_csv(out / "estimate.csv")
    assert len(slow["t_s"]) == len(full["t_s"]) - (len(rows) % 2 == 0)
    for name in ("roll_deg", "yaw_deg", "h_Nms"):
        n = len(slow["t_s"])
        z = (slow[name] - full[name][:n]) / slow[f"sigma_{name}"]
        assert np.sqrt(np.mean(z**2)) <= 1.0, name
