"""An attitude history from another tool, a CCSDS AEM, read back as a truth: for
`estimate --truth X.aem` (``read_truth_aem``) and `export --truth X.aem`
(``orbit_frame_attitude``).

The AEM's quaternions are C_{body←frame} (``aem.read_aem``, whatever the file's
order and direction).  They are taken to dynprop's orbit frame R with the
scenario's own orbit and epoch, the inverse of the export
(``sim.inertial.orbit_frame_from_inertial``: C_BR = C_{B←EME2000} (C_RN(t) P(t))ᵀ)
for EME2000, J2000, ICRF and GCRF (one frame to the frame bias, 1.12e-7 rad:
``aem.INERTIAL_FRAMES``);
LVLH_ROTATING is R itself, and so, for the orientation alone, are LVLH_INERTIAL and
LVLH (Orekit: the same axes at each epoch, only taken as not rotating), the one
difference being in rates, which dynprop does not read.  Then to the 3-1-2 angles
(``sim.frames.euler312_from_quat``).

Where a grid time has an AEM row (within ``EPOCH_MATCH_S``: the file's epochs are
printed to the microsecond) that row is taken; between rows the segment is
interpolated (``AemSegment.interpolate``: Lagrange of the segment's degree,
normalised), inside a segment only, never across a dropout between two.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime
from pathlib import Path

import numpy as np
from dynprop.sim.frames import euler312_from_quat
from dynprop.sim.inertial import orbit_frame_from_inertial

from ..config import build
from ..config.schema import Scenario
from .aem import INERTIAL_FRAMES, AemSegment, read_aem, stamps_of
from .rundir import RunDirError
from .truth_file import TruthFromFile

# The AEM prints epochs to the microsecond (``aem``): a row within half of that, and
# the float of t0 + k·dt, is at the grid time.
EPOCH_MATCH_S = 0.6e-6


@dataclass(frozen=True)
class TruthFromAem(TruthFromFile):
    """``TruthFromFile``'s shape, attitude only: ``euler_rad`` (yaw, roll, pitch) at
    the grid samples ``rows``; ``w_br_radps`` (N, 3) and ``h_Nms`` (N,) are NaN and
    ``torques`` is empty (an AEM of quaternions carries neither rates, wheels nor
    torques).  ``file_rows``: the AEM's data rows; ``frame``: its REF_FRAME (the
    external one); ``interpolated``: how many of ``rows`` fell between AEM rows."""

    frame: str
    interpolated: int


def is_aem(path) -> bool:
    """An attitude history (CCSDS AEM, attitude only) rather than a truth.csv: by its
    first keyword, whatever the file is called."""
    try:
        with open(path, "rb") as f:
            return f.read(256).lstrip().startswith(b"CCSDS_AEM_VERS")
    except OSError:
        return False    # read_truth says what is wrong with it


def attitude_at(segments: list[AemSegment], stamps: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """(indices into ``stamps`` inside a segment, their quaternions C_{body←frame}, the
    segment of each, how many were interpolated): a row the file has at the time
    (within ``EPOCH_MATCH_S``) is taken as it is, any other time inside a segment is
    interpolated in that segment; times in a dropout or outside are left out."""
    stamps = np.asarray(stamps, dtype="datetime64[ns]")
    ns = stamps.astype(np.int64)
    found = np.full(len(ns), -1)
    q = np.full((len(ns), 4), np.nan)
    between, tol = 0, int(EPOCH_MATCH_S * 1e9)
    for k, seg in enumerate(segments):
        rows = seg.epochs.astype(np.int64)
        inside = np.flatnonzero((ns >= rows[0] - tol) & (ns <= rows[-1] + tol) & (found < 0))
        if not inside.size:
            continue
        t = ns[inside]
        after = np.searchsorted(rows, t)
        lo, hi = np.clip(after - 1, 0, len(rows) - 1), np.clip(after, 0, len(rows) - 1)
        near = np.where(np.abs(rows[lo] - t) <= np.abs(rows[hi] - t), lo, hi)
        exact = np.abs(rows[near] - t) <= tol
        q[inside[exact]] = seg.quaternions[near[exact]]
        other = inside[~exact]
        if other.size:
            q[other] = seg.interpolate(stamps[other])
            between += other.size
        found[inside] = k
    keep = np.flatnonzero(found >= 0)
    return keep, q[keep], found[keep], between


def orbit_frame_attitude(segments: list[AemSegment], t_s, s: Scenario
                         ) -> tuple[np.ndarray, np.ndarray, int]:
    """(indices into ``t_s`` (s after the scenario's epoch) inside a segment, q_BR there,
    how many were interpolated): ``attitude_at``, and a segment in an inertial frame
    taken to the orbit frame R with the scenario's orbit (``orbit_frame_from_inertial``);
    an LVLH frame, the only other ``read_aem`` gives, is R."""
    t_s = np.asarray(t_s, dtype=float)
    epoch = build.epoch(s)
    keep, q, seg_of, between = attitude_at(segments, stamps_of(t_s, epoch))
    for j in np.unique(seg_of):
        if segments[j].frame in INERTIAL_FRAMES:
            mine = seg_of == j
            q[mine] = orbit_frame_from_inertial(t_s[keep][mine], q[mine], build.orbit(s), epoch)
    return keep, q, between


def segment_spans(segments: list[AemSegment], epoch: datetime) -> str:
    """The first segments' spans in s after ``epoch``, for a message: ``0 to 10752 s``."""
    spans = ", ".join(f"{a:g} to {b:g} s" for a, b in (
        seg.seconds_since(epoch)[[0, -1]] for seg in segments[:3]))
    return spans + (", ..." if len(segments) > 3 else "")


def read_truth_aem(path: Path, s: Scenario, t_grid: np.ndarray, on_grid: bool = True
                   ) -> TruthFromAem:
    """The AEM's attitude at the samples of ``t_grid`` (s after ``s.epoch_utc``) it
    covers, as ``truth_file.read_truth`` gives truth.csv's.  ``on_grid`` (the
    telemetry on the grid t0 + k·dt): the samples the file has a row at, as truth.csv
    gives them, so `--truth truth.aem` compares at the rows `--truth truth.csv` does;
    a file with no row on the grid (another tool's own epochs) is interpolated at every
    grid sample inside its segments.  ``on_grid`` False: interpolated at ``t_grid``'s
    own times inside segments.  A bad file raises ``AemError``, one covering no
    sample ``RunDirError``, each in one line."""
    path = Path(path)
    segments = read_aem(path)
    t_grid = np.asarray(t_grid, dtype=float)
    rows = np.arange(len(t_grid))
    if on_grid:
        file_t = np.concatenate([seg.seconds_since(build.epoch(s)) for seg in segments])
        dt, t0 = s.sample_interval_s, float(t_grid[0])
        k = np.rint((file_t - t0) / dt)
        ok = (k >= 0) & (k < len(t_grid)) & (np.abs(file_t - (t0 + k * dt)) <= EPOCH_MATCH_S)
        if ok.any():
            rows = np.unique(k[ok].astype(np.int64))
    keep, q_br, between = orbit_frame_attitude(segments, t_grid[rows], s)
    rows = rows[keep]
    if not len(rows):
        raise RunDirError(
            f"{path}: no segment ({segment_spans(segments, build.epoch(s))} after "
            f"{s.epoch_utc}) covers a time of the filter's grid ({t_grid[0]:g} to "
            f"{t_grid[-1]:g} s), so no error can be computed")
    t_rows = t_grid[rows]
    euler = np.column_stack(euler312_from_quat(q_br))
    n = len(rows)
    frames = sorted({seg.frame for seg in segments})
    return TruthFromAem(t_rows, euler, np.full((n, 3), np.nan), np.full(n, np.nan), {},
                        rows, sum(len(seg.epochs) for seg in segments), ", ".join(frames),
                        between)
