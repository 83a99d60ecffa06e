"""CasADi machinery shared by ``sim`` and ``estimator``, which may not import each
other: compile a step function once (cached on disk, VM fallback) and roll it
out in chunks through ``Function.buffer()``.  It knows no physics."""
