"""The state augmented with sensor biases (not in the paper): its names, F_a and
measurement rows, which the filter (``filter``, ``steps``) runs on and the
observability analysis (``analysis.observability``) ranks.

x_a = [x (Eq. 10), b].  A bias has no dynamics (a constant, or a random walk whose
noise does not enter observability), so F_a = blockdiag(F, 0); it adds to its
sensor's measurement row: roll = e_r + e_earth_roll, yaw from a head = e_y +
e_<head>_yaw, h = e_h.
"""

from __future__ import annotations

import numpy as np

from ..linear.model import STATE_NAMES, measurement_rows

BIAS_NAMES = ("earth_roll", "dss_yaw", "cass1_yaw", "cass2_yaw")
YAW_HEADS = ("dss_yaw", "cass1_yaw", "cass2_yaw")   # sun_head code 0, 1, 2


def augmented_dynamics(F, n_biases: int) -> np.ndarray:
    """F_a = blockdiag(F, 0_{n_biases})."""
    F = np.asarray(F, dtype=float)
    n = F.shape[0]
    Fa = np.zeros((n + n_biases, n + n_biases))
    Fa[:n, :n] = F
    return Fa


def augmented_rows(kinds, biases, keep=None) -> np.ndarray:
    """Measurement rows on [x, b] (x the paper's states ``keep``, default all nine; b
    the ``biases``, in ``BIAS_NAMES`` order): 'roll', 'h' and 'yaw:<head>'."""
    keep = list(range(len(STATE_NAMES))) if keep is None else list(keep)
    rows = measurement_rows()
    G = np.zeros((len(kinds), len(keep) + len(biases)))
    for i, kind in enumerate(kinds):
        base, _, head = kind.partition(":")
        G[i, :len(keep)] = rows[base][keep]
        bias = "earth_roll" if base == "roll" else f"{head}_yaw" if base == "yaw" else None
        if bias in biases:
            G[i, len(keep) + list(biases).index(bias)] = 1.0
    return G
