"""`dynprop linearization`: which of the paper's linearization assumptions breaks
first.  ``coefficients``: the truth's Jacobian against Eqs. 3, 5–7 and 11c;
``propagation``: nonlinear against linear propagation; ``analysis``: the sweep of
initial errors and the error budget; ``verdict`` and ``report``: report.md,
report.json and its figures.

May import: ``run`` and every room below it.  Not ``trim`` or ``montecarlo``, its
siblings.
"""
