"""Records from the producer process to the consumer without piping their arrays.

A window's record holds ~55 MB of arrays a simulated day.  Through a
``multiprocessing.Queue`` they were pickled, written into a pipe 64 kB at a time by
a feeder thread, read and unpickled: about a third of a core in a year's run.  Here
the record is pickled with protocol 5, which hands every array's memory out of band;
those buffers are copied once into a file in a shared-memory directory, and only
the small pickle and the file's name go through the queue.  The consumer maps the
file, unlinks it and unpickles onto the mapping: its arrays are the file's pages,
not copies, and the memory returns when the last of them is dropped.

The directory is the parent's (``HandoffDir``): whatever an interrupted run leaves
in it goes with it.  Without a shared-memory file system (``/dev/shm``), or when it
has no room for a record, the record goes in band, through the queue, as before.
"""

from __future__ import annotations

import mmap
import os
import pickle
import shutil
import tempfile
from pathlib import Path

from ...files.rundir import HANDOFF_PREFIX, SHM_ROOT, clean_stale_handoffs

MIN_OUT_OF_BAND = 1 << 16   # smaller records are not worth a file


class HandoffDir:
    """A private directory for one run's handed-off records, removed on close.  Its
    name carries the run's process id, so that the next run removes what a killed
    one (SIGKILL: no ``finally``) left in memory (``rundir.clean_stale_handoffs``,
    which every command writing a run directory calls too)."""

    def __init__(self):
        self.path = None
        if SHM_ROOT.is_dir() and os.access(SHM_ROOT, os.W_OK) \
                and hasattr(os, "posix_fallocate"):
            clean_stale_handoffs()
            self.path = Path(tempfile.mkdtemp(prefix=f"{HANDOFF_PREFIX}{os.getpid()}-",
                                              dir=SHM_ROOT))

    def close(self) -> None:
        if self.path is not None:
            shutil.rmtree(self.path, ignore_errors=True)
            self.path = None


def pack(obj, directory: Path | None) -> tuple:
    """``obj`` as (pickle, file name or None, buffer sizes) for ``unpack``."""
    if directory is None:
        return pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL), None, ()
    buffers: list[pickle.PickleBuffer] = []
    data = pickle.dumps(obj, protocol=5, buffer_callback=buffers.append)
    raws = [b.raw() for b in buffers]
    sizes = tuple(r.nbytes for r in raws)
    if sum(sizes) < MIN_OUT_OF_BAND:
        return pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL), None, ()
    fd, name = tempfile.mkstemp(dir=directory)
    try:
        # Reserved before it is written: a full /dev/shm (a container's is often
        # 64 MB) refuses here, where a write into a mapping would kill the process.
        os.posix_fallocate(fd, 0, sum(sizes))
    except OSError:
        os.close(fd)
        os.unlink(name)
        return pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL), None, ()
    try:
        # Written by the kernel from the arrays' own memory: no mapping here to
        # fault in page by page.
        offset = 0
        for raw in raws:
            view = raw.cast("B")
            while view:
                done = os.pwrite(fd, view, offset)
                view, offset = view[done:], offset + done
    finally:
        os.close(fd)
    return data, name, sizes


def unpack(data: bytes, name: str | None, sizes: tuple[int, ...]):
    """The object ``pack`` packed; its arrays live on the file's mapping, and the file
    is unlinked at once (the mapping stays until nothing refers to it)."""
    if name is None:
        return pickle.loads(data)
    fd = os.open(name, os.O_RDWR)
    try:
        # MAP_POPULATE: the pages are mapped in one call, not faulted in one by one
        # as the consumer first reads them (a fault costs microseconds on a VM).
        m = mmap.mmap(fd, sum(sizes), flags=mmap.MAP_SHARED | getattr(mmap, "MAP_POPULATE", 0))
    finally:
        os.close(fd)
        os.unlink(name)
    view, offset, buffers = memoryview(m), 0, []
    for size in sizes:
        buffers.append(view[offset:offset + size])
        offset += size
    return pickle.loads(data, buffers=buffers)
