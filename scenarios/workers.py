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
import signal
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor

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
