"""Fast, deterministic CSV for day-long 0.512 s histories.

np.savetxt formats row by row in Python (~5 s for two days of truth).  Here each
block of rows is formatted by one C-level ``%`` operation, blocks are spread over
worker processes, and missing values (NaN) are written as empty fields.  The same
data always gives the same bytes.

Two number formats:

- ``exact``: the shortest text that reads back to the same double (Python's
  ``repr``, David Gay's algorithm), for files a computation re-reads:
  telemetry.csv, whose re-read must reproduce a run's filter bit for bit.  A
  quantised reading is written as its decimal, ``5485.0967``, not the 17 digits
  ``5485.0967000000001``.
- otherwise 10 significant digits (``%.10g``), for truth.csv and estimate.csv,
  which are read by people and plotting tools: each value is kept to within 5e-10
  of itself (half a unit of the tenth digit), i.e. 1e-11° on a 0.02° attitude,
  9e-8° on a 180° yaw, 3e-6 rpm on 5485 rpm and 1e-15 N m on a 2e-6 N m torque
  estimate, far below every sensor quantum and every σ the filter reports.  A
  re-read differs from the run's doubles in those digits; the run's summary is
  computed from the doubles.

A file may begin with ``#`` comment lines (telemetry.csv's ``# epoch_utc: ...``,
``columns.UtcTags``), which ``read_csv`` skips (``comments`` reads them), and hold
text columns (``TEXT_COLUMNS``: ``time_utc``), which it returns as strings.
"""

from __future__ import annotations

import io
import itertools
import os
from contextlib import nullcontext
from multiprocessing import get_context
from pathlib import Path

import numpy as np

from ..workers import ignore_sigint, sigint_held, worker_pool
from .columns import UtcTags, decimals_of
from .rundir import names_file

FMT = "%.10g"
BLOCK_ROWS = 40_000


EXACT_FMT = "%r"  # shortest text that round-trips every double (repr)
# Columns of text, not numbers: ISO 8601 UTC time tags (``columns.UtcTags``).
TEXT_COLUMNS = ("time_utc",)


def _format_block(block: np.ndarray, fmt_one: str = FMT, lattices=None, tags=None) -> str:
    """Rows of ``block`` as CSV text.  With ``EXACT_FMT``, ``lattices`` may give each
    column's reading quantum (None for a column that has none): see
    ``_lattice_text``.  ``tags`` (a ``columns.UtcTags`` and the index of the t_s
    column) appends each row's time_utc, formatted here (in the worker) at once."""
    if tags is not None:
        utc, k = tags
        return _format_exact(block, lattices or (None,) * block.shape[1], fmt_one,
                             utc.text(block[:, k]))
    if fmt_one == EXACT_FMT and lattices is not None and any(lattices):
        return _format_exact(block, lattices)
    fmt = ",".join([fmt_one] * block.shape[1]) + "\n"
    text = (fmt * block.shape[0]) % tuple(block.ravel().tolist())
    return _empty_nan(text)


def _format_exact(block: np.ndarray, lattices, fmt_one: str = EXACT_FMT,
                  last: np.ndarray | None = None) -> str:
    """``_format_block(block, fmt_one)``, byte for byte, with the quantised columns'
    text looked up rather than formatted value by value (exact text only), and the
    text column ``last`` after the others, if given."""
    cells = np.empty((block.shape[0], block.shape[1] + (last is not None)), dtype=object)
    fmts = []
    for j, q in enumerate(lattices):
        text = _lattice_text(block[:, j], q) if q and fmt_one == EXACT_FMT else None
        if text is None:
            cells[:, j] = block[:, j]   # Python floats, formatted by fmt_one
            fmts.append(fmt_one)
        else:
            cells[:, j] = text
            fmts.append("%s")
    if last is not None:
        cells[:, -1] = last
        fmts.append("%s")
    fmt = ",".join(fmts) + "\n"
    return _empty_nan((fmt * block.shape[0]) % tuple(cells.ravel().tolist()))


def _lattice_text(values: np.ndarray, quantum: float) -> np.ndarray | None:
    """repr of each value of a column of quantised readings (``columns.
    as_decimal_reading``: round(k·q, d) for integer k, d the quantum's decimals),
    from one repr per reading level: a reading's text is the table's only where its
    double is the level's bit for bit (−0.0 included), otherwise its own repr.
    None when the column is not worth it (no decimals, too many levels)."""
    d = decimals_of(quantum)
    if d is None:
        return None
    with np.errstate(invalid="ignore", over="ignore"):
        k = np.round(values / quantum)
    ok = np.isfinite(k)
    if not ok.any():
        return None
    lo, hi = k[ok].min(), k[ok].max()
    if hi - lo > 100_000:
        return None
    levels = np.append(np.round(np.arange(lo, hi + 1) * quantum, d), np.nan)
    table = np.array(list(map(repr, levels.tolist())), dtype=object)
    idx = np.where(ok, k - lo, len(levels) - 1).astype(np.int64)
    text = table[idx]
    same = levels[idx].view(np.int64) == values.view(np.int64)
    other = np.flatnonzero(~same & ~np.isnan(values))
    text[other] = list(map(repr, values[other].tolist()))
    return text


def _empty_nan(text: str) -> str:
    # NaN marks a missing value: an empty field.  ",nan" cannot occur otherwise.
    text = text.replace(",nan", ",").replace("\nnan", "\n")
    return text[3:] if text.startswith("nan") else text


def write_csv(path: Path | str, columns: dict[str, np.ndarray], workers: int | None = None,
              progress=None, exact: bool = False,
              lattices: dict[str, float] | None = None, tags: UtcTags | None = None) -> None:
    """Write named equal-length columns; ``progress(n_rows)`` is called per block.
    ``exact`` writes the shortest round-trip text, so that reading the file back
    gives the very same doubles; ``lattices`` (column name to reading quantum) only
    makes that faster, never different (``_lattice_text``).  ``tags`` puts its
    ``# epoch_utc:`` line first and a ``time_utc`` column after the others (from
    ``t_s``), leaving every other byte as it was."""
    names = list(columns)
    data = np.column_stack([np.asarray(columns[k], dtype=float) for k in names])
    blocks = [data[i:i + BLOCK_ROWS] for i in range(0, len(data), BLOCK_ROWS)]
    workers = workers or min(2, os.cpu_count() or 1)
    # Fork keeps worker start-up to milliseconds; one block needs no pool at all.
    pool = worker_pool(workers, get_context("fork")) \
        if workers > 1 and len(blocks) > 1 else nullcontext()
    with names_file(path), open(path, "w", newline="") as fh, pool as executor:
        fh.write(_header(names, tags))
        fmts = [EXACT_FMT if exact else FMT] * len(blocks)
        quanta = [_quanta(names, lattices)] * len(blocks)
        tagged = [None if tags is None else (tags, names.index("t_s"))] * len(blocks)
        texts = (executor.map if executor is not None else map)(_format_block, blocks, fmts,
                                                                quanta, tagged)
        for block, text in zip(blocks, texts, strict=True):
            fh.write(text)
            if progress is not None:
                progress(len(block))


def _quanta(names: list[str], lattices: dict[str, float] | None) -> tuple | None:
    return None if lattices is None else tuple(lattices.get(n) for n in names)


def _header(names: list[str], tags: UtcTags | None) -> str:
    if tags is None:
        return ",".join(names) + "\n"
    return tags.comment() + ",".join([*names, "time_utc"]) + "\n"


def _write_quietly(path: Path, columns: dict[str, np.ndarray]) -> None:
    ignore_sigint()  # the parent handles Ctrl-C and cancels this writer
    write_csv(path, columns, workers=1)


class BackgroundWriter:
    """Write one CSV in a forked process while the caller goes on computing.

    ``wait()`` raises if the child failed; ``cancel()`` stops it (used when the run
    fails, before its staging directory is removed)."""

    def __init__(self, path: Path | str, columns: dict[str, np.ndarray]):
        self.path = Path(path)
        self.process = get_context("fork").Process(
            target=_write_quietly, args=(self.path, columns), daemon=True)
        with sigint_held():
            self.process.start()

    def wait(self) -> None:
        self.process.join()
        if self.process.exitcode != 0:
            raise RuntimeError(f"writing {self.path.name} failed "
                               f"(exit {self.process.exitcode})")

    def cancel(self) -> None:
        if self.process.is_alive():
            self.process.terminate()
        self.process.join()


def read_csv(path: Path | str, text=TEXT_COLUMNS, only=None) -> dict[str, np.ndarray]:
    """Columns of a CSV of numbers (empty fields read as NaN), with NumPy's C parser;
    leading ``#`` comment lines are skipped.  The columns named in ``text`` are
    returned as strings (an empty field as ""); with ``only``, just those columns
    are returned (the others are not parsed).  A file that is not one raises
    ValueError in one line naming the file, the row (the header being row 1, comment
    lines not counted) and the column."""
    with open(path) as fh:
        header = fh.readline()
        while header.startswith("#"):
            header = fh.readline()
        body = fh.read()
    if not header.strip():
        raise ValueError(f"{path}: the file is empty (no header)" if not body.strip()
                         else f"{path}: row 1 is empty; it must be the header of column names")
    names = header.strip().split(",")
    wanted = [n for n in names if only is None or n in only]
    if not body.strip():
        return {name: np.empty(0, dtype=str if name in text else float) for name in wanted}
    try:
        return _parse_body(body, names, [n for n in wanted if n in text],
                           [n for n in wanted if n not in text])
    except ValueError:
        # NumPy's message counts rows from the first data row and ends with a hint for
        # its own API (`usecols`); find the row and say what is wrong with it instead.
        raise ValueError(f"{path}: {_first_bad_row(body, names, wanted, text)}") from None


def read_csv_blocks(path: Path | str, text=TEXT_COLUMNS, only=None, block_rows: int = 100_000):
    """``read_csv``'s columns ``block_rows`` lines at a time, for a file too long to
    hold (a month's truth.csv is 2 GB of text): each block is parsed by the same
    parser as the whole read, so the blocks joined are ``read_csv``'s values bit for
    bit, and a bad row raises its message, row for row.  A file of no rows gives no
    block."""
    with open(path) as fh:
        header = fh.readline()
        while header.startswith("#"):
            header = fh.readline()
        if not header.strip():
            raise ValueError(f"{path}: row 1 is empty; it must be the header of column names"
                             if any(line.strip() for line in fh)
                             else f"{path}: the file is empty (no header)")
        names = header.strip().split(",")
        wanted = [n for n in names if only is None or n in only]
        first = 2              # the file's row of the block's first line (the header is 1)
        while lines := list(itertools.islice(fh, block_rows)):
            body = "".join(lines)
            if not body.isspace():     # (strip would copy the block)
                try:
                    yield _parse_body(body, names, [n for n in wanted if n in text],
                                      [n for n in wanted if n not in text])
                except ValueError:
                    why = _first_bad_row(body, names, wanted, text, first)
                    raise ValueError(f"{path}: {why}") from None
            first += len(lines)


def _has_non_number_text(path: Path | str, block: int = 1 << 24) -> bool:
    """Whether the rows after the header hold ``nan`` or ``inf`` in any case, read a
    block at a time (a season's file is not held whole for this)."""
    with open(path) as fh:
        line = fh.readline()
        while line.startswith("#"):
            line = fh.readline()
        tail = ""
        while chunk := fh.read(block):
            text = tail + chunk.lower()
            if "nan" in text or "inf" in text:
                return True
            tail = text[-2:]
    return False


def non_number_cells(path: Path | str, numeric: list[str]) -> dict[str, np.ndarray]:
    """Per column of ``numeric``, the cells written as a non-finite number (``nan``,
    ``inf``): the fast reader takes them as it takes an empty cell, a dropout, so they
    are found here from the text, and only when the text has any at all.  Line by
    line, parsing only the lines that hold such text: memory does not grow with the
    file (a month of telemetry is 550 MB of text).  Rows are counted as ``read_csv``
    counts them, blank lines skipped."""
    if not _has_non_number_text(path):
        return {}
    hits: dict[str, list[int]] = {}
    with open(path) as fh:
        header = fh.readline()
        while header.startswith("#"):
            header = fh.readline()
        cols = [(j, n) for j, n in enumerate(header.strip().split(",")) if n in numeric]
        k = non_number_rows(fh, cols, hits)
    return marks_of(hits, k + 1)


def non_number_rows(lines, cols: list[tuple[int, str]], hits: dict[str, list[int]]) -> int:
    """Appends to ``hits`` (per column name) the data rows of ``lines`` whose cell in
    column index j (``cols``: (j, name)) is written as a non-finite number, rows
    counted from 0 with blank lines skipped, as ``read_csv`` counts them; returns the
    last row's number (−1 for none)."""
    k = -1
    for line in lines:
        if not line.strip():
            continue
        k += 1
        low = line.lower()
        if "nan" not in low and "inf" not in low:
            continue
        cells = line.rstrip("\r\n").split(",")
        for j, name in cols:
            text = cells[j].strip() if j < len(cells) else ""
            if text and not np.isfinite(float(text)):
                hits.setdefault(name, []).append(k)
    return k


def marks_of(hits: dict[str, list[int]], n: int) -> dict[str, np.ndarray]:
    """``non_number_rows``' hits as a boolean column of ``n`` rows each."""
    marks = {}
    for name, rows in hits.items():
        marks[name] = np.zeros(n, dtype=bool)
        marks[name][rows] = True
    return marks


def comments(path: Path | str) -> dict[str, str]:
    """The ``# key: value`` lines a CSV begins with, by key (``# epoch_utc: ...``)."""
    found = {}
    with open(path) as fh:
        for line in fh:
            if not line.startswith("#"):
                break
            key, sep, value = line[1:].partition(":")
            if sep:
                found[key.strip()] = value.strip()
    return found


def _first_bad_row(body: str, names: list[str], wanted=None, text=(), first: int = 2) -> str:
    numbers = [n for n in (names if wanted is None else wanted) if n not in text]
    for k, line in enumerate(body.splitlines(), start=first):
        if not line.strip():
            continue
        fields = line.split(",")
        if len(fields) != len(names):
            return (f"row {k} has {len(fields)} value{'s' * (len(fields) != 1)}, but the "
                    f"header (row 1) names {len(names)} column{'s' * (len(names) != 1)}")
        for name, field in zip(names, fields, strict=True):
            try:
                if name in numbers:
                    float(field.strip() or "nan")
            except ValueError:
                return f"row {k}, column {name}: {field.strip()!r} is not a number"
    return "not a CSV of numbers"


def _parse_body(body: str, names: list[str], text=(), numbers=None) -> dict[str, np.ndarray]:
    # Empty fields become "nan" so the fast parser can take them.
    body = "\n" + body
    body = body.replace("\n,", "\nnan,").replace(",\n", ",nan\n")
    while ",," in body:
        body = body.replace(",,", ",nan,")
    if body.endswith(","):
        body += "nan"
    numbers = names if numbers is None else numbers
    if not text and numbers == names:
        data = np.loadtxt(io.StringIO(body), delimiter=",", ndmin=2)
        if data.shape[1] != len(names):
            raise ValueError(f"{data.shape[1]} values per row for {len(names)} columns")
        return {name: data[:, k] for k, name in enumerate(names)}
    # Some columns only: NumPy checks no row's length then, so count the commas.
    while "\n\n" in body:   # blank lines, which the parser skips
        body = body.replace("\n\n", "\n")
    rows = body.count("\n") - body.endswith("\n")
    if body.count(",") != rows * (len(names) - 1):
        raise ValueError("a row's length differs from the header's")
    body = body.lstrip("\n")
    out = {}
    if numbers:
        data = np.loadtxt(io.StringIO(body), delimiter=",", ndmin=2,
                          usecols=[names.index(n) for n in numbers])
        out = {name: data[:, k] for k, name in enumerate(numbers)}
    for name in text:
        values = np.loadtxt(io.StringIO(body), delimiter=",", ndmin=1, dtype=str,
                            comments=None, usecols=[names.index(name)])
        out[name] = np.where(values == "nan", "", values)
    return {name: out[name] for name in names if name in out}


class CsvAppender:
    """A CSV written a window at a time, with the bytes ``write_csv`` gives for the
    whole table (every row is formatted on its own, so how the rows arrive in
    blocks changes nothing).  ``close()`` after the last block."""

    def __init__(self, path: Path | str, exact: bool = False,
                 lattices: dict[str, float] | None = None, tags: UtcTags | None = None):
        self.path = Path(path)
        self.fmt = EXACT_FMT if exact else FMT
        self.lattices = lattices
        self.tags = tags   # as write_csv's
        with names_file(self.path):
            self.fh = open(self.path, "w", newline="")  # noqa: SIM115 (closed by close())
        self.names: list[str] | None = None

    def append(self, columns: dict[str, np.ndarray]) -> None:
        with names_file(self.path):
            self._append(columns)

    def _append(self, columns: dict[str, np.ndarray]) -> None:
        if self.names is None:
            self.names = list(columns)
            self.fh.write(_header(self.names, self.tags))
        elif list(columns) != self.names:
            raise ValueError(f"{self.path.name}: columns changed between blocks")
        data = np.column_stack([np.asarray(columns[k], dtype=float) for k in self.names])
        quanta = _quanta(self.names, self.lattices)
        tagged = None if self.tags is None else (self.tags, self.names.index("t_s"))
        for i in range(0, len(data), BLOCK_ROWS):
            self.fh.write(_format_block(data[i:i + BLOCK_ROWS], self.fmt, quanta, tagged))

    def close(self) -> None:
        with names_file(self.path):
            self.fh.close()
