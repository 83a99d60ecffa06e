"""The paper's filter with sensor-bias states and outlier gating (not in the paper):
``model`` (the augmented state's names, F_a and measurement rows), ``steps`` (the
compiled steps) and ``filter`` (the filter and smoother).

May import: ``kalman``, ``linear``, ``rollout``.
"""
