"""What a page draws of a long CSV, read in blocks (``files.csvio.read_csv_blocks``)
and folded block by block into exactly what the whole columns give: a month's
truth.csv is 2 GB of text, and held whole it took 12 GB.

- each series reduced as ``traces.reduced`` reduces the whole column: the same
  bins (``traces.bin_starts``: their size from the row count, counted first), with
  the extremes of a bin that straddles two blocks folded together;
- the runs of a condition as ``traces.spans`` finds them in the whole column;
- a column's largest magnitude, and the 99th percentile of its magnitudes from its
  largest 1% (the order statistics ``np.percentile`` interpolates between);
- sums over the rows (counts).

Times stay in the file's seconds: the page's unit comes from the whole span, known
at the end (``Columns.in_unit``).  Memory: one block of text, a few thousand points
per series and 1% of a percentile's column.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from ..files.csvio import read_csv_blocks
from . import traces as tr

BLOCK_ROWS = 50_000      # a block of truth.csv (38 columns): 20 MB of text, 80 MB parsing


def count_rows(path) -> int:
    """The lines after the header and its ``#`` lines: the rows ``read_csv`` reads,
    unless the file holds blank lines (which it skips; ``read_columns`` checks)."""
    lines, last = 0, b"\n"
    with open(path, "rb") as fh:
        skip = 1
        while fh.readline().startswith(b"#"):
            skip += 1
        fh.seek(0)
        while chunk := fh.read(1 << 24):
            lines += chunk.count(b"\n")
            last = chunk[-1:]
    return max(0, lines + (last != b"\n") - skip)


class SeriesFold:
    """``traces.reduced(t, y)`` of named columns of ``n`` rows, fed in order, each
    column as ``read_csv`` gives it: a column of one 2-D array.

    The rows of the bin still open at a block's end are held for the next, so that
    each bin is reduced in one ``reduceat`` over its own rows, as over the whole
    column; and the rows are held as columns of one 2-D array too: which of 0.0 and
    -0.0 a bin's extreme is depends on the order numpy's loop compares them in, which
    differs between a strided column and a contiguous one."""

    def __init__(self, n: int, names):
        self.step = math.ceil(n / tr.MAX_POINTS) if n > tr.MAX_POINTS else 0
        self.names = list(names)
        self.row, self.after_break = 0, False   # the first held row; a break before it
        self.held = np.empty((0, 1 + len(self.names)))    # t_s, then the names
        self.x: list[np.ndarray] = []
        self.starts: list[int] = []            # the first two bins' first rows (the label)
        self.parts = {k: ([], []) for k in self.names}   # rows, or bins' lo and hi

    def add(self, t: np.ndarray, cols: dict) -> None:
        if not self.step:
            self.x.append(t)
            for k in self.names:
                self.parts[k][0].append(np.asarray(cols[k], dtype=float))
            return
        rows = np.column_stack([t, *(cols[k] for k in self.names)]).astype(float)
        self._bins(np.concatenate([self.held, rows]), final=False)

    def _bins(self, rows: np.ndarray, final: bool) -> None:
        t = rows[:, 0]
        if not len(t):
            return
        brk = np.isnan(t)   # a break is a bin of its own (traces.bin_starts)
        start = ((np.arange(self.row, self.row + len(t)) % self.step == 0) | brk
                 | np.r_[self.after_break, brk[:-1]])
        first = np.flatnonzero(start)          # first[0] == 0: held rows open a bin
        cut = len(t) if final else int(first[-1])
        first = first[first < cut]
        if cut:
            self.starts = (self.starts + (first + self.row).tolist())[:2]
            self.x.append(t[first])
            for j, k in enumerate(self.names, start=1):
                self.parts[k][0].append(np.fmin.reduceat(rows[:cut, j], first))
                self.parts[k][1].append(np.fmax.reduceat(rows[:cut, j], first))
            self.after_break = bool(brk[cut - 1])
            self.row += cut
        self.held = rows[cut:]

    def reduced(self, name: str) -> tr.Reduced:
        """The column's ``traces.Reduced``, x in the file's seconds (after the last
        block: the rows held are drawn)."""
        if self.step:
            self._bins(self.held, final=True)
        x = np.concatenate(self.x) if self.x else np.empty(0)
        a, b = (np.concatenate(p) if p else np.empty(0) for p in self.parts[name])
        if not self.step:
            return tr.Reduced(x, a, None, None)
        step = self.starts[1] - self.starts[0] if len(self.starts) > 1 else 1
        return tr.Reduced(x, None, a, b, step)


class RunsFold:
    """``traces.spans(t, mask)`` of the whole columns, fed in order: (t at a run's
    first row, t at the row after it, or at its last row at the end of the file;
    the row before where that t is NaN)."""

    def __init__(self):
        self.done: list[tuple[float, float]] = []
        self.open: float | None = None
        self.tail = np.full(2, np.nan)          # the last two rows' t

    def add(self, t: np.ndarray, mask: np.ndarray) -> None:
        if not len(t):
            return
        mask = np.asarray(mask, dtype=bool)
        before = np.r_[self.open is not None, mask[:-1]]
        ends = np.flatnonzero(~mask & before)
        end_t = np.where(np.isfinite(t[ends]), t[ends], np.r_[self.tail[-1], t[:-1]][ends])
        begin = ([self.open] if self.open is not None else []) + \
            t[np.flatnonzero(mask & ~before)].tolist()
        self.done += list(zip(begin, end_t.tolist(), strict=False))
        self.open = begin[len(ends)] if len(begin) > len(ends) else None
        self.tail = np.r_[self.tail, t][-2:]

    def spans(self) -> list[tuple[float, float]]:
        last, before = self.tail[-1], self.tail[-2]
        return self.done + ([] if self.open is None else
                            [(self.open, float(last if np.isfinite(last) else before))])


class TopFold:
    """``np.percentile(v[np.isfinite(v)], 99)`` of a column of at most ``n`` rows,
    fed in order, from its largest values only (the two order statistics the
    percentile interpolates between lie in its top 1%)."""

    def __init__(self, n: int):
        self.keep = n // 100 + 3
        self.top, self.count = np.empty(0), 0

    def add(self, v) -> None:
        v = np.asarray(v, dtype=float)
        v = v[np.isfinite(v)]
        self.count += v.size
        top = np.concatenate([self.top, v])
        self.top = np.partition(top, top.size - self.keep)[-self.keep:] \
            if top.size > self.keep else top

    def percentile99(self) -> float | None:
        """None for a column of no finite value."""
        if not self.count:
            return None
        top, n = np.sort(self.top), self.count
        v = (n - 1) * (99 / 100)      # as np.percentile's "linear" method places it
        lo = math.floor(v)
        hi = min(lo + 1, n - 1)
        below = n - top.size          # the values not kept
        # np.quantile of the two neighbours at the fraction: its own interpolation.
        return float(np.quantile(np.array([top[lo - below], top[hi - below]]), v - lo))


@dataclass(frozen=True)
class Columns:
    """One CSV as a page draws it (the x of every series, the runs, first_t and last_t
    in the file's seconds, ``in_unit`` for the page's)."""
    rows: int
    first_t: float
    last_t: float
    series: dict
    abs_max: dict         # largest |value| per column (NaN: none finite)
    p99: dict             # TopFold.percentile99 of |value| per column asked
    runs: dict            # name -> [(start, end)]
    sums: dict            # name -> the sum over the blocks

    def in_unit(self, name: str, scale: float) -> tr.Reduced:
        r = self.series[name]
        return replace(r, x=r.x / scale)


def header(path) -> list[str]:
    """The CSV's column names (after its ``#`` lines)."""
    with open(path) as fh:
        line = fh.readline()
        while line.startswith("#"):
            line = fh.readline()
    return line.strip().split(",") if line.strip() else []


def read_columns(path, names, runs: dict | None = None, p99=(),
                 sums: dict[str, Callable] | None = None,
                 block_rows: int | None = None) -> Columns:
    """The columns ``names`` (with ``t_s``, which the file must have) of the CSV at
    ``path``, with the runs of each ``runs`` condition (a function of a block's
    columns giving a mask), the percentile of each of ``p99`` and the sums of each
    ``sums`` function.  Raises ``read_csv``'s ValueError for a file that is not a
    CSV of numbers."""
    missing = [k for k in ("t_s", *names) if k not in header(path)]
    if missing:
        raise ValueError(f"{path}: no column {', '.join(dict.fromkeys(missing))}")
    n = count_rows(path)
    while True:
        got = _fold(path, names, n, runs or {}, p99, sums or {}, block_rows or BLOCK_ROWS)
        if got.rows == n:
            return got
        n = got.rows      # blank lines: the bins follow from the rows read


def _fold(path, names, n, runs, p99, sums, block_rows) -> Columns:
    series = SeriesFold(n, [k for k in names if k != "t_s"])
    top, spans = {k: TopFold(n) for k in p99}, {k: RunsFold() for k in runs}
    peak, total = dict.fromkeys(series.names, math.nan), dict.fromkeys(sums, 0)
    rows, first, last = 0, math.nan, math.nan
    for cols in read_csv_blocks(path, only={"t_s", *names}, block_rows=block_rows):
        t = cols["t_s"]
        first = float(t[0]) if not rows and len(t) else first
        series.add(t, cols)
        for k in series.names:
            a = np.abs(cols[k])
            peak[k] = np.fmax(peak[k], np.fmax.reduce(a) if len(a) else np.nan)
        for k, f in top.items():
            f.add(np.abs(cols[k]))
        for k, f in spans.items():
            f.add(t, runs[k](cols))
        for k, f in sums.items():
            total[k] = total[k] + f(cols)
        rows += len(t)
        last = float(t[-1]) if len(t) else last
    return Columns(rows, first, last, {k: series.reduced(k) for k in series.names},
                   {k: float(v) for k, v in peak.items()},
                   {k: f.percentile99() for k, f in top.items()},
                   {k: f.spans() for k, f in spans.items()}, total)
