"""The producer of a streamed run in a forked process of its own.

Joined to the consumer by a queue of at most ``QUEUE_ITEMS`` records, whose arrays
go by shared-memory file (``handoff``): memory holds a few windows, whatever the
duration.  Ctrl-C is the parent's: the child ignores it and is terminated.
"""

from __future__ import annotations

from multiprocessing import get_context

from ...config.schema import Scenario
from ...workers import ignore_sigint, sigint_held
from . import handoff
from .producer import producer

QUEUE_ITEMS = 4   # two windows: a real and a twin record each


def _child(queue, s, run, window_samples, out, telemetry_file, steering, shared) -> None:
    ignore_sigint()   # the parent handles Ctrl-C and terminates this process
    try:
        for item in producer(s, run, window_samples, out, telemetry_file, steering):
            queue.put(("item", handoff.pack(item, shared)))
        queue.put(("done", None))
    except BaseException as exc:  # noqa: BLE001 - handed to the parent, which raises it
        try:
            queue.put(("error", exc))
        except Exception:  # noqa: BLE001 - an exception that does not pickle
            queue.put(("error", RuntimeError(f"{type(exc).__name__}: {exc}")))


def producer_process(s: Scenario, run: int, window_samples, out, telemetry_file,
                     steering=None):
    """``producer.producer`` in a forked process; yields what it yields."""
    ctx = get_context("fork")
    queue = ctx.Queue(maxsize=QUEUE_ITEMS)
    shared = handoff.HandoffDir()
    proc = ctx.Process(target=_child, args=(queue, s, run, window_samples, out,
                                            telemetry_file, steering, shared.path),
                       daemon=True)
    with sigint_held():
        proc.start()
    try:
        while True:
            try:
                kind, item = queue.get(timeout=1.0)
            except Exception:  # noqa: BLE001 - queue.Empty: is the producer still there?
                if not proc.is_alive():
                    raise RuntimeError(f"the truth process died (exit {proc.exitcode})") \
                        from None
                continue
            if kind == "done":
                break
            if kind == "error":
                raise item
            yield handoff.unpack(*item)
        proc.join()
    finally:
        if proc.is_alive():
            proc.terminate()
            proc.join()
        queue.close()
        shared.close()
