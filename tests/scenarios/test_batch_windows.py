"""`dynprop batch` and `dynprop trim` read span by span and window by window (issue
44), held to the whole read as reference on the 13 h ``gap_run`` (every sample, its
night Sun gap 3.25–11.1 h in), cut as a month is cut but in hours (``Windows``):
boundaries inside the Sun gap, inside a dropout, and (``block_rows``) the reader's
blocks.  The whole read is the code as it was for a file of up to two days; the
smoother's reference is the whole filter's history smoothed by ``rts_smoother``
over each window and the stretch after it."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from estimator.linear.transition import discretize
from scenarios.batch.histories import histories_at
from scenarios.batch.report import run_batch
from scenarios.bridge.inputs import telemetry_inputs
from scenarios.config import build
from scenarios.config.loader import load_scenario
from scenarios.files.csvio import read_csv
from scenarios.files.telemetry_source import open_source
from scenarios.run.filtering import design_of, head, paper_smoother
from scenarios.run.whole import filter_telemetry
from scenarios.run.windowed import ArraySource, Windows
from scenarios.trim.batch import choose_batch, estimate_kappa, kappa_from_source
from scenarios.trim.report import run_trim

pytestmark = pytest.mark.slow_in_vm

HOUR = 3600.0
# Two-hour windows (boundaries at 2, 4, … h: three inside the Sun gap) and 4 h spans
# reaching 1 h back (epochs at 3, 6, 9 h: two inside the gap).
SMALL = Windows(whole_s=0.0, window_s=2 * HOUR)
SPANS = {"model": "linear", "span_h": 4.0, "overlap_h": 1.0}
# A dropout of every column across the 4 h window boundary and the reader's blocks.
DROPOUT_S = (4 * HOUR - 40.0, 4 * HOUR + 70.0)


def _batch(tel: Path, run: Path, out: Path, windows=None, **kw) -> tuple[dict, bytes]:
    """`dynprop batch TELEMETRY --scenario RUN/scenario.yaml` at 64 s rows (the file's
    every sample would be written and drawn otherwise)."""
    d, _ = run_batch(tel, run / "scenario.yaml", ["output.interval_s=64"], out=out,
                     windows=windows, **{**SPANS, **kw})
    return d, (out / "estimate_batch.csv").read_bytes()


def test_batch_in_spans_and_windows_is_the_whole_read_bit_for_bit(gap_run, tmp_path):
    """Each span's data formed from its own padded samples, and the filter and smoother
    in 2 h windows carrying the prior (the smoother, 12 h past each window, reaching
    this 13 h record's end from every one): batch.json and estimate_batch.csv are the
    whole read's to the bit."""
    tel = gap_run / "telemetry.csv"
    whole = _batch(tel, gap_run, tmp_path / "whole")
    streamed = _batch(tel, gap_run, tmp_path / "streamed", SMALL, block_rows=5000)
    assert streamed[0] == whole[0]
    assert streamed[1] == whole[1]
    d = whole[0]
    assert [b["epoch_s"] for b in d["batches"]][:4] == pytest.approx(
        [0.0, 3 * HOUR, 6 * HOUR, 9 * HOUR], abs=0.6)
    assert d["batches"][1]["overlap"]["samples"] > 0 and len(d["gap_ends"]) == 1


def test_the_smoother_runs_over_each_window_and_the_stretch_after_it(gap_run, tmp_path):
    """With 1 h of look-ahead the streamed smoother is, at every row of a window, the
    RTS smoother of the whole filter's history up to 1 h past that window (sample 0 to
    there: the backward pass never reads what is before the window); the filter is the
    whole filter, bit for bit."""
    s = load_scenario(gap_run / "scenario.yaml")
    windows = Windows(whole_s=0.0, window_s=2 * HOUR, overlap_s=HOUR)
    source = open_source(gap_run / "telemetry.csv", s, tmp_path)
    t = source.columns(0, source.n, ["t_s"])["t_s"]
    rows = np.arange(0, source.n, 97)
    h = histories_at(s, source, t, rows, windows)
    cols = read_csv(gap_run / "telemetry.csv")
    params, noise = build.estimator_model(s)
    disc = discretize(params, noise, s.sample_interval_s)
    real, args = filter_telemetry(s, params, disc, *telemetry_inputs(s, cols))
    np.testing.assert_array_equal(h.filter_x, real.x[rows])
    np.testing.assert_array_equal(h.filter_sigma, real.sigma[rows])
    # 2 h windows in time, each from the first sample at or after its start; the
    # last, 13 h − 12 h, joins the one before.
    n, look = len(t), int(round(HOUR / s.sample_interval_s))
    starts = [int(i) for i in np.searchsorted(t, 2 * HOUR * np.arange(6))]
    for a, b in zip(starts, starts[1:] + [n], strict=True):
        e = min(n, b + look)
        ref = paper_smoother(design_of(s), head(real, e), disc, u=args["u"][:e],
                             extra=args["extra"])
        mine = (rows >= a) & (rows < b)
        np.testing.assert_array_equal(h.smoother_x[mine], ref.x[rows[mine]])
        np.testing.assert_array_equal(h.smoother_sigma[mine], ref.sigma[rows[mine]])
    # Not the whole smoother: the look-ahead is short enough to matter somewhere.
    whole = paper_smoother(design_of(s), real, disc, **args)
    assert not np.array_equal(h.smoother_x, whole.x[rows])


@pytest.fixture(scope="module")
def dropout_file(gap_run, tmp_path_factory) -> Path:
    """gap_run's telemetry with every value but the tags blank over ``DROPOUT_S``, and
    beside it its truth every 64 s (truth.csv)."""
    folder = tmp_path_factory.mktemp("dropout")
    frame = pd.read_csv(gap_run / "telemetry.csv", comment="#")
    blank = (frame["t_s"] > DROPOUT_S[0]) & (frame["t_s"] < DROPOUT_S[1])
    values = [c for c in frame.columns if c not in ("t_s", "time_utc")]
    frame.loc[blank, values] = np.nan
    frame.to_csv(folder / "telemetry.csv", index=False, na_rep="", float_format="%.17g")
    truth = pd.read_csv(gap_run / "truth.csv", comment="#")
    truth.iloc[::125].to_csv(folder / "truth.csv", index=False, float_format="%.17g")
    return folder / "telemetry.csv"


def test_a_dropout_across_span_and_window_boundaries(gap_run, dropout_file, tmp_path):
    """The nonlinear batch with a dropout across the 4 h window boundary, read in
    blocks that end inside it: each span's data reach out to the wheel readings either
    side of the dropout, so the batches are the whole read's bit for bit; the filter's
    dropout noise is measured on its window (as `run`'s), so it differs there, by
    less than a thousandth of σ in yaw."""
    kw = {"truth": dropout_file.parent / "truth.csv", "model": "nonlinear", "span_h": 6.0,
          "overlap_h": 0.0}
    whole = _batch(dropout_file, gap_run, tmp_path / "whole", **kw)
    streamed = _batch(dropout_file, gap_run, tmp_path / "streamed", SMALL, block_rows=7031,
                      **kw)
    assert streamed[1] == whole[1]
    assert streamed[0]["batches"] == whole[0]["batches"]
    assert streamed[0]["truth"]["batch"] == whole[0]["truth"]["batch"]
    (w,), (m,) = whole[0]["gap_ends"], streamed[0]["gap_ends"]
    assert m["batch_yaw_deg"] == w["batch_yaw_deg"]
    assert abs(m["filter_yaw_deg"] - w["filter_yaw_deg"]) < 1e-3 * w["filter_sigma_deg"]


def _trim_copy(run: Path, where: Path) -> Path:
    where.mkdir()
    for name in ("scenario.yaml", "truth.csv", "estimate.csv", "summary.json"):
        shutil.copy(run / name, where)
    (where / "telemetry.csv").symlink_to(run / "telemetry.csv")
    return where


def test_trim_in_windows_is_the_whole_read_bit_for_bit(gap_run, tmp_path):
    """`trim` filtering the 13 h in 1 h windows (boundaries inside the Sun gap) keeps
    the filter's rows and its end state to the bit: trim.json is the whole read's."""
    whole = run_trim(_trim_copy(gap_run, tmp_path / "whole"))
    streamed = run_trim(_trim_copy(gap_run, tmp_path / "streamed"),
                        windows=Windows(whole_s=0.0, window_s=HOUR), block_rows=4000)
    assert streamed == whole
    assert whole["batch"]["duration_h"] == pytest.approx(13.0, abs=1e-3)


def test_trim_windows_of_a_part_with_a_dropout(gap_run, dropout_file):
    """A batch from 1 h to 12 h of the dropout file in 30 min windows against
    ``estimate_kappa`` on the whole columns: its padding stays inside the batch and
    reaches across the dropout, so the figure's rows are the whole filter's before the
    dropout, and κ̂ agrees to 1e-4 of σ (measured 2e-6: the dropout's noise is measured
    on its window), σ to 1e-6."""
    s = load_scenario(gap_run / "scenario.yaml")
    cols = read_csv(dropout_file)
    batch = choose_batch(cols["t_s"], s.sample_interval_s, HOUR, 12 * HOUR)
    whole = estimate_kappa(s, cols, batch)
    part = kappa_from_source(s, ArraySource(cols), batch,
                             windows=Windows(whole_s=0.0, window_s=HOUR / 2))
    np.testing.assert_array_equal(part.rows_t_s, whole.rows_t_s)
    before = whole.rows_t_s < DROPOUT_S[0]
    np.testing.assert_array_equal(part.torque_xz[before], whole.torque_xz[before])
    assert abs(part.fit.kappa_Nm - whole.fit.kappa_Nm) < 1e-4 * whole.fit.sigma_Nm
    assert part.fit.sigma_Nm == pytest.approx(whole.fit.sigma_Nm, rel=1e-6)
    assert json.dumps(part.rec.move) == json.dumps(whole.rec.move)
