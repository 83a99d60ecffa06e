"""Comparing covariances of states with mixed units (rad next to N m s and N m)."""

import numpy as np


def cov_dev(P, P_ref) -> np.ndarray:
    """|P − P_ref| / √(P_ref,ii P_ref,jj), element by element (any leading shape): one
    absolute tolerance across all states would check the torque states (P ~ 1e-12)
    not at all."""
    d = np.sqrt(np.einsum("...ii->...i", P_ref))
    return np.abs(P - P_ref) / (d[..., :, None] * d[..., None, :])
