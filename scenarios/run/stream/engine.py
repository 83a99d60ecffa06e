"""What a streamed run makes of each window, the one engine of `run` and `estimate`:
the summary's tallies (``tally``, ``daily``, ``pitch``, ``filter_tally``),
estimate.csv (and smoothed.csv, estimate_<filter>.csv) and comparison.npz at the
output cadence (``files.decimate``), a window at a time.

`run`'s windows carry the truth and the linear twin; a telemetry file's
(``file_windows``) carry neither, or a truth file's states, and their smoothed 1σ.
Whatever is absent is left out of the figures, never made up.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...config import build
from ...config.schema import Scenario
from ...files.columns import estimate_columns, pitch_columns
from ...files.csvio import CsvAppender
from ...files.decimate import ComparisonRows
from ...files.summary import eq55_sigma_yaw_deg
from ...records import Window
from ...samples import nees_rows, output_rows
from ..daily import DailyTally
from ..event_days import event_dicts
from ..filter_tally import FilterTally
from ..filtering import count_rejected
from ..pitch import PitchTally
from ..tally import RunTally


class Engine:
    """The tallies and files of a streamed run, fed one ``records.Window`` at a time
    (``add``) and closed by ``finish``.  ``truth``/``twin``: whether the windows carry
    them; ``t0_s`` the first sample's time (a file's first tag; 0 in a run), from
    which the start-up and the days are counted; ``smoothed``: write smoothed.csv.
    A file off the scenario's grid gives ``step_s`` (its median step) and ``span_s``
    (its first and last times): its gaps and days are then measured in time."""

    def __init__(self, s: Scenario, stage: Path, plan, *, truth: bool = True,
                 twin: bool = True, t0_s: float = 0.0, smoothed: bool = False,
                 step_s: float | None = None, span_s: tuple[float, float] | None = None):
        self.s, self.stage, self.plan = s, Path(stage), plan
        self.truth, self.twin, self.t0 = truth, twin, t0_s
        self.params, _ = build.estimator_model(s)
        n = plan.n_samples
        self.timed = step_s is not None
        self.tally = RunTally(s, truth, twin, step_s, t0_s)
        self.pitch = PitchTally(s)
        self.daily = DailyTally(s, build.epoch(s), n, eq55_sigma_yaw_deg(s, self.params),
                                span_s, event_dicts(s), t0_s)
        self.comparison = ComparisonRows(self.stage / ".comparison", n, plan.stride)
        self.estimate = CsvAppender(self.stage / "estimate.csv")
        self.smoothed = CsvAppender(self.stage / "smoothed.csv") if smoothed else None
        # Filters beside the paper's (estimator.filters): their tallies and estimate file.
        self.extra = {name: (FilterTally(name), CsvAppender(self.stage / f"estimate_{name}.csv"))
                      for name in s.estimator.filters if name != "paper"}
        self.last_bias, self.rejected = None, np.zeros(6, dtype=np.int64)
        self.rows_before = 0    # a sparse truth's rows in the windows before

    def add(self, w: Window) -> None:
        err = None if w.truth_model is None else w.real.x - w.truth_model
        err_lin = None if w.linear is None else w.linear.x - w.twin_model
        sparse = w.truth_rows is not None
        nees_idx = w.start + w.truth_rows if sparse else nees_rows(w.start, w.stop)
        closed = self.tally.add(w, err, err_lin, nees_idx)
        self.tally.end_window(w, err)
        hours = self.tally.gaps.hours[len(self.tally.gaps.hours) - len(closed):] \
            if self.timed else None
        self.daily.add(w, err, err_lin, nees_idx, closed, hours,
                       self.tally.end_errors if sparse else None)
        self.comparison.add(w, nees_idx, err, err_lin)
        k = output_rows(w.start, w.stop, self.plan.stride) - w.start
        wn = self.params.omega_n_radps
        bias = w.real.bias_columns or {}
        p = w.pitch
        self.estimate.append(estimate_columns(w.t_s[k], w.real.x[k], w.real.sigma[k], wn)
                             | {name: v[k] for name, v in bias.items()}
                             | ({} if p is None else pitch_columns(p.x[k], p.sigma[k])))
        if self.smoothed is not None and w.smoothed_sigma is not None:
            self.smoothed.append(estimate_columns(w.t_s[k], w.smoothed_x[k],
                                                  w.smoothed_sigma[k], wn))
        t_rel = w.t_s - self.t0
        if p is not None and not sparse:
            self.pitch.add(p, w.start, t_rel, w.pitch_truth)
        elif p is not None:
            self.pitch.add_own(p, t_rel)
            r = w.truth_rows
            self.pitch.add_errors(w.pitch_rows, self.rows_before, t_rel[r], w.pitch_truth[r])
            self.rows_before += len(r)
        if bias:
            self.last_bias = {name: v[-1] for name, v in bias.items()}
        if w.real.rejected is not None:
            self.rejected = self.rejected + count_rejected(w.real.rejected, w.measured.sun_head)
        for name, (figs, file) in self.extra.items():
            # A sparse truth's errors are the paper filter's alone.
            figs.add(w.filters[name], w.start, None if sparse else w.truth_model, closed,
                     t_rel)
            file.append(estimate_columns(w.t_s[k], w.filters[name].x[k],
                                         w.filters[name].sigma[k], wn))

    def finish(self, interval_s: float) -> None:
        """comparison.npz and daily.csv, once every window is in."""
        from ...files.csvio import write_csv
        self.comparison.finish(self.stage / "comparison.npz", interval_s)
        write_csv(self.stage / "daily.csv", self.daily.columns())

    def close(self) -> None:
        self.estimate.close()
        if self.smoothed is not None:
            self.smoothed.close()
        for _, file in self.extra.values():
            file.close()
