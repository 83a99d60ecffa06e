"""truth.csv read back into the filter's model coordinates, for `estimate --truth`.

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
    """truth.csv at the filter's grid times: what ``bridge.coordinates.truth_torques``
    and ``model_truth`` read of a truth, and ``euler_rad`` (yaw, roll, pitch) for the
    figures.  ``torques`` holds the external sources (``sim.history.EXTERNAL_TORQUES``)
    the file has: the optional ones (the disturbance) only when it has their columns."""

    t_s: np.ndarray
    euler_rad: np.ndarray
    w_br_radps: np.ndarray
    h_Nms: np.ndarray
    torques: dict[str, np.ndarray]


def read_truth(path: Path, s: Scenario, t_grid: np.ndarray) -> TruthFromFile:
    """The truth at the filter's grid times ``t_grid`` (every one must have a row)."""
    path = Path(path)
    cols = read_input_csv(path, "truth")
    # The optional sources have columns only in runs that flew them: read when the file
    # has any of their columns, and required when the scenario flies them.
    flown = {"disturbance"} if build.build_disturbance(s).enabled else set()
    sources = [src for src in EXTERNAL_TORQUES if src not in OPTIONAL_TORQUES
               or src in flown or any(f"{src}_{a}_Nm" in cols for a in "xyz")]
    torque_cols = [f"{src}_{a}_Nm" for src in sources for a in "xyz"]
    missing = [c for c in (*ATTITUDE, *torque_cols) if c not in cols]
    if missing:
        raise RunDirError("\n".join(f"{path}: missing column {c}" for c in missing))
    dt = s.sample_interval_s
    t = cols["t_s"]
    # Truth rows are matched to grid samples by their step number: the file's t_s
    # is written to 10 digits, so compare indices, not times.
    k_truth = np.rint((t - t_grid[0]) / dt)
    k_grid = np.rint((t_grid - t_grid[0]) / dt)
    where = np.searchsorted(k_truth, k_grid)
    where = np.minimum(where, len(t) - 1)
    absent = k_truth[where] != k_grid
    if absent.any():
        raise RunDirError(f"{path}: no row at t_s = {t_grid[np.argmax(absent)]:g} s: the truth "
                          "must cover every sample of the telemetry's grid")
    at = {name: values[where] for name, values in cols.items()}
    euler = np.column_stack([at["yaw_deg"], at["roll_deg"], at["pitch_deg"]]) * DEG
    w_bn = np.column_stack([at["wx_radps"], at["wy_radps"], at["wz_radps"]])
    c_br = dcm_from_euler312(euler[:, 0], euler[:, 1], euler[:, 2])
    w_br = rate_wrt_orbit(c_br, w_bn, build.orbit(s).rate_radps)
    torques = {src: np.column_stack([at[f"{src}_{a}_Nm"] for a in "xyz"])
               for src in sources}
    return TruthFromFile(t_grid, euler, w_br, at["h_Nms"], torques)
