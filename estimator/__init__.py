"""Every estimation algorithm and analysis of dynprop, array in, array out: no I/O, no
scenario, no truth (``sim`` is never imported here).  The rooms, by algorithm family,
each a sub-package whose ``__init__`` says what it holds:

- ``linear``: the paper's linear model (Eqs. 9–12) and its discrete forms: the
  closed-form Φ, Γ and Q_d (``transition``), the exact propagation (``propagate``),
  the per-step tables at any cadence (``steps``) and the sensors' noise (``noise``);
- ``kalman``: the paper's Kalman filter and RTS smoother (``filter``, compiled in
  ``steps``), the telemetry's preprocessing into its measurements and inputs
  (``preprocess``, ``savgol``) and the consistency statistics (``consistency``);
- ``augmented``: the filter with sensor-bias states and outlier gating;
- ``pitch``: the pitch filter of Eq. 3b;
- ``ekf``: the extended Kalman filter on the gyrostat;
- ``tuning``: the filter's likelihood and its maximum over the noise;
- ``batch``: batch least squares, on the paper's model or the gyrostat;
- ``analysis``: observability, the steady-state covariance of Section 6, and the
  solar imbalance κ with the trim tab's move.

A room imports rooms of a lower rank only (docs/architecture.md, "The rooms of
``estimator/``"; tests/test_layering.py): ``linear`` → ``kalman`` → ``augmented``,
``pitch``, ``ekf``, ``tuning`` → ``batch``, ``analysis``.
"""
