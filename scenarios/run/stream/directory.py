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

from ...config import build
from ...config.schema import Scenario, output_writes_telemetry, resolved_yaml
from ...files.checks import add_checks
from ...files.summary import assemble_summary, write_summary
from ...units import DAY_S
from ...workers import blas_one_thread
from ..filtering import design_of, filter_section
from .engine import Engine
from .process import producer_process
from .producer import MANAGEMENT_FILE, producer
from .windows import windows_of

LOG_EVERY_DAYS = 10


class Progress:
    """Simulated days: a tqdm bar on a terminal, else a line every LOG_EVERY_DAYS."""

    def __init__(self, total_days: float, enabled: bool, verb: str = "simulated"):
        self.total, self.enabled, self.verb = total_days, enabled, verb
        self.bar = None
        self.start = time.perf_counter()
        self.next_log = LOG_EVERY_DAYS
        if enabled and sys.stderr.isatty():
            from tqdm import tqdm
            self.bar = tqdm(total=round(total_days, 3), unit="day", desc=verb,
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
            print(f"dynprop: {done_days:.1f} of {self.total:.1f} days {self.verb}, "
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
    engine = Engine(s, stage, plan)
    bar = Progress(n * dt / DAY_S, progress and len(plan.bounds) > 1)
    design = design_of(s)
    # The figures need only comparison.npz and daily.csv, so they are drawn while the
    # producer writes the last of its files; a steered run's figure also reads the
    # file the producer writes (trim_loop.csv), so that run draws after it.
    overlap = steering is None

    def finished() -> dict:
        """summary.json, written, once every window is in (and a steered run's
        producer has written its trim_loop.csv)."""
        tally = engine.tally
        summary = assemble_summary(s, params, tally.backend, True, True, tally.statistics(n))
        summary.update(output_interval_s=plan.stride * dt, telemetry_written=tel_file,
                       daily="daily.csv")
        summary["filters"] = list(s.estimator.filters)   # the paper's alone elsewhere
        summary.update(filter_section(s, design, engine.last_bias, engine.rejected,
                                      build.truth_biases_rad(s)))
        for name, (figs, _) in engine.extra.items():
            summary[name] = figs.summary()
        summary["pitch"] = engine.pitch.summary()
        if s.momentum_management.on():
            summary["momentum_management"] = s.momentum_management.summary(MANAGEMENT_FILE)
        if steering is not None:
            summary.update(steering.summary(stage))
        write_summary(stage / "summary.json", add_checks(summary))
        return summary

    try:
        # The windows' records, and not one more: asking for the next would wait for
        # the producer to finish its files (stream.windows_of drains it there).
        for w in islice(records, len(plan.bounds)):
            engine.add(w)
            bar.update(w.stop * dt / DAY_S)
            del w
        bar.close()
        engine.finish(plan.stride * dt)
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
        engine.close()
        bar.close()
    if not overlap:
        summary = finished()
        plot_run_figures(stage)
    return summary
