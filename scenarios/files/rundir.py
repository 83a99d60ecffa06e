"""Run directories that are written whole or not at all.

A run is written into a hidden staging directory beside ``--out`` and renamed at
the end.  Its name carries the owner, ``.NAME.stage-HOST-PID-XXXXXXXX``, so that a
staging directory left by a killed process (SIGKILL, power loss: nothing ran to
clean it) is recognised and removed by the next command that writes into the same
parent directory.  A replaced run is moved aside as ``.NAME.old-HOST-PID-...``
until the new one is in place; if its owner died in between, it is put back.
"""

from __future__ import annotations

import contextlib
import os
import re
import shutil
import socket
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

_OWNED = re.compile(r"^\.(?P<name>.+)\.(?P<kind>stage|old)-(?P<host>.+)-(?P<pid>\d+)-"
                    r"[A-Za-z0-9_]{8}$")


class RunDirError(ValueError):
    """The output directory cannot be used (exists and is not empty, no --force)."""


def public_path(path: Path | str) -> str:
    """``path`` as the user knows it: a staging (or moved-aside) directory in it is
    named by the run directory it becomes, ``.run.stage-HOST-PID-XXXXXXXX`` → ``run``."""
    parts = Path(path).parts
    return str(Path(*[m["name"] if (m := _OWNED.match(p)) else p for p in parts])) \
        if parts else str(path)


@contextlib.contextmanager
def names_file(path: Path | str) -> Iterator[None]:
    """An OSError inside the block names ``path`` when it names no file itself:
    a write that fails on a full disk says only "No space left on device"."""
    try:
        yield
    except OSError as exc:
        if exc.filename is not None:
            raise
        # OSError(errno, ...) gives the errno's own subclass (PermissionError, ...).
        raise OSError(exc.errno, exc.strerror or str(exc), str(path)) from exc


# What dynprop writes into the directories it makes (run, estimate, simulate,
# linearization, montecarlo, tune, trim) or into a run's (report, export): `--force`
# replaces a directory that holds nothing else.  Files, figures included, are
# dynprop's by their very names, so that a user's own CSV, notes or pictures are
# never taken for a run's (tests/scenarios/test_messages.py checks this list against
# the names the commands write).
OWN_FIGURES = frozenset((
    "errors.png", "estimates.png", "consistency.png", "torques.png",
    "telemetry_overview.png", "season.png", "trim_loop.png", "truth.png", "telemetry.png",
    "mc_errors.png", "mc_nees.png", "mc_gap_yaw.png", "coefficients.png",
    "divergence_time.png", "divergence_sweep.png", "budget.png", "estimation.png",
    "trim.png", "tune.png", "batch.png"))
OWN_FILES = frozenset((
    "scenario.yaml", "case_scenario.yaml", "summary.json", "truth.csv", "telemetry.csv",
    "estimate.csv", "smoothed.csv", "daily.csv", "comparison.npz", "trim_loop.csv",
    "momentum_management.csv",
    "montecarlo.json", "montecarlo.npz", "montecarlo_case.json", "montecarlo_case.npz",
    "report.json", "report.md", "tune.json", "tune.md", "tuned_noise.yaml", "trim.json",
    "trim.md", "batch.json", "report.html",
    # `dynprop export`'s default names only: an AEM of another tool kept in a run
    # directory (for `--truth`) is the user's, and --force must not take it.
    "estimate.aem", "truth.aem", "estimate.apm", "truth.apm")) | OWN_FIGURES
_OWN_PATTERN = re.compile(r"^(estimate_[a-z0-9_]+\.csv|case-\d+\.(json|npz|full\.npz))$")
OWN_DIRS = frozenset(("plots", "cases", "trim", "tune", "verify", "batch"))
# Temporaries of a write killed half way: ``.NAME.XXXXXXXX`` (montecarlo.store's
# atomic_write, export.write's) and ``.NAME.tmp`` (figures.save_figure).
_TEMPORARY = re.compile(r"^\.(?P<name>.+)\.(tmp|[A-Za-z0-9_]{8})$")
LISTED = 5   # foreign files named in a message


def _is_own_file(name: str) -> bool:
    if name in OWN_FILES or _OWN_PATTERN.match(name):
        return True
    m = _TEMPORARY.match(name)
    return m is not None and (m["name"] in OWN_FILES or bool(_OWN_PATTERN.match(m["name"])))


def foreign_files(out: Path) -> list[str]:
    """What ``out`` holds that dynprop did not write, as paths relative to ``out``
    (a directory with a trailing slash, not looked into), in sorted order."""
    found = []
    for path in sorted(Path(out).iterdir()):
        if path.is_dir() and not path.is_symlink():
            if path.name in OWN_DIRS:
                found += [f"{path.name}/{f}" for f in foreign_files(path)]
            elif not _OWNED.match(path.name):
                found.append(f"{path.name}/")
        elif not (path.is_file() and _is_own_file(path.name)):
            found.append(path.name)
    return found


def check_out_dir(out: Path | str, force: int = 0, label: str = "--out") -> Path:
    """Refuse an unusable output directory before any work is done.  ``force`` (the
    count of ``--force``) replaces a non-empty one that holds only what dynprop
    writes; 2 or more replaces it whatever it holds.  ``label`` names the option the
    directory came from in messages ("" for a directory the command picks itself)."""
    out = Path(out)
    where = f"{label} {out}" if label else str(out)
    if out.exists() and not out.is_dir():
        raise RunDirError(f"{where}: exists and is not a directory")
    if out.is_dir() and any(out.iterdir()):
        if not force:
            raise RunDirError(f"{where}: directory exists and is not empty (use --force)"
                              if label == "--out" else
                              f"{where}: directory exists and is not empty")
        foreign = foreign_files(out) if force < 2 else []
        if foreign:
            names = ", ".join(foreign[:LISTED]) + (
                f" and {len(foreign) - LISTED} more" if len(foreign) > LISTED else "")
            if label == "--out":
                raise RunDirError(
                    f"{where}: holds {names}, which dynprop did not write, and --force "
                    f"replaces only a directory of dynprop's own files: move them "
                    f"elsewhere, or give --force --force to replace them too")
            raise RunDirError(
                f"{where}: holds {names}, which dynprop did not write, and dynprop "
                f"replaces only a directory of its own files: move them elsewhere first")
    for parent in out.parents:
        if parent.exists():
            if not parent.is_dir():
                raise RunDirError(f"{where}: {parent} is not a directory")
            if not os.access(parent, os.W_OK):
                raise RunDirError(f"{where}: {parent} is not writable")
            break
    return out


def _owner_prefix(out: Path, kind: str) -> str:
    return f".{out.name}.{kind}-{socket.gethostname()}-{os.getpid()}-"


def _process_start_epoch(pid: int) -> float | None:
    """When process ``pid`` started (Unix time), from /proc; None where unknown."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        boot = next(float(line.split()[1]) for line in Path("/proc/stat").read_text()
                    .splitlines() if line.startswith("btime "))
    except (OSError, StopIteration, IndexError, ValueError):
        return None
    return boot + int(fields[19]) / os.sysconf("SC_CLK_TCK")  # field 22: starttime


def _is_dying(pid: int) -> bool:
    """True if process ``pid`` is a zombie or has a SIGKILL pending: it will never
    write again.  A killed process of a gigabyte or two takes a second or two to
    release its memory and be reaped, and the user's next command may come sooner."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
        status = Path(f"/proc/{pid}/status").read_text()
    except (OSError, IndexError):
        return False
    if state in ("Z", "X", "x"):
        return True
    pending = [int(line.split()[1], 16) for line in status.splitlines()
               if line.startswith(("SigPnd:", "ShdPnd:"))]
    return any(mask & (1 << (9 - 1)) for mask in pending)   # bit 8: SIGKILL


def _owner_is_gone(pid: int, since: float) -> bool:
    """True if no process ``pid`` runs, it is dying, or the one that does started
    after ``since`` (the pid was reused).  A process of another user counts as alive."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    except PermissionError:
        return False
    if _is_dying(pid):
        return True
    started = _process_start_epoch(pid)
    # /proc's start time is in clock ticks; allow a few seconds of rounding.
    return started is not None and started > since + 5.0


def clean_stale(parent: Path) -> list[str]:
    """Remove staging directories in ``parent`` whose owner on this host is gone,
    and put back a run moved aside whose replacement never arrived.  Returns one
    note per action.  Directories of live processes or other hosts are left alone."""
    notes = []
    host = socket.gethostname()
    try:
        entries = list(Path(parent).iterdir())
    except OSError:
        return notes
    for path in entries:
        m = _OWNED.match(path.name)
        if not m or m["host"] != host or not path.is_dir():
            continue
        try:
            # A staging directory is written by its owner until the owner dies, so a
            # process with its pid that started later is another one.  A run moved
            # aside keeps its old times: only a missing pid tells there.
            since = path.stat().st_mtime if m["kind"] == "stage" else float("inf")
        except OSError:
            continue
        if not _owner_is_gone(int(m["pid"]), since):
            continue
        target = path.with_name(m["name"])
        if m["kind"] == "old" and not target.exists():
            # Killed between moving the previous run aside and renaming the new one in.
            with contextlib.suppress(OSError):
                os.replace(path, target)
                notes.append(f"restored {target}, which process {m['pid']} had moved aside "
                             "before it was killed")
            continue
        shutil.rmtree(path, ignore_errors=True)
        if not path.exists():
            notes.append(f"removed {path}, left by process {m['pid']}, which is gone")
    return notes


SHM_ROOT = Path("/dev/shm")
HANDOFF_PREFIX = "dynprop-"   # scenarios.run.stream.handoff's directories: dynprop-<pid>-<random>


def clean_stale_handoffs(root: Path = SHM_ROOT) -> list[Path]:
    """Remove the record handoff directories (``scenarios.run.stream.handoff``) under ``root``
    whose run is gone: a killed `dynprop run` leaves its records in memory there."""
    removed = []
    for path in root.glob(f"{HANDOFF_PREFIX}*-*"):
        try:
            pid = int(path.name[len(HANDOFF_PREFIX):].split("-")[0])
            since = path.stat().st_mtime
        except (ValueError, OSError):
            continue
        if _owner_is_gone(pid, since):
            shutil.rmtree(path, ignore_errors=True)
            removed.append(path)
    return removed


@contextlib.contextmanager
def staged_run_dir(out: Path | str, force: int = 0, label: str = "--out") -> Iterator[Path]:
    """Yield a temporary sibling directory; on success it replaces ``out``.

    An existing non-empty ``out`` is refused unless ``force``, and one holding files
    dynprop did not write unless ``force`` ≥ 2 (``check_out_dir``).  If anything fails
    while writing, ``out`` is left exactly as it was and the staging directory
    is removed.
    """
    out = check_out_dir(out, force, label)
    created = [p for p in reversed(out.absolute().parents) if not p.exists()]
    out.parent.mkdir(parents=True, exist_ok=True)
    for note in clean_stale(out.parent):
        print(f"dynprop: note: {note}", file=sys.stderr)
    if SHM_ROOT.is_dir():
        clean_stale_handoffs()
    stage = Path(tempfile.mkdtemp(prefix=_owner_prefix(out, "stage"), dir=out.parent))
    # mkdtemp makes 0700; give the finished directory the user's usual permissions.
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(stage, 0o777 & ~umask)
    try:
        yield stage
    except BaseException:
        shutil.rmtree(stage, ignore_errors=True)
        # Parents this call created go too: a failed run leaves no trace at all.
        for parent in reversed(created):
            with contextlib.suppress(OSError):
                parent.rmdir()
        raise
    backup = None
    try:
        if out.exists():
            backup = Path(tempfile.mkdtemp(prefix=_owner_prefix(out, "old"), dir=out.parent))
            os.rmdir(backup)
            os.replace(out, backup)
        os.replace(stage, out)
    except BaseException:
        # Put the previous run back where it was; drop the new one.
        if backup is not None and backup.exists() and not out.exists():
            os.replace(backup, out)
        shutil.rmtree(stage, ignore_errors=True)
        raise
    if backup is not None:
        shutil.rmtree(backup, ignore_errors=True)
