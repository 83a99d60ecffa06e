"""The filter's innovations at one noise setting, as `dynprop tune` reports them before
and after the fit (tune.json's ``before``/``after``, tune.png): NIS per measurement
kind against its χ² bounds, whiteness of the standardised innovations ν/√S, their
autocorrelation and the mean NIS per hour, taken a block of samples at a time
(``Likelihood.innovation_blocks``), so a month of telemetry never holds its
innovations whole.  The sums are the whole series' to the last bit (``PairwiseSum``;
the hours' sums are each hour's own), but for the autocorrelation of a series longer
than ``span`` samples (``LaggedProducts``: rounding, ~1e-16 of ρ(0))."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from dynprop.estimator.kalman.consistency import chi2_bounds, whiteness_of
from dynprop.estimator.tuning.samples import LaggedProducts, PairwiseSum

MAX_LAG_S = 600.0            # innovation autocorrelation to this lag
KINDS = ("roll", "yaw", "h")


@dataclass(frozen=True)
class Diagnostics:
    """The filter's innovations at one noise setting: NIS per measurement kind against
    its χ² bounds, and whiteness of the standardised innovations."""

    loglik: float
    nis: dict
    whiteness: dict
    rho: dict                      # kind -> ρ(k), k = 0 … max lag
    hourly_nis: dict               # kind -> (hours, mean NIS per hour)
    sigma_yaw_deg: dict


class _GridHours:
    """Σ NIS and the updates of each whole hour of ``per_hour`` samples on the grid (a
    last partial hour left out), as a reshape of the whole series sums them."""

    def __init__(self, per_hour: int):
        self.per_hour = per_hour
        self.rest = (np.zeros((0, 3)), np.zeros((0, 3), dtype=bool))
        self.total, self.count = [], []

    def add(self, sq, ok, t=None) -> None:
        sq, ok = (np.concatenate([a, b]) for a, b in zip(self.rest, (sq, ok), strict=True))
        m = len(sq) // self.per_hour * self.per_hour
        for i in range(3):   # each kind's own contiguous series, as the whole one
            self.total.append(np.ascontiguousarray(sq[:m, i]).reshape(-1, self.per_hour)
                              .sum(axis=1))
            self.count.append(np.ascontiguousarray(ok[:m, i]).reshape(-1, self.per_hour)
                              .sum(axis=1))
        self.rest = sq[m:], ok[m:]

    def sums(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        return (np.concatenate(self.count[i::3] or [np.zeros(0)]),
                np.concatenate(self.total[i::3] or [np.zeros(0)]))


class _OwnHours:
    """The same off the grid: whole hours from the first sample's time, the last
    (partial) hour left out, summed in order as ``np.bincount`` sums the whole series
    (an hour split across blocks carries its partial sum into the next block's count
    as its first weight: 0 + s + w … is the whole series' s + w …)."""

    def __init__(self, t0: float, t_last: float):
        self.t0 = t0
        self.last = int((t_last - t0) // 3600)
        self.done = [[[], []] for _ in range(3)]      # per kind: counts, totals
        self.carry = [None] * 3

    def add(self, sq, ok, t) -> None:
        hour = ((t - self.t0) // 3600).astype(np.int64)
        whole = hour < self.last if self.last > 0 else np.ones(len(hour), bool)
        hour = hour[whole]
        if not len(hour):
            return
        for i in range(3):
            weights = (ok[whole, i].astype(float), sq[whole, i])
            base, h = 0, hour
            if self.carry[i] is not None:
                base, carried = self.carry[i]
                h = np.r_[base, hour]
                weights = tuple(np.r_[c, w] for c, w in zip(carried, weights, strict=True))
            sums = [np.bincount(h - base, weights=w) for w in weights]
            for j in range(2):
                self.done[i][j].extend(sums[j][:-1])
            self.carry[i] = (base + len(sums[0]) - 1, (sums[0][-1], sums[1][-1]))

    def sums(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        cnt, tot = (list(v) for v in self.done[i])
        if self.carry[i] is not None:
            cnt.append(self.carry[i][1][0])
            tot.append(self.carry[i][1][1])
        return np.array(cnt, dtype=float), np.array(tot, dtype=float)


def innovation_diagnostics(lik, theta, src, sigma_yaw_deg: dict) -> Diagnostics:
    """``Diagnostics`` of the likelihood ``lik``'s filter at θ over the source ``src``
    (a ``source.TuneSource`` or ``streamed.StreamedSource``)."""
    # Off the grid, lags in samples at the median cadence (a gap's rows are not there).
    dt = src.cadence_s
    lags = int(round(MAX_LAG_S / dt))
    counts = lik.counts.astype(np.int64)
    nis_sums = [PairwiseSum(c) for c in counts]
    ll_sum = PairwiseSum(int(counts.sum()))
    lagged = LaggedProducts(lik.n_samples, lags, 3, src.span)
    hours = (_GridHours(int(round(3600 / dt))) if src.regular else
             _OwnHours(src.t_first, src.t_last))
    for start, nu, S in lik.innovation_blocks(theta):
        e = nu / np.sqrt(S)
        ok = np.isfinite(e)
        for i in range(3):
            nis_sums[i].add(e[ok[:, i], i] ** 2)
        present = np.isfinite(nu)
        ll_sum.add(np.log(2 * np.pi * S[present]) + nu[present] ** 2 / S[present])
        lagged.add(np.where(ok, e, 0.0), ok)
        t = None if src.regular else src.times(start, start + len(nu))
        hours.add(np.where(ok, e**2, 0.0), ok, t)
    rho_all, pairs = lagged.rho()
    nis, white, rho, hourly = {}, {}, {}, {}
    for i, kind in enumerate(KINDS):
        n = int(counts[i])
        mean = nis_sums[i].total() / n if n else None
        nis[kind] = {"mean": mean, "updates": n,
                     "bounds": list(chi2_bounds(1, n)) if n else None,
                     "inside": None if not n else bool(chi2_bounds(1, n)[0] <= mean
                                                       <= chi2_bounds(1, n)[1])}
        white[kind] = whiteness_of(rho_all[:, i], pairs[:, i])
        rho[kind] = rho_all[:, i]
        cnt, total = hours.sums(i)
        with np.errstate(invalid="ignore", divide="ignore"):
            hourly[kind] = (np.arange(len(cnt)) + 0.5, np.where(cnt > 0, total / cnt, np.nan))
    return Diagnostics(-0.5 * ll_sum.total(), nis, white, rho, hourly, sigma_yaw_deg)
