"""A telemetry file as a ``telemetry_source.TelemetrySource`` kept on disk: read once
in blocks (``reader.Pass``) into raw float64 scratch columns in the caller's folder,
then answered by range, every answer the whole read's (``WholeSource``) bit for bit.

On the grid with steps no row fell on, the rows are spread onto the grid in a second
sweep of the scratch columns (``on_grid``: NaN where no row fell, rows keeping their
own tags).  ``median_step_s`` and ``stats`` are found by sweeping the scratch time
column (``select.median``: exact, in bounded memory), once each.
"""

from __future__ import annotations

import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from ..telemetry_file import cadence_note
from . import disk
from .disk import Columns
from .reader import Pass
from .select import median


class SpoolSource:
    """The ``TelemetrySource`` of a file read in blocks (``open_spool``)."""

    def __init__(self, p: Pass, report, folder: Path, max_gap_s: float):
        self.folder = folder
        self.rows = p.cols
        self.n_rows = p.n_rows
        self.names = tuple(p.cols.paths)
        self.screen = report
        self.max_gap_s = max_gap_s
        self.dt = p.dt
        self.t0 = p.t0
        self.regular = not p.off_grid
        self.n = p.last_k + 1 if self.regular else self.n_rows
        # As many rows as grid steps: on_grid takes the rows as they are, each row
        # the sample of its index (even when a repeated step makes up for a hole).
        self.as_rows = self.n == self.n_rows
        self.repeats = 0 if self.as_rows else p.repeats
        self.present = self.n_rows if self.as_rows else p.present
        self.cadence = 1 if self.as_rows else p.cadence_steps()
        self.samples = self.rows if self.n == self.n_rows else self._spread()
        self._median: float | None = None
        self._stats: dict[float, dict] = {}
        if report is not None and report.count:
            # The rows summary.json names, read now so that it can be written after
            # close().
            for x in report.screened:
                for r in x.rows[:5]:
                    report.t_s[r]

    def _spread(self) -> Columns:
        """The rows placed on the grid (``on_grid``), a chunk of rows at a time: each
        sample is NaN but where a row fell (the last such row of a step, as NumPy's
        assignment leaves it), t_s the grid's time but where a row keeps its own."""
        grid = Columns(self.folder, self.names, ".grid")
        end = 0
        for a, t in self.rows.sweep("t_s"):
            k = np.rint((t - self.t0) / self.dt).astype(np.int64)
            lo, hi = min(int(k[0]), end), int(k[-1]) + 1
            for name in self.names:
                if name == "t_s":
                    seg = self.t0 + np.arange(lo, hi) * self.dt
                    seg[k - lo] = t
                else:
                    seg = np.full(hi - lo, np.nan)
                    seg[k - lo] = self.rows.read(name, a, a + len(t))
                grid.write(name, lo, seg)
            end = hi
        grid.close()
        for name in self.names:
            if name != "t_s":
                self.rows.paths[name].unlink()
        return grid

    def columns(self, start: int, stop: int, names=None) -> dict[str, np.ndarray]:
        r = range(self.n)[start:stop]
        return {c: self.samples.read(c, r.start, r.stop) for c in (names or self.names)}

    def steps(self, start: int, stop: int) -> np.ndarray | None:
        if self.regular:
            return None
        r = range(self.n)[start:stop]
        a, b = r.start, r.stop
        if a >= b:
            return np.zeros(0)
        dt = np.diff(self.rows.read("t_s", a, min(b + 1, self.n)))
        if b == self.n:
            dt = np.r_[dt, np.diff(self.rows.read("t_s", self.n - 2, self.n))]
        return dt

    def _present(self, cols: Columns, present: bool) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        """(t, k) of the samples a chunk at a time (``present``: on the grid, only the
        last row of each grid step, the rows ``stats`` sees; k: the grid step)."""
        dedupe = present and self.regular and self.repeats
        for a, t in cols.sweep("t_s", overlap=1 if dedupe else 0):
            k = (np.arange(a, a + len(t), dtype=float) if self.as_rows
                 else np.rint((t - self.t0) / self.dt))
            if dedupe:
                body = min(len(t), disk.READ_ROWS)
                keep = np.r_[k[1:] != k[:-1], True][:body]
                t, k = t[:body][keep], k[:body][keep]
            yield t, k

    def _diffs(self, cols: Columns, present: bool = False) -> Iterator[np.ndarray]:
        """The steps between consecutive samples, a chunk at a time."""
        prev = None
        for t, _ in self._present(cols, present):
            x = t if prev is None else np.r_[prev, t]
            if len(x):
                prev = x[-1]
                yield np.diff(x)

    def median_step_s(self) -> float:
        if self._median is None:
            self._median = median(lambda: self._diffs(self.samples))
        return self._median

    def stats(self, dt_s: float) -> dict:
        if dt_s not in self._stats:
            self._stats[dt_s] = self._compute_stats(dt_s)
        return dict(self._stats[dt_s])

    def _compute_stats(self, dt_s: float) -> dict:
        """``GriddedTelemetry.stats``, one sweep after the median."""
        med = median(lambda: self._diffs(self.rows, present=True))
        count = self.present - 1
        dropouts, longest, jitter, gaps = 0, 0.0, 0.0, []
        cadence = self.cadence
        cadence_s = cadence * dt_s if self.regular else med
        prev_t = prev_k = None
        for tp, kp in self._present(self.rows, True):
            if prev_t is not None:
                tp, kp = np.r_[prev_t, tp], np.r_[prev_k, kp]
            if not len(tp):
                continue
            prev_t, prev_k = tp[-1], kp[-1]
            steps = np.diff(tp)
            if self.regular:
                kd = np.diff(kp).astype(np.int64)
                long = kd > cadence
                lengths = (kd[long] - cadence) * dt_s
            else:
                long = steps > 1.5 * cadence_s
                lengths = steps[long] - cadence_s
                jitter = max(jitter, float(np.max(np.abs(steps[~long] - cadence_s),
                                                  initial=0.0)))
            over = lengths > self.max_gap_s
            gaps += [[float(tp[i] / 3600.0), float(steps[i] / 3600.0)]
                     for i in np.flatnonzero(long)[over]]
            dropouts += len(lengths)
            longest = max(longest, float(lengths.max(initial=0.0)))
        if self.regular:
            note = cadence_note(cadence, dt_s)
        else:
            note = (f"telemetry off the filter's {dt_s:g} s grid (cadence {cadence_s:g} s, "
                    f"steps within ±{jitter:.3g} s of it): the filter steps with each "
                    "sample's own interval")
        return {"rows": int(self.n_rows), "filter_steps": int(self.n),
                "missing_steps": int(self.n - self.present), "dropouts": int(dropouts),
                "longest_dropout_s": float(longest),
                "median_cadence_s": float(med) if count else None,
                "cadence_s": cadence_s, "cadence_note": note,
                "on_filter_grid": self.regular, "step_jitter_s": jitter,
                "gaps_over_max_gap_h": gaps,
                "screened": None if self.screen is None else self.screen.summary()}

    def screened_t_s(self) -> np.ndarray:
        s = self.screen
        if s is None or not s.count:
            return np.zeros(0)
        return s.t_s[s.rows_any()]

    def close(self) -> None:
        shutil.rmtree(self.folder, ignore_errors=True)

    def __enter__(self) -> SpoolSource:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def open_spool(path, s, folder, block_rows: int | None = None) -> SpoolSource:
    """``telemetry_source.open_source``, read in blocks: every problem raised
    (``RunDirError``) before it returns, its scratch files then removed."""
    scratch = Path(tempfile.mkdtemp(prefix=".telemetry-", dir=folder))
    p = None
    try:
        p = Pass(Path(path), s, scratch)
        p.run(block_rows)
        report = p.finish()
        p.cols.close()
        return SpoolSource(p, report, scratch, s.estimator.max_gap_s)
    except BaseException:
        if p is not None and p.cols is not None:
            p.cols.close()
        shutil.rmtree(scratch, ignore_errors=True)
        raise
