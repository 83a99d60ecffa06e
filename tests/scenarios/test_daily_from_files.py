"""daily.csv, comparison.npz's envelopes and ``RunResult.errors()`` recomputed from
the run's own files (docs/outputs.md), independently of the code that wrote them.

Only the CLI (``scenarios.cli.main``), the public API (``dynprop.run``) and the
files are used: estimate.csv, truth.csv, telemetry.csv, scenario.yaml and
comparison.npz.  Every figure is rebuilt here from its definition:

- day k holds the samples with t in [k, k+1) days; 86400 s is exactly 168750
  samples of 0.512 s, so a sample's day is its index // 168750 (integers, no
  rounding), and the run's last sample at exactly k days closes day k − 1;
- a Sun gap is a run of samples without a telemetry yaw at least
  ``estimator.sun_gap_min_h`` long; its end is the first sample with yaw again, and
  a day's gap is the longest one ending in it;
- a NEES sample is every 10th sample of the run (global index a multiple of 10).

Tolerances follow from the files' precision.  estimate.csv, truth.csv and daily.csv
hold 10 significant digits (%.10g: each value within 5e-10 of itself, relative), so
an error estimate − truth read from them is within 5e-10·(|estimate| + |truth|) of
the float64 one daily.csv was computed from (bound carried per sample below).
comparison.npz holds float32 (round to nearest: within 2⁻²⁴ relative of the float64
value it was rounded from).  daily.csv's own sums run in float64 over ≤ 168750
samples: ≤ 2e-11 relative, covered by SUM_REL.
"""

from __future__ import annotations

import contextlib
import io
from datetime import datetime, timedelta
from pathlib import Path

import numpy as np
import pytest
import yaml

import dynprop
from scenarios.cli import main
from scenarios.files.csvio import read_csv

from .test_cli_run import eq55_sigma_deg
from .test_sun_gaps import brute_force_gaps

DT = 0.512
N_DAY = 168_750            # samples per day: 86400 s / 0.512 s, exactly
THREE_DAYS_S = 3 * 86400
NEES_EVERY = 10            # NEES on every 10th sample of the run (docs/outputs.md)
CSV_REL = 5e-10            # %.10g
F32_REL = 2.0**-24         # float32, round to nearest
SUM_REL = 1e-10            # float64 sums over a day (≤ 168750 · 2⁻⁵³ ≈ 2e-11)
FULL_RATE = ("--set", f"output.interval_s={DT}", "--set", "output.telemetry=true")
# 00:00 local at 75° W: the night Sun gaps (~20:15–04:07 local) run 20.3–28.1 h and
# 44.3–52.1 h into the run, across the day (and window) boundaries at 24 h and 48 h.
EPOCH_05 = "epoch_utc=2026-03-20T05:00:00Z"
# Decimated rows every 128 samples (65.536 s): 168750 = 1318·128 + 46, so rows 1318
# and 2636 take samples from both sides of the window boundaries at 1 and 2 days.
STRIDE = 128


def run_cli(out: Path, duration_s: float, *extra: str) -> Path:
    """``dynprop run goes_next_equinox`` through ``main`` (stdout and stderr captured)."""
    o, e = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(o), contextlib.redirect_stderr(e):
        rc = main(["run", "goes_next_equinox", "--duration-s", str(duration_s),
                   "--out", str(out), *extra])
    assert rc == 0, e.getvalue()
    return out


@pytest.fixture(scope="module")
def full3(tmp_path_factory) -> Path:
    """Three days at every sample from 12:00 UTC: three one-day windows."""
    return run_cli(tmp_path_factory.mktemp("full3") / "run", THREE_DAYS_S, *FULL_RATE)


@pytest.fixture(scope="module")
def full3_05(tmp_path_factory) -> Path:
    """The same from 05:00 UTC: Sun gaps across the day and window boundaries."""
    return run_cli(tmp_path_factory.mktemp("full3_05") / "run", THREE_DAYS_S, *FULL_RATE,
                   "--set", EPOCH_05)


@pytest.fixture(scope="module")
def one_window_two_days(tmp_path_factory) -> Path:
    """30 h from 05:00 UTC: up to two days is one window, here holding two days and
    a Sun gap across midnight."""
    return run_cli(tmp_path_factory.mktemp("w30h") / "run", 30 * 3600, *FULL_RATE,
                   "--set", EPOCH_05)


@pytest.fixture(scope="module")
def decimated3():
    """The three days of ``full3`` (the same windows) at a row every 128 samples,
    through the public API."""
    s = dynprop.load_scenario("goes_next_equinox", duration_s=THREE_DAYS_S,
                              set={"output.interval_s": STRIDE * DT})
    return dynprop.run(s)


# ------------------------------------------------------------------ helpers


def yaw_gaps(present: np.ndarray, min_h: float) -> list[tuple[int, int]]:
    """(first sample without yaw, first sample with yaw again) of every outage of at
    least ``min_h`` that ends inside the run (``test_sun_gaps``'s one-sample-at-a-time
    definition)."""
    return [(a, b) for a, b in brute_force_gaps(present, DT, min_h) if b < len(present)]


def rms_with_bound(e: np.ndarray, bound: np.ndarray) -> tuple[float, float]:
    """RMS of ``e`` and how far it may be from the RMS of the exact values when each
    e_i is within bound_i of its own (Minkowski: |‖a‖ − ‖b‖| ≤ ‖a − b‖)."""
    return float(np.sqrt(np.mean(np.square(e)))), float(np.sqrt(np.mean(np.square(bound))))


def expected_daily(run: Path) -> tuple[dict, dict, dict]:
    """daily.csv recomputed from the run's full-rate files: (value, tolerance) column
    arrays, and what was found (``gaps``, ``day`` of each sample, ``n``)."""
    resolved = yaml.safe_load((run / "scenario.yaml").read_text())
    assert resolved["sample_interval_s"] == DT
    epoch = datetime.fromisoformat(resolved["epoch_utc"].replace("Z", "+00:00"))
    est, tru, tel = (read_csv(run / name) for name in ("estimate.csv", "truth.csv",
                                                       "telemetry.csv"))
    with np.load(run / "comparison.npz") as f:
        cmp = {k: f[k] for k in ("t_s", "yaw_present", "nees_real", "err_linear",
                                 "err_real_minus_linear")}
    n = len(tru["t_s"])
    idx = np.arange(n)
    # Every sample, from 0, in every file (t_s of the CSVs is 10-digit text).
    for t in (tru["t_s"], est["t_s"], tel["t_s"], cmp["t_s"]):
        assert np.array_equal(np.rint(t / DT), idx)
    n_days = max(1, -(-(n - 1) // N_DAY))        # the last sample closes its day
    day = np.minimum(idx // N_DAY, n_days - 1)

    err, bound = {}, {}
    for col in ("roll_deg", "yaw_deg", "h_Nms"):
        err[col] = est[col] - tru[col]
        bound[col] = CSV_REL * (np.abs(est[col]) + np.abs(tru[col]))
    err_lin_yaw = cmp["err_linear"][:, 2].astype(float)
    diff_yaw = cmp["err_real_minus_linear"][:, 1].astype(float)
    nees = cmp["nees_real"].astype(float)
    assert np.array_equal(np.isfinite(nees), idx % NEES_EVERY == 0)

    present = np.isfinite(tel["yaw_deg"])
    assert np.array_equal(present, cmp["yaw_present"] == 1)
    gaps = yaw_gaps(present, resolved["estimator"]["sun_gap_min_h"])
    # The longest gap ending in each day (the first of equals).
    day_gap: dict[int, tuple[int, int]] = {}
    for a, b in gaps:
        d = int(day[b])
        if d not in day_gap or b - a > day_gap[d][1] - day_gap[d][0]:
            day_gap[d] = (a, b)

    shadow = tru["shadow"]
    assert np.array_equal(shadow < 1.0, tru["eclipse"] == 1)
    eq55 = eq55_sigma_deg(resolved)

    cols = ("day", "day_of_year", "sun_gap_start_h", "sun_gap_end_h", "sun_gap_length_h",
            "gap_end_yaw_error_deg", "gap_end_yaw_sigma_deg", "eq55_sigma_yaw_deg",
            "eclipse_min", "roll_error_rms_deg", "yaw_error_rms_deg", "h_error_rms_Nms",
            "nees_mean", "yaw_error_rms_linear_deg", "yaw_error_rms_real_minus_linear_deg")
    want = {c: np.full(n_days, np.nan) for c in cols}
    tol = {c: np.zeros(n_days) for c in cols}
    for d in range(n_days):
        sel = day == d
        want["day"][d] = d
        want["day_of_year"][d] = (epoch + timedelta(days=d)).timetuple().tm_yday
        if d in day_gap:
            a, b = day_gap[d]
            want["sun_gap_start_h"][d] = a * DT / 3600
            want["sun_gap_end_h"][d] = b * DT / 3600
            want["sun_gap_length_h"][d] = (b - a) * DT / 3600
            want["gap_end_yaw_error_deg"][d] = err["yaw_deg"][b]
            tol["gap_end_yaw_error_deg"][d] = bound["yaw_deg"][b]
            want["gap_end_yaw_sigma_deg"][d] = est["sigma_yaw_deg"][b]
            # Both files print the same double to 10 digits: one rounding each.
            tol["gap_end_yaw_sigma_deg"][d] = CSV_REL * abs(est["sigma_yaw_deg"][b])
        # Eq. 55 from the scenario's q, H and ω0 here; the constants' last digits may
        # differ from the code's (as test_cli_run allows: 1e-6).
        want["eq55_sigma_yaw_deg"][d] = eq55
        tol["eq55_sigma_yaw_deg"][d] = 1e-6 * eq55
        want["eclipse_min"][d] = np.count_nonzero(shadow[sel] < 1.0) * DT / 60
        for name, col in (("roll_error_rms_deg", "roll_deg"), ("yaw_error_rms_deg", "yaw_deg"),
                          ("h_error_rms_Nms", "h_Nms")):
            want[name][d], tol[name][d] = rms_with_bound(err[col][sel], bound[col][sel])
        # From float32 values (each within 2⁻²⁴ of its float64): a mean of positive
        # numbers, or an RMS, keeps that relative bound.
        nd = nees[sel & (idx % NEES_EVERY == 0)]
        want["nees_mean"][d] = np.mean(nd)
        tol["nees_mean"][d] = F32_REL * want["nees_mean"][d]
        want["yaw_error_rms_linear_deg"][d] = np.sqrt(np.mean(np.square(err_lin_yaw[sel])))
        tol["yaw_error_rms_linear_deg"][d] = F32_REL * want["yaw_error_rms_linear_deg"][d]
        want["yaw_error_rms_real_minus_linear_deg"][d] = np.sqrt(np.mean(np.square(
            diff_yaw[sel])))
        tol["yaw_error_rms_real_minus_linear_deg"][d] = \
            F32_REL * want["yaw_error_rms_real_minus_linear_deg"][d]
        # The same from estimate.csv − truth.csv − err_linear: independent of the
        # float32 difference the npz holds (each term's own bound carried).
        rm, rb = rms_with_bound(err["yaw_deg"][sel] - err_lin_yaw[sel],
                                bound["yaw_deg"][sel] + F32_REL * np.abs(err_lin_yaw[sel]))
        from_npz = want["yaw_error_rms_real_minus_linear_deg"][d]
        assert abs(rm - from_npz) <= rb + tol["yaw_error_rms_real_minus_linear_deg"][d], \
            f"day {d}: real − linear yaw RMS {rm} from the CSVs, {from_npz} from the npz"
    for c in cols:
        # daily.csv's own 10 digits and its float64 sums.
        tol[c] = tol[c] + (CSV_REL + SUM_REL) * np.abs(np.nan_to_num(want[c]))
    return want, tol, {"gaps": gaps, "day": day, "n": n}


def assert_daily_matches(run: Path, expected=None) -> dict:
    """Every column of daily.csv against ``expected_daily``; returns what was found."""
    daily = read_csv(run / "daily.csv")
    want, tol, found = expected or expected_daily(run)
    assert list(daily) == list(want)
    for c in want:
        got = daily[c]
        assert len(got) == len(want[c]), f"{c}: {len(got)} rows, recomputed {len(want[c])}"
        assert np.array_equal(np.isnan(got), np.isnan(want[c])), \
            f"{c}: empty cells {np.isnan(got)} vs recomputed {np.isnan(want[c])}"
        ok = np.isnan(got) | (np.abs(got - want[c]) <= tol[c])
        assert ok.all(), (f"{c}: daily.csv {got.tolist()} vs recomputed "
                          f"{want[c].tolist()} (tolerance {tol[c].tolist()})")
    return found


# ------------------------------------------------------------------ daily.csv


def test_daily_csv_of_three_one_day_windows_is_recomputed_from_the_files(full3):
    found = assert_daily_matches(full3)
    # Three rows: the last sample, at exactly 3 days, closes day 2 (no fourth row).
    assert found["n"] == 3 * N_DAY + 1
    assert len(read_csv(full3 / "daily.csv")["day"]) == 3
    # One night gap ends in each day, each inside its day.
    assert [int(found["day"][b]) for _, b in found["gaps"]] == [0, 1, 2]


def test_daily_csv_files_a_gap_across_midnight_under_the_day_it_ends(full3_05):
    expected = expected_daily(full3_05)
    found = expected[2]
    day, gaps = found["day"], found["gaps"]
    across = [(a, b) for a, b in gaps if day[a] != day[b]]
    # The night gaps start before 24 h and 48 h (a day and a window boundary) and end
    # after them.
    assert len(across) >= 2, gaps
    daily = read_csv(full3_05 / "daily.csv")
    for a, b in across:
        assert day[b] == day[a] + 1 and a < day[b] * N_DAY <= b
        # Filed under the day it ends (the longest ending there), not where it starts.
        assert daily["sun_gap_end_h"][day[b]] == pytest.approx(b * DT / 3600, rel=1e-9), \
            f"the gap {a * DT / 3600:.4f}–{b * DT / 3600:.4f} h is not under day {day[b]}"
        assert daily["sun_gap_start_h"][day[b]] == pytest.approx(a * DT / 3600, rel=1e-9)
        assert np.isnan(daily["sun_gap_start_h"][day[a]]) \
            or daily["sun_gap_start_h"][day[a]] != pytest.approx(a * DT / 3600, rel=1e-9)
    assert_daily_matches(full3_05, expected)


def test_daily_csv_of_one_window_holding_two_days(one_window_two_days):
    found = assert_daily_matches(one_window_two_days)
    assert len(read_csv(one_window_two_days / "daily.csv")["day"]) == 2
    assert any(found["day"][a] == 0 and found["day"][b] == 1 for a, b in found["gaps"])


# ------------------------------------------------------------------ comparison.npz envelopes


def _blocks_reduce(v: np.ndarray, stride: int, op) -> np.ndarray:
    """op (np.fmin / np.fmax: NaN only where the whole block is) over samples
    i·stride … (i+1)·stride − 1 of each row i."""
    n_rows = -(-len(v) // stride)
    pad = np.full((n_rows * stride - len(v), *v.shape[1:]), np.nan, v.dtype)
    blocks = np.concatenate([v, pad]).reshape(n_rows, stride, *v.shape[1:])
    return op.reduce(blocks, axis=1)


def _differing_rows(got: np.ndarray, want: np.ndarray) -> list[int]:
    same = (got == want) | (np.isnan(got) & np.isnan(want))
    return np.flatnonzero(~same.reshape(len(got), -1).all(axis=1)).tolist()


def test_envelopes_of_rows_across_window_boundaries_hold_both_windows(full3, decimated3):
    with np.load(full3 / "comparison.npz") as f, \
            np.load(decimated3.path / "comparison.npz") as g:
        full, dec = dict(f), dict(g)
    n = len(full["t_s"])
    n_rows = -(-n // STRIDE)
    assert float(dec["output_interval_s"]) == STRIDE * DT
    assert np.array_equal(dec["t_s"], full["t_s"][::STRIDE])
    # The same duration: the same three one-day windows, so even what is per window
    # (the torque-state fit, the twin, NEES, the smoother) is the same in both runs.
    boundaries = [N_DAY, 2 * N_DAY]
    straddling = [b // STRIDE for b in boundaries if b % STRIDE]
    assert straddling == [1318, 2636]
    enveloped = ("err_real", "err_linear", "err_real_minus_linear", "err_smoothed",
                 "nees_real", "nees_linear", "err_pitch", "nees_pitch")
    assert set(full) | {f"{k}_{m}" for k in enveloped for m in ("min", "max")} \
        | {"output_interval_s"} == set(dec)
    for key in full:
        assert np.array_equal(dec[key], full[key][::STRIDE], equal_nan=True), key
    merged_matters = []
    for key in enveloped:
        for suffix, op in (("_min", np.fmin), ("_max", np.fmax)):
            want = _blocks_reduce(full[key], STRIDE, op)
            got = dec[key + suffix]
            assert got.shape == (n_rows, *full[key].shape[1:]), key + suffix
            for b in boundaries:
                r = b // STRIDE
                # The row's samples before the boundary b belong to the earlier window.
                late = op.reduce(full[key][b:(r + 1) * STRIDE], axis=0)
                assert np.array_equal(got[r], want[r], equal_nan=True), \
                    (f"{key}{suffix} row {r} across the window boundary: {got[r]} vs "
                     f"{want[r]} over both windows ({late} over the later one only)")
                merged_matters.append(not np.array_equal(late, want[r], equal_nan=True))
            bad = _differing_rows(got, want)
            assert not bad, f"{key}{suffix}: rows {bad[:10]} differ from the full-rate run's"
    # The earlier window's part decides some of those extremes: dropping it would show.
    assert sum(merged_matters) >= 10, merged_matters
    # The real filter's attitude and h errors do not even depend on the window cut.
    err = full["err_real"][:, :5]
    assert np.array_equal(dec["err_real_min"][:, :5], _blocks_reduce(err, STRIDE, np.fmin))
    assert np.array_equal(dec["err_real_max"][:, :5], _blocks_reduce(err, STRIDE, np.fmax))


# ------------------------------------------------------------------ RunResult.errors()


def test_errors_are_the_estimate_minus_the_truth_of_the_run_files(decimated3):
    errors = decimated3.errors()
    est = read_csv(decimated3.path / "estimate.csv")
    tru = read_csv(decimated3.path / "truth.csv")
    np.testing.assert_allclose(errors.index.to_numpy(), est["t_s"], rtol=1e-12, atol=1e-9)
    with np.load(decimated3.path / "comparison.npz") as f:
        twin = f["err_linear"].astype(float)
    for k, col in ((0, "roll_deg"), (2, "yaw_deg"), (4, "h_Nms")):
        want = est[col] - tru[col]
        # errors() is float32 (within 2⁻²⁴ of the float64 error); the files' 10 digits
        # put estimate − truth within 5e-10·(|estimate| + |truth|) of it.
        bound = CSV_REL * (np.abs(est[col]) + np.abs(tru[col]))
        tol = F32_REL * (np.abs(want) + bound) + bound
        got = errors[col].to_numpy()
        excess = np.abs(got - want) - tol
        worst = int(np.argmax(excess))
        assert np.all(excess <= 0), \
            (f"{col}: errors() {got[worst]} vs estimate − truth {want[worst]} at "
             f"t = {est['t_s'][worst]} s (tolerance {tol[worst]})")
        # The linear twin's roll and yaw errors are outside that tolerance on most
        # rows, so errors() returning them instead could not pass (h is measured by
        # the tachometers: the twin's h error is the real one to ~1e-12 N m s).
        if col != "h_Nms":
            assert np.mean(np.abs(twin[:, k] - want) > tol) > 0.9, col
