"""Batch least squares over a span of telemetry: ``linear`` (the paper's model in one
solve, with consider parameters), ``nonlinear`` (the gyrostat by Gauss–Newton) and
``steps`` (their compiled sensitivities).

May import: ``ekf``, ``kalman``, ``linear``, ``eom``, ``rollout``.
"""
