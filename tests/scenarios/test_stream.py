"""`dynprop run` streamed in windows (``scenarios.run.stream``: windows, stages, directory;
``scenarios.run``: tally, daily; files.decimate).

Identity is the requirement for what does not depend on the window cut: the truth,
its telemetry and the real filter continue across a window boundary exactly as in
one long array (carried rollout state, generators and filter prior; the wheel-torque
derivative on padded windows).  What is per window by design (the torque-state fit,
hence the twin and NEES, and the smoother's overlap) is checked against the
one-window run with tolerances saying how far it may move.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from estimator.linear.model import Y
from scenarios.config.loader import load_scenario
from scenarios.files.csvio import read_csv
from scenarios.run.stream.directory import stream_to_directory

HOUR = 3600.0
# 17:00 local at 75° W on the equinox: the night Sun gap (~20:08–04:00 local) falls
# 3.25–11.1 h into the run; midnight (the eclipse) 7 h in.
GAP_EPOCH = "epoch_utc=2026-03-20T22:00:00Z"


def _run(tmp_path_factory, name, overrides, window_samples=None, processes=1):
    s = load_scenario("goes_next_equinox", overrides)
    out = tmp_path_factory.mktemp(name)
    summary = stream_to_directory(s, out, window_samples=window_samples, processes=processes,
                                  progress=False)
    return out, summary


# The session's gap_run (tests/conftest.py): telemetry.csv is written (up to two days).
FULL = ["duration_s=46800", GAP_EPOCH, "output.interval_s=0.512"]


@pytest.fixture(scope="module")
def one_window(gap_run):
    """The 13 h in one window: the session's ``gap_run`` (`dynprop run` with FULL's
    settings, the producer in its own process) and its summary."""
    return gap_run, json.loads((gap_run / "summary.json").read_text())


@pytest.fixture(scope="module")
def windows(tmp_path_factory):
    # Two windows (6.4 h, 6.6 h): the boundary inside the Sun gap, at the eclipse; the
    # producer in its own process, as `dynprop run` runs it.
    return _run(tmp_path_factory, "many", FULL, window_samples=45_000, processes=2)


@pytest.fixture(scope="module")
def decimated(tmp_path_factory):
    return _run(tmp_path_factory, "dec", ["duration_s=46800", GAP_EPOCH,
                                          "output.interval_s=64"], window_samples=45_000)


@pytest.mark.parametrize("name", ["truth.csv", "telemetry.csv", "estimate.csv"])
def test_windows_continue_the_truth_telemetry_and_filter_exactly(one_window, windows, name):
    assert (one_window[0] / name).read_bytes() == (windows[0] / name).read_bytes()


def test_per_window_figures_stay_close_to_the_one_window_run(one_window, windows):
    a, b = one_window[1], windows[1]
    # The filter and the truth's attitude are identical; only the order of the sums
    # changes (a few ulps).
    for key in ("yaw_error_rms_deg", "roll_error_rms_deg", "h_error_rms_Nms"):
        assert b[key] == pytest.approx(a[key], rel=1e-12)
    assert b["sun_gaps_h"] == a["sun_gaps_h"] and len(a["sun_gaps_h"]) == 1
    assert b["yaw_error_at_gap_end_deg"] == a["yaw_error_at_gap_end_deg"]
    assert b["yaw_sigma_at_gap_end_deg"] == a["yaw_sigma_at_gap_end_deg"]
    assert b["nis_mean"] == pytest.approx(a["nis_mean"], rel=1e-12)
    # The linear twin resets its torque states to each window's fit at the boundary
    # (6.4 h, at the eclipse; 4.7 h before the gap's end): its state differs by the
    # fit's change.
    # Its gap-end error moves by 9.67e-8° (1.7e-6 of the filter's σ, 0.056°): the same
    # 9.67284844600319e-8 compiled and in the VM with the other OpenBLAS kernel, the
    # fit's effect, not rounding.  2e-7°, twice it (keeping the torque states carried
    # over instead moves it by 2.9e-3°, 0.05 σ).
    for x, y in zip(a["yaw_error_linear_at_gap_end_deg"], b["yaw_error_linear_at_gap_end_deg"],
                    strict=True):
        assert abs(x - y) < 2e-7
    # The smoother's overlap (12 h) covers the whole second window (6.6 h): both runs
    # smooth backwards from the run's last filtered state through the same steps on
    # the same inputs (by construction the same operations), so the smoothed yaw is
    # the same bits and only the sum of squares is added in another order (a few ulps;
    # measured equal on both backends).  A restart 3 h into the second window moves the
    # RMS by 4.8 %, one at the boundary by 4.0 % (a restart inside a window longer than
    # the overlap: the next test).
    assert b["yaw_error_rms_smoothed_deg"] == pytest.approx(a["yaw_error_rms_smoothed_deg"],
                                                            rel=1e-12)
    with np.load(one_window[0] / "comparison.npz") as f, \
            np.load(windows[0] / "comparison.npz") as g:
        assert np.array_equal(f["err_smoothed"][:, Y], g["err_smoothed"][:, Y])
    # The NEES's "true" torque states are fitted per window: the mean moves by −0.189 %
    # (−1.8886164e-3 compiled and VM + other kernel alike, agreeing to 1e-16): the
    # fit's effect, not rounding.  Twice it.
    assert b["nees_mean"] == pytest.approx(a["nees_mean"], rel=4e-3)


def _whole_run_filter(s):
    """The paper's filter over the run in one window with its covariance history and
    inputs (``stages.filtered``'s record, before the smoother lightens it)."""
    from scenarios.run.stream import stages, windows
    from scenarios.run.stream.producer import producer
    demux = windows.Demux(producer(s))
    records = stages.filtered(s, demux.reals())
    next(records)
    (rec,) = records
    demux.drain()
    return rec.real, (rec.u, rec.extra)


def test_the_smoother_restarts_inside_a_window_longer_than_its_overlap():
    """Two days cut into 14.2 h windows (the last 19.6 h): a window's smoother runs
    over the next window's first 12 h (``plan.overlap``) from the filtered estimate
    there, inside the next window; the last window's from the run's end.  Each
    window's smoothed states are those of the whole-run smoother over [window + its
    overlap] (the same steps on the same filtered states and inputs: bit for bit), and
    stay within a small part of σ of the whole run's smoother."""
    # The smoother's API as the stream imports it (``estimator.kalman`` would be a
    # second copy of the module).
    from dynprop.estimator.kalman.filter import ExtraNoise, FilterResult, rts_smoother
    from dynprop.estimator.linear.transition import discretize

    from scenarios.config import build
    from scenarios.run.stream.windows import windows_of

    s = load_scenario("goes_next_equinox", ["duration_s=172800", GAP_EPOCH])
    records = windows_of(s, window_samples=100_000)
    plan = next(records)
    smoothed = [w.smoothed_x for w in records]
    n = plan.n_samples
    assert plan.bounds == [(0, 100_000), (100_000, 200_000), (200_000, n)]
    assert plan.overlap == 84_375 < 100_000    # the restart is inside the next window

    real, (u, extra) = _whole_run_filter(s)
    params, noise = build.estimator_model(s)
    disc = discretize(params, noise, s.sample_interval_s)

    def smoother(a, b):
        """The whole-run filter's history [a, b) smoothed, from its filtered end."""
        part = FilterResult(real.x[a:b], real.P_packed[a:b], real.innovations[a:b],
                            real.innovation_var[a:b], real.x_next, real.P_next, real.backend)
        return rts_smoother(part, disc, u=u[a:b], covariance=False,
                            extra=None if extra is None else ExtraNoise(extra.scale[a:b],
                                                                        extra.Qd_unit)).x

    for (a, b), x in zip(plan.bounds[:-1], smoothed, strict=False):
        ref = smoother(a, b + plan.overlap)[:b - a]
        same = np.array_equal(x, ref)
        assert same, f"window [{a}, {b}): {np.max(np.abs(x - ref)):.3g} off its overlap's smoother"
    whole = smoother(0, n)
    # The last window smooths from the run's end, as the whole run: the same bits.
    assert np.array_equal(smoothed[-1], whole[plan.bounds[-1][0]:])
    # The earlier windows restart 12 h into the next one, where the filtered yaw is up
    # to 0.5 σ from the smoothed: their estimates differ from the whole run's.
    assert not np.array_equal(smoothed[0], whole[:100_000])
    # How far, in the filter's σ of yaw at each sample: at most 0.0196 σ, 5.4 h in (in
    # rad at most 1.55e-5, 7.2 h in): inside the first Sun gap, 21 h before its
    # window's restart, not at a boundary (3.5e-3 σ at the first window's last sample,
    # 9.4e-3 σ at the second's): yaw unobserved there rests on the torque states, whose
    # restart error decays slowest.  Compiled and VM + other OpenBLAS kernel alike (the
    # differences agree to 3e-17 rad): the restart's effect, not rounding.  0.03 σ, 1.5
    # times it.  (A 3 h overlap gives 0.0265 σ, a restart at the boundary 0.124 σ; the
    # identity above is what pins the overlap.)
    dyaw = np.concatenate(smoothed)[:, Y] - whole[:, Y]
    worst = np.max(np.abs(dyaw) / real.sigma[:, Y])
    assert worst < 0.03, f"the windows' smoothed yaw is {worst:.4f} σ off the whole run's"


def test_decimated_rows_are_the_full_rate_samples_and_envelopes_hold_the_peaks(
        one_window, decimated):
    with np.load(one_window[0] / "comparison.npz") as f, \
            np.load(decimated[0] / "comparison.npz") as d:
        full, dec = dict(f), dict(d)
    stride = 125  # 64 s / 0.512 s
    assert float(dec["output_interval_s"]) == 64.0
    assert np.array_equal(dec["t_s"], full["t_s"][::stride])
    for key in ("x_real", "sigma", "true_euler_deg", "tel_yaw_deg", "yaw_present"):
        assert np.array_equal(dec[key], full[key][::stride], equal_nan=True), key
    # The real filter's attitude and h errors do not depend on windows (the torque
    # states' "truth" is fitted per window): rows and envelopes exactly.
    n = len(dec["t_s"])
    err = full["err_real"][:, :5]
    pad = n * stride - len(err)
    blocks = np.concatenate([err, np.full((pad, 5), np.nan, np.float32)]).reshape(n, stride, 5)
    assert np.array_equal(dec["err_real"][:, :5], err[::stride])
    assert np.array_equal(dec["err_real_min"][:, :5], np.nanmin(blocks, axis=1))
    assert np.array_equal(dec["err_real_max"][:, :5], np.nanmax(blocks, axis=1))
    # The largest yaw error of the run falls between two rows and still shows.
    k = int(np.nanargmax(np.abs(err[:, 2])))
    assert k % stride != 0
    assert np.nanmax(np.abs(dec["err_real_max"][:, 2])) >= abs(err[k, 2]) \
        or np.nanmin(dec["err_real_min"][:, 2]) <= err[k, 2]
    # NEES spikes: the envelope covers every computed NEES.
    assert np.nanmax(dec["nees_real_max"]) == pytest.approx(np.nanmax(full["nees_real"]),
                                                            rel=0.5)


def test_decimated_csvs_hold_the_rows_at_the_output_interval(one_window, decimated):
    for name in ("truth.csv", "estimate.csv"):
        full, dec = read_csv(one_window[0] / name), read_csv(decimated[0] / name)
        assert np.array_equal(dec["t_s"], full["t_s"][::125])
        assert np.array_equal(dec["yaw_deg"], full["yaw_deg"][::125], equal_nan=True)
    # auto: a 13 h run writes its telemetry; the summary says so.
    assert (decimated[0] / "telemetry.csv").exists()
    assert json.loads((decimated[0] / "summary.json").read_text())["telemetry_written"]


def test_daily_rows_count_the_eclipse_and_the_gap_end(one_window):
    run, s = one_window
    daily = read_csv(run / "daily.csv")
    assert len(daily["day"]) == 1 and daily["day_of_year"][0] == 79   # 2026-03-20
    truth = read_csv(run / "truth.csv")
    eclipse_min = np.sum(truth["shadow"] < 1.0) * 0.512 / 60
    assert 60 < eclipse_min < 80            # the equinox eclipse, ~70 min
    # daily.csv holds 10 significant digits (each value within 5e-10 of itself).
    assert daily["eclipse_min"][0] == pytest.approx(eclipse_min, rel=1e-9)
    for col, key in (("gap_end_yaw_error_deg", "yaw_error_at_gap_end_deg"),
                     ("gap_end_yaw_sigma_deg", "yaw_sigma_at_gap_end_deg")):
        assert daily[col][0] == pytest.approx(s[key][0], rel=1e-9)
    assert daily["sun_gap_end_h"][0] == pytest.approx(s["sun_gaps_h"][0][1], rel=1e-9)
    assert daily["yaw_error_rms_deg"][0] == pytest.approx(s["yaw_error_rms_deg"], rel=1e-9)
    assert daily["eq55_sigma_yaw_deg"][0] == pytest.approx(s["analytic_sigma_yaw_deg"],
                                                           rel=1e-9)


def test_a_run_over_two_days_is_cut_into_days_and_reports_them(tmp_path_factory):
    from scenarios.run.stream.plan import window_bounds
    n_day = 168_750
    assert window_bounds(2 * n_day + 1, 0.512) == [(0, 2 * n_day + 1)]
    b = window_bounds(3 * n_day + 1, 0.512)
    assert b == [(0, n_day), (n_day, 2 * n_day), (2 * n_day, 3 * n_day + 1)]
    b = window_bounds(int(3.6 * n_day), 0.512)
    assert len(b) == 4 and b[-1][1] == int(3.6 * n_day)


def test_no_stage_folder_is_left_in_the_run(decimated):
    assert not any(p.name.startswith(".") for p in Path(decimated[0]).iterdir())


def test_a_long_run_logs_days_and_ctrl_c_mid_stream_leaves_nothing(tmp_path):
    """Four days (four windows, the producer in its own process), stderr not a
    terminal: a line per 10 simulated days is too rare here, so the first line is
    the interrupt's.  Ctrl-C while the second window streams: exit 130, one line,
    no stage, no process left (the producer would otherwise go on writing)."""
    import os
    import signal
    import subprocess
    import sys
    import time

    import psutil

    repo = Path(__file__).resolve().parents[2]
    out = tmp_path / "runs" / "long"
    proc = subprocess.Popen(
        [sys.executable, "-m", "scenarios.cli", "run", "goes_next_equinox", "--duration-s",
         str(4 * 86400), "--out", str(out)], cwd=repo, stdout=subprocess.PIPE,
        stderr=subprocess.PIPE, text=True, start_new_session=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    deadline = time.monotonic() + 120
    stage = None
    while time.monotonic() < deadline and proc.poll() is None:
        stages = list(out.parent.glob(".long.stage-*"))
        # truth.csv grows a window at a time (~0.55 MB a day at 64 s): past one day.
        if stages and (stages[0] / "truth.csv").exists() \
                and (stages[0] / "truth.csv").stat().st_size > 600_000:
            stage = stages[0]
            break
        time.sleep(0.02)
    assert stage is not None, "the run never reached its second window"
    children = psutil.Process(proc.pid).children(recursive=True)
    assert children, "the producer runs in a second process"
    os.killpg(proc.pid, signal.SIGINT)
    stdout, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, (stdout, err)
    assert err == "dynprop: interrupted; nothing was written\n", err
    assert not out.parent.exists() or not any(out.parent.iterdir())
    gone, alive = psutil.wait_procs(children, timeout=10)
    assert not alive


def test_gaps_found_window_by_window_are_sun_gaps_of_the_whole_mask():
    """GapTracker against outputs.sun_gaps on the whole mask (the independent
    reference): random outages, cut into random windows, with gaps open across cuts
    and at the run's end."""
    from scenarios.run.tally import GapTracker
    from scenarios.samples import sun_gaps

    rng = np.random.default_rng(0)
    for _ in range(2000):
        n = int(rng.integers(1, 200))
        present = np.repeat(rng.random(50) < 0.5, rng.integers(1, 30, 50))[:n]
        present = np.r_[present, np.ones(n - len(present), bool)]
        min_s = float(rng.integers(1, 20))
        tracker = GapTracker(1.0, min_s)
        cuts = np.sort(rng.choice(np.arange(1, n), size=min(n - 1, int(rng.integers(0, 6))),
                                  replace=False)) if n > 1 else []
        bounds = [0, *cuts, n]
        for a, b in zip(bounds[:-1], bounds[1:], strict=True):
            tracker.add(int(a), present[a:b])
        tracker.finish(n)
        assert tracker.gaps == [(int(a), int(b)) for a, b in sun_gaps(present, 1.0, min_s / 3600)]


def _running_children() -> set[int]:
    """This process's live descendants (a zombie has ended; one may also end while
    being looked at)."""
    import psutil
    running = set()
    for p in psutil.Process().children(recursive=True):
        try:
            if p.status() != psutil.STATUS_ZOMBIE:
                running.add(p.pid)
        except psutil.NoSuchProcess:
            pass
    return running


def test_an_error_while_the_figures_are_drawn_comes_out_and_stops_them(tmp_path, monkeypatch):
    """The figures are drawn in two workers while the producer writes the last of its
    files (plotting.run_figures_drawn); a failure there (here: the drain raising, as a
    full disk would in the producer) is the run's error, and no drawing worker is
    left running.  Processes other tests started (the multiprocessing resource
    tracker and forkserver) are counted before and allowed.  The operating system's
    table is asked, not ``multiprocessing.active_children()``: when the pool's
    manager thread and ``workers.worker_pool`` both join a killed worker, the one
    that loses the race keeps listing it as started although it is gone."""
    from scenarios.run.stream import windows

    def full_disk(self):
        raise OSError(28, "No space left on device")
    monkeypatch.setattr(windows.Demux, "drain", full_disk)
    s = load_scenario("goes_next_equinox", ["duration_s=7200"])
    before = _running_children()
    with pytest.raises(OSError, match="No space left"):
        stream_to_directory(s, tmp_path, processes=1, progress=False)
    assert _running_children() <= before
