"""`dynprop trim`: the solar trim-tab setting from the estimated torque
(docs/trim.md).  ``batch``: the batch filter, the known torques and κ̂ ± σ;
``report``: trim.json, trim.md, trim.png and ``--verify``; ``loop``: the trim loop
(``trim.every_days``) as the run engine's steering.

May import: ``run`` and every room below it.  Not ``linearization`` or
``montecarlo``, its siblings.
"""
