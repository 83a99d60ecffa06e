"""`dynprop export DIR`: the run's attitude as a CCSDS AEM (every row of estimate.csv
or truth.csv, ``files.aem.write_aem_blocks``) or APM (one time, ``--at``), in
EME2000 (``sim.inertial.inertial_quaternions``, from the run's own orbit and epoch)
or in the orbit frame, LVLH_ROTATING (``orbit_frame_quaternions``).

The file is written to a temporary file beside it and renamed at the end: a failed
export (a bad row half way, a ``--truth`` file covering none of it) leaves nothing,
and a file it would have replaced as it was.  DIR/estimate.aem (or truth.aem, .apm)
is dynprop's own and replaced by a new export; an ``--out`` file that exists needs
``force``.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
import textwrap
from collections.abc import Iterator
from dataclasses import dataclass, field
from datetime import datetime, timedelta
from pathlib import Path

import numpy as np
from dynprop.sim.ephemeris import parse_epoch
from dynprop.sim.frames import euler312_from_quat
from dynprop.sim.inertial import (
    inertial_quaternions,
    orbit_frame_from_inertial,
    orbit_frame_quaternions,
)

from .. import __version__
from ..config import build
from ..files.aem import GAP_FACTOR as AEM_GAP_FACTOR
from ..files.aem import AemMeta, AemSegment, stamps_of, write_aem_blocks, write_apm
from ..files.rundir import names_file
from .compare import Comparison
from .source import Block, ExportError, RunSource, open_source

FRAMES = {"inertial": "EME2000", "orbit": "LVLH_ROTATING"}
FORMATS = ("aem", "apm")
# A simulated spacecraft has no international designator: OBJECT_ID says so unless
# the user gives the real one (--object-id 2016-071A for GOES-16).
OBJECT_ID = "SIMULATED"
COMMENT_WIDTH = 90      # KVN lines stay short (504.0-B-2 allows 254 characters)
APM_WINDOW_ROWS = 12    # rows kept either side of --at: more than the 8 Lagrange reads


@dataclass(frozen=True)
class ExportResult:
    """What an export wrote: ``path``, ``format`` (aem, apm), ``what`` (estimate,
    truth), ``frame`` (the message's REF_FRAME_A), ``rows`` written, ``segments``
    ((START_TIME, STOP_TIME, rows) per AEM segment), ``epoch`` (the APM's, ISO UTC)
    and ``comparison`` (``--truth``'s figures, ``compare.Comparison.result``)."""

    path: Path
    format: str
    what: str
    frame: str
    rows: int
    segments: list = field(default_factory=list)
    epoch: str | None = None
    comparison: dict | None = None


def seconds_at(at, s) -> float:
    """``--at`` as seconds after the scenario's epoch: a number of seconds, or an ISO
    8601 UTC time with its zone (``2026-03-20T18:00:00Z``), or an aware datetime."""
    epoch = build.epoch(s)
    if isinstance(at, datetime):
        when = at
    else:
        text = str(at).strip()
        try:
            return float(text)
        except ValueError:
            pass
        try:
            when = parse_epoch(text)
        except ValueError as exc:
            raise ExportError(f"--at {text}: neither seconds after epoch_utc nor an ISO "
                              f"8601 UTC time ({exc})") from None
    if when.tzinfo is None:
        raise ExportError(f"--at {when}: no time zone (give UTC, e.g. a Z at the end)")
    return (when - epoch) / timedelta(seconds=1)


def _meta(src: RunSource, frame: str, object_id: str | None) -> AemMeta:
    s = src.scenario
    # The run by its folder's name, not its path: the file is exchanged, and the user's
    # local tree is no part of it (a long path also wrapped mid-word over COMMENT lines).
    run_name = src.directory.resolve().name.encode("ascii", "backslashreplace").decode()
    composed = ("C(SC_BODY_1 <- EME2000) = C_BR(yaw, roll, pitch) C_RN(t) P(t): the file's "
                "3-1-2 angles against the orbit frame R, R against dynprop's frame N (mean "
                "of date) from the run's orbit and epoch, N precessed to EME2000 "
                "(sim/inertial.py)"
                if frame == "inertial" else
                "C(SC_BODY_1 <- LVLH_ROTATING) = C_BR = R2(pitch) R1(roll) R3(yaw): the "
                "file's 3-1-2 angles (docs/conventions.md)")
    notes = [f"dynprop {__version__} export of the {src.what}: {src.csv.name} (t_s, "
             f"roll_deg, pitch_deg, yaw_deg) of the run directory {run_name}",
             f"{'case_scenario.yaml' if src.case else 'scenario.yaml'}: {s.name}, seed "
             f"{s.seed}, epoch_utc {s.epoch_utc}, orbit longitude "
             f"{s.orbit.longitude_deg:.10g} deg, radius {s.orbit.radius_m:.10g} m.",
             composed, "A row with an empty angle is left out: a dropout ends its segment."]
    comments = [line for note in notes
                for line in textwrap.wrap(note, COMMENT_WIDTH, break_on_hyphens=False)]
    return AemMeta(s.name, object_id or OBJECT_ID, FRAMES[frame], comments=tuple(comments))


def _quaternions(src: RunSource, b: Block, frame: str) -> np.ndarray:
    if frame == "orbit":
        return orbit_frame_quaternions(b.roll, b.pitch, b.yaw)
    s = src.scenario
    return inertial_quaternions(b.t_s, b.roll, b.pitch, b.yaw, build.orbit(s), build.epoch(s))


def _target(src: RunSource, fmt: str, out, force: bool) -> Path:
    if out is None:
        return src.directory / f"{src.what}.{fmt}"
    out = Path(out)
    if out.is_dir():
        raise ExportError(f"--out {out}: is a directory; give the file to write")
    if out.exists() and not force:
        raise ExportError(f"--out {out}: exists (--force replaces it)")
    if not out.parent.is_dir():
        raise ExportError(f"--out {out}: no directory {out.parent} to write it in")
    return out


@contextlib.contextmanager
def _atomic(path: Path) -> Iterator:
    """A text stream to a temporary file beside ``path``, renamed to it at the end;
    removed if the block fails.  An OSError names ``path`` (a full disk's names no
    file: ``rundir.names_file``)."""
    with names_file(path):
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
        try:
            with os.fdopen(fd, "w", encoding="ascii", newline="\n") as stream:
                yield stream
            umask = os.umask(0)
            os.umask(umask)
            os.chmod(tmp, 0o666 & ~umask)
            os.replace(tmp, path)
        except BaseException:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
            raise


def export_run(directory, format: str = "aem", what: str = "estimate",
               frame: str = "inertial", at=None, out=None, truth=None,
               object_id: str | None = None, force: bool = False) -> ExportResult:
    """Export the run directory's ``what`` as ``format`` (see the module); ``at`` (APM
    only): seconds after epoch_utc or an ISO UTC time; ``truth``: an AEM to compare
    with (``compare``).  Bad input raises ``ExportError`` (or the loader's
    ``ScenarioError``, ``aem.AemError``) in one line and writes nothing."""
    if format not in FORMATS:
        raise ExportError(f"--format {format}: choose aem or apm")
    if frame not in FRAMES:
        raise ExportError(f"--frame {frame}: choose inertial or orbit")
    if at is not None and format != "apm":
        raise ExportError("--at: a time is for --format apm (an AEM holds every row)")
    if format == "apm" and at is None:
        raise ExportError("--format apm: give the time with --at (seconds after epoch_utc "
                          "or an ISO 8601 UTC time)")
    src = open_source(directory, what)
    path = _target(src, format, out, force)
    comparison = None if truth is None else Comparison(truth, src.scenario)
    meta = _meta(src, frame, object_id)
    if format == "apm":
        t_at = seconds_at(at, src.scenario)
        q = attitude_at_time(src, t_at, frame)
        block = _one_row(src, t_at, q, frame)
        if comparison is not None:
            comparison.add(block)
        epoch = stamps_of([t_at], build.epoch(src.scenario))[0]
        figures = None if comparison is None else comparison.result()
        with _atomic(path) as stream:
            write_apm(stream, epoch, q, meta)
        return ExportResult(path, format, what, FRAMES[frame], 1,
                            epoch=str(np.datetime_as_string(epoch, unit="us")),
                            comparison=figures)

    def quaternion_blocks(blocks):
        """The blocks as quaternions.  A failure (a bad row half way) passes through
        the writer, which closes its spool, and ``_atomic``, which drops the file."""
        last = -np.inf
        for b in blocks:
            steps = np.diff(np.r_[last, b.t_s])
            if np.any(~(steps > 0)):
                k = int(np.argmax(~(steps > 0)))
                raise ExportError(f"{src.csv}: t_s {b.t_s[k]:g} does not follow "
                                  f"{last if k == 0 else b.t_s[k - 1]:g}: the rows must "
                                  "increase in time")
            last = b.t_s[-1] if len(b.t_s) else last
            if comparison is not None:
                comparison.add(b)
            yield b.t_s, _quaternions(src, b, frame)

    with _atomic(path) as stream, contextlib.closing(src.blocks()) as blocks:
        segments = write_aem_blocks(stream, quaternion_blocks(blocks), meta,
                                    epoch=build.epoch(src.scenario), cadence_s=src.cadence_s)
        figures = None if comparison is None else comparison.result()
    return ExportResult(path, format, what, FRAMES[frame], sum(n for *_, n in segments),
                        segments=segments, comparison=figures)


def _one_row(src: RunSource, t_at: float, q: np.ndarray, frame: str) -> Block:
    """The APM's attitude as a block of one row of 3-1-2 angles (for ``--truth``)."""
    s = src.scenario
    q_br = q[None] if frame == "orbit" else orbit_frame_from_inertial(
        [t_at], q[None], build.orbit(s), build.epoch(s))
    yaw, roll, pitch = euler312_from_quat(q_br)
    return Block(np.array([t_at]), yaw, roll, pitch)


def attitude_at_time(src: RunSource, t_at: float, frame: str) -> np.ndarray:
    """The attitude (scalar-last, in ``frame``) at ``t_at`` s, interpolated as an AEM
    reader interpolates the export (``AemSegment.interpolate``, Lagrange of degree 7 on
    the nearest rows of the segment, normalised; a row's own value at its time), from
    the rows within ``APM_WINDOW_ROWS`` cadences of it.  Outside the rows, or in a
    dropout (a step over 1.5 cadences, ``aem.GAP_FACTOR``), ``ExportError``."""
    gap, reach = AEM_GAP_FACTOR * src.cadence_s, APM_WINDOW_ROWS * src.cadence_s
    near, prev, after, first, last = [], -np.inf, np.inf, None, None
    with contextlib.closing(src.blocks()) as blocks:
        for b in blocks:
            ok = np.isfinite(b.yaw) & np.isfinite(b.roll) & np.isfinite(b.pitch)
            if not ok.any():
                continue
            t = b.t_s[ok]
            first, last = t[0] if first is None else first, t[-1]
            prev = max(prev, t[t <= t_at].max(initial=-np.inf))
            after = min(after, t[t >= t_at].min(initial=np.inf))
            inside = (t >= t_at - reach) & (t <= t_at + reach)
            if inside.any():
                near.append((t[inside], *(x[ok][inside] for x in (b.yaw, b.roll, b.pitch))))
            if t[-1] > t_at + reach:
                break
    if not np.isfinite(prev) or not np.isfinite(after):
        span = "it has no row with all three angles" if first is None else \
            f"its first row is at {first:g} s" if not np.isfinite(prev) else \
            f"its last row is at {last:g} s"
        raise ExportError(f"--at {t_at:g} s after epoch_utc: outside the run ({span})")
    if after - prev > gap:
        raise ExportError(f"--at {t_at:g} s after epoch_utc: in a dropout of {src.csv.name} "
                          f"(no rows from {prev:g} to {after:g} s)")
    t, yaw, roll, pitch = (np.concatenate(c) for c in zip(*near, strict=True))
    start = np.union1d([0], np.flatnonzero(np.diff(t) > gap) + 1)
    k = int(np.searchsorted(t, prev))            # the row at prev
    lo = start[np.searchsorted(start, k, "right") - 1]
    hi = next((j for j in start if j > lo), len(t))
    piece = Block(t[lo:hi], yaw[lo:hi], roll[lo:hi], pitch[lo:hi])
    q = _quaternions(src, piece, frame)
    stamps = stamps_of(piece.t_s, build.epoch(src.scenario))
    degree = str(min(7, len(q) - 1))
    segment = AemSegment({"INTERPOLATION_DEGREE": degree}, stamps, q, FRAMES[frame],
                         "SC_BODY_1", 0)
    return segment.interpolate(stamps_of([t_at], build.epoch(src.scenario)))[0]
