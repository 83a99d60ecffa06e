"""Which samples of a run each output keeps, counted on the global sample index.

A run is samples 0 … N−1 at ``sample_interval_s``.  Its output rows are every
``stride``-th sample (``output.interval_s``), its NEES is formed on every
``NEES_STRIDE``-th, and its Sun gaps are yaw outages of a minimum length.  Every
room that writes, reduces or draws a run asks here, so the whole-array run, the
streamed windows and the figures agree on the very same samples.
"""

from __future__ import annotations

import numpy as np

NEES_STRIDE = 10  # NEES on every 10th sample (5 s apart): plenty for means and figures
#: Largest relative change of the filter's yaw σ between a truth row and the Sun-gap
#: end it stands for, with a truth at some samples only (``run.estimate_truth``).
END_SIGMA_MATCH = 0.01


def output_rows(start: int, stop: int, stride: int) -> np.ndarray:
    """Global sample indices of the output rows (multiples of ``stride``) within
    [start, stop)."""
    return np.arange(-(-start // stride) * stride, stop, stride)


def nees_rows(start: int, stop: int) -> np.ndarray:
    """Global sample indices within [start, stop) on which the NEES is formed."""
    return output_rows(start, stop, NEES_STRIDE)


def sun_gaps(yaw_present: np.ndarray, dt_s: float, min_hours: float) -> list[tuple[int, int]]:
    """(first missing, first present again) index pairs of yaw outages ≥ ``min_hours``;
    a gap still open at the end of the run has end = N."""
    missing = ~np.asarray(yaw_present, dtype=bool)
    edges = np.flatnonzero(np.diff(np.r_[0, missing.astype(int), 0]))
    pairs = list(zip(edges[::2], edges[1::2], strict=True))
    return [(a, b) for a, b in pairs if (b - a) * dt_s >= min_hours * 3600]


def sun_gaps_at(yaw_present: np.ndarray, t_s: np.ndarray, min_hours: float
                ) -> list[tuple[int, int]]:
    """``sun_gaps`` for samples at their own times ``t_s`` (telemetry off the grid): an
    outage's length is the time from the last yaw before it to the first after it
    (or to the last sample), less one median step, which on a regular grid is
    ``sun_gaps``' (first present − first missing) × Δt."""
    missing = ~np.asarray(yaw_present, dtype=bool)
    t = np.asarray(t_s, dtype=float)
    step = float(np.median(np.diff(t))) if len(t) > 1 else 0.0
    edges = np.flatnonzero(np.diff(np.r_[0, missing.astype(int), 0]))
    pairs = list(zip(edges[::2], edges[1::2], strict=True))
    out = []
    for a, b in pairs:
        before = t[a - 1] if a > 0 else t[0] - step
        after = t[b] if b < len(t) else t[-1] + step
        if after - before - step >= min_hours * 3600:
            out.append((a, b))
    return out
