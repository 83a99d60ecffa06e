"""`dynprop run` as a stream: the run directory written window by window.

The producer (truth, telemetry, the linear twin and its filter; it also writes
truth.csv and telemetry.csv) runs in a second process, joined to this one by a
queue of at most ``QUEUE_ITEMS`` records (their arrays go by shared-memory file,
``handoff``), while this one runs the real filter and the smoother, accumulates
the summary (``accumulate``) and writes estimate.csv and comparison.npz
(``decimate``) at the output cadence.  Memory holds a few windows, whatever the
duration.  Progress: a bar of simulated days on a terminal, otherwise a line every
``LOG_EVERY_DAYS`` days, for runs longer than one window.
"""

from __future__ import annotations

import contextlib
import sys
import time
from itertools import islice
from multiprocessing import get_context
from pathlib import Path

from ..config import build
from ..config.loader import resolved_yaml
from ..config.schema import Scenario, output_writes_telemetry
from ..files.csvio import CsvAppender, write_csv
from ..files.decimate import ComparisonRows, output_rows
from ..files.summary import assemble_summary, eq55_sigma_yaw_deg, estimate_columns, write_summary
from ..trim.loop import loop_summary
from ..workers import blas_one_thread, ignore_sigint, sigint_held
from . import handoff
from .filter_tally import FilterFigures
from .stream import DAY_S, producer, windows_of
from .tally import DailyFigures, RunFigures, window_nees

QUEUE_ITEMS = 4   # two windows: a real and a twin record each
LOG_EVERY_DAYS = 10


def _child(queue, s, run, window_samples, out, telemetry_file, shared) -> None:
    ignore_sigint()   # the parent handles Ctrl-C and terminates this process
    try:
        for item in producer(s, run, window_samples, out, telemetry_file):
            queue.put(("item", handoff.pack(item, shared)))
        queue.put(("done", None))
    except BaseException as exc:  # noqa: BLE001 - handed to the parent, which raises it
        try:
            queue.put(("error", exc))
        except Exception:  # noqa: BLE001 - an exception that does not pickle
            queue.put(("error", RuntimeError(f"{type(exc).__name__}: {exc}")))


def producer_process(s: Scenario, run: int, window_samples, out, telemetry_file):
    """``stream.producer`` in a forked process; yields what it yields."""
    ctx = get_context("fork")
    queue = ctx.Queue(maxsize=QUEUE_ITEMS)
    shared = handoff.HandoffDir()
    proc = ctx.Process(target=_child, args=(queue, s, run, window_samples, out,
                                            telemetry_file, shared.path), daemon=True)
    with sigint_held():
        proc.start()
    try:
        while True:
            try:
                kind, item = queue.get(timeout=1.0)
            except Exception:  # noqa: BLE001 - queue.Empty: is the producer still there?
                if not proc.is_alive():
                    raise RuntimeError(f"the truth process died (exit {proc.exitcode})") \
                        from None
                continue
            if kind == "done":
                break
            if kind == "error":
                raise item
            yield handoff.unpack(*item)
        proc.join()
    finally:
        if proc.is_alive():
            proc.terminate()
            proc.join()
        queue.close()
        shared.close()


class Progress:
    """Simulated days: a tqdm bar on a terminal, else a line every LOG_EVERY_DAYS."""

    def __init__(self, total_days: float, enabled: bool):
        self.total, self.enabled = total_days, enabled
        self.bar = None
        self.start = time.perf_counter()
        self.next_log = LOG_EVERY_DAYS
        if enabled and sys.stderr.isatty():
            from tqdm import tqdm
            self.bar = tqdm(total=round(total_days, 3), unit="day", desc="simulated",
                            leave=False, file=sys.stderr,
                            bar_format="{l_bar}{bar}| {n:.1f}/{total:.1f} d "
                                       "[{elapsed}<{remaining}]")

    def update(self, done_days: float) -> None:
        if not self.enabled:
            return
        if self.bar is not None:
            self.bar.update(round(done_days - self.bar.n, 3))
        elif done_days + 1e-9 >= self.next_log or done_days + 1e-9 >= self.total:
            wall = time.perf_counter() - self.start
            eta = wall / done_days * (self.total - done_days)
            print(f"dynprop: {done_days:.1f} of {self.total:.1f} days simulated, "
                  f"{wall:.0f} s, about {eta:.0f} s to go", file=sys.stderr, flush=True)
            while self.next_log <= done_days + 1e-9:
                self.next_log += LOG_EVERY_DAYS

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


@blas_one_thread()   # the producer, forked inside, inherits the limit
def stream_to_directory(s: Scenario, stage: Path, run: int = 0,
                        window_samples: int | None = None, processes: int = 2,
                        progress: bool = True) -> dict:
    """Everything of one `dynprop run` into ``stage`` (docs/outputs.md); returns the
    summary.  ``processes=1`` keeps the producer in this process."""
    stage = Path(stage)
    (stage / "scenario.yaml").write_text(resolved_yaml(s))
    tel_file = output_writes_telemetry(s)
    if processes > 1:
        source = producer_process(s, run, window_samples, stage, tel_file)
    else:
        source = producer(s, run, window_samples, stage, tel_file)
    records = windows_of(s, items=source)
    plan = next(records)
    # The figures' modules (matplotlib: ~0.4 s) load while the producer simulates the
    # first window, rather than after the last.
    from ..figures.run import plot_run_figures, run_figures_drawn
    params, _ = build.estimator_model(s)
    dt = s.sample_interval_s
    n = plan.n_samples
    figures = RunFigures(s)
    daily = DailyFigures(s, build.epoch(s), n, eq55_sigma_yaw_deg(s, params))
    comparison = ComparisonRows(stage / ".comparison", n, plan.stride)
    estimate = CsvAppender(stage / "estimate.csv")
    # Filters beside the paper's (estimator.filters): their figures and estimate file.
    extra = {name: (FilterFigures(name), CsvAppender(stage / f"estimate_{name}.csv"))
             for name in s.estimator.filters if name != "paper"}
    bar = Progress(n * dt / DAY_S, progress and len(plan.bounds) > 1)
    # The figures need only comparison.npz and daily.csv, so they are drawn while the
    # producer writes the last of its files; a trim loop's figure also reads
    # trim_loop.csv, which the producer writes, so that run draws after it.
    overlap = s.trim.every_days is None
    try:
        # The windows' records, and not one more: asking for the next would wait for
        # the producer to finish its files (stream.windows_of drains it there).
        for rec in islice(records, len(plan.bounds)):
            err = rec["real"].x - rec["truth_model"]
            err_lin = rec["linear"].x - rec["twin_model"]
            nees_idx, nees_real, nees_lin = window_nees(rec)
            closed = figures.add(rec, err, err_lin, nees_idx, nees_real, nees_lin)
            daily.add(rec, err, err_lin, nees_idx, nees_real, closed)
            comparison.add(rec, nees_idx, nees_real, nees_lin, tuple(extra), err, err_lin)
            k = output_rows(rec["start"], rec["stop"], plan.stride) - rec["start"]
            estimate.append(estimate_columns(rec["t_s"][k], rec["real"].x[k],
                                             rec["real"].sigma[k], params.omega_n_radps))
            for name, (figs, file) in extra.items():
                figs.add(rec, closed)
                file.append(estimate_columns(rec["t_s"][k], rec[name].x[k],
                                             rec[name].sigma[k], params.omega_n_radps))
            bar.update(rec["stop"] * dt / DAY_S)
            del rec, err, err_lin
        bar.close()
        comparison.finish(stage / "comparison.npz", plan.stride * dt)
        write_csv(stage / "daily.csv", daily.columns())
        with run_figures_drawn(stage) if overlap else contextlib.nullcontext():
            for _ in records:   # none left: the producer finishing its files
                pass
    finally:
        # Stop the producer now (not when the generators are collected), so that an
        # interrupted run's second process is gone before its stage is removed.
        records.close()
        source.close()
        estimate.close()
        for _, file in extra.values():
            file.close()
        bar.close()
    summary = assemble_summary(s, params, figures.backend, True, True, figures.figures(n))
    summary.update(output_interval_s=plan.stride * dt, telemetry_written=tel_file,
                   daily="daily.csv")
    summary["filters"] = list(s.estimator.filters)   # the paper's alone elsewhere
    for name, (figs, _) in extra.items():
        summary[name] = figs.summary()
    if s.trim.every_days is not None:
        summary["trim_loop"] = loop_summary(s, stage / "trim_loop.csv")
    if not overlap:
        plot_run_figures(stage)
    write_summary(stage / "summary.json", summary)
    return summary

