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


def check_out_dir(out: Path | str, force: bool = False) -> Path:
    """Refuse an unusable ``--out`` before any work is done."""
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise RunDirError(f"--out {out}: exists and is not a directory")
    if out.is_dir() and any(out.iterdir()) and not force:
        raise RunDirError(f"--out {out}: directory exists and is not empty (use --force)")
    for parent in out.parents:
        if parent.exists():
            if not parent.is_dir():
                raise RunDirError(f"--out {out}: {parent} is not a directory")
            if not os.access(parent, os.W_OK):
                raise RunDirError(f"--out {out}: {parent} is not writable")
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
HANDOFF_PREFIX = "dynprop-"   # scenarios.run.handoff's directories: dynprop-<pid>-<random>


def clean_stale_handoffs(root: Path = SHM_ROOT) -> list[Path]:
    """Remove the record handoff directories (``scenarios.run.handoff``) under ``root``
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
def staged_run_dir(out: Path | str, force: bool = False) -> Iterator[Path]:
    """Yield a temporary sibling directory; on success it replaces ``out``.

    An existing non-empty ``out`` is refused unless ``force``.  If anything fails
    while writing, ``out`` is left exactly as it was and the staging directory
    is removed.
    """
    out = check_out_dir(out, force)
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
