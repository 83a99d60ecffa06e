"""One rule for where a Sun-gap end is judged (docs/outputs.md, issue 43 item 5).

The reference is the run itself: its summary's gap-end error, computed from the truth
at every sample in the streamed engine.  `estimate --truth` and `batch` read the same
telemetry and truth from files; with a truth at every sample they must print the same
filter gap-end yaw error, to the printed digits (four decimals of a degree), and with a
coarser truth say the sample they judged, and both the same one.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from scenarios.files.csvio import read_csv

from .mc_helpers import run_cli

ERROR = re.compile(r"[+-]\d\.\d{4}")


@pytest.fixture(scope="module")
def full_rate(gap_run, tmp_path_factory) -> dict:
    """`estimate --truth` and `batch --model linear` on the session's 13 h full-rate
    run (truth at every sample): name -> (stdout, summary or batch.json)."""
    tmp = tmp_path_factory.mktemp("gapend")
    rc, est_out, err = run_cli("estimate", gap_run / "telemetry.csv", "--scenario",
                               gap_run / "scenario.yaml", "--truth", gap_run / "truth.csv",
                               "--out", tmp / "est")
    assert rc == 0, err
    rc, batch_out, err = run_cli("batch", gap_run, "--model", "linear", "--span-h", "13",
                                 "--out", tmp / "batch")
    assert rc in (0, 1), err
    return {"estimate": (est_out, json.loads((tmp / "est" / "summary.json").read_text())),
            "batch": (batch_out, json.loads((tmp / "batch" / "batch.json").read_text()))}


def test_full_rate_truth_gives_the_runs_gap_end_error_in_every_command(gap_run, full_rate):
    run = json.loads((gap_run / "summary.json").read_text())
    expected = [f"{e:+.4f}" for e in run["yaw_error_at_gap_end_deg"]]
    assert len(expected) == 1                              # the night gap's end
    est_out, est = full_rate["estimate"]
    batch_out, batch = full_rate["batch"]
    line = next(x for x in est_out.splitlines() if "Sun-gap ends" in x)
    assert ERROR.findall(line.split("at Sun-gap ends")[1].split("deg")[0]) == expected, line
    filt = re.search(r"filter gap-end yaw ([^;]*) deg", batch_out)
    assert filt is not None, batch_out
    assert ERROR.findall(filt.group(1)) == expected, batch_out
    # Judged at the same sample: the first with a Sun-sensor yaw again.
    t = read_csv(gap_run / "telemetry.csv")
    gap_end_t = batch["truth"]["gap_end_t_s"]
    assert batch["truth"]["gap_end_judged_at_t_s"] == gap_end_t
    assert est["telemetry"]["gap_end_compared_at_s"] == gap_end_t
    k = int(((t["t_s"] - gap_end_t[0]) ** 2).argmin())
    assert t["yaw_deg"][k] == t["yaw_deg"][k] and t["yaw_deg"][k - 1] != t["yaw_deg"][k - 1]


def test_batch_gives_each_gap_ends_yaw_and_its_difference_from_the_filter(full_rate):
    """Truth or none, batch.json and the console give the batch's and the filter's yaw
    and σ at each gap end and their difference, the filter's as estimate.csv has it."""
    batch_out, batch = full_rate["batch"]
    (g,) = batch["gap_ends"]
    assert g["t_s"] == batch["truth"]["gap_end_t_s"][0]
    assert g["batch_minus_filter_deg"] == pytest.approx(
        g["batch_yaw_deg"] - g["filter_yaw_deg"], abs=1e-12)
    est = read_csv(Path(batch["telemetry"]["file"]).parent / "estimate.csv")
    k = int(abs(est["t_s"] - g["t_s"]).argmin())
    assert est["t_s"][k] == pytest.approx(g["t_s"], abs=1e-6)
    # estimate.csv holds 10 significant digits.
    assert g["filter_yaw_deg"] == pytest.approx(est["yaw_deg"][k], rel=1e-9, abs=1e-12)
    assert g["filter_sigma_deg"] == pytest.approx(est["sigma_yaw_deg"][k], rel=1e-9)
    assert f"batch yaw {g['batch_yaw_deg']:+.4f} ± {g['batch_sigma_deg']:.4f}" in batch_out
    assert f"batch − filter {g['batch_minus_filter_deg']:+.4f}" in batch_out


def test_coarse_truth_each_command_says_the_sample_it_judged(gap_run, tmp_path):
    """The same run's truth every 64 s (as a run writes it by default): `estimate
    --truth` and `batch --truth` judge each gap end at the same truth row, the last
    inside the gap before the end, and both print it."""
    lines = (gap_run / "truth.csv").read_text().splitlines(keepends=True)
    body = [x for x in lines if not x.startswith("#")]
    header, rows = body[0], body[1:]
    coarse = tmp_path / "truth64.csv"
    coarse.write_text("".join(x for x in lines if x.startswith("#")) + header
                      + "".join(rows[::125]))          # 125 × 0.512 s = 64 s
    rc, est_out, err = run_cli("estimate", gap_run / "telemetry.csv", "--scenario",
                               gap_run / "scenario.yaml", "--truth", coarse,
                               "--out", tmp_path / "est")
    assert rc == 0, err
    rc, batch_out, err = run_cli("batch", gap_run / "telemetry.csv", "--scenario",
                                 gap_run / "scenario.yaml", "--truth", coarse, "--model",
                                 "linear", "--span-h", "13", "--out", tmp_path / "batch")
    assert rc in (0, 1), err
    est = json.loads((tmp_path / "est" / "summary.json").read_text())["telemetry"]
    tr = json.loads((tmp_path / "batch" / "batch.json").read_text())["truth"]
    truth_t = read_csv(coarse)["t_s"]
    (end,) = tr["gap_end_t_s"]
    expected = float(truth_t[truth_t < end].max())       # the last truth row before it
    assert est["gap_end_compared_at_s"] == [expected]
    assert tr["gap_end_judged_at_t_s"] == [expected]
    assert f"t = {expected:.3f} s" in est_out
    assert f"judged at the truth's t = {expected:.3f} s" in batch_out
