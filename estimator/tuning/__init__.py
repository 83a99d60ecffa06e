"""The paper filter's noise from its own innovations: ``likelihood`` (ln L, its score
and expected information in one compiled pass, ``steps``) and ``maximum`` (the
maximum over the noise by Fisher scoring, σ and one-sided limits).

May import: ``kalman``, ``linear``, ``rollout``.
"""
