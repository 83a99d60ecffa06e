"""The paper's Kalman filter and RTS smoother (Eqs. 31–38): ``filter`` (the filter
and smoother on whole arrays or a window at a time), ``steps`` (their compiled
CasADi steps), ``preprocess`` (telemetry arrays to the filter's measurements and
inputs, N_w* from ``savgol``'s Savitzky–Golay derivative), ``consistency`` (NEES,
NIS and their χ² bounds) and ``maneuver`` (the filters' response to a thruster-firing
flag in the telemetry: inflated noise or a reset, the run filtered segment by segment).

May import: ``linear``, ``eom``, ``rollout``.
"""
