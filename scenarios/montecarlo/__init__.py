"""`dynprop montecarlo`: dispersed, reproducible, resumable ensembles of `dynprop run`.

dispersions (what varies and how it is drawn) → case (one dispersed run, reduced on
the worker) → store (one file pair per finished case) → execute (local processes or
dask.distributed) → stats (ensemble figures and montecarlo.json) → runset (the
command).  ``case_dir``: one case alone as a run directory (`dynprop run
--montecarlo-case K`).  The ``montecarlo`` scenario section is ``config.montecarlo``.

May import: ``run`` and every room below it.  Not ``trim`` or ``linearization``, its
siblings.
"""


class SchedulerError(ValueError):
    """--scheduler names no reachable dask scheduler (or dask is not installed)."""
