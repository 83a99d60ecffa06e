"""truth.csv read back into the filter's model coordinates, for `estimate --truth`,
at the samples of the filter's grid that the file has a row for: every sample for
`dynprop simulate`'s file, every ``output.interval_s`` for `dynprop run`'s.

The file holds what the run's truth arrays hold, at 10 significant digits
(``csvio``): attitude, ω_BN, wheel momentum h and every torque by source.  From
those the model states are rebuilt exactly as `run` builds them from the arrays
(``bridge.coordinates.truth_torques`` and ``model_truth``), so errors computed from the file
agree with the run's to the file's precision (5e-10 relative).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from dynprop.sim.frames import dcm_from_euler312, rate_wrt_orbit
from dynprop.sim.history import EXTERNAL_TORQUES, OPTIONAL_TORQUES, Euler312

from ..config import build
from ..config.schema import Scenario
from ..units import DEG
from .rundir import RunDirError
from .telemetry_file import read_input_csv

ATTITUDE = ("t_s", "yaw_deg", "roll_deg", "pitch_deg", "wx_radps", "wy_radps", "wz_radps",
            "h_Nms")


@dataclass(frozen=True)
class TruthFromFile(Euler312):
    """truth.csv at the grid samples ``rows`` (increasing indices into the filter's
    grid) it has a row for: what ``bridge.coordinates.truth_torques`` and
    ``model_truth`` read of a truth, and ``euler_rad`` (yaw, roll, pitch) for the
    figures.  ``torques`` holds the external sources (``sim.history.EXTERNAL_TORQUES``)
    the file has: the optional ones (the disturbance, the thrusters) only when it has
    their columns.
    ``file_rows``: the rows the file holds (on the grid or not)."""

    t_s: np.ndarray
    euler_rad: np.ndarray
    w_br_radps: np.ndarray
    h_Nms: np.ndarray
    torques: dict[str, np.ndarray]
    rows: np.ndarray
    file_rows: int

    def every_sample(self, n_samples: int) -> bool:
        """Whether the truth has a row at each of the grid's ``n_samples`` samples."""
        return len(self.rows) == n_samples


# %.10g (``csvio``) keeps t_s within half a unit of its tenth digit, at most 5e-10
# of |t|; 5.1e-10 leaves room for the grid's own t_0 + k·dt (~1e-16 of t).  Far
# below a step (0.512 s), so a row matches one grid sample or none.
TIME_MATCH_REL = 5.1e-10


def common_samples(t_truth: np.ndarray, t0: float, dt: float, n: int
                   ) -> tuple[np.ndarray, np.ndarray]:
    """(grid samples, file rows): the samples k of the grid t0 + k·dt (0 ≤ k < n) whose
    time a truth row holds, to the precision t_s is written with, and that row (the
    first, should the file repeat a time)."""
    k = np.rint((t_truth - t0) / dt)
    inside = (k >= 0) & (k < n)
    ideal = t0 + k * dt
    on = inside & (np.abs(t_truth - ideal) <= TIME_MATCH_REL * np.maximum(np.abs(ideal), dt))
    samples, first = np.unique(k[on].astype(np.int64), return_index=True)
    return samples, np.flatnonzero(on)[first]


# Off the grid (``telemetry_file.on_grid``), the truth is interpolated linearly to the
# telemetry's times from rows at most this far apart: at the nutation and orbit rates
# (a few 1e-4 rad/s at most) the attitude's curvature over 1.1 s leaves < 1e-8 rad,
# far below the sensors' 1.7e-4 rad quantum.
INTERPOLATE_MAX_STEP_S = 1.1


def _interpolated(path, cols: dict, t_samples: np.ndarray) -> tuple[dict, np.ndarray]:
    """The truth's columns at those of ``t_samples`` inside its span, and which."""
    t = cols["t_s"]
    step = float(np.max(np.diff(t), initial=0.0))
    if step > INTERPOLATE_MAX_STEP_S:
        raise RunDirError(
            f"{path}: the telemetry is off the filter's grid, so the truth is interpolated "
            f"to its times, and this file's rows are up to {step:g} s apart (at most "
            f"{INTERPOLATE_MAX_STEP_S:g} s): use `dynprop simulate`'s truth.csv (every sample)")
    rows = np.flatnonzero((t_samples >= t[0]) & (t_samples <= t[-1]))
    at = {name: np.interp(t_samples[rows], t, values) for name, values in cols.items()}
    return at, rows


def read_truth(path: Path, s: Scenario, t_grid: np.ndarray, on_grid: bool = True
               ) -> TruthFromFile:
    """The truth at the grid samples (``t_grid``: the filter's) it has a row for; at
    least one is needed, or one line saying how to get a file that has them.  For
    telemetry off the grid (``on_grid`` False: samples at their own times) the truth
    interpolated to those times (``_interpolated``)."""
    path = Path(path)
    return truth_at(path, s, truth_columns(path), t_grid, on_grid)


def truth_columns(path: Path) -> dict[str, np.ndarray]:
    """A truth.csv's columns as read (``read_truth`` reads them once and places them
    on a grid with ``truth_at``; a streamed estimate does so window by window)."""
    return read_input_csv(Path(path), "truth")


def truth_at(path: Path, s: Scenario, cols: dict, t_grid: np.ndarray, on_grid: bool = True
             ) -> TruthFromFile:
    """``read_truth`` of the columns ``cols`` of the file ``path``."""
    # The optional sources have columns only in runs that flew them: read when the file
    # has any of their columns, and required when the scenario flies them.
    flown = {"disturbance"} if build.build_disturbance(s).enabled else set()
    if build.build_schedule(s).of_kind("thruster"):
        flown.add("thruster")
    sources = [src for src in EXTERNAL_TORQUES if src not in OPTIONAL_TORQUES
               or src in flown or any(f"{src}_{a}_Nm" in cols for a in "xyz")]
    torque_cols = [f"{src}_{a}_Nm" for src in sources for a in "xyz"]
    missing = [c for c in (*ATTITUDE, *torque_cols) if c not in cols]
    if missing:
        raise RunDirError("\n".join(f"{path}: missing column {c}" for c in missing))
    dt = s.sample_interval_s
    t0, n = float(t_grid[0]), len(t_grid)
    if on_grid:
        rows, where = common_samples(cols["t_s"], t0, dt, n)
        at = {name: values[where] for name, values in cols.items()}
        t_rows = t0 + rows * dt
    else:
        at, rows = _interpolated(path, cols, np.asarray(t_grid, dtype=float))
        t_rows = np.asarray(t_grid, dtype=float)[rows]
    if not len(rows):
        raise RunDirError(
            f"{path}: no row at a time of the telemetry's filter grid ({t0:g} s + k × "
            f"{dt:g} s, up to {t0 + (n - 1) * dt:g} s), so no error can be computed: use a "
            "truth.csv of the same run or simulation (`dynprop simulate` writes every "
            "sample; `dynprop run` every output.interval_s, a whole multiple of "
            "sample_interval_s)")
    euler = np.column_stack([at["yaw_deg"], at["roll_deg"], at["pitch_deg"]]) * DEG
    w_bn = np.column_stack([at["wx_radps"], at["wy_radps"], at["wz_radps"]])
    c_br = dcm_from_euler312(euler[:, 0], euler[:, 1], euler[:, 2])
    w_br = rate_wrt_orbit(c_br, w_bn, build.orbit(s).rate_radps)
    torques = {src: np.column_stack([at[f"{src}_{a}_Nm"] for a in "xyz"])
               for src in sources}
    return TruthFromFile(t_rows, euler, w_br, at["h_Nms"], torques, rows,
                         len(cols["t_s"]))
