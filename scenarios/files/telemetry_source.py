"""A telemetry file as the commands that read it step through it: samples read by
range, never the whole record at once (issue 44: telemetry of any length).

``TelemetrySource`` is what `estimate`, `tune`, `batch` and `trim` ask of a file:
the filter's samples [start, stop) (``columns``), exactly the arrays
``telemetry_file.on_grid`` would hold whole, sliced, bit for bit; the interval after
each sample off the grid (``steps``); what summary.json says of the file
(``stats``) and of its screen (``screen``).  ``WholeSource`` holds a file read whole
(``read_screened`` + ``on_grid``): the reference the streamed reader
(``telemetry_spool``) is tested against, and what a file of a day or two costs
nothing to hold.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from .screen import ScreenReport
from .telemetry_file import GriddedTelemetry


class TelemetrySource(Protocol):
    """A telemetry file as the filter's samples (on the grid: one per grid step, NaN
    where no row fell, rows keeping their own tags; off it: one per row)."""

    regular: bool               # on the scenario's grid (``on_grid``)
    n: int                      # the filter's samples
    n_rows: int                 # the file's data rows
    names: tuple[str, ...]      # canonical columns (``read_screened``'s keys)
    screen: ScreenReport | None

    def columns(self, start: int, stop: int, names=None) -> dict[str, np.ndarray]:
        """Samples [start, stop) of ``names`` (all when None), as ``on_grid``'s
        whole columns sliced."""

    def steps(self, start: int, stop: int) -> np.ndarray | None:
        """Off the grid, the interval after each sample of [start, stop)
        (``step_intervals`` of the whole file, sliced); None on the grid."""

    def median_step_s(self) -> float:
        """The file's own cadence, ``np.median(np.diff(t))`` over the whole file's
        samples (``preprocess.cadence``)."""

    def stats(self, dt_s: float) -> dict:
        """``GriddedTelemetry.stats``: summary.json's ``telemetry`` figures."""

    def screened_t_s(self) -> np.ndarray:
        """Times of the file rows with a screened value (comparison.npz)."""

    def close(self) -> None:
        """Frees what the source holds (a spool's scratch files)."""


class WholeSource:
    """A ``TelemetrySource`` over a file read whole (``GriddedTelemetry``)."""

    def __init__(self, grid: GriddedTelemetry):
        self.grid = grid
        self.regular = grid.regular
        self.n = len(grid.rows)
        self.n_rows = grid.n_rows
        self.names = tuple(grid.columns)
        self.screen = grid.screen

    def columns(self, start: int, stop: int, names=None) -> dict[str, np.ndarray]:
        return {c: self.grid.columns[c][start:stop] for c in (names or self.names)}

    def steps(self, start: int, stop: int) -> np.ndarray | None:
        return None if self.grid.steps is None else self.grid.steps[start:stop]

    def median_step_s(self) -> float:
        t = self.grid.columns["t_s"]
        return float(np.median(np.diff(t)))

    def stats(self, dt_s: float) -> dict:
        return self.grid.stats(dt_s)

    def screened_t_s(self) -> np.ndarray:
        s = self.grid.screen
        if s is None or not s.count:
            return np.zeros(0)
        return s.t_s[s.rows_any()]

    def close(self) -> None:
        pass


def open_source(path, s, folder, block_rows: int | None = None) -> TelemetrySource:
    """The telemetry file ``path`` as the scenario ``s`` reads it, every problem
    reported (``RunDirError``, one line each) before this returns, so before a caller
    writes anything.  ``folder``: where a streamed reader keeps its scratch files (the
    caller's stage); ``block_rows``: its block size (a test hook).  The file is read in
    blocks into raw scratch columns there (``spool``): a block in memory at a time,
    every answer ``WholeSource``'s on the same file."""
    from .spool.source import open_spool
    return open_spool(path, s, folder, block_rows)


def whole_source(path, s) -> WholeSource:
    """The file read whole (``read_screened`` + ``on_grid``): the reference."""
    from .telemetry_file import on_grid, read_screened
    cols, report = read_screened(path, s)
    return WholeSource(on_grid(cols, s.sample_interval_s, s.estimator.max_gap_s, path, report))
