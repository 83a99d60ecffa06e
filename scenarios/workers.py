"""Worker processes that leave the interrupt to their parent.

Ctrl-C sends SIGINT to the whole foreground process group, so every forked worker
would raise KeyboardInterrupt wherever it is and print its own traceback
("Process ForkProcess-2: Traceback ...") under the CLI's one-line message.  Workers
ignore SIGINT; the parent, which receives it too, stops them: queued work is
cancelled and running workers are terminated, so an interrupt takes effect at once
instead of after the work in flight.

SIGINT is blocked while the parent forks.  Otherwise a Ctrl-C that lands during
the fork is raised inside an at-fork hook (logging registers some), where Python
can only print it and go on: the child prints a traceback and the parent loses the
interrupt.  Blocked, it waits: the parent raises it as soon as the fork is done,
and the child discards it when it starts ignoring SIGINT.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import signal
import tempfile
import threading
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import context as mp_context
from multiprocessing import spawn

_SIGINT = {signal.SIGINT}


def ignore_sigint() -> None:
    """First thing in a worker process: the parent alone handles Ctrl-C.  A SIGINT
    that arrived while it was blocked for the fork is discarded here."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, _SIGINT)


@contextlib.contextmanager
def sigint_held() -> Iterator[None]:
    """Hold SIGINT back while forking; a Ctrl-C meanwhile is raised on leaving."""
    old = signal.pthread_sigmask(signal.SIG_BLOCK, _SIGINT)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def _nothing() -> None:
    return None


# Workers started by spawn or forkserver run the parent's __main__ again (as
# __mp_main__) before their first task, so that functions defined there unpickle.
# A user's script without an `if __name__ == "__main__":` guard then runs once per
# worker: `dynprop.montecarlo` in it ran `dynprop.run` again in every worker.  Our
# workers only ever run dynprop's own functions, so the parent does not send its
# __main__ (loky's `init_main_module=False` does the same).  multiprocessing has no
# option for it: the preparation data, built by spawn.get_preparation_data, loses
# its two __main__ keys, for launches from this thread only, under a lock.
_MAIN_KEYS = ("init_main_from_path", "init_main_from_name")
_withholding = threading.Lock()


@contextlib.contextmanager
def _main_withheld() -> Iterator[None]:
    launcher = threading.get_ident()
    original = spawn.get_preparation_data

    def preparation_data(name):
        data = original(name)
        if threading.get_ident() == launcher:
            for key in _MAIN_KEYS:
                data.pop(key, None)
        return data

    with _withholding:
        spawn.get_preparation_data = preparation_data
        try:
            yield
        finally:
            spawn.get_preparation_data = original


# Module-level classes: the process object is pickled to the child by reference.
class _MainlessForkServerProcess(mp_context.ForkServerProcess):
    @staticmethod
    def _Popen(process_obj):
        with _main_withheld():
            return mp_context.ForkServerProcess._Popen(process_obj)


class _MainlessSpawnProcess(mp_context.SpawnProcess):  # pragma: no cover - not POSIX
    @staticmethod
    def _Popen(process_obj):
        with _main_withheld():
            return mp_context.SpawnProcess._Popen(process_obj)


class _MainlessForkServerContext(mp_context.ForkServerContext):
    Process = _MainlessForkServerProcess


class _MainlessSpawnContext(mp_context.SpawnContext):
    Process = _MainlessSpawnProcess


# The forkserver listens on a socket at <temp dir>/pymp-XXXXXXXX/listener-XXXXXXXX, and
# an AF_UNIX address holds 107 bytes on Linux, 103 on macOS: under a long TMPDIR the
# server cannot bind ("AF_UNIX path too long") and no worker starts.
_UNIX_ADDRESS_BYTES = 103
_SOCKET_TAIL = len("/pymp-XXXXXXXX/listener-XXXXXXXX")


def forkserver_fits(tempdir: str | None = None) -> bool:
    """Whether the forkserver's socket under ``tempdir`` (default: the temporary
    directory, TMPDIR) fits in an AF_UNIX address."""
    base = tempfile.gettempdir() if tempdir is None else tempdir
    return len(os.fsencode(base)) + _SOCKET_TAIL <= _UNIX_ADDRESS_BYTES


@contextlib.contextmanager
def clean_start_context(preload: list[str]) -> Iterator[mp_context.BaseContext]:
    """A multiprocessing context for worker pools whose processes start clean and
    never run the parent's __main__ (see above).

    forkserver where there is one: workers fork from a server that has imported
    ``preload`` already, so each starts in milliseconds and inherits no threads or
    locks from this process (tqdm's monitor, a notebook kernel's).

    On leaving, the forkserver and the resource tracker it needs are stopped if this
    block started them, so no process outlives the command.  Left running, they are
    children of a notebook kernel, which at shutdown signals them for 29 s (the
    tracker ignores SIGTERM); Jupyter kills the kernel after 5 s, before it removes
    its temporary directories.

    spawn where there is no forkserver, or where its socket would not fit under the
    temporary directory (``forkserver_fits``): each worker then imports dynprop itself,
    a second or so, once per pool."""
    # multiprocessing's own singletons; _stop is what its test suite stops them with.
    from multiprocessing import forkserver, resource_tracker
    server, tracker = forkserver._forkserver, resource_tracker._resource_tracker
    if "forkserver" in multiprocessing.get_all_start_methods() and forkserver_fits():
        ctx = _MainlessForkServerContext()
        ctx.set_forkserver_preload(preload)
    else:
        ctx, server = _MainlessSpawnContext(), None
    ours = [p for p, pid in ((server, server and server._forkserver_pid),
                             (tracker, tracker._pid)) if p is not None and pid is None]
    try:
        yield ctx
    finally:
        # The server first: it holds the tracker's pipe open.  Each exits when its
        # pipe from this process closes; the pools' workers have been joined.
        for process in ours:
            with contextlib.suppress(OSError):
                process._stop()


@contextlib.contextmanager
def worker_pool(workers: int, context) -> Iterator[ProcessPoolExecutor]:
    """A process pool whose workers ignore SIGINT and are stopped at once when the
    block raises (KeyboardInterrupt included)."""
    pool = ProcessPoolExecutor(workers, mp_context=context, initializer=ignore_sigint)
    try:
        if context.get_start_method() == "fork":
            # A fork pool starts every worker at its first submit: do that here, with
            # SIGINT held.  (forkserver workers are forked by their server.)
            with sigint_held():
                pool.submit(_nothing).result()
        yield pool
    except BaseException:
        # ProcessPoolExecutor has no public way to stop running work before Python
        # 3.14 (terminate_workers); its process table is the way until then.
        processes = list((getattr(pool, "_processes", None) or {}).values())
        pool.shutdown(wait=False, cancel_futures=True)
        for p in processes:
            p.terminate()
        for p in processes:
            p.join()
        raise
    pool.shutdown(wait=True)


@contextlib.contextmanager
def blas_one_thread() -> Iterator[None]:
    """BLAS (numpy's and scipy's OpenBLAS) on one thread meanwhile.

    dynprop keeps both cores busy with its own processes and threads; the BLAS calls
    it makes are small (9×9 solves, N×3 products).  OpenBLAS would start a thread
    per core for the larger ones and leave them spinning after each call, taking a
    core from the other process: 13% of a long run's CPU.  One thread computes the
    same values here (every run directory stayed byte-identical)."""
    import scipy.linalg  # noqa: F401 - loads scipy's OpenBLAS, so it is limited too
    from threadpoolctl import threadpool_limits
    with threadpool_limits(limits=1, user_api="blas"):
        yield
