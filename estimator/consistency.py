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
