"""Analyses of the paper's model that run no filter on telemetry: ``observability``
(Section 4's rank tests, with bias states too), ``covariance`` (Section 6's
steady-state yaw σ by every route) and ``covariance_report`` (`dynprop covariance`),
``trim`` (the solar imbalance κ from the torque states, and the trim tab's move).

May import: ``augmented``, ``linear``.
"""
