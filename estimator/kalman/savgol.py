"""The Savitzky–Golay derivative of ``preprocess.wheel_torque``, without scipy.signal.

``scipy.signal.savgol_filter(x, window, order, deriv=1, delta=dt, mode="interp")``
is what N_w* (Eq. 4) is.  Importing scipy.signal costs 0.4 s (it loads
scipy.stats), which every `dynprop` command paid before doing anything; this is
the same computation from the two pieces it is made of, ``scipy.ndimage``'s
convolution and ``scipy.linalg``'s least squares: the window's coefficients, a
convolution in the interior, and a polynomial fitted to the first and last
``window`` samples for the ``window // 2`` samples at either end.  The steps and
their order follow scipy 1.17's ``_savitzky_golay``, so the values are its values
(tests/estimator/test_savgol.py compares the two).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg import lstsq
from scipy.ndimage import convolve1d


def savgol_coeffs(window: int, order: int, deriv: int, delta: float) -> np.ndarray:
    """Convolution coefficients of the order-``order`` least-squares fit's
    ``deriv``-th derivative at the centre of an odd ``window``."""
    if deriv > order:
        return np.zeros(window)
    pos = window // 2
    x = np.arange(-pos, window - pos, dtype=np.float64)[::-1]   # reversed: a convolution
    A = x ** np.arange(order + 1, dtype=np.float64).reshape(-1, 1)
    y = np.zeros(order + 1)
    y[deriv] = float(math.factorial(deriv)) / (delta ** deriv)
    return lstsq(A, y, cond=np.finfo(np.float64).eps * max(A.shape))[0]


def _polyfit(x: np.ndarray, y: np.ndarray, order: int) -> np.ndarray:
    """Least-squares polynomial, highest power first, with scaled columns."""
    powers = np.arange(order + 1, dtype=x.dtype)[::-1]
    lhs = x[:, None] ** powers[None, :]
    scale = np.sqrt(np.sum(lhs * lhs, axis=0))
    lhs /= scale
    c = lstsq(lhs, y, cond=x.shape[0] * np.finfo(x.dtype).eps)[0]
    return (c.T / scale).T


def _fit_edge(x, start, stop, interp_start, interp_stop, order, deriv, delta, y) -> None:
    p = _polyfit(np.arange(0, stop - start, dtype=x.dtype), x[start:stop, None], order)
    n = p.shape[0]
    if deriv:   # differentiate the polynomial (columns: highest power first)
        p = p[:-deriv].copy() if n > deriv else np.zeros_like(p[:1])
        for k in range(deriv if n > deriv else 0):
            p *= np.arange(n - k - 1, deriv - k - 1, -1, dtype=p.dtype).reshape(-1, 1)
    t = np.arange(interp_start - start, interp_stop - start, dtype=p.dtype).reshape(-1, 1)
    values = np.zeros_like(t)
    for j in range(p.shape[0]):
        values = values * t + p[j, ...]
    y[interp_start:interp_stop] = (values / (delta ** deriv)).reshape(-1)


def savgol_derivative(x: np.ndarray, window: int, order: int, delta: float,
                      deriv: int = 1) -> np.ndarray:
    """``scipy.signal.savgol_filter(x, window, order, deriv, delta, mode="interp")`` of
    a 1-D float array, ``window`` odd and at most ``len(x)``."""
    x = np.asarray(x, dtype=np.float64)
    if window % 2 == 0 or not order < window <= len(x):
        raise ValueError("window must be odd, above the order and at most len(x)")
    y = convolve1d(x, savgol_coeffs(window, order, deriv, delta), mode="constant")
    half, n = window // 2, len(x)
    _fit_edge(x, 0, window, 0, half, order, deriv, delta, y)
    _fit_edge(x, n - window, n, n - half, n, order, deriv, delta, y)
    return y
