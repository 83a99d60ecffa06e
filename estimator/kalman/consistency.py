"""Filter consistency: NEES, NIS and their χ² bounds (Bar-Shalom, Li & Kirubarajan,
*Estimation with Applications to Tracking and Navigation*, 2001, section 5.4)."""

from __future__ import annotations

import numpy as np


def nees(x_hat: np.ndarray, P: np.ndarray, x_true: np.ndarray, states=None) -> np.ndarray:
    """Normalised estimation error squared e·P⁻¹e per sample, e = x̂ − x, over the
    chosen ``states`` (all by default); χ²(len(states)) for a consistent filter."""
    idx = np.arange(x_hat.shape[-1]) if states is None else np.asarray(states)
    e = (np.asarray(x_hat) - np.asarray(x_true))[..., idx]
    Ps = np.asarray(P)[..., idx[:, None], idx[None, :]]
    return np.einsum("...i,...i->...", e, np.linalg.solve(Ps, e[..., None])[..., 0])


def nis(innovations: np.ndarray, innovation_var: np.ndarray) -> np.ndarray:
    """ν²/S per scalar update (NaN where there was none); χ²(1) when consistent."""
    return np.asarray(innovations) ** 2 / np.asarray(innovation_var)


def chi2_bounds(dof: int, n_runs: int = 1, confidence: float = 0.95) -> tuple[float, float]:
    """Two-sided bounds on the average of ``n_runs`` independent χ²(dof) values:
    n·ε̄ ~ χ²(n·dof), so ε̄ lies in [χ²_{α/2}, χ²_{1−α/2}](n·dof)/n."""
    if not 0 < confidence < 1:
        raise ValueError("confidence must be in (0, 1)")
    alpha = 1.0 - confidence
    # χ²(k)'s quantile is 2·P⁻¹(k/2, q), P the regularised lower incomplete gamma
    # function: scipy.stats.chi2.ppf's own formula, without the 0.35 s import of
    # scipy.stats.
    from scipy.special import gammaincinv
    lo, hi = 2.0 * gammaincinv(n_runs * dof / 2, np.array([alpha / 2, 1 - alpha / 2]))
    return float(lo / n_runs), float(hi / n_runs)


def fraction_inside(values: np.ndarray, bounds: tuple[float, float]) -> float:
    """Share of finite ``values`` within ``bounds``."""
    v = np.asarray(values)
    v = v[np.isfinite(v)]
    return float(np.mean((v >= bounds[0]) & (v <= bounds[1]))) if v.size else float("nan")


def autocorrelation(e: np.ndarray, max_lag: int) -> tuple[np.ndarray, np.ndarray]:
    """Normalised autocorrelation ρ(k), k = 0 … max_lag, of a series with gaps (NaN):
    the mean of e_t e_{t+k} over the pairs where both are present, over the mean of
    e_t² (Box–Jenkins, for a series of zero mean: the standardised innovations ν/√S of
    a consistent filter).  Returns ρ and the number of pairs at each lag.  White, ρ(k)
    for k ≥ 1 lies within ±1.96/√pairs 95% of the time."""
    e = np.asarray(e, dtype=float)
    present = np.isfinite(e)
    x = np.where(present, e, 0.0)
    n = len(x)
    size = 1 << int(np.ceil(np.log2(2 * n)))   # no wrap-around: zero-padded FFT
    fx = np.fft.rfft(x, size)
    fm = np.fft.rfft(present.astype(float), size)
    sums = np.fft.irfft(fx * np.conj(fx), size)[:max_lag + 1]
    pairs = np.rint(np.fft.irfft(fm * np.conj(fm), size)[:max_lag + 1])
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = sums / pairs
    return mean / mean[0], pairs.astype(np.int64)


def whiteness(e: np.ndarray, max_lag: int) -> dict:
    """How white a standardised innovation series is: ρ(k) for k = 1 … max_lag against
    ±1.96/√pairs; the share of lags outside (about 5% for a white series), the largest
    |ρ|, and ρ at the first lag with 30 pairs (``rho_1``, at lag ``first_lag``: 1 for
    an update every sample; 2 for telemetry at every other sample, whose lag 1 has no
    pair at all).  None where there are too few samples to judge."""
    return whiteness_of(*autocorrelation(e, max_lag))


def whiteness_of(rho: np.ndarray, pairs: np.ndarray) -> dict:
    """``whiteness`` from the autocorrelation ρ(k) and its pairs at each lag."""
    ok = pairs[1:] >= 30
    if not ok.any():
        return {"lags": 0, "fraction_outside": None, "max_abs_rho": None, "rho_1": None,
                "first_lag": None}
    r, bound = rho[1:][ok], 1.96 / np.sqrt(pairs[1:][ok])
    first = int(np.argmax(ok)) + 1
    return {"lags": int(ok.sum()), "fraction_outside": float(np.mean(np.abs(r) > bound)),
            "max_abs_rho": float(np.abs(r).max()), "rho_1": float(rho[first]),
            "first_lag": first}
