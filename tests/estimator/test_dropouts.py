"""Telemetry dropouts in the ground preprocessing: the wheel torque bridged across
a dropout, and the wheel-torque noise sized from the telemetry itself, against
processes whose answers are known in closed form."""

from __future__ import annotations

import numpy as np
import pytest

from estimator.kalman.preprocess import _bridge_q, dropout_wheel_noise, wheel_torque

DT = 0.512


def test_wheel_torque_across_a_dropout_is_the_mean_rate_over_it():
    """A quadratic h (constant ḧ) with a 60 s hole: outside the hole and its 20 s
    window the Savitzky–Golay derivative is exact for a quadratic; inside, the bridge
    is the chord, whose slope is Δh/Δt over the hole."""
    t = np.arange(4000) * DT
    h = 1e-3 + 2e-6 * t + 3e-9 * t**2
    hole = slice(1500, 1617)
    gapped = h.copy()
    gapped[hole] = np.nan
    nw = wheel_torque(gapped, DT)
    a, b = hole.start - 1, hole.stop
    chord = (h[b] - h[a]) / (t[b] - t[a])
    # Exact in exact arithmetic; the fit's rounding is ~1e-16 of h / 20 s.
    assert nw[a + 30:b - 30] == pytest.approx(chord, rel=1e-9)
    far = np.r_[100:a - 40, b + 40:3900]
    assert nw[far] == pytest.approx(2e-6 + 6e-9 * t[far], rel=1e-9)
    assert np.array_equal(wheel_torque(h, DT), wheel_torque(h.copy(), DT))


def test_bridge_q_recovers_a_random_walks_intensity(rng):
    """For a random walk of intensity q sampled every dt with white noise of variance
    r, the midpoint of a straight-line bridge over L steps deviates with variance
    q·L·dt·w(1−w) + r(1 + w² + (1−w)²).  _bridge_q must return q for any L.
    200,000 samples give ~100,000/L independent windows: the estimate's relative
    standard error is √(2L/N) ≲ 5% for L ≤ 100; 5σ bound."""
    q, r, n = 4e-9, 2.3e-10, 200_000
    h = np.cumsum(rng.standard_normal(n)) * np.sqrt(q * DT) + rng.standard_normal(n) * np.sqrt(r)
    for steps in (2, 3, 20, 101):
        est = _bridge_q(h, steps, DT, r)
        assert est == pytest.approx(q, rel=5 * np.sqrt(2 * steps / n) + 0.02)
    # The measurement noise alone is no torque: q = 0, not the noise's share.
    assert _bridge_q(rng.standard_normal(n) * np.sqrt(r), 5, DT, r) < 0.02 * r / DT


def test_dropout_wheel_noise_lands_on_the_bridged_steps_only(rng):
    q, r, n = 4e-9, 2.3e-10, 50_000
    h = np.cumsum(rng.standard_normal(n)) * np.sqrt(q * DT) + rng.standard_normal(n) * np.sqrt(r)
    assert dropout_wheel_noise(h, DT, r) is None
    gapped = h.copy()
    gapped[1000:1010] = np.nan   # bridged by steps 999 … 1009 (11 steps)
    gapped[30000] = np.nan       # steps 29999, 30000
    per_step = dropout_wheel_noise(gapped, DT, r)
    on = np.zeros(n, bool)
    on[999:1010] = on[29999:30001] = True
    assert np.all(per_step[~on] == 0.0)
    assert per_step[on] == pytest.approx(q, rel=0.5)
    # Each dropout takes the q of its own length.
    assert np.unique(per_step[999:1010]).size == 1
    assert np.unique(per_step[29999:30001]).size == 1
