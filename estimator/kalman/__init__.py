"""The paper's Kalman filter and RTS smoother (Eqs. 31–38): ``filter`` (the filter
and smoother on whole arrays or a window at a time), ``steps`` (their compiled
CasADi steps), ``preprocess`` (telemetry arrays to the filter's measurements and
inputs, N_w* from ``savgol``'s Savitzky–Golay derivative) and ``consistency`` (NEES,
NIS and their χ² bounds).

May import: ``linear``, ``eom``, ``rollout``.
"""
