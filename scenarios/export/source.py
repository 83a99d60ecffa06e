"""What an export reads: the run directory's scenario (its orbit, epoch and name:
scenario.yaml, or a Monte Carlo case's case_scenario.yaml, the one that flew) and
the 3-1-2 angles of estimate.csv or truth.csv, streamed in blocks of ``BLOCK_ROWS``
rows (pandas' chunked C parser): a year's 140 MB estimate.csv is never held whole.

A row's ``t_s`` is written with 10 significant digits (``files.csvio``), which past
1e6 s is coarser than a microsecond: a time within that precision of the scenario's
sample grid (k · sample_interval_s, as `dynprop run` writes its rows) is put back on
it, so that the AEM's epochs are the rows' true times.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import closing
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..config.loader import load_scenario
from ..config.schema import Scenario
from ..files.truth_file import TIME_MATCH_REL
from ..units import DEG

BLOCK_ROWS = 50_000
FILES = {"estimate": "estimate.csv", "truth": "truth.csv"}
COLUMNS = ("t_s", "roll_deg", "pitch_deg", "yaw_deg")


class ExportError(ValueError):
    """Bad input to `dynprop export`: one line per problem, naming the file or option."""


@dataclass(frozen=True)
class Block:
    """Rows of the file: ``t_s`` (s after the scenario's epoch) and the 3-1-2 angles
    of C_BR in rad (NaN where the file's field is empty)."""

    t_s: np.ndarray
    yaw: np.ndarray
    roll: np.ndarray
    pitch: np.ndarray


@dataclass(frozen=True)
class RunSource:
    """A run directory's attitude file: ``what`` (estimate or truth), the file, its
    scenario (``case``: a Monte Carlo case's, case_scenario.yaml), and its cadence
    (the median step of its first block of rows)."""

    directory: Path
    what: str
    csv: Path
    scenario: Scenario
    cadence_s: float
    skip: int          # comment lines before the header
    case: bool = False

    def blocks(self) -> Iterator[Block]:
        """The file's rows, ``BLOCK_ROWS`` at a time (close the generator when leaving
        it early: ``contextlib.closing``)."""
        import pandas as pd
        try:
            with pd.read_csv(self.csv, usecols=list(COLUMNS), dtype="float64",
                             skiprows=self.skip, chunksize=BLOCK_ROWS) as chunks:
                for chunk in chunks:
                    yield self._block(chunk)
        except ValueError as exc:   # pandas' ParserError is one
            why = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
            raise ExportError(f"{self.csv}: not a CSV of numbers ({why})") from None

    def _block(self, chunk) -> Block:
        t = on_grid(chunk["t_s"].to_numpy(), self.scenario.sample_interval_s)
        return Block(t, *(chunk[c].to_numpy() * DEG for c in ("yaw_deg", "roll_deg",
                                                                "pitch_deg")))


def on_grid(t: np.ndarray, dt: float) -> np.ndarray:
    """``t`` with each time that is k·dt to its 10 printed digits put back on k·dt
    (``truth_file.TIME_MATCH_REL``); any other time (off-grid telemetry) as it is."""
    k = np.rint(t / dt)
    ideal = k * dt
    near = np.abs(t - ideal) <= TIME_MATCH_REL * np.maximum(np.abs(ideal), dt)
    return np.where(near, ideal, t)


def _header(path: Path) -> tuple[list[str], int]:
    """The column names and the count of ``#`` lines before them."""
    skip = 0
    with open(path) as fh:
        for line in fh:
            if not line.startswith("#"):
                return line.strip().split(","), skip
            skip += 1
    return [], skip


def open_source(directory: Path | str, what: str = "estimate") -> RunSource:
    """The run directory's ``what`` (``estimate``: estimate.csv; ``truth``: truth.csv),
    checked: a directory dynprop wrote, the file, its columns and a first row.  A bad
    one raises ``ExportError`` (or the loader's ``ScenarioError``) in one line."""
    d = Path(directory)
    if what not in FILES:
        raise ExportError(f"--what {what}: choose estimate or truth")
    if not d.is_dir():
        raise ExportError(f"{d}: {'not a directory' if d.exists() else 'no such directory'}")
    if not (d / "scenario.yaml").is_file():
        raise ExportError(f"{d}: not a run directory (no scenario.yaml): export reads what "
                          "`dynprop run`, `simulate` or `estimate` wrote")
    csv = d / FILES[what]
    if not csv.is_file():
        hint = ("a `dynprop simulate` directory holds the truth only: --what truth"
                if what == "estimate" else "`dynprop estimate` writes none: export the "
                "truth from the run or simulation that made the telemetry")
        raise ExportError(f"{d}: no {csv.name} ({hint})")
    names, skip = _header(csv)
    if what == "estimate" and names and "pitch_deg" not in names:
        raise ExportError(f"{csv}: no pitch_deg column: the directory was written before "
                          "dynprop estimated pitch; rerun `dynprop run` or `dynprop estimate` "
                          "to export the estimate (or export the truth: --what truth)")
    missing = [c for c in COLUMNS if c not in names]
    if missing:
        raise ExportError(f"{csv}: no column {', '.join(missing)}"
                          if names else f"{csv}: the file is empty (no header)")
    # A Monte Carlo case's truth flew its own scenario (a dispersed epoch or orbit):
    # case_scenario.yaml; the filter's scenario.yaml is the nominal one.
    case = d / "case_scenario.yaml"
    s = load_scenario(case if case.is_file() else d / "scenario.yaml")
    first = RunSource(d, what, csv, s, float("nan"), skip, case.is_file())
    with closing(first.blocks()) as blocks:
        block = next(blocks, None)
    if block is None or not len(block.t_s):
        raise ExportError(f"{csv}: no rows to export")
    steps = np.diff(block.t_s)
    cadence = float(np.median(steps)) if steps.size else s.output.interval_s or \
        s.sample_interval_s
    if not cadence > 0:
        raise ExportError(f"{csv}: t_s does not increase (median step {cadence:g} s)")
    return replace(first, cadence_s=cadence)
