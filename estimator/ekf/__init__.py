"""The extended Kalman filter on the nonlinear gyrostat: ``model`` (its states,
dynamics and measurements in CasADi, from ``eom``'s gyrostat) and ``filter`` (the
compiled filter and smoother, sub-stepped at any cadence).

May import: ``kalman``, ``linear``, ``eom``, ``rollout``.
"""
