"""The sums `dynprop tune`'s diagnostics take over a whole innovation series, fed a
block at a time (``tuning.samples``): ``PairwiseSum`` is ``np.sum`` of the whole
series bit for bit, however it is cut; ``LaggedProducts`` is
``consistency.autocorrelation`` exactly for a series of one piece, and to rounding
for longer ones.  Planted off-by-ones these were seen failing on: the pairwise split
not rounded to a multiple of 8; a piece's look-ahead one row short."""

from __future__ import annotations

import numpy as np
import pytest

from estimator.kalman.consistency import autocorrelation
from estimator.tuning.samples import LaggedProducts, PairwiseSum


def _pieces(n: int, rng) -> list[tuple[int, int]]:
    """[a, b) pieces of 0 … n of random sizes, from 1 row to a few thousand."""
    cuts = np.unique(np.r_[0, rng.integers(1, n, size=max(n // 900, 1)), n])
    return list(zip(cuts[:-1], cuts[1:], strict=True))


@pytest.mark.parametrize("n", [0, 7, 128, 1000, 65_537, 300_001])
def test_pairwise_sum_is_numpys_sum_of_the_whole_series_bit_for_bit(n):
    """Positive numbers over ten decades (ν²/S and ln 2πS + ν²/S are of this kind), where
    a sum in another order differs in the last bits (checked: the plain running sum
    does), fed in random pieces, with leaves of 256 so the tree has many levels."""
    rng = np.random.default_rng(n)
    x = rng.chisquare(1, n) * 10.0 ** rng.uniform(-5, 5, n)
    acc = PairwiseSum(n, leaf=256)
    for a, b in _pieces(n, rng) if n else []:
        acc.add(x[a:b])
    assert acc.total() == np.sum(x)
    if n >= 65_537:
        assert float(np.cumsum(x)[-1]) != np.sum(x)    # the order matters here


def test_pairwise_sum_refuses_a_short_series():
    acc = PairwiseSum(10)
    acc.add(np.ones(9))
    with pytest.raises(ValueError, match="fed 9 numbers of 10"):
        acc.total()


def _series(n: int, rng) -> np.ndarray:
    """Three standardised-innovation-like columns: AR(1) (ρ = 0.3), NaN in gaps and
    at every other sample of one (``autocorrelation``'s pairs then vary by lag)."""
    e = rng.standard_normal((n, 3))
    for k in range(1, n):
        e[k] += 0.3 * e[k - 1]
    e[n // 3:n // 3 + 5000, 1] = np.nan
    e[::2, 2] = np.nan
    e[rng.random(n) < 0.01, 0] = np.nan
    return e


@pytest.mark.parametrize("span", [3_000, 40_000])
def test_lagged_products_are_autocorrelations(span):
    """ρ(k) and the pairs of each column against ``autocorrelation`` of the whole
    column: equal bit for bit when the series is one piece (span ≥ n), else to 1e-14
    (ρ(0) = 1; the FFTs' rounding is ~1e-16 of Σ x²), the pairs exactly, fed in random
    pieces of 1 to thousands of rows."""
    n, lag = 30_000, 1172
    rng = np.random.default_rng(span)
    e = _series(n, rng)
    ok = np.isfinite(e)
    acc = LaggedProducts(n, lag, 3, span)
    for a, b in _pieces(n, rng):
        acc.add(np.where(ok[a:b], e[a:b], 0.0), ok[a:b])
    rho, pairs = acc.rho()
    for j in range(3):
        ref, ref_pairs = autocorrelation(e[:, j], lag)
        np.testing.assert_array_equal(pairs[:, j], ref_pairs)
        if span >= n:
            np.testing.assert_array_equal(rho[:, j], ref)
        else:
            np.testing.assert_allclose(rho[:, j], ref, rtol=0, atol=1e-14)
