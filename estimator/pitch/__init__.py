"""The pitch estimator of Eq. 3b beside the paper's roll/yaw filter: ``model`` (the
pitch model, its closed-form Φ, Γ, Q_d for either sign of the stiffness, and its
steady state) and ``filter`` (the compiled filter and RTS smoother).

May import: ``linear``, ``rollout``.
"""
