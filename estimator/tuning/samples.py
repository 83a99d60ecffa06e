"""The samples a likelihood pass reads, a block at a time (issue 44: telemetry of any
length): ``Samples`` is what ``likelihood.Likelihood`` asks of them, the step's
inputs of samples [start, stop) and, off the scenario's grid, their step intervals.
``ArraySamples`` holds them whole (a filter run's arrays); a caller with a longer
record gives its own, read from where it keeps them (`dynprop tune`'s scratch file).

A pass carries the filter's state from block to block exactly, so the blocks change
no number: ln L, its score and the innovations are those of one pass over all.

``PairwiseSum`` and ``LaggedProducts`` are the sums the innovations' diagnostics
take over a whole series, fed a block at a time.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from ..kalman.filter import Measurements, _inputs


class Samples(Protocol):
    """The filter's samples as the likelihood's step reads them."""

    n: int
    counts: np.ndarray      # present updates per kind (roll, yaw, h), as floats

    def block(self, start: int, stop: int) -> tuple[list[np.ndarray], np.ndarray | None]:
        """The step's inputs of samples [start, stop): z (NaN as 0), the update mask m,
        the variances r (each (k, 3)), ū (k, 9) and the raw bridge noise e (k,); and
        off the grid each step's interval (``intervals.intervals``), else None."""


def step_inputs(meas: Measurements, u, bridge_noise) -> list[np.ndarray]:
    """The step's inputs of whole ``Measurements``, ū and bridge noise (``Samples.block``)."""
    z, r = meas.z(), meas.r()
    n = len(z)
    present = np.isfinite(z)
    e = np.zeros(n) if bridge_noise is None else np.asarray(bridge_noise, dtype=float)
    if e.shape != (n,) or not np.all(np.isfinite(e) & (e >= 0)):
        raise ValueError(f"bridge noise must be ({n},), finite and non-negative")
    return [np.where(present, z, 0.0), present.astype(float), r, _inputs(u, n), e]


class ArraySamples:
    """``Samples`` held whole: a filter run's measurements, inputs ū and bridge noise,
    and off the grid the step intervals ``dt`` (one per sample)."""

    def __init__(self, meas: Measurements, u=None, bridge_noise=None, dt=None):
        self.inputs = step_inputs(meas, u, bridge_noise)
        self.n = len(self.inputs[0])
        self.counts = self.inputs[1].sum(axis=0)
        self.dt = dt

    def block(self, start: int, stop: int) -> tuple[list[np.ndarray], np.ndarray | None]:
        return ([a[start:stop] for a in self.inputs],
                None if self.dt is None else self.dt[start:stop])


def distinct_intervals(samples: Samples, block: int) -> np.ndarray:
    """The distinct step intervals of samples off the grid, sorted (``np.unique`` of
    them all), a block at a time."""
    seen = np.zeros(0)
    for start in range(0, samples.n, block):
        _, dt = samples.block(start, min(start + block, samples.n))
        seen = np.union1d(seen, dt)
    return seen


class PairwiseSum:
    """``np.sum`` of a series of known length ``n`` fed in pieces of any size, to the
    last bit: numpy sums a contiguous array pairwise (halves rounded down to a multiple
    of 8, down to 128 or fewer numbers); each node of that tree small enough is summed
    by numpy itself as it fills, and the nodes are added as numpy adds them.  Holds at
    most ``leaf`` numbers."""

    def __init__(self, n: int, leaf: int = 1 << 16):
        self.n, self.leaf = int(n), leaf
        self._spans = list(self._leaves(0, self.n)) if self.n else []
        self._sums: list[float] = []
        self._buf: list[np.ndarray] = []
        self._held = 0

    def _leaves(self, lo: int, n: int):
        if n <= self.leaf:
            yield n
            return
        n2 = n // 2
        n2 -= n2 % 8
        yield from self._leaves(lo, n2)
        yield from self._leaves(lo + n2, n - n2)

    def add(self, values: np.ndarray) -> None:
        values = np.asarray(values, dtype=float).ravel()
        self._buf.append(values)
        self._held += len(values)
        k = len(self._sums)
        while k < len(self._spans) and self._held >= self._spans[k]:
            held = np.concatenate(self._buf)
            self._sums.append(np.add.reduce(held[:self._spans[k]]))
            self._buf, self._held = [held[self._spans[k]:]], self._held - self._spans[k]
            k += 1

    def total(self) -> float:
        if len(self._sums) != len(self._spans) or self._held:
            raise ValueError(f"fed {sum(self._spans[:len(self._sums)]) + self._held} numbers "
                             f"of {self.n}")
        if not self._spans:
            return 0.0        # np.sum of nothing
        sums = iter(self._sums)
        return float(self._combine(0, self.n, sums))

    def _combine(self, lo: int, n: int, sums):
        if n <= self.leaf:
            return next(sums)
        n2 = n // 2
        n2 -= n2 % 8
        return self._combine(lo, n2, sums) + self._combine(lo + n2, n - n2, sums)


class LaggedProducts:
    """Σ_t x_t x_{t+k} for k = 0 … ``max_lag`` of series (columns) with gaps (x = 0
    there), and the count of pairs where both are present, fed a block of rows at a
    time: ``consistency.autocorrelation``'s sums.  Computed as it does, by a
    zero-padded FFT, over pieces of ``span`` rows each with the ``max_lag`` rows after
    it; a series of at most ``span`` rows is one piece, that function's own FFT
    exactly.  Longer ones differ from its whole-series FFT by rounding (~1e-16 of
    Σ x², tests/estimator/test_likelihood_blocks.py)."""

    def __init__(self, n: int, max_lag: int, n_cols: int, span: int = 1 << 20):
        self.n, self.lag, self.span = int(n), int(max_lag), int(span)
        self.sums = np.zeros((self.lag + 1, n_cols))
        self.pairs = np.zeros((self.lag + 1, n_cols))
        self._x = np.zeros((0, n_cols))
        self._m = np.zeros((0, n_cols))
        self._done = 0

    def add(self, x: np.ndarray, present: np.ndarray) -> None:
        """Rows of the series (NaN-free, 0 where absent) and their presence."""
        self._x = np.concatenate([self._x, x])
        self._m = np.concatenate([self._m, present.astype(float)])
        end = self._done + len(self._x)
        while len(self._x) >= self.span + self.lag or (end == self.n and len(self._x)):
            k = min(self.span, len(self._x))
            self._piece(k)
            self._x, self._m = self._x[k:], self._m[k:]
            self._done += k

    def _piece(self, k: int) -> None:
        whole = self._done == 0 and k == len(self._x) and self._done + k == self.n
        for j in range(self.sums.shape[1]):
            for out, series in ((self.sums, np.ascontiguousarray(self._x[:, j])),
                                (self.pairs, np.ascontiguousarray(self._m[:, j]))):
                if whole:   # the whole series in one: autocorrelation's own FFT
                    size = 1 << int(np.ceil(np.log2(2 * k)))
                    f = np.fft.rfft(series, size)
                    out[:, j] += np.fft.irfft(f * np.conj(f), size)[:self.lag + 1]
                    continue
                seg = series[:k + self.lag]
                size = 1 << int(np.ceil(np.log2(k + len(seg))))
                f = np.fft.rfft(seg, size) * np.conj(np.fft.rfft(series[:k], size))
                out[:, j] += np.fft.irfft(f, size)[:self.lag + 1]

    def rho(self) -> tuple[np.ndarray, np.ndarray]:
        """ρ(k) and the pairs at each lag, per column (``autocorrelation``'s)."""
        if self._done != self.n:
            raise ValueError(f"fed {self._done + len(self._x)} rows of {self.n}")
        pairs = np.rint(self.pairs)
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = self.sums / pairs
        return mean / mean[0], pairs.astype(np.int64)
