"""`dynprop batch`: batch least squares across the Sun gap, the paper's set-aside
alternative to its filter (docs/batch.md).  ``spans``: the chained batches and
their joined history; ``source``: the telemetry (and truth) of a run directory or
a file; ``compare``: the batch, the filter and the smoother against the truth;
``report``: estimate_batch.csv, batch.json and batch.png.

May import: ``run`` and every room below it.  Not ``trim``, ``tune``,
``linearization`` or ``montecarlo``, its siblings.
"""
