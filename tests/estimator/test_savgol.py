"""``estimator.kalman.savgol``: scipy.signal's Savitzky–Golay derivative without importing
scipy.signal (0.4 s of every command's start-up)."""

import numpy as np
import pytest
from scipy.signal import savgol_filter

from estimator.kalman.preprocess import wheel_torque
from estimator.kalman.savgol import savgol_derivative

CASES = [(n, *c) for n in (5, 40, 1000, 20_001)
         for c in ((3, 2, 1), (39, 2, 1), (41, 2, 1), (39, 3, 2), (5, 1, 0), (5, 1, 2))
         if c[0] <= n]


@pytest.mark.parametrize(("n", "window", "order", "deriv"), CASES)
def test_equals_scipy_savgol_filter(n, window, order, deriv):
    """The same steps as scipy's (coefficients by least squares, convolution inside,
    a polynomial fit at each end): on this machine the bits are scipy's; the
    tolerance, a few ulps of the largest value, is what another LAPACK may change."""
    x = 10.0 + 1e-3 * np.cumsum(np.random.default_rng(n + window).normal(size=n))
    ref = savgol_filter(x, window, order, deriv=deriv, delta=0.512, mode="interp")
    got = savgol_derivative(x, window, order, 0.512, deriv=deriv)
    scale = max(np.max(np.abs(ref)), np.max(np.abs(x)) / 0.512 ** deriv * 1e-3)
    np.testing.assert_allclose(got, ref, rtol=0, atol=64 * np.finfo(float).eps * scale)


def test_derivative_of_a_quadratic_is_exact_everywhere_edges_included():
    """A quadratic is its own local fit: ḣ = b + 2ct at every sample, the first and
    last window//2 samples (the edge polynomials) as well as the interior."""
    dt, n = 0.512, 2001
    t = np.arange(n) * dt
    h = 12.0 + 3e-4 * t - 2e-8 * t**2
    np.testing.assert_allclose(wheel_torque(h, dt, 20.0), 3e-4 - 4e-8 * t, rtol=0, atol=1e-12)


def test_bad_window():
    with pytest.raises(ValueError, match="window"):
        savgol_derivative(np.zeros(10), 4, 2, 1.0)
    with pytest.raises(ValueError, match="window"):
        savgol_derivative(np.zeros(10), 11, 2, 1.0)
