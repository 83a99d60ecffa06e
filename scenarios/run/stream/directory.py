"""`dynprop run` as a stream: the run directory written window by window.

The producer (truth, telemetry, the linear twin and its filter; it also writes
truth.csv and telemetry.csv) runs in a second process (``process``), while this
one runs the real filter and the smoother (``stream.windows_of``), tallies the
summary and daily.csv (``tally``, ``daily``, ``filter_tally``) and writes
estimate.csv and comparison.npz (``files.decimate``) at the output cadence.
Memory holds a few windows, whatever the duration.  Progress: a bar of simulated
days on a terminal, otherwise a line every ``LOG_EVERY_DAYS`` days, for runs
longer than one window.
"""

from __future__ import annotations

import contextlib
import sys
import time
from itertools import islice
from pathlib import Path

import numpy as np

from ...config import build
from ...config.schema import Scenario, output_writes_telemetry, resolved_yaml
from ...files.checks import add_checks
from ...files.columns import estimate_columns, pitch_columns
from ...files.csvio import CsvAppender, write_csv
from ...files.decimate import ComparisonRows
from ...files.summary import assemble_summary, eq55_sigma_yaw_deg, write_summary
from ...samples import nees_rows, output_rows
from ...units import DAY_S
from ...workers import blas_one_thread
from ..daily import DailyTally
from ..filter_tally import FilterTally
from ..filtering import count_rejected, design_of, filter_section
from ..pitch import PitchTally
from ..tally import RunTally
from .process import producer_process
from .producer import producer
from .windows import windows_of

LOG_EVERY_DAYS = 10


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
                        progress: bool = True, steering=None) -> dict:
    """Everything of one `dynprop run` into ``stage`` (docs/outputs.md); returns the
    summary.  ``processes=1`` keeps the producer in this process.  ``steering``
    steers the truth from the run's own telemetry (``producer``'s module doc): the
    trim loop, whose summary.json section its ``summary(stage)`` gives."""
    stage = Path(stage)
    (stage / "scenario.yaml").write_text(resolved_yaml(s))
    tel_file = output_writes_telemetry(s)
    if processes > 1:
        source = producer_process(s, run, window_samples, stage, tel_file, steering)
    else:
        source = producer(s, run, window_samples, stage, tel_file, steering)
    records = windows_of(s, items=source)
    plan = next(records)
    # The figures' modules (matplotlib: ~0.4 s) load while the producer simulates the
    # first window, rather than after the last.
    from ...figures.run import plot_run_figures, run_figures_drawn
    params, _ = build.estimator_model(s)
    dt = s.sample_interval_s
    n = plan.n_samples
    tally = RunTally(s)
    pitch = PitchTally(s)
    daily = DailyTally(s, build.epoch(s), n, eq55_sigma_yaw_deg(s, params))
    comparison = ComparisonRows(stage / ".comparison", n, plan.stride)
    estimate = CsvAppender(stage / "estimate.csv")
    # Filters beside the paper's (estimator.filters): their tallies and estimate file.
    extra = {name: (FilterTally(name), CsvAppender(stage / f"estimate_{name}.csv"))
             for name in s.estimator.filters if name != "paper"}
    bar = Progress(n * dt / DAY_S, progress and len(plan.bounds) > 1)
    design = design_of(s)
    last_bias, rejected = None, np.zeros(6, dtype=np.int64)
    # The figures need only comparison.npz and daily.csv, so they are drawn while the
    # producer writes the last of its files; a steered run's figure also reads the
    # file the producer writes (trim_loop.csv), so that run draws after it.
    overlap = steering is None

    def finished() -> dict:
        """summary.json, written, once every window is in (and a steered run's
        producer has written its trim_loop.csv)."""
        summary = assemble_summary(s, params, tally.backend, True, True, tally.statistics(n))
        summary.update(output_interval_s=plan.stride * dt, telemetry_written=tel_file,
                       daily="daily.csv")
        summary["filters"] = list(s.estimator.filters)   # the paper's alone elsewhere
        summary.update(filter_section(s, design, last_bias, rejected,
                                      build.truth_biases_rad(s)))
        for name, (figs, _) in extra.items():
            summary[name] = figs.summary()
        summary["pitch"] = pitch.summary()
        if steering is not None:
            summary.update(steering.summary(stage))
        write_summary(stage / "summary.json", add_checks(summary))
        return summary

    try:
        # The windows' records, and not one more: asking for the next would wait for
        # the producer to finish its files (stream.windows_of drains it there).
        for w in islice(records, len(plan.bounds)):
            err = w.real.x - w.truth_model
            err_lin = w.linear.x - w.twin_model
            nees_idx = nees_rows(w.start, w.stop)
            closed = tally.add(w, err, err_lin, nees_idx)
            daily.add(w, err, err_lin, nees_idx, closed)
            comparison.add(w, nees_idx, err, err_lin)
            k = output_rows(w.start, w.stop, plan.stride) - w.start
            bias = w.real.bias_columns or {}
            estimate.append(estimate_columns(w.t_s[k], w.real.x[k], w.real.sigma[k],
                                             params.omega_n_radps)
                            | {name: v[k] for name, v in bias.items()}
                            | pitch_columns(w.pitch.x[k], w.pitch.sigma[k]))
            pitch.add(w.pitch, w.start, w.t_s, w.pitch_truth)
            if bias:
                last_bias = {name: v[-1] for name, v in bias.items()}
            if w.real.rejected is not None:
                rejected = rejected + count_rejected(w.real.rejected, w.measured.sun_head)
            for name, (figs, file) in extra.items():
                figs.add(w.filters[name], w.start, w.truth_model, closed, w.t_s)
                file.append(estimate_columns(w.t_s[k], w.filters[name].x[k],
                                             w.filters[name].sigma[k], params.omega_n_radps))
            bar.update(w.stop * dt / DAY_S)
            del w, err, err_lin
        bar.close()
        comparison.finish(stage / "comparison.npz", plan.stride * dt)
        write_csv(stage / "daily.csv", daily.columns())
        if overlap:
            # summary.json before the figures: they draw its verdicts and warnings.
            summary = finished()
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
    if not overlap:
        summary = finished()
        plot_run_figures(stage)
    return summary
