"""Run directories that are written whole or not at all (DESIGN.md section 6)."""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path


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
    stage = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=out.parent))
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
            backup = Path(tempfile.mkdtemp(prefix=f".{out.name}.old.", dir=out.parent))
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
