"""`dynprop tune`: the paper filter's noise parameters from its own telemetry, by
maximum likelihood (docs/tune.md).  ``source``: the telemetry (a run directory or a
file with ``--scenario``) on the filter's grid, and what makes it too little to
tune on; ``fit``: the likelihood, its maximum, σ and limits, and the before/after
diagnostics; ``report``: tune.json, tune.md, tuned_noise.yaml and tune.png;
``noise``: a tune result read back for `run`, `estimate` and `montecarlo`
(``--tuned-from``).

May import: ``run`` and every room below it.  Not ``trim``, ``linearization`` or
``montecarlo``, its siblings.
"""
