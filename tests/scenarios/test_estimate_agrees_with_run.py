"""`dynprop estimate` and `dynprop run` are one engine (issue 44): on a 3-day run's
telemetry.csv (three windows of a day), with the run's scenario.yaml, estimate
writes the run's estimate.csv byte for byte, the daily.csv columns it can form
without a truth byte for byte, and every comparison.npz key the two share array
for array.  With the run's truth.csv (every ``output.interval_s``), its errors are
the run's at those rows to the truth file's own precision (10 significant
digits) and the float32 the errors are stored in.

The reference is the run itself: its files come from the simulation's own arrays,
the estimate's from the text of telemetry.csv and truth.csv read back.
"""

from __future__ import annotations

import numpy as np
import pytest

from scenarios.cli import main
from scenarios.files.csvio import read_csv

DAYS3 = "259200"
# Columns of daily.csv that need no truth (the rest are the run's errors and its
# shadow, empty in an estimate without --truth).
OWN_DAILY = ("day", "day_of_year", "sun_gap_start_h", "sun_gap_end_h", "sun_gap_length_h",
             "gap_end_yaw_sigma_deg", "eq55_sigma_yaw_deg")


def _cli(*argv) -> None:
    import contextlib
    import io
    err = io.StringIO()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
        rc = main(list(argv))
    assert rc == 0, err.getvalue()


@pytest.fixture(scope="module", params=[
    "64", pytest.param("0.512", marks=pytest.mark.slow_in_vm)], ids=["default", "every_sample"])
def pair(request, tmp_path_factory):
    """A 3-day run (output.interval_s 64 s, or every sample) and `estimate` on its
    telemetry.csv, without and with its truth.csv."""
    tmp = tmp_path_factory.mktemp("agree")
    run, est, tru = tmp / "run", tmp / "est", tmp / "tru"
    _cli("run", "goes_next_equinox", "--duration-s", DAYS3, "--set", "output.telemetry=true",
         "--set", f"output.interval_s={request.param}", "--out", str(run))
    tel, scen = str(run / "telemetry.csv"), str(run / "scenario.yaml")
    _cli("estimate", tel, "--scenario", scen, "--out", str(est))
    _cli("estimate", tel, "--scenario", scen, "--truth", str(run / "truth.csv"),
         "--out", str(tru))
    return run, est, tru


def test_estimate_csv_is_the_runs_byte_for_byte(pair):
    run, est, tru = pair
    assert (est / "estimate.csv").read_bytes() == (run / "estimate.csv").read_bytes()
    assert (tru / "estimate.csv").read_bytes() == (run / "estimate.csv").read_bytes()


def test_daily_csv_columns_without_a_truth_are_the_runs(pair):
    run, est, _ = pair
    a, b = read_csv(run / "daily.csv"), read_csv(est / "daily.csv")
    assert list(a) == list(b) and len(a["day"]) == 3
    for key in OWN_DAILY:
        assert np.array_equal(a[key], b[key], equal_nan=True), key
    # What needs the truth is empty, never made up: the errors, and the eclipse.
    for key in ("yaw_error_rms_deg", "gap_end_yaw_error_deg", "eclipse_min"):
        assert np.isnan(b[key]).all(), key


def test_comparison_npz_shares_the_runs_arrays(pair):
    run, est, _ = pair
    a, b = np.load(run / "comparison.npz"), np.load(est / "comparison.npz")
    shared = set(a) & set(b)
    assert {"t_s", "x_real", "sigma", "nis_real", "x_pitch", "tel_yaw_deg"} <= shared
    assert set(b) <= set(a)          # nothing of its own beside the run's keys
    for key in shared:
        assert np.array_equal(a[key], b[key], equal_nan=True), key


def test_with_the_truth_the_errors_are_the_runs_at_its_rows(pair):
    run, _, tru = pair
    a, b = np.load(run / "comparison.npz"), np.load(tru / "comparison.npz")
    assert np.array_equal(a["t_s"], b["t_s"])
    # Roll, its rate, yaw, its rate, h: their truth is the file's row.  (The torque
    # states' truth is a fit per window, on the truth's rows, not every sample.)
    for key, cols in (("err_real", slice(0, 5)), ("true_euler_deg", slice(None))):
        x, y = a[key][:, cols].astype(float), b[key][:, cols].astype(float)
        # %.10g in truth.csv (5e-10 of the angle) and float32 storage (6e-8 of the error).
        assert np.all(np.abs(x - y) <= 1.2e-7 * np.abs(x) + 1e-9 * np.abs(a["truth_model"][
            :, cols] if key == "err_real" else x) + 1e-12), key
    da, db = read_csv(run / "daily.csv"), read_csv(tru / "daily.csv")
    ok = np.isfinite(da["yaw_error_rms_deg"])
    assert ok.all() and np.isfinite(db["yaw_error_rms_deg"]).all()
    # Over the truth's rows (every 64 s, or every sample), the daily RMS is the run's
    # to its sampling: within a few percent at 64 s, to rounding at every sample.
    assert np.allclose(db["yaw_error_rms_deg"], da["yaw_error_rms_deg"], rtol=0.2)
