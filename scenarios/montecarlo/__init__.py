"""`dynprop montecarlo`: dispersed, reproducible, resumable ensembles of `dynprop run`.

dispersions (what varies and how it is drawn) → case (one dispersed run, reduced on
the worker) → store (one file pair per finished case) → execute (local processes or
dask.distributed) → stats (ensemble figures and montecarlo.json).
"""


class SchedulerError(ValueError):
    """--scheduler names no reachable dask scheduler (or dask is not installed)."""
