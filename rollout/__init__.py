"""CasADi machinery shared by ``sim`` and ``estimator``, which may not import each
other: compile a step function once (cached on disk, VM fallback) and roll it
out, compiled by a C loop of its own, in the VM in chunks through
``Function.buffer()``.  It knows no physics."""
