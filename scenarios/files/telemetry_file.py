"""A telemetry file, as a ground system delivers it, as the filter's samples.

Real telemetry has dropouts, irregular time tags and other cadences.  Rows on the
scenario's grid (``sample_interval_s``, 0.512 s, counted from the first row) are
placed on it: a grid sample with no row gets no measurement update (NaN), so the
filter propagates across it and its covariance grows, and a cadence that is a
multiple of the step (1.024 s, 2.048 s) is every other sample missing.  Rows off
that grid (a 1.0 s cadence, jittered tags) are samples at their own times, and the
filter propagates over each interval with the closed forms at that interval
(``estimator.linear.steps``).  A gap of any length is accepted; one longer than
``estimator.max_gap_s`` is a warning in summary.json.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from dynprop.estimator.linear.steps import step_intervals

from ..config import build
from ..config.schema import Scenario
from ..config.suggestions import cap_lines
from .rundir import RunDirError
from .screen import ScreenReport, screen, unit_problems
from .telemetry_reader import (
    file_names,
    file_times,
    measurements,
    read_input_csv,  # noqa: F401 (truth_file reads through it)
    read_table,
    written_marks,
)

# A time tag may sit this fraction of a step off the grid: 5 ms at 0.512 s.  The
# filter takes the sample at the grid time; at the orbit rate (7.3e-5 rad/s) and
# the nutation rates of a few 1e-4 rad/s, 5 ms moves the attitude by ~1e-6°,
# far below the Earth sensor's 0.01° quantum.
GRID_TOLERANCE = 0.01


@dataclass(frozen=True)
class GriddedTelemetry:
    """Telemetry as the filter steps through it.  On the scenario's grid: ``columns``
    hold one value per grid sample (NaN where no row fell), ``rows`` the file row each
    sample came from (−1 if none) and ``steps`` is None.  Off it (another cadence,
    jittered tags): every row is a sample at its own time, and ``steps`` holds the
    interval after each (``estimator.steps.step_intervals``).  ``max_gap_s`` is the
    gap length from which the summary warns."""

    columns: dict[str, np.ndarray]
    rows: np.ndarray
    n_rows: int
    steps: np.ndarray | None = None
    max_gap_s: float = float("inf")
    screen: ScreenReport | None = None      # what ``files.screen`` took out, if read so

    @property
    def missing(self) -> np.ndarray:
        return self.rows < 0

    @property
    def regular(self) -> bool:
        return self.steps is None

    def stats(self, dt_s: float) -> dict:
        """What summary.json says about the telemetry itself.  A dropout is a step
        between rows longer than the file's own cadence (on the grid, its most common
        step; off it, 1.5 × its median step): a 1.024 s file on the 0.512 s grid misses
        every other filter step, but none of its rows (``cadence_note`` says so)."""
        t = self.columns["t_s"][~self.missing]
        steps = np.diff(t)
        if self.regular:
            k = np.diff(np.flatnonzero(~self.missing))        # each step, in filter steps
            cadence = int(np.bincount(k).argmax()) if k.size else 1
            long = k > cadence
            lengths = (k[long] - cadence) * dt_s
            cadence_s, note = cadence * dt_s, cadence_note(cadence, dt_s)
            jitter = 0.0
        else:
            cadence_s = float(np.median(steps))
            long = steps > 1.5 * cadence_s
            lengths = steps[long] - cadence_s
            jitter = float(np.max(np.abs(steps[~long] - cadence_s), initial=0.0))
            note = (f"telemetry off the filter's {dt_s:g} s grid (cadence {cadence_s:g} s, "
                    f"steps within ±{jitter:.3g} s of it): the filter steps with each "
                    "sample's own interval")
        over = lengths > self.max_gap_s
        gaps = [[float(t[i] / 3600.0), float(steps[i] / 3600.0)]
                for i in np.flatnonzero(long)[over]]
        return {"rows": int(self.n_rows), "filter_steps": int(len(self.rows)),
                "missing_steps": int(self.missing.sum()), "dropouts": int(len(lengths)),
                "longest_dropout_s": float(lengths.max(initial=0.0)),
                "median_cadence_s": float(np.median(steps)) if steps.size else None,
                "cadence_s": cadence_s, "cadence_note": note,
                "on_filter_grid": self.regular, "step_jitter_s": jitter,
                "gaps_over_max_gap_h": gaps,
                "screened": None if self.screen is None else self.screen.summary()}


def cadence_note(cadence_steps: int, dt_s: float) -> str | None:
    """One line when the telemetry's cadence is not the filter's step (None when it is)."""
    if cadence_steps == 1:
        return None
    return (f"telemetry cadence {cadence_steps * dt_s:g} s is not the filter's {dt_s:g} s "
            f"step: the filter updates on 1 step in {cadence_steps} and propagates across "
            f"the others, which are not counted as dropouts")


def run_telemetry(run_dir: Path) -> Path | None:
    """The telemetry a run directory filtered: its telemetry.csv, else the file a
    `dynprop estimate` directory recorded in its summary.json (``recorded_path``).
    None for a run that wrote none (one longer than two days, without
    output.telemetry: true); a RunDirError naming the file and why when it is gone."""
    run_dir = Path(run_dir)
    own = run_dir / "telemetry.csv"
    if own.is_file():
        return own
    named = _recorded_telemetry(run_dir / "summary.json")
    if named is not None:
        path = recorded_path(run_dir, named)
        if path.is_file():
            return path
        where = "" if Path(named).is_absolute() else f", recorded as {named} relative to it"
        raise RunDirError(f"{run_dir}: the telemetry file {path} this estimate read is no "
                          f"longer there (moved or deleted{where})")
    if not (run_dir / "scenario.yaml").is_file():
        raise RunDirError(f"{run_dir}: not a run directory (no scenario.yaml)")
    from ..config.loader import load_scenario
    from ..config.schema import output_writes_telemetry
    if output_writes_telemetry(load_scenario(run_dir / "scenario.yaml")):
        raise RunDirError(f"{run_dir}: its telemetry.csv is no longer there (the run wrote "
                          "one: it was moved or deleted)")
    return None


def _recorded_telemetry(summary: Path) -> str | None:
    """The telemetry file an `estimate` directory's summary.json records (None in a
    `run` directory, whose summary records none)."""
    if not summary.is_file():
        return None
    try:
        record = json.loads(summary.read_text()).get("telemetry")
    except (ValueError, AttributeError):
        return None
    return record.get("file") if isinstance(record, dict) else None


def recorded_path(run_dir: Path, named: str) -> Path:
    """A path an output directory records: absolute, or relative to that directory
    (never to the working directory, which changes from one command to the next)."""
    path = Path(named)
    return path if path.is_absolute() else Path(run_dir) / path


def read_telemetry(path: Path, s: Scenario) -> dict[str, np.ndarray]:
    """``read_screened``'s columns."""
    return read_screened(path, s)[0]


def read_screened(path: Path, s: Scenario) -> tuple[dict[str, np.ndarray], ScreenReport]:
    """A telemetry file's canonical columns (``t_s`` from the scenario's epoch_utc,
    degrees, rpm), read as the scenario's ``telemetry`` section says
    (``telemetry_reader``), checked, and screened (``files.screen``: a value the
    spacecraft cannot produce becomes a dropout of its sensor, and the report says
    which).  Every problem is reported, one line each naming the column (or the row,
    or the key), a unit a factor away from the spacecraft's among them; the time tags'
    spacing is checked by ``on_grid``."""
    path = Path(path)
    n_wheels = len(build.yaw_factors(s))
    wheels = tuple(f"wheel{i + 1}_rpm" for i in range(n_wheels))
    table = read_table(path, s.telemetry, n_wheels)
    measured, problems = measurements(path, table, s.telemetry, n_wheels)
    t, time_problems = file_times(path, table, s)
    problems += time_problems
    cols = {"t_s": t, **measured} if t is not None else measured
    c = s.telemetry.columns   # the file's names, for the messages
    if t is not None and len(t) < 2:
        problems.append(f"{path}: needs at least two samples")
    names = file_names(s.telemetry, n_wheels)
    if s.telemetry.screen.enabled:
        problems += unit_problems(path, cols, s, names)
    report = None
    if t is not None and not problems:
        cols, report = screen(cols, written_marks(table, s.telemetry, n_wheels), s, names)
    bad_t = ~np.isfinite(t) if t is not None else np.zeros(0, bool)
    if bad_t.any():
        problems.append(f"{path}: column {c.t_s} has a missing or non-numeric value in row "
                        f"{int(np.argmax(bad_t)) + 2}")
    for k, name in enumerate(wheels):
        ends = cols[name][[0, -1]] if name in cols and len(cols[name]) >= 2 else ()
        if not np.all(np.isfinite(ends)):
            problems.append(wheel_end_problem(path, c, k, name, report))
    present = np.isfinite(cols["yaw_deg"]) if "yaw_deg" in cols else None
    if "yaw_sigma_deg" in cols and present is not None:
        sig = cols["yaw_sigma_deg"][present]
        if not np.all(np.isfinite(sig) & (sig > 0)):
            problems.append(f"{path}: {c.yaw_sigma} must be positive wherever {c.yaw} is "
                            "present")
    if "sun_head" in cols:
        head = cols["sun_head"][np.isfinite(cols["sun_head"])]
        if not np.all(np.isin(head, (0.0, 1.0, 2.0))):
            problems.append(f"{path}: {c.sun_head} must be 0 (dss), 1 (cass1) or 2 (cass2)")
    if problems:
        raise RunDirError("\n".join(cap_lines(problems)))
    return cols, report


def wheel_end_problem(path, c, k: int, name: str, report: ScreenReport | None) -> str:
    """The line for wheel ``k`` (canonical ``name``; ``c`` the file's column names)
    without a reading in the file's first or last row."""
    return (f"{path}: column {getattr(c, f'wheel{k + 1}', name)} must have a value in the "
            "first and the last row (a dropout is bridged between readings)" + (
                "; the screen took it out there (telemetry.screen)"
                if report is not None and any(x.column == name for x in report.screened)
                else ""))


def on_grid(cols: dict[str, np.ndarray], dt_s: float, max_gap_s: float,
            path: Path | str = "telemetry", report: ScreenReport | None = None
            ) -> GriddedTelemetry:
    """The rows of ``cols`` as the filter's samples.

    Rows must increase in time.  Rows that all sit on the grid t_0 + k·dt_s (within
    GRID_TOLERANCE of a step) are placed on it, a grid sample without a row missing
    (NaN): with every sample present the columns are the file's own, bit for bit, and
    the filter runs exactly as on `run`'s telemetry.  Otherwise (another cadence,
    jittered tags) each row is a sample at its own time and the filter propagates
    over each interval with that interval's Φ, Γ, Q_d (``estimator.linear.steps``).  Roll,
    yaw and wheel values that are empty in a row are missing at that sample only.  A
    gap longer than ``max_gap_s`` is accepted (the covariance grows across it) and
    reported (``GriddedTelemetry.stats``, and a warning in summary.json)."""
    t = np.asarray(cols["t_s"], dtype=float)
    steps = np.diff(t)
    if np.any(steps <= 0):
        k = int(np.argmax(steps <= 0))
        raise RunDirError(f"{path}: time tags must increase; row {k + 3} ({t[k + 1]:g} s) "
                          f"does not follow row {k + 2} ({t[k]:g} s)")
    k_float = (t - t[0]) / dt_s
    k = np.rint(k_float)
    if np.any(np.abs(k_float - k) > GRID_TOLERANCE):
        return GriddedTelemetry(dict(cols), np.arange(len(t)), len(t),
                                step_intervals(t), max_gap_s, report)
    index = k.astype(np.int64)
    n = int(index[-1]) + 1
    if n == len(t):
        # Every sample present: the file's values as they are (bit for bit).
        return GriddedTelemetry(dict(cols), np.arange(n), len(t), None, max_gap_s, report)
    gridded = {"t_s": t[0] + np.arange(n) * dt_s}
    for name, values in cols.items():
        if name == "t_s":
            continue
        column = np.full(n, np.nan)
        column[index] = values
        gridded[name] = column
    gridded["t_s"][index] = t  # rows keep their own tags (within tolerance of the grid)
    rows = np.full(n, -1, dtype=np.int64)
    rows[index] = np.arange(len(t))
    return GriddedTelemetry(gridded, rows, len(t), None, max_gap_s, report)
