"""A telemetry CSV, as a ground system delivers it, onto the filter's time grid.

Real telemetry has dropouts, irregular time tags and other cadences; the paper's
filter steps at the scenario's ``sample_interval_s`` (0.512 s).  Every row must
fall on that grid, counted from the first row; a grid sample with no row gets
no measurement update (NaN), so the filter propagates across it and its
covariance grows.  A cadence that is a multiple of the step (1.024 s, 2.048 s)
is the same thing: every other sample missing.  A dropout longer than
``estimator.max_gap_s`` is rejected, naming the row where it starts.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..config import build
from ..config.schema import Scenario
from ..config.suggestions import cap_lines, closest
from .csvio import read_csv
from .rundir import RunDirError

REQUIRED = ("t_s", "roll_deg", "yaw_deg", "wheel1_rpm", "wheel2_rpm")
OPTIONAL = ("pitch_deg", "yaw_sigma_deg", "sun_head")
# A time tag may sit this fraction of a step off the grid: 5 ms at 0.512 s.  The
# filter takes the sample at the grid time; at the orbit rate (7.3e-5 rad/s) and
# the nutation rates of a few 1e-4 rad/s, 5 ms moves the attitude by ~1e-6°,
# far below the Earth sensor's 0.01° quantum.
GRID_TOLERANCE = 0.01


@dataclass(frozen=True)
class GriddedTelemetry:
    """Telemetry on the filter's grid: ``columns`` hold one value per grid sample
    (NaN where no row fell), ``rows`` the file row each sample came from (−1 if
    none)."""

    columns: dict[str, np.ndarray]
    rows: np.ndarray
    n_rows: int

    @property
    def missing(self) -> np.ndarray:
        return self.rows < 0

    def stats(self, dt_s: float) -> dict:
        """What summary.json says about the telemetry itself.  A dropout is a step
        between rows longer than the file's own cadence (its most common step): a
        1.024 s file on the 0.512 s grid misses every other filter step, but none of
        its rows (``cadence_note`` says so)."""
        missing = self.missing
        steps = np.diff(self.columns["t_s"][~missing])
        k = np.diff(np.flatnonzero(~missing))            # each step, in filter steps
        cadence = int(np.bincount(k).argmax()) if k.size else 1
        lengths = (k[k > cadence] - cadence) * dt_s
        return {"rows": int(self.n_rows), "filter_steps": int(len(self.rows)),
                "missing_steps": int(missing.sum()), "dropouts": int(len(lengths)),
                "longest_dropout_s": float(lengths.max(initial=0.0)),
                "median_cadence_s": float(np.median(steps)) if steps.size else None,
                "cadence_s": cadence * dt_s,
                "cadence_note": cadence_note(cadence, dt_s)}


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


def read_input_csv(path: Path, kind: str) -> dict[str, np.ndarray]:
    """The columns of a CSV the user named, or one line saying why it cannot be read."""
    if not path.is_file():
        raise RunDirError(f"{path}: no such {kind} file")
    try:
        return read_csv(path)
    except UnicodeDecodeError:
        raise RunDirError(f"{path}: not a CSV text file (it holds bytes that are not UTF-8 "
                          "text)") from None
    except ValueError as exc:
        # read_csv's own one line, naming the file, the row and the column.
        raise RunDirError(str(exc).splitlines()[0]) from None


def _problem_columns(path: Path, cols: dict, required: tuple[str, ...]) -> list[str]:
    unused = [c for c in cols if c not in required and c not in OPTIONAL]
    problems = []
    for name in required:
        if name in cols:
            continue
        # A file column that looks like the missing one is most likely it, misspelt:
        # name the file's column and suggest the valid name, as for a scenario key.
        typo = closest(name, unused)
        problems.append(f"{path}: unknown column {typo}; did you mean '{name}'?" if typo
                        else f"{path}: missing column {name}")
    return problems


def read_telemetry(path: Path, s: Scenario) -> dict[str, np.ndarray]:
    """A telemetry CSV's columns, checked.  Every problem is reported, one line
    each naming the column (or the row); the time tags are checked by ``on_grid``."""
    path = Path(path)
    cols = read_input_csv(path, "telemetry")
    n_wheels = len(build.yaw_factors(s))
    wheels = tuple(f"wheel{i + 1}_rpm" for i in range(n_wheels))
    required = (*REQUIRED, *wheels[2:])
    problems = _problem_columns(path, cols, required)
    t = cols.get("t_s")
    if t is not None and len(t) < 2:
        problems.append(f"{path}: needs at least two samples")
    bad_t = ~np.isfinite(t) if t is not None else np.zeros(0, bool)
    if bad_t.any():
        problems.append(f"{path}: column t_s has a missing or non-numeric value in row "
                        f"{int(np.argmax(bad_t)) + 2}")
    for name in wheels:
        ends = cols[name][[0, -1]] if name in cols and len(cols[name]) >= 2 else ()
        if not np.all(np.isfinite(ends)):
            problems.append(f"{path}: column {name} must have a value in the first and the "
                            "last row (a dropout is bridged between readings)")
    present = np.isfinite(cols["yaw_deg"]) if "yaw_deg" in cols else None
    if "yaw_sigma_deg" in cols and present is not None:
        sig = cols["yaw_sigma_deg"][present]
        if not np.all(np.isfinite(sig) & (sig > 0)):
            problems.append(f"{path}: yaw_sigma_deg must be positive wherever yaw_deg is "
                            "present")
    if "sun_head" in cols:
        head = cols["sun_head"][np.isfinite(cols["sun_head"])]
        if not np.all(np.isin(head, (0.0, 1.0, 2.0))):
            problems.append(f"{path}: sun_head must be 0 (dss), 1 (cass1) or 2 (cass2)")
    if problems:
        raise RunDirError("\n".join(cap_lines(problems)))
    return cols


def on_grid(cols: dict[str, np.ndarray], dt_s: float, max_gap_s: float,
            path: Path | str = "telemetry") -> GriddedTelemetry:
    """The rows of ``cols`` placed on the grid t_0 + k·dt_s.

    Rows must increase in time and sit on the grid (within GRID_TOLERANCE of a
    step); a step between rows longer than ``max_gap_s`` is rejected.  Roll,
    yaw and wheel values that are empty in a row are missing at that sample only.
    With every sample present the columns are the file's own, bit for bit."""
    t = np.asarray(cols["t_s"], dtype=float)
    steps = np.diff(t)
    problems = []
    if np.any(steps <= 0):
        k = int(np.argmax(steps <= 0))
        problems.append(f"{path}: t_s must increase; row {k + 3} ({t[k + 1]:g} s) does not "
                        f"follow row {k + 2} ({t[k]:g} s)")
    k_float = (t - t[0]) / dt_s
    k = np.rint(k_float)
    off = np.abs(k_float - k) > GRID_TOLERANCE
    if off.any():
        i = int(np.argmax(off))
        problems.append(f"{path}: row {i + 2} (t_s = {t[i]:g}) is {(k_float[i] - k[i]) * dt_s:+.3g}"
                        f" s off the filter's grid: time tags must be t_0 + k × the "
                        f"scenario's sample_interval_s ({dt_s:g} s)")
    long = steps > max_gap_s
    if long.any():
        i = int(np.argmax(long))
        problems.append(f"{path}: a {steps[i]:g} s dropout after row {i + 2} (t_s = {t[i]:g})"
                        f" is longer than estimator.max_gap_s ({max_gap_s:g} s)")
    if problems:
        raise RunDirError("\n".join(problems))
    index = k.astype(np.int64)
    n = int(index[-1]) + 1
    if n == len(t):
        # Every sample present: the file's values as they are (bit for bit).
        return GriddedTelemetry(dict(cols), np.arange(n), len(t))
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
    return GriddedTelemetry(gridded, rows, len(t))
