"""The one pass over a telemetry file: ``read_screened`` and ``on_grid`` a block at a
time, every row converted, checked, screened and appended to raw scratch columns.

What the whole read judges over every row is carried from block to block: the first
row of each problem (a non-finite or decreasing tag, a bad time tag), the raw and the
screened answers of the checks that follow the screen (the whole read screens only a
file with no earlier problem, so both are kept until the end), the grid's step
counts.  The unit check (``screen.unit_problems``, medians over the file) is judged on
the file's first two days of rows (at most ``UNIT_ROWS``): the whole file for the
files of two days or less that were read whole before.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...config import build
from ...config.suggestions import cap_lines
from ..rundir import RunDirError
from ..screen import unit_problems
from ..telemetry_file import GRID_TOLERANCE, wheel_end_problem
from ..telemetry_reader import (
    MEASUREMENTS,
    SUN_ANGLE_COLUMNS,
    Table,
    file_names,
    mapped_name,
    measurements,
    wheel_keys,
    written_marks,
)
from .blocks import read_blocks
from .disk import Columns, RowTimes
from .screening import BlockScreen
from .times import Times

UNIT_SPAN_S = 2 * 86400.0
UNIT_ROWS = 2_000_000
SMALL_STEP = 4096           # grid steps counted in a bincount; longer ones in a dict


class Pass:
    """State of the pass; ``run`` feeds the blocks, ``finish`` judges the file."""

    def __init__(self, path: Path, s, folder: Path):
        self.path, self.s, self.folder = path, s, folder
        self.spec = s.telemetry
        self.n_wheels = len(build.yaw_factors(s))
        self.wheels = tuple(f"wheel{i + 1}_rpm" for i in range(self.n_wheels))
        self.names = file_names(self.spec, self.n_wheels)
        self.dt = s.sample_interval_s
        self.screen = BlockScreen(s, self.names)
        self.n_rows = 0
        self.times = None
        self.cols: Columns | None = None
        self.measure_problems: list[str] = []
        self.unit: dict[str, list] = {}
        self.unit_rows = 0
        self.unit_open = True
        self.raw_ends: dict[str, list] = {}
        self.raw_sigma_bad = self.raw_head_bad = False
        self.sigma_bad = self.head_bad = False
        self.first_bad_t: int | None = None
        self.decrease: str | None = None
        self.t0 = self.last_t = self.last_k = None
        self.off_grid = False
        self.k_small = np.zeros(SMALL_STEP, dtype=np.int64)
        self.k_big: dict[int, int] = {}
        self.present = 0          # distinct grid steps with a row
        self.repeats = 0          # rows on the grid step of the row before

    def wanted(self) -> set[str]:
        c = self.spec.columns
        return {c.t_s, c.time_utc,
                *(mapped_name(c, k, canon) for k, (canon, _, _) in MEASUREMENTS.items()),
                *(mapped_name(c, k, canon) for k, canon in wheel_keys(self.n_wheels)),
                *SUN_ANGLE_COLUMNS}

    def run(self, block_rows: int | None) -> None:
        head, blocks = read_blocks(self.path, self.wanted(), self.spec.columns.time_utc,
                                   block_rows)
        self.head = head
        for b in blocks:
            self.block(b)

    def block(self, b) -> None:
        head = self.head
        # Text read by pyarrow stays arrow; measurements only needs to see it is text.
        plain = {k: (v if isinstance(v, np.ndarray) else np.empty(0, dtype=str))
                 for k, v in b.columns.items()}
        table = Table(plain, head.names, head.epoch, head.epoch_source, b.written)
        measured, problems = measurements(self.path, table, self.spec, self.n_wheels)
        if self.times is None:
            self.times = Times(self.path, head, set(b.columns), self.s)
            self.measure_problems = problems
        t = self.times.block(b.columns, b.row0)
        self._raw_checks(measured, b)
        self._unit_sample(measured, t, b.n)
        self.n_rows += b.n
        if t is None or not b.n:
            return
        self._times(t, b.row0)
        cols = {"t_s": t, **measured}
        out, patches = self.screen.block(cols, written_marks(table, self.spec, self.n_wheels),
                                         b.row0)
        self.sigma_bad |= _sigma_bad(out)
        self.head_bad |= _head_bad(out)
        if self.cols is None:
            self.cols = Columns(self.folder, list(out), ".rows")
        for name, row, value in patches:
            self.cols.write(name, row, np.array([value]))
        self.cols.append(out)

    def _raw_checks(self, measured: dict, b) -> None:
        for name in self.wheels:
            if name in measured and b.n:
                v = measured[name]
                ends = self.raw_ends.setdefault(name, [v[0], v[-1]])
                ends[1] = v[-1]
        self.raw_sigma_bad |= _sigma_bad(measured)
        self.raw_head_bad |= _head_bad(measured)

    def _unit_sample(self, measured: dict, t, n: int) -> None:
        if not self.unit_open or not self.spec.screen.enabled:
            return
        take = min(n, UNIT_ROWS - self.unit_rows)
        if t is not None and n:
            t0 = self.t0 if self.t0 is not None else t[0]
            late = np.flatnonzero(t[:take] > t0 + UNIT_SPAN_S)
            take = int(late[0]) if late.size else take
        for name, v in measured.items():
            if name not in SUN_ANGLE_COLUMNS:
                self.unit.setdefault(name, []).append(v[:take].copy())
        self.unit_rows += take
        self.unit_open = take == n and self.unit_rows < UNIT_ROWS

    def _times(self, t: np.ndarray, row0: int) -> None:
        bad = np.flatnonzero(~np.isfinite(t))
        if bad.size and self.first_bad_t is None:
            self.first_bad_t = row0 + int(bad[0])
        prev = t if self.last_t is None else np.concatenate([[self.last_t], t])
        first = row0 if self.last_t is None else row0 - 1
        if self.decrease is None:
            stop = np.flatnonzero(np.diff(prev) <= 0)
            if stop.size:
                k = int(stop[0])
                self.decrease = (f"{self.path}: time tags must increase; row {first + k + 3} "
                                 f"({prev[k + 1]:g} s) does not follow row {first + k + 2} "
                                 f"({prev[k]:g} s)")
        if self.t0 is None:
            self.t0 = t[0]
        self.last_t = t[-1]
        if self.off_grid or self.first_bad_t is not None:
            return      # (a file with a non-finite tag is refused)
        k_float = (t - self.t0) / self.dt
        k = np.rint(k_float)
        if np.any(np.abs(k_float - k) > GRID_TOLERANCE):
            self.off_grid = True
            return
        k = k.astype(np.int64)
        kd = np.diff(k) if self.last_k is None else np.diff(np.concatenate([[self.last_k], k]))
        self.present += int(self.last_k is None) + int(np.count_nonzero(kd))
        self.repeats += int(np.count_nonzero(kd == 0))
        step = kd[kd > 0]
        self.k_small += np.bincount(step[step < SMALL_STEP], minlength=SMALL_STEP)
        for v, count in zip(*np.unique(step[step >= SMALL_STEP], return_counts=True),
                            strict=True):
            self.k_big[int(v)] = self.k_big.get(int(v), 0) + int(count)
        self.last_k = int(k[-1])

    def cadence_steps(self) -> int:
        """``stats``' cadence on the grid: the most common step between rows, in grid
        steps (the smallest of the most common), 1 for a single present sample."""
        if self.present < 2:
            return 1
        best = int(self.k_small.max())
        big = max(self.k_big.values(), default=0)
        if big > best:
            return min(k for k, v in self.k_big.items() if v == big)
        return int(self.k_small.argmax())

    def finish(self):
        """Every problem of the whole read, raised in its one-line form; else the
        screen report (None if the screen is off) for ``source``."""
        path, times = self.path, self.times
        problems = self.measure_problems + times.problems(self.n_rows)
        known = times.known
        if known and self.n_rows < 2:
            problems.append(f"{path}: needs at least two samples")
        if self.spec.screen.enabled:
            sample = {k: np.concatenate(v) for k, v in self.unit.items()}
            problems += unit_problems(path, sample, self.s, self.names)
        screened = known and not problems
        report = None
        if screened:
            report, patches = self.screen.finish(self.n_rows, RowTimes(self.cols, self.n_rows))
            for name, row, value in patches:
                self.cols.write(name, row, np.array([value]))
        if known and self.first_bad_t is not None:
            problems.append(f"{path}: column {self.spec.columns.t_s} has a missing or "
                            f"non-numeric value in row {self.first_bad_t + 2}")
        c = self.spec.columns
        for k, name in enumerate(self.wheels):
            if name not in self.raw_ends or self.n_rows < 2:
                continue
            ends = ([self.cols.read(name, 0, 1)[0], self.cols.read(name, self.n_rows - 1,
                                                                     self.n_rows)[0]]
                    if screened else self.raw_ends[name])
            if not np.all(np.isfinite(ends)):
                problems.append(wheel_end_problem(path, c, k, name, report))
        if self.raw_sigma_bad if not screened else self.sigma_bad:
            problems.append(f"{path}: {c.yaw_sigma} must be positive wherever {c.yaw} is "
                            "present")
        if self.raw_head_bad if not screened else self.head_bad:
            problems.append(f"{path}: {c.sun_head} must be 0 (dss), 1 (cass1) or 2 (cass2)")
        if problems:
            raise RunDirError("\n".join(cap_lines(problems)))
        if self.decrease is not None:
            raise RunDirError(self.decrease)
        return report


def _sigma_bad(cols: dict) -> bool:
    if "yaw_sigma_deg" not in cols or "yaw_deg" not in cols:
        return False
    sig = cols["yaw_sigma_deg"][np.isfinite(cols["yaw_deg"])]
    return not np.all(np.isfinite(sig) & (sig > 0))


def _head_bad(cols: dict) -> bool:
    if "sun_head" not in cols:
        return False
    head = cols["sun_head"][np.isfinite(cols["sun_head"])]
    return not np.all(np.isin(head, (0.0, 1.0, 2.0)))
