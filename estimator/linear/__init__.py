"""The paper's linear model and its discrete forms, which every filter of dynprop
shares: ``model`` (the states, F, G, the inputs and the torque model of Eqs. 9–12),
``transition`` (the closed-form Φ, Γ and Q_d of Eqs. 15–23, 31–32), ``propagate``
(the model propagated exactly over a run, compiled), ``steps`` (the filters' steps
at any cadence: each interval's closed forms once) and ``noise`` (R and q from the
sensors' specifications, Eqs. 44–48, 51).

May import: ``eom`` and ``rollout``; no other room of ``estimator``.
"""
