"""The telemetry `dynprop tune` fits, for a file of any length (issue 44): read a block
at a time (``files.telemetry_source.open_source``) into a few numbers per sample
(``store``), which each likelihood pass reads back a block at a time.  The same
interface as the whole ``source.TuneSource``, and the same numbers: what `tune` writes
is that source's, held to it by tests/scenarios/test_tune_blocks.py."""

from __future__ import annotations

import shutil
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from dynprop.estimator.linear.model import ModelParams, ProcessNoise
from dynprop.estimator.tuning.likelihood import PASS_BLOCK

from ..bridge.inputs import initial_prior
from ..config import build
from ..config.schema import Scenario
from ..files.telemetry_source import open_source
from .source import LAG_SPAN, PAPER_GAP_S, locate, sun_gap_s
from .store import BLOCK_ROWS, Store, StoreSamples, Written, write_store


@dataclass(frozen=True)
class StreamedSource:
    """``source.TuneSource``'s interface over a ``store.Store``."""

    scenario: Scenario
    telemetry: Path
    run_dir: Path | None
    store: Store
    written: Written
    x0: np.ndarray
    P0: np.ndarray
    params: ModelParams
    noise: ProcessNoise
    stats: dict
    regular: bool
    cadence_s: float                  # the scenario's step on its grid, else the median
    block: int = PASS_BLOCK           # samples per block of a likelihood pass
    span: int = LAG_SPAN              # samples per piece of the autocorrelation
    rows: int = BLOCK_ROWS            # rows per block of the store

    @property
    def n(self) -> int:
        return self.written.n

    @property
    def t_first(self) -> float:
        return self.written.t_first

    @property
    def t_last(self) -> float:
        return self.written.t_last

    @property
    def span_s(self) -> float:
        return self.written.t_last - self.written.t_first

    def measured_gap_s(self) -> float | None:
        return sun_gap_s(self.scenario, self.written.yaw_present, self.written.t_s,
                         self.cadence_s)

    def gap_s(self) -> float:
        measured = self.measured_gap_s()
        return PAPER_GAP_S if measured is None else measured

    def updates(self) -> dict:
        return dict(self.written.updates)

    def roll_variance(self) -> float:
        return float(self.written.var_roll)

    def samples(self, every: int = 1) -> StoreSamples:
        return StoreSamples(self.store, self.written, self.scenario, self.params,
                            self.regular, every, self.rows)

    def times(self, start: int, stop: int) -> np.ndarray:
        return self.store.read("t", start, stop)


@contextmanager
def open_streamed(source: Path, scenario=None, overrides=(), folder: Path | None = None,
                  block_rows: int | None = None):
    """The ``StreamedSource`` of a run directory or a telemetry file with its scenario,
    its scratch files in ``folder`` (created, and removed on leaving); every problem of
    the file reported before it yields.  ``block_rows``: every block size at once, the
    store's, the passes' and the autocorrelation's (a test hook: small blocks put
    block boundaries anywhere)."""
    run_dir, path, s = locate(source, scenario, overrides)
    folder = Path(folder)
    folder.mkdir(parents=True)
    store = Store(folder / "samples")
    tel = None
    try:
        tel = open_source(path, s, folder, block_rows)      # its files beside the store
        rows = block_rows or BLOCK_ROWS
        written = write_store(store, tel, s, rows)
        stats = tel.stats(s.sample_interval_s)
        cadence = s.sample_interval_s if tel.regular else tel.median_step_s()
        regular = tel.regular
        tel.close()
        tel = None
        params, noise = build.estimator_model(s)
        x0, P0 = initial_prior(s, params)
        blocks = {} if block_rows is None else {"block": block_rows, "span": block_rows,
                                                "rows": block_rows}
        yield StreamedSource(s, path, run_dir, store, written, x0, P0, params, noise, stats,
                             regular, cadence, **blocks)
    finally:
        if tel is not None:
            tel.close()
        store.close()
        shutil.rmtree(folder, ignore_errors=True)
