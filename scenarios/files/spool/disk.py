"""Raw float64 scratch columns on disk, read by range (``np.fromfile`` with an
offset: only the rows asked for are read, and nothing stays mapped, so a year's
columns cost the reader no memory), written by appending blocks and patched in place.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

import numpy as np

READ_ROWS = 1 << 18         # rows per chunk when a whole column is swept (2 MB)


class Columns:
    """Named float64 columns of equal length in ``folder``."""

    def __init__(self, folder: Path, names, tag: str = ""):
        self.folder = Path(folder)
        self.paths = {n: self.folder / f"{n}{tag}.f8" for n in names}
        self.fds = {n: os.open(p, os.O_RDWR | os.O_CREAT | os.O_TRUNC, 0o600)
                    for n, p in self.paths.items()}
        self.size = 0

    def append(self, cols: dict[str, np.ndarray]) -> None:
        n = None
        for name, fd in self.fds.items():
            v = np.ascontiguousarray(cols[name], dtype=np.float64)
            n = len(v)
            _pwrite(fd, v, self.size)
        self.size += n or 0

    def write(self, name: str, start: int, values: np.ndarray) -> None:
        _pwrite(self.fds[name], np.ascontiguousarray(values, dtype=np.float64), start)
        self.size = max(self.size, start + len(values))

    def read(self, name: str, start: int, stop: int) -> np.ndarray:
        count = max(0, stop - start)
        if count == 0:
            return np.zeros(0)
        return np.fromfile(self.paths[name], dtype=np.float64, count=count, offset=start * 8)

    def rows(self, name: str, rows: np.ndarray) -> np.ndarray:
        """The values at sorted ``rows``, read a chunk of the column at a time."""
        rows = np.asarray(rows, dtype=np.int64)
        out = np.empty(len(rows))
        i = 0
        while i < len(rows):
            a = int(rows[i])
            b = min(a + READ_ROWS, self.size)
            j = int(np.searchsorted(rows, b, side="left"))
            out[i:j] = self.read(name, a, b)[rows[i:j] - a]
            i = j
        return out

    def sweep(self, name: str, overlap: int = 0) -> Iterator[tuple[int, np.ndarray]]:
        """(start, values) over the whole column; each chunk also holds the next
        ``overlap`` values (the last chunk, as many as there are)."""
        for a in range(0, self.size, READ_ROWS):
            yield a, self.read(name, a, min(a + READ_ROWS + overlap, self.size))

    def close(self) -> None:
        for fd in self.fds.values():
            os.close(fd)
        self.fds = {}

    def delete(self) -> None:
        self.close()
        for p in self.paths.values():
            p.unlink(missing_ok=True)


class RowTimes:
    """The time of any file row (``ScreenReport.t_s``) read from the scratch time
    column, without holding every row's: an integer or an array of rows."""

    def __init__(self, cols: Columns, n_rows: int):
        self.cols, self.n = cols, n_rows
        self.known: dict[int, float] = {}

    def __len__(self) -> int:
        return self.n

    def __getitem__(self, rows):
        if np.ndim(rows) == 0:
            r = int(rows)
            if r not in self.known:
                self.known[r] = float(self.cols.read("t_s", r, r + 1)[0])
            return self.known[r]
        rows = np.asarray(rows)
        if rows.dtype == bool:
            rows = np.flatnonzero(rows)
        order = np.argsort(rows, kind="stable")
        out = np.empty(len(rows))
        out[order] = self.cols.rows("t_s", rows[order])
        return out


def _pwrite(fd: int, values: np.ndarray, start: int) -> None:
    view = memoryview(values).cast("B")
    offset = start * 8
    while len(view):
        done = os.pwrite(fd, view, offset)
        view, offset = view[done:], offset + done
