"""`make bench`: the speed figures the issues ask for, one line each.

Format: ``bench <name> <value> <unit>``.  Each figure is
the median of several repetitions after a warm-up, because the machine is
shared and noisy.
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import tempfile
import time
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from dynprop.scenarios.config.loader import load_scenario  # noqa: E402
from dynprop.scenarios.run.simulate import simulate  # noqa: E402
from dynprop.sim.control import Control  # noqa: E402
from dynprop.sim.environment import Environment  # noqa: E402
from dynprop.sim.frames import GeoOrbit  # noqa: E402
from dynprop.sim.spacecraft import goes_next  # noqa: E402
from dynprop.sim.truth import InitialState, TruthModel, simulate_truth  # noqa: E402

DAY = 86400.0
EQUINOX = datetime(2026, 3, 20, 12, 0, 0, tzinfo=UTC)
DYNPROP = str(Path(sys.executable).with_name("dynprop"))


def report(name: str, value: float, unit: str) -> None:
    print(f"bench {name} {value:.4g} {unit}", flush=True)


def median_time(fn, repeats: int, warmup: int = 1) -> float:
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def _dynprop(*args) -> None:
    """A whole `dynprop` command, its output kept back; a failure raises."""
    subprocess.run([DYNPROP, *map(str, args)], check=True, capture_output=True)


def _command_s(*args, repeats: int = 5) -> float:
    """Median wall time of a whole `dynprop` command, start-up included."""
    return median_time(lambda: _dynprop(*args), repeats=repeats)


def _two_day_run(tmp: str) -> Path:
    """The default two-day run, made in the scratch directory ``tmp``."""
    run = Path(tmp) / "run"
    _dynprop("run", "goes_next_equinox", "--out", run)
    return run


def _year_run(year: Path | None) -> Path | None:
    """``year``, else $BENCH_YEAR_DIR (a year's run made before), else None."""
    given = os.environ.get("BENCH_YEAR_DIR")
    return year if year is not None or not given else Path(given)


def cli_wall_s(*args: str, repeats: int = 3) -> float:
    """Median wall time of a whole `dynprop` command writing into a scratch directory."""
    with tempfile.TemporaryDirectory() as tmp:
        return _command_s(*args, "--out", f"{tmp}/run", "--force", repeats=repeats)


def _tree_memory_mb(proc) -> tuple[float, float]:
    """Memory of a process and all its children (MB), 0 once it is gone: the sum of
    their proportional set sizes (a page shared between forked processes counted
    once, not once per process as summed RSS would), and the largest single RSS."""
    import psutil
    try:
        procs = [proc, *proc.children(recursive=True)]
    except psutil.NoSuchProcess:
        return 0.0, 0.0
    total, largest = 0, 0
    for p in procs:
        try:
            info = p.memory_full_info()
        except (psutil.NoSuchProcess, psutil.AccessDenied):
            continue
        total += info.pss
        largest = max(largest, info.rss)
    return total / 2**20, largest / 2**20


def _watched(args: list[str], what: str) -> tuple[float, float, float]:
    """Wall time of a command, the peak of the summed memory of its processes and the
    largest single process's peak RSS (``_tree_memory_mb``, sampled every 0.2 s)."""
    import psutil
    start = time.perf_counter()
    proc = psutil.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    total = largest = 0.0
    while proc.poll() is None:
        now = _tree_memory_mb(proc)
        total, largest = max(total, now[0]), max(largest, now[1])
        time.sleep(0.2)
    wall = time.perf_counter() - start
    if proc.returncode != 0:
        raise RuntimeError(f"{what} failed (exit {proc.returncode})")
    return wall, total, largest


def estimate_figures(year: Path | None = None) -> list[tuple[str, float, str]]:
    """Issue 44: `dynprop estimate` on the 30-day run's telemetry.csv, with and
    without its truth.csv: wall time and the peak memory of the whole process tree
    (``_watched``: the summed PSS, and the largest RSS).  With a year's run made with
    telemetry (``year``, else $BENCH_YEAR_DIR holding a telemetry.csv), the year too."""
    month = _thirty_day_run()
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        args = [DYNPROP, "estimate", str(month / "telemetry.csv"), "--scenario",
                str(month / "scenario.yaml")]
        wall, total, largest = _watched([*args, "--out", f"{tmp}/e"], "the 30-day estimate")
        out += [("estimate_30day_s", wall, "s"),
                ("estimate_30day_peak_rss_MB", max(total, largest), "MB")]
        wall, total, largest = _watched([*args, "--truth", str(month / "truth.csv"), "--out",
                                         f"{tmp}/t"], "the 30-day estimate with its truth")
        out += [("estimate_truth_30day_s", wall, "s"),
                ("estimate_truth_30day_peak_rss_MB", max(total, largest), "MB")]
        year = _year_run(year)
        if year is not None and (year / "telemetry.csv").is_file():
            wall, total, largest = _watched(
                [DYNPROP, "estimate", str(year / "telemetry.csv"), "--scenario",
                 str(year / "scenario.yaml"), "--out", f"{tmp}/y"], "the year's estimate")
            out += [("estimate_year_s", wall, "s"),
                    ("estimate_year_peak_rss_MB", max(total, largest), "MB")]
    return out


def run_365day(out: Path | None = None) -> tuple[float, float, float, float]:
    """`dynprop run goes_next_equinox` over one year with the default output section:
    wall time, the peak of the summed memory of its processes and the largest single
    process's peak RSS, and the size of the run directory (kept at ``out`` if given,
    for report_figures)."""
    with tempfile.TemporaryDirectory() as tmp:
        out = out or Path(tmp) / "run"
        wall, total, largest = _watched([DYNPROP, "run", "goes_next_equinox", "--duration-s",
                                         str(365 * DAY), "--out", str(out)],
                                        "the one-year run")
        size = sum(p.stat().st_size for p in out.rglob("*") if p.is_file()) / 1e6
    return wall, total, largest, size


def managed_year_figures(equinox_wall_s: float | None = None) -> list[tuple[str, float, str]]:
    """Issue 45: `dynprop run goes_next_year` (a year with momentum management: the
    managed step and the daily solar loop), its wall time, memory and, given the
    equinox year's wall time just before, the ratio (target ≤ 1.1×, peak unchanged)."""
    with tempfile.TemporaryDirectory() as tmp:
        wall, total, largest = _watched([DYNPROP, "run", "goes_next_year", "--out",
                                         str(Path(tmp) / "run")], "the managed year")
    out = [("run_managed_365day_wall_s", wall, "s"),
           ("run_managed_365day_peak_rss_MB", total, "MB"),
           ("run_managed_365day_largest_process_rss_MB", largest, "MB")]
    if equinox_wall_s is not None:
        out.append(("run_managed_over_equinox_365day", wall / equinox_wall_s, "x"))
    return out


def report_figures(year: Path | None = None) -> list[tuple[str, float, str]]:
    """Issue 32: `dynprop report` as a user runs it (the whole command, start-up
    included) on the default two-day run (median of 5; target ≤ 2 s) and on a year's
    run (``year``: one made by run_365day; else $BENCH_YEAR_DIR, else a new one, 2
    minutes): its wall time, peak memory and page size (≤ 20 MB); and, with
    chromium installed, the year page's own opening time in the browser, from
    navigation start to every figure drawn (median of 3; target ≤ 3 s)."""
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        out.append(("report_2day_s", _command_s("report", _two_day_run(tmp)), "s"))
        year = _year_run(year)
        if year is None:
            year = Path(tmp) / "year"
            run_365day(year)
        _dynprop("report", year)  # warm
        wall, total, _ = _watched([DYNPROP, "report", str(year)], "the year's report")
        page = year / "report.html"
        out += [("report_year_s", wall, "s"), ("report_year_peak_rss_MB", total, "MB"),
                ("report_year_MB", page.stat().st_size / 1e6, "MB")]
        opened = _page_open_s(page)
        if opened is not None:
            out.append(("report_year_open_s", opened, "s"))
    return out


def export_figures(year: Path | None = None) -> list[tuple[str, float, str]]:
    """Issue 33: `dynprop export` as a user runs it (the whole command, start-up
    included): the AEM of the default two-day run's estimate (median of 5; target
    ≤ 1 s) and, given a year's run (``year``, else $BENCH_YEAR_DIR; none is made here),
    the AEM of its whole year, its wall time and its peak memory (the process's RSS,
    ``_watched``), which stays bounded: estimate.csv (140 MB) is read in blocks.  The
    year's estimate needs ``pitch_deg`` (a run before the pitch filter has none): its
    truth is exported then, and a note says so."""
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        out.append(("export_2day_s", _command_s("export", _two_day_run(tmp), "--format",
                                                "aem", "--what", "estimate"), "s"))
        year = _year_run(year)
        if year is not None:
            wall, _, rss = _watched([DYNPROP, "export", str(year), "--format", "aem", "--what",
                                     _exported(year), "--out", f"{tmp}/year.aem"],
                                    "the year's export")
            out += [("export_year_s", wall, "s"), ("export_year_peak_rss_MB", rss, "MB")]
    return out


BENCH_CACHE = Path(os.environ.get("BENCH_CACHE_DIR") or Path(__file__).resolve().parent / ".cache")


def _thirty_day_run() -> Path:
    """Issue 44's 30-day run with its telemetry.csv (552 MB), written once into the
    bench cache (benchmarks/.cache, or $BENCH_CACHE_DIR) by the streamed `run` (20 s)
    and reused; one without its summary.json (a killed run) is written again."""
    run = BENCH_CACHE / "run30"
    if not (run / "summary.json").is_file():
        _dynprop("run", "goes_next_equinox", "--duration-s", str(30 * DAY), "--set",
                 "output.telemetry=true", "--out", run, "--force")
    return run


def page_30day_figures() -> list[tuple[str, float, str]]:
    """Issue 44: peak memory of the whole process tree (``_watched``; target ≤ 1 GB)
    of `dynprop report` and of `dynprop export` (the largest over its formats, AEM and
    APM, of the estimate and of the truth) on the cached 30-day run."""
    run = _thirty_day_run()
    _, report_mb, _ = _watched([DYNPROP, "report", str(run)], "the 30-day report")
    export_mb = 0.0
    with tempfile.TemporaryDirectory() as tmp:
        for what in ("estimate", "truth"):
            for fmt, extra in (("aem", []), ("apm", ["--at", str(15 * DAY)])):
                _, mb, _ = _watched([DYNPROP, "export", str(run), "--format", fmt, "--what",
                                     what, *extra, "--out", f"{tmp}/x.{fmt}", "--force"],
                                    f"the 30-day {what} {fmt} export")
                export_mb = max(export_mb, mb)
    return [("report_30day_peak_rss_MB", report_mb, "MB"),
            ("export_30day_peak_rss_MB", export_mb, "MB")]


def real_30day_figures() -> list[tuple[str, float, str]]:
    """Issue 44's real-shaped month: the cached 30-day run's telemetry as a ground
    system might deliver it (``benchmarks/realshape.py``: ISO UTC tags only, ±50 ms of
    jitter, 10% of rows dropped, a 6 h hole; made once into the bench cache), through
    `dynprop estimate`: its wall time and peak memory, and how many of its Sun-gap-end
    yaw estimates lie within 3σ of the run's truth (``benchmarks/gap_ends.py``; read
    from a second estimate written at every row)."""
    from benchmarks.gap_ends import gap_end_check
    run = _thirty_day_run()
    real = BENCH_CACHE / "real30" / "telemetry.csv"
    if not real.is_file():
        real.parent.mkdir(parents=True, exist_ok=True)
        subprocess.run([sys.executable, str(Path(__file__).parent / "realshape.py"),
                        str(run / "telemetry.csv"), str(real) + ".part"], check=True)
        Path(str(real) + ".part").replace(real)
    with tempfile.TemporaryDirectory() as tmp:
        args = [DYNPROP, "estimate", str(real), "--scenario", str(run / "scenario.yaml")]
        wall, total, largest = _watched([*args, "--out", f"{tmp}/e"], "the real-shaped month")
        _dynprop(*args[1:], "--set", "output.interval_s=0.512", "--out", f"{tmp}/all")
        within, ends, worst = gap_end_check(Path(tmp) / "all", run)
    return [("estimate_real_30day_s", wall, "s"),
            ("estimate_real_30day_peak_rss_MB", max(total, largest), "MB"),
            ("real_30day_gap_ends_within_3sigma", within, f"of {ends} ends"),
            ("real_30day_gap_end_max_err_over_sigma", worst, "σ")]


def batch_30day_figures() -> list[tuple[str, float, str]]:
    """Issue 44: `dynprop batch --span-h 24` on the cached 30-day run, with its
    truth.csv (the run directory) and without (the telemetry file with --scenario), and
    `dynprop trim` on it: the first's wall time and each command's peak memory of the
    whole process tree (``_watched``: the summed PSS or the largest RSS, whichever is
    more; target ≤ 1 GB; before issue 44, 9.0 GB and 5.3 GB)."""
    run = _thirty_day_run()
    with tempfile.TemporaryDirectory() as tmp:
        wall, total, largest = _watched([DYNPROP, "batch", str(run), "--span-h", "24",
                                         "--out", f"{tmp}/b"], "the 30-day batch")
        _, total_n, largest_n = _watched(
            [DYNPROP, "batch", str(run / "telemetry.csv"), "--scenario",
             str(run / "scenario.yaml"), "--span-h", "24", "--out", f"{tmp}/bn"],
            "the 30-day batch without its truth")
        # trim writes RUN_DIR/trim: a folder of links to the cached run's files.
        linked = Path(tmp) / "run"
        linked.mkdir()
        for name in ("scenario.yaml", "telemetry.csv", "truth.csv", "estimate.csv",
                     "summary.json"):
            (linked / name).symlink_to(run / name)
        _, trim_total, trim_largest = _watched([DYNPROP, "trim", str(linked)],
                                               "the 30-day trim")
    return [("batch_30day_s", wall, "s"),
            ("batch_30day_peak_rss_MB", max(total, largest, total_n, largest_n), "MB"),
            ("trim_30day_peak_rss_MB", max(trim_total, trim_largest), "MB")]


def _exported(run: Path) -> str:
    """``estimate`` when the run's estimate.csv has pitch_deg (a year's run made before
    the pitch filter has none), else ``truth``."""
    header = (run / "estimate.csv").open().readline().strip().split(",")
    if "pitch_deg" in header:
        return "estimate"
    print(f"bench note: {run}/estimate.csv has no pitch_deg; its truth.csv is exported",
          flush=True)
    return "truth"


def _page_open_s(page: Path) -> float | None:
    """The page's own opening time in headless Chromium, through the browser test's
    helper (tests/scenarios/browser.py): navigation start to every figure drawn, the
    median of 3 opens after a warm-up; None without chromium."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from tests.scenarios.browser import Browser
    try:
        browser = Browser()
    except BaseException as exc:   # pytest's skip: chromium, its driver or selenium missing
        print(f"bench note: report_year_open_s not measured: {exc}", flush=True)
        return None
    with browser:
        browser.open(page)
        return statistics.median(browser.open(page).drawn_ms / 1000 for _ in range(3))


YEAR_FIGURES = (("run_365day_wall_s", "s"), ("run_365day_peak_rss_MB", "MB"),
                ("run_365day_largest_process_rss_MB", "MB"), ("run_365day_dir_MB", "MB"))


def truth_day(model: TruthModel):
    """One simulated day at 0.512 s output with every torque, the control and the
    ripple on, including input generation and result assembly."""
    rng = np.random.default_rng(1)
    return simulate_truth(goes_next(), GeoOrbit(), Environment(), Control(),
                          InitialState(yaw_rad=1e-3, roll_rad=5e-4), EQUINOX, DAY,
                          rng=rng, model=model)


def run_figures_2day_s() -> float:
    """The four `dynprop run` figures of the default two-day run, drawn and saved
    (two at a time, as `dynprop run` does), from its comparison.npz and telemetry."""
    from dynprop.scenarios.figures.run import plot_run_figures
    with tempfile.TemporaryDirectory() as tmp:
        run = _two_day_run(tmp)
        return median_time(lambda: plot_run_figures(run), repeats=3)


def discretize_ms() -> float:
    """Φ, Γ and Q_d of the paper's model at 0.512 s (Eqs. 15–23, 31–32), the best of
    200 calls: the filter is rebuilt from these for every run and Monte Carlo case."""
    from dynprop.estimator.linear.transition import discretize
    from dynprop.scenarios.config.build import estimator_model
    params, noise = estimator_model(load_scenario("goes_next_equinox"))
    discretize(params, noise, 0.512)
    times = []
    for _ in range(200):
        start = time.perf_counter()
        discretize(params, noise, 0.512)
        times.append(time.perf_counter() - start)
    return 1e3 * min(times)


def _filter_day():
    from dynprop.estimator.kalman.filter import Measurements
    from dynprop.scenarios.config.build import estimator_model
    params, noise = estimator_model(load_scenario("goes_next_equinox", ["duration_s=86400"]))
    n = 168_750
    rng = np.random.default_rng(3)
    t_h = np.arange(n) * 0.512 / 3600
    yaw = np.where(t_h < 16, rng.normal(0, 6e-4, n), np.nan)
    meas = Measurements(rng.normal(0, 1.8e-4, n), yaw, rng.normal(0, 4e-4, n), 3.3e-8,
                        4e-7, 1.5e-7)
    x0, P0 = np.zeros(9), np.diag([1e-6, 1e-6, 1e-4, 1e-6, 1e-4, 1e-12, 1e-12, 1e-12, 1e-12])
    return params, noise, meas, x0, P0, rng


def filter_s_per_day() -> float:
    """The paper's filter over one day of 0.512 s samples (as in ``main``)."""
    from dynprop.estimator.kalman.filter import kalman_filter
    from dynprop.estimator.linear.transition import discretize
    params, noise, meas, x0, P0, _ = _filter_day()
    disc = discretize(params, noise, 0.512)
    return median_time(lambda: kalman_filter(meas, disc, x0, P0), repeats=5)


def filter_jitter_s_per_day() -> float:
    """The filter over the same day with ±50 ms jitter on every time tag: every step's
    Φ, Γ, Q_d evaluated from the closed forms (``estimator.linear.steps``), included."""
    from dynprop.estimator.kalman.filter import kalman_filter
    from dynprop.estimator.linear.steps import StepTable
    params, noise, meas, x0, P0, rng = _filter_day()
    n = len(meas.roll_rad)
    t = np.arange(n) * 0.512 + rng.uniform(-0.05, 0.05, n)
    return median_time(lambda: kalman_filter(meas, StepTable.from_times(params, noise, t),
                                             x0, P0), repeats=3)


def screen_s_per_day() -> float:
    """Issue 43: the telemetry screen (``scenarios.files.screen``) over one day of
    0.512 s telemetry.csv columns: roll, pitch, yaw, two wheels and the three heads'
    raw angles, noisy and clean (nothing screened, so every rule runs in full)."""
    from dynprop.scenarios.files.screen import screen
    s = load_scenario("goes_next_equinox", ["duration_s=86400"])
    n = 168_750
    rng = np.random.default_rng(4)
    cols = {"t_s": np.arange(n) * 0.512, "roll_deg": np.round(rng.normal(0, 0.01, n), 2),
            "pitch_deg": np.round(rng.normal(0, 0.01, n), 2),
            "yaw_deg": rng.normal(0, 0.04, n), "yaw_sigma_deg": np.full(n, 0.04),
            "sun_head": np.zeros(n),
            **{f"wheel{i}_rpm": 5485 + np.round(rng.normal(0, 0.03, n), 4) for i in (1, 2)},
            **{f"{h}_{a}_deg": rng.uniform(-30, 30, n) for h in ("dss", "cass1", "cass2")
               for a in ("alpha", "beta")}}
    out, rep = screen(cols, {}, s)
    assert rep.count == 0 and out is cols
    return median_time(lambda: screen(cols, {}, s), repeats=5)


def ekf_over_filter() -> float:
    """ekf_s_per_day / filter_s_per_day, each the median of 7 one-day runs on the same
    synthetic day, taken in turn (issue 16's target: ≤ 4)."""
    from dynprop.estimator.ekf.filter import EkfInputs, ekf_filter
    from dynprop.estimator.kalman.filter import Measurements, kalman_filter
    from dynprop.estimator.linear.transition import discretize
    from dynprop.scenarios.bridge.ekf import ekf_design
    from dynprop.scenarios.config.build import estimator_model
    scenario = load_scenario("goes_next_equinox", ["duration_s=86400"])
    params, noise = estimator_model(scenario)
    disc = discretize(params, noise, 0.512)
    n = 168_750
    rng = np.random.default_rng(3)
    yaw = np.where(np.arange(n) * 0.512 / 3600 < 16, rng.normal(0, 6e-4, n), np.nan)
    roll, pitch, h = (rng.normal(0, s, n) for s in (1.8e-4, 1.8e-4, 4e-4))
    meas = Measurements(roll, yaw, h, 3.3e-8, 4e-7, 1.5e-7)
    x0, P0 = np.zeros(9), np.diag([1e-6, 1e-6, 1e-4, 1e-6, 1e-4, 1e-12, 1e-12, 1e-12, 1e-12])
    pm, wn, X0, P0e = ekf_design(scenario)
    ekf_in = EkfInputs(np.column_stack([roll, pitch, yaw, h]),
                       np.tile([3.3e-8, 3.3e-8, 4e-7, 1.5e-7], (n, 1)),
                       np.tile([params.H_Nms, 0.0, 0.0, 0.0, 0.0], (n, 1)))
    kalman_filter(meas, disc, x0, P0)
    ekf_filter(ekf_in, pm, wn, X0, P0e)
    tf, te = [], []
    for _ in range(7):
        tf.append(median_time(lambda: kalman_filter(meas, disc, x0, P0), 1, 0))
        te.append(median_time(lambda: ekf_filter(ekf_in, pm, wn, X0, P0e), 1, 0))
    return statistics.median(te) / statistics.median(tf)


def batch_figures() -> list[tuple[str, float, str]]:
    """Issue 31: the nonlinear batch over 24 h of simulated goes_next_equinox telemetry
    (the linear solve it starts from, the Gauss–Newton passes and the consider pass,
    ``batch.spans.solve_spans`` as `dynprop batch` runs it, without the files), and
    ``batch_over_filter``: that over one pass of the paper's filter on the same
    telemetry, the two timed in turn, 5 times (target ≤ 30, moonshot ≤ 8); also the
    linear batch."""
    from dynprop.estimator.kalman.filter import kalman_filter
    from dynprop.estimator.linear.transition import discretize
    from dynprop.scenarios.batch.spans import solve_spans
    from dynprop.scenarios.bridge.inputs import filter_inputs, initial_prior, measured
    from dynprop.scenarios.config.build import estimator_model
    s = load_scenario("goes_next_equinox", ["duration_s=86400"])
    sim = simulate(s)
    tel = measured(sim.telemetry)
    params, noise = estimator_model(s)
    disc = discretize(params, noise, s.sample_interval_s)
    meas, u, _ = filter_inputs(s, params, *tel)
    x0, P0 = initial_prior(s, params)
    rows = np.arange(0, len(u), 125)

    def batch(model):
        return solve_spans(s, tel, sim.telemetry.pitch_rad, rows, model=model, span_h=24.0)

    run = batch("nonlinear")
    assert all(sol.converged for sol in run.solutions)
    kalman_filter(meas, disc, x0, P0, u)
    tb, tf = [], []
    for _ in range(5):
        tb.append(median_time(lambda: batch("nonlinear"), 1, 0))
        tf.append(median_time(lambda: kalman_filter(meas, disc, x0, P0, u), 1, 0))
    b = statistics.median(tb)
    return [("batch_24h_s", b, "s"), ("batch_over_filter", b / statistics.median(tf), "x"),
            ("batch_linear_24h_s", median_time(lambda: batch("linear"), 3), "s")]


def main() -> None:
    only = sys.argv[1:]
    if only:
        # `python benchmarks/run.py discretize_ms run_figures_2day_s`: just those.
        for name in only:
            name = {"export": "export_figures"}.get(name, name)   # `make bench BENCH=export`
            if name in ("tune_figures", "batch_figures", "report_figures", "export_figures",
                        "estimate_figures", "page_30day_figures", "tune_30day_figures",
                        "batch_30day_figures", "real_30day_figures",
                        "managed_year_figures"):
                for key, value, unit in globals()[name]():
                    report(key, value, unit)
                continue
            if name == "run_365day":
                for (key, unit), value in zip(YEAR_FIGURES, run_365day(), strict=True):
                    report(key, value, unit)
                continue
            unit = "ms" if name.endswith("_ms") else "x" if name == "ekf_over_filter" else "s"
            report(name, globals()[name](), unit)
        return
    report("discretize_ms", discretize_ms(), "ms")
    with tempfile.TemporaryDirectory() as cache:
        os.environ["DYNPROP_CACHE_DIR"] = cache
        start = time.perf_counter()
        compiled = TruthModel(2, backend="auto")
        report("truth_compile_s", time.perf_counter() - start, "s")
    report("truth_s_per_day", median_time(lambda: truth_day(compiled), repeats=7), "s")
    if compiled.backend != "compiled":
        print("bench note: no C compiler; truth_s_per_day ran in the VM", flush=True)
    vm = TruthModel(2, backend="vm")
    report("truth_vm_s_per_day", median_time(lambda: truth_day(vm), repeats=3), "s")

    # Issue 3: truth plus sensors and ground yaw (no files), and the whole command.
    scenario = load_scenario("goes_next_equinox", ["duration_s=86400"])
    report("truth_telemetry_s_per_day",
           median_time(lambda: simulate(scenario, model=compiled), repeats=5), "s")
    report("simulate_2day_wall_s", cli_wall_s("simulate", "goes_next_equinox"), "s")

    # Issue 4: the filter over one day, roll and h every step, yaw two thirds of it.
    from dynprop.estimator.kalman.filter import kalman_filter
    from dynprop.estimator.linear.transition import discretize
    params, noise, meas, x0, P0, rng = _filter_day()
    disc = discretize(params, noise, 0.512)
    n, yaw = len(meas.roll_rad), meas.yaw_rad
    report("filter_s_per_day", median_time(lambda: kalman_filter(meas, disc, x0, P0),
                                           repeats=5), "s")
    # Issue 30: the same day with ±50 ms jitter on every tag (each step its own Φ, Γ, Q_d).
    report("filter_jitter_s_per_day", filter_jitter_s_per_day(), "s")
    report("screen_s_per_day", screen_s_per_day(), "s")
    # Issue 16: the extended Kalman filter on the same day, pitch measured like roll;
    # its target is a ratio to filter_s_per_day of the same bench run (≤ 4×).
    from dynprop.estimator.ekf.filter import EkfInputs, ekf_filter
    from dynprop.scenarios.bridge.ekf import ekf_design
    pm, wn, X0, P0e = ekf_design(scenario)
    ekf_in = EkfInputs(
        np.column_stack([meas.roll_rad, rng.normal(0, 1.8e-4, n), yaw, meas.h_Nms]),
        np.tile([3.3e-8, 3.3e-8, 4e-7, 1.5e-7], (n, 1)),
        np.tile([params.H_Nms, 0.0, 0.0, 0.0, 0.0], (n, 1)))
    ekf_s = median_time(lambda: ekf_filter(ekf_in, pm, wn, X0, P0e), repeats=5)
    report("ekf_s_per_day", ekf_s, "s")
    report("ekf_over_filter", ekf_over_filter(), "x")
    report("run_2day_wall_s", cli_wall_s("run", "goes_next_equinox"), "s")
    # Issue 14: a year in one run, streamed (skipped with BENCH_QUICK=1); kept for the
    # year's review page (issue 32).
    year_dir = tempfile.TemporaryDirectory()
    year = None
    if os.environ.get("BENCH_QUICK") != "1":
        year = Path(year_dir.name) / "year"
        year_figures = run_365day(year)
        for (key, unit), value in zip(YEAR_FIGURES, year_figures, strict=True):
            report(key, value, unit)
        # Back to back with the equinox year, so the ratio sees the same machine.
        for key, value, unit in managed_year_figures(year_figures[0]):
            report(key, value, unit)
    report("run_figures_2day_s", run_figures_2day_s(), "s")
    for key, value, unit in tune_figures():
        report(key, value, unit)
    if os.environ.get("BENCH_QUICK") != "1":    # a 30-day tune: minutes
        for key, value, unit in tune_30day_figures():
            report(key, value, unit)
    for key, value, unit in batch_figures():
        report(key, value, unit)
    if year is not None:
        for key, value, unit in report_figures(year):
            report(key, value, unit)
    for key, value, unit in export_figures(year):
        report(key, value, unit)
    for key, value, unit in estimate_figures():
        report(key, value, unit)
    year_dir.cleanup()
    for key, value, unit in page_30day_figures():
        report(key, value, unit)
    for key, value, unit in batch_30day_figures():
        report(key, value, unit)
    for key, value, unit in real_30day_figures():
        report(key, value, unit)
    # The plain-numpy loop, for comparison, scaled to a day: the tests' textbook
    # reference (tests/estimator/dense_reference.py), one Python iteration per step.
    from tests.estimator.dense_reference import kalman_reference
    k = 5000
    z = np.column_stack([meas.roll_rad[:k], meas.yaw_rad[:k], meas.h_Nms[:k]])
    report("filter_numpy_loop_s_per_day",
           median_time(lambda: kalman_reference(z, (3.3e-8, 4e-7, 1.5e-7), disc, x0, P0),
                       repeats=3) * n / k, "s")

    # Issue 6: the whole linearization report of the default scenario (22 two-day runs
    # and 20 truth-only runs through the one compiled step, five figures).
    report("linearization_report_wall_s",
           cli_wall_s("linearization", "goes_next_equinox", repeats=2), "s")

    # Issue 7: 100 dispersed two-day cases of the default scenario with the filter,
    # reduced on the workers, plus the ensemble figures: on every core, then through
    # a local dask cluster (two single-threaded worker processes) for comparison.
    report("montecarlo_100x2day_wall_s", montecarlo_wall_s(), "s")
    from distributed import LocalCluster
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address=None) as cluster:
        report("montecarlo_dask_100x2day_wall_s",
               montecarlo_wall_s("--scheduler", cluster.scheduler_address), "s")


TUNE_SCENARIOS = ("goes_next_paper_torques", "goes_next_equinox")


def tune_figures() -> list[tuple[str, float, str]]:
    """Issue 28: `dynprop tune` on two days of telemetry.  ``tune_2day_s`` is the
    whole command (reading telemetry.csv, the fit, the report and its figure) on a
    run of `goes_next_paper_torques`, the paper's own torque assumption, which is what
    tuning is for; ``tune_over_filter`` is the fit on the telemetry in memory
    (``scenarios.tune.fit.tune``: the maximum, the limits, the before/after
    diagnostics) over one pass of the paper's filter (``kalman_filter``, as `run` and
    `estimate` call it) over the same telemetry, medians taken in turn.  The
    default scenario, whose truth lies outside the filter's noise model (its
    likelihood is flat along most parameters), gets its ratio too."""
    from dynprop.estimator.kalman.filter import kalman_filter
    from dynprop.estimator.linear.transition import discretize
    from dynprop.scenarios.tune.fit import TuneOptions, tune
    from dynprop.scenarios.tune.source import read_source
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in TUNE_SCENARIOS:
            run = Path(tmp) / name
            _dynprop("run", name, "--out", run)
            if name == TUNE_SCENARIOS[0]:
                out.append(("tune_2day_s", _command_s("tune", run, repeats=3), "s"))
            src = read_source(run)
            disc = discretize(src.params, src.noise, src.scenario.sample_interval_s)
            fit_t, filter_t = [], []
            tune(src, TuneOptions())
            for _ in range(3):
                fit_t.append(median_time(lambda src=src: tune(src, TuneOptions()), 1, 0))
                filter_t.append(median_time(lambda src=src, disc=disc: kalman_filter(
                    src.meas, disc, src.x0, src.P0, u=src.u), 3, 1))
            ratio = statistics.median(fit_t) / statistics.median(filter_t)
            key = "tune_over_filter" if name == TUNE_SCENARIOS[0] else \
                "tune_equinox_over_filter"
            out.append((key, ratio, "x"))
    return out


def tune_30day_figures() -> list[tuple[str, float, str]]:
    """Issue 44: `dynprop tune` on the 30-day run's telemetry (``_thirty_day_run``), the whole
    command as a user runs it: the peak of its process tree's summed memory
    (``_watched``; target ≤ 1 GB, 5.3 GB when it held the file whole) and its wall
    time."""
    with tempfile.TemporaryDirectory() as tmp:
        wall, total, _ = _watched([DYNPROP, "tune", str(_thirty_day_run()), "--out",
                                   f"{tmp}/tune"], "the 30-day tune")
    return [("tune_30day_peak_rss_MB", total, "MB"), ("tune_30day_s", wall, "s")]


def montecarlo_wall_s(*extra: str, runs: int = 100, repeats: int = 2) -> float:
    """Median wall time of a whole `dynprop montecarlo` set, each into a new
    directory so that nothing is resumed."""
    with tempfile.TemporaryDirectory() as tmp:
        sets = iter(range(repeats))
        return median_time(lambda: _dynprop(
            "montecarlo", "goes_next_equinox", "--runs", runs, "--out", f"{tmp}/set{next(sets)}",
            *extra), repeats=repeats, warmup=0)


if __name__ == "__main__":
    main()
