"""Run cases locally (one process per core) or on a dask.distributed cluster.

Both hand every finished case to ``on_done`` as soon as it arrives, so the caller
stores it before the next one: a set killed at any moment loses only the cases in
flight.  Scheduling is the libraries' (``concurrent.futures`` locally, dask's
scheduler on a cluster); here there is only bookkeeping.
"""

from __future__ import annotations

import hashlib
import os
import sys
from collections.abc import Callable, Iterable
from concurrent.futures import FIRST_COMPLETED, wait
from concurrent.futures.process import BrokenProcessPool

from ..config.schema import Scenario, resolved_yaml
from ..workers import clean_start_context, worker_pool
from . import SchedulerError
from .case import failed, run_case

WORKER_MODULE = __package__ + ".case"
CONNECT_TIMEOUT_S = 20.0  # how long --scheduler may take to answer


def default_workers() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        return os.cpu_count() or 1


def _progress(total: int, initial: int, desc: str):
    """A bar with the rate and ETA on a terminal; silent otherwise (logs, tests)."""
    from tqdm import tqdm
    return tqdm(total=total, initial=initial, desc=desc, unit="case", file=sys.stderr,
                disable=not sys.stderr.isatty(), smoothing=0.1, dynamic_ncols=True)


def _context():
    # Workers fork from a server that has already imported the simulator, and do
    # not run the caller's __main__ again: a script using dynprop.montecarlo needs
    # no `if __name__ == "__main__":` guard.
    return clean_start_context([WORKER_MODULE])


def run_local(s: Scenario, cases: list[int], keep: Iterable[int], workers: int,
              on_done: Callable[[dict], None], done_before: int = 0, total: int = 0) -> None:
    """Up to ``workers`` cases at a time in worker processes.  A worker that dies
    (killed, out of memory) fails only the cases it may have held; the pool is
    restarted for the rest."""
    keep = set(keep)
    todo = list(cases)
    # One forkserver for the set, across pool restarts too; stopped after it.
    with _context() as ctx, _progress(total or len(todo), done_before, "montecarlo") as bar:
        while todo:
            with worker_pool(workers, ctx) as pool:
                running = {}
                broken = False
                while (todo or running) and not broken:
                    while todo and len(running) < 2 * workers:
                        k = todo.pop(0)
                        running[pool.submit(run_case, s, k, k in keep)] = k
                    finished, _ = wait(running, return_when=FIRST_COMPLETED)
                    for fut in finished:
                        k = running.pop(fut)
                        try:
                            outcome = fut.result()
                        except BrokenProcessPool as exc:
                            broken = True
                            outcome = failed(k, RuntimeError(f"worker process died ({exc})"))
                        on_done(outcome)
                        bar.update()
                if broken:
                    # Every case still held by the dead pool is failed, not lost.
                    for k in running.values():
                        on_done(failed(k, RuntimeError("worker process died")))
                        bar.update()


def connect(address: str):
    """A dask.distributed Client on ``address``, or SchedulerError in one line."""
    try:
        from distributed import Client
    except ImportError:
        raise SchedulerError("--scheduler needs dask.distributed: pip install "
                             "'dynprop[dask]'") from None
    try:
        return Client(address, timeout=CONNECT_TIMEOUT_S)
    except (OSError, ValueError, TypeError) as exc:
        raise SchedulerError(f"--scheduler {address}: cannot connect ({exc})") from None


def run_dask(s: Scenario, cases: list[int], keep: Iterable[int], client,
             on_done: Callable[[dict], None], done_before: int = 0, total: int = 0) -> None:
    """The same cases on an existing dask.distributed cluster, through ``client``."""
    from distributed import as_completed
    keep = set(keep)
    # Keys name this very set, so two sets on one cluster never share results.
    digest = hashlib.sha256(resolved_yaml(s).encode()).hexdigest()[:12]
    bar = _progress(total or len(cases), done_before, "montecarlo (dask)")
    try:
        futures = {client.submit(run_case, s, k, k in keep, pure=False,
                                 key=f"dynprop-{digest}-case-{k}"): k for k in cases}
        for fut in as_completed(futures):
            k = futures[fut]
            try:
                outcome = fut.result()
            except Exception as exc:  # a worker lost for good (KilledWorker, ...)
                outcome = failed(k, exc)
            on_done(outcome)
            fut.release()
            bar.update()
    finally:
        bar.close()
