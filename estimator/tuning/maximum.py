"""Noise parameters by maximum likelihood on the filter's own innovations.

θ (process-noise spectral densities, and optionally a factor on the roll
variance) is fitted in log space, λ = ln θ, where the likelihood is close to
quadratic and every θ stays positive.  The maximiser is Fisher scoring with
Levenberg–Marquardt damping and box bounds (Gupta & Mehra 1974, the standard for
state-space noise identification): each iteration is one compiled score pass
(``likelihood.Likelihood.score``), which gives ln L, its gradient and the expected
information together, so Newton-like steps cost one filter pass each and no
finite-difference passes are needed.  A quasi-Newton method (scipy's L-BFGS-B
with the same gradient) reaches the same optimum in three to five times as many
passes; the tests hold the two to each other.

Uncertainty: the inverse Fisher information of the free parameters gives σ of
ln θ (a σ of 0.1 is a 10% σ of θ; by the delta method σ_θ = θ σ_λ).  A parameter
the telemetry does not determine (σ_λ > ``DETERMINED_SIGMA``, or at a bound) gets
one-sided 95% limits from the likelihood along it instead (``nearest_allowed``):
where ln L has fallen by χ²₁(0.90)/2 = 1.35 from its maximum.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .likelihood import Evaluation, Likelihood

DETERMINED_SIGMA = 1.0      # σ of ln θ above which θ is not determined (a factor e)
WEAK_SIGMA = 3.0            # σ of ln θ above which the telemetry hardly informs θ
STEEP = 0.5                 # |∂ln L/∂ln θ| above which θ is climbed all the same
LIMIT_DROP = 1.3528   # χ²₁(0.90)/2: a one-sided 95% limit


@dataclass(frozen=True)
class Fit:
    """The maximum-likelihood θ and how it was reached."""

    theta: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    best: Evaluation               # score pass at θ (ln L, gradient, information)
    start: Evaluation              # score pass at the starting θ
    iterations: int
    converged: bool
    passes: dict[str, int]
    path: list[tuple[np.ndarray, float]] = field(default_factory=list)

    @property
    def log_gradient(self) -> np.ndarray:
        return self.best.score * self.theta

    @property
    def log_fisher(self) -> np.ndarray:
        return self.best.fisher * np.outer(self.theta, self.theta)

    @property
    def at_bound(self) -> np.ndarray:
        """−1 at the lower bound, +1 at the upper, 0 inside."""
        lam = np.log(self.theta)
        return np.where(lam <= np.log(self.lower) + 1e-9, -1,
                        np.where(lam >= np.log(self.upper) - 1e-9, 1, 0))

    @property
    def covariance_log(self) -> np.ndarray:
        """Covariance of ln θ from the inverse information; rows of parameters at a
        bound, or without information, are NaN (no symmetric σ exists there)."""
        n = len(self.theta)
        F = self.log_fisher
        free = (self.at_bound == 0) & (np.diag(F) > 0)
        cov = np.full((n, n), np.nan)
        if free.any():
            sub = F[np.ix_(free, free)]
            scale = np.sqrt(np.diag(sub))
            inv = np.linalg.pinv(sub / np.outer(scale, scale), rcond=1e-12)
            cov[np.ix_(free, free)] = inv / np.outer(scale, scale)
        return cov

    @property
    def sigma_log(self) -> np.ndarray:
        return np.sqrt(np.diag(self.covariance_log))

    @property
    def determined(self) -> np.ndarray:
        s = self.sigma_log
        return np.isfinite(s) & (s <= DETERMINED_SIGMA)


RIDGE = 0.1   # scale-metric floor: a direction without information moves like one of σ = 3
MAX_RADIUS = 12.0   # a factor e¹² = 1.6e5 in one step
FAR_GAIN = 5.0      # a predicted gain in ln L above which longer steps are tried


STEP_IN_SIGMA = 0.1   # converged once the next step is within 0.1 σ in every ln θ


def _within_sigma(step: np.ndarray, F: np.ndarray) -> bool:
    """The step moves no parameter by more than ``STEP_IN_SIGMA`` of its own σ (from
    the information): what remains is below the estimate's
    uncertainty in every coordinate, though ln L may still creep up along
    parameters the telemetry hardly determines."""
    cov = np.linalg.pinv(F + np.diag(1e-6 * np.ones(len(F))), rcond=1e-12, hermitian=True)
    sigma = np.sqrt(np.maximum(np.diag(cov), 1e-300))
    return bool(np.all(np.abs(step) <= STEP_IN_SIGMA * sigma))


def _stalled(path, tol: float, steps: int = 3) -> bool:
    """The last ``steps`` accepted steps together gained less than 5 ``tol``: the
    likelihood is flat where the optimiser walks (parameters the data hardly see)."""
    return len(path) > steps and path[-1][1] - path[-1 - steps][1] < 5 * tol


def _lm_step(g, F, lam, lo, hi, radius: float) -> tuple[np.ndarray, float]:
    """The Levenberg–Marquardt step in ln θ: (F + μ D) Δ = g with D = diag F + ridge,
    μ ≥ 0 the smallest (by factors of 4) that keeps |Δ|∞ ≤ ``radius``, parameters that
    would leave their bounds held at them (and the rest solved again).  Returns Δ and
    its predicted gain gᵀΔ − ½ΔᵀFΔ, positive for F positive semi-definite."""
    n = len(g)
    fixed = ((lam <= lo + 1e-9) & (g < 0)) | ((lam >= hi - 1e-9) & (g > 0))
    D = np.maximum(np.diag(F), 0.0) + RIDGE
    step = np.zeros(n)
    for _ in range(2):   # once more if a bound is hit
        free = ~fixed
        if not free.any():
            break
        rhs = g[free] - F[np.ix_(free, fixed)] @ step[fixed]
        A = F[np.ix_(free, free)]
        mu = 0.0
        while True:
            d = np.linalg.solve(A + np.diag((mu + 1e-12) * D[free]), rhs)
            if np.abs(d).max() <= radius or mu > 1e12:
                break
            mu = max(4 * mu, 1e-4)
        step[free] = d
        new = np.clip(lam + step, lo, hi)
        hit = (new != lam + step) & free
        step = new - lam
        if not hit.any():
            break
        fixed |= hit
    return step, float(g @ step - 0.5 * step @ F @ step)


def _informative(ev: Evaluation, lam, lo, hi) -> np.ndarray:
    """Indices of the parameters a full score pass says the telemetry informs (σ of
    ln θ ≤ ``WEAK_SIGMA``) or pulls (|∂ln L/∂ln θ| ≥ ``STEEP``), and that are free to
    move (not pressed against a bound)."""
    theta = np.exp(lam)
    g, F = ev.score * theta, ev.fisher * np.outer(theta, theta)
    blocked = ((lam <= lo + 1e-9) & (g < 0)) | ((lam >= hi - 1e-9) & (g > 0))
    cov = np.linalg.pinv(F + np.diag(1e-9 * np.ones(len(F))), rcond=1e-12, hermitian=True)
    sigma = np.sqrt(np.maximum(np.diag(cov), 0.0))
    # Also one whose σ is large but whose slope is steep: ln L still climbs along it by
    # more than half a unit per factor e, towards where the telemetry will inform it.
    return np.flatnonzero(((sigma <= WEAK_SIGMA) | (np.abs(g) >= STEEP)) & ~blocked)


def maximize(lik: Likelihood, theta0, lower, upper, *, tol: float = 0.05,
             max_iter: int = 40, radius: float = 3.0) -> Fit:
    """Maximise ln L over lower ≤ θ ≤ upper from θ0 (clipped into the bounds).

    In cycles: a score pass with every parameter's gradient and information picks
    those the telemetry informs (σ of ln θ ≤ ``WEAK_SIGMA``), and a trust-region
    scoring method in ln θ climbs in those alone, each of its score passes costing
    only their few directions; then a full pass again, until it finds nothing left to
    climb.  A parameter the telemetry leaves undetermined stays where it was: its
    maximum is not worth the passes, and ``upper_limit`` says what the telemetry
    allows of it.  Each step is tried with a plain likelihood pass first (and, while
    the model holds, twice and four times as far), and only where ln L rose is a
    score pass taken there.  A cycle stops when the predicted gain of its next step,
    gᵀΔ − ½ΔᵀIΔ, is below ``tol``, when that step moves no parameter by more than
    ``STEP_IN_SIGMA`` of its σ, or when its last steps gained next to nothing."""
    lo, hi = np.log(np.asarray(lower, float)), np.log(np.asarray(upper, float))
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.all(lo < hi)):
        raise ValueError("bounds must be positive, finite and lower < upper")
    lam = np.clip(np.log(np.maximum(np.asarray(theta0, float), 1e-300)), lo, hi)
    ev = start = lik.score(np.exp(lam))
    passes = {"score": 1, "likelihood": 0, "directions": len(lam)}
    path = [(np.exp(lam), ev.loglik)]
    converged, it, cycles = False, 0, 0
    active = _informative(ev, lam, lo, hi)
    while cycles < 4:
        cycles += 1
        sub = ev     # the score pass of the active parameters at lam
        if len(active) == 0:
            converged = True
            break
        if sub.subset is None or not np.array_equal(sub.subset, active):
            sub = _restrict(ev, active)
        moved = False
        while it < max_iter:
            it += 1
            theta = np.exp(lam[active])
            g, F = sub.score * theta, sub.fisher * np.outer(theta, theta)
            step, predicted = _lm_step(g, F, lam[active], lo[active], hi[active], radius)
            if predicted < tol or _within_sigma(step, F) or _stalled(path, tol):
                break
            trial = lik.evaluate(np.exp(_with(lam, active, step)))
            passes["likelihood"] += 1
            rho = (trial.loglik - sub.loglik) / predicted
            if rho > 0.75 and predicted > FAR_GAIN:
                # Far from the maximum and the model holds out to the step: try twice
                # as far along it, and again, before paying for a score pass (the
                # start is often many factors of e from the optimum, and the expected
                # information overstates the curvature where a noise parameter heads
                # for zero).  Near the maximum it would only cost passes.
                direction = step
                for scale in (2.0, 4.0, 8.0):
                    longer = np.clip(lam[active] + scale * direction, lo[active],
                                     hi[active]) - lam[active]
                    if np.abs(longer).max() > MAX_RADIUS or np.allclose(longer, step):
                        break
                    further = lik.evaluate(np.exp(_with(lam, active, longer)))
                    passes["likelihood"] += 1
                    if further.loglik <= trial.loglik:
                        break
                    step, trial = longer, further
                radius = min(max(radius, 2 * np.abs(step).max()), MAX_RADIUS)
            elif rho < 0.25:
                radius = radius / 4
            elif rho > 0.75:
                radius = min(max(radius, 2 * np.abs(step).max()), MAX_RADIUS)
            if trial.loglik > sub.loglik:
                lam = _with(lam, active, step)
                sub = lik.score(np.exp(lam), active)
                passes["score"] += 1
                passes["directions"] += len(active)
                path.append((np.exp(lam), sub.loglik))
                moved = True
            elif radius < 1e-4:
                break
        if not moved and ev.subset is not None and len(ev.subset) == len(lam) \
                and np.array_equal(ev.theta, np.exp(lam)):
            converged = it < max_iter
            break
        ev = lik.score(np.exp(lam))       # every parameter again, at the new point
        passes["score"] += 1
        passes["directions"] += len(lam)
        new_active = _informative(ev, lam, lo, hi)
        if not moved and np.array_equal(new_active, active):
            converged = it < max_iter
            break
        active = new_active
    lower, upper = np.asarray(lower, float), np.asarray(upper, float)
    # At a bound, the bound itself (exp(ln b) is b only to the last bit or two).
    theta = np.where(lam <= lo, lower, np.where(lam >= hi, upper, np.exp(lam)))
    return Fit(theta, lower, upper, ev, start, it, converged, passes, path)


def _with(lam: np.ndarray, idx: np.ndarray, step: np.ndarray) -> np.ndarray:
    out = lam.copy()
    out[idx] += step
    return out


def _restrict(ev: Evaluation, idx: np.ndarray) -> Evaluation:
    """A full score pass's gradient and information cut to the parameters ``idx``."""
    return Evaluation(ev.theta, ev.loglik, ev.counts, ev.sum_log_S, ev.sum_nis,
                      ev.score[idx], ev.fisher[np.ix_(idx, idx)], idx)


def nearest_allowed(lik: Likelihood, fit: Fit, j: int, value: float,
                    drop: float = LIMIT_DROP, xtol: float = 0.7, max_passes: int = 10
                    ) -> tuple[float, bool, int]:
    """The θ_j nearest ``value`` (the scenario's) that the telemetry allows at 95%: where
    ln L, the others held at the fit, is within ``drop`` of its maximum.  Returns it,
    whether ``value`` itself is allowed (then it is the answer) and the likelihood
    passes taken.  Otherwise the boundary between the fit and ``value`` is found to
    ``xtol`` in ln θ (a factor 2, precision enough for a limit): a one-sided 95% limit,
    upper if ``value`` lies above the fit.  The search runs on ln(fall of ln L), which
    is close to straight in ln θ (far from the fit the fall grows like θ itself), by
    secant steps kept inside a bracket, so it takes three or four passes where
    bisection over twenty factors of e would take eight.  A slice, not a re-optimised
    profile: for a parameter the telemetry hardly informs the two differ little."""
    best = fit.best.loglik
    base = fit.theta.copy()
    passes = 0

    def fall(lam: float) -> float:
        nonlocal passes
        passes += 1
        t = base.copy()
        t[j] = np.exp(lam)
        return best - lik.evaluate(t).loglik

    lam_v, lam_fit = np.log(value), np.log(fit.theta[j])
    if value <= 0:
        return value, True, passes
    f_v = fall(lam_v)
    if f_v <= drop:
        return value, True, passes
    # Bracket [inside, outside]: ln L has fallen by less than ``drop`` at the first.
    inside, outside = (lam_fit, 0.0), (lam_v, f_v)
    while passes < max_passes and abs(outside[0] - inside[0]) > xtol:
        (a, fa), (b, fb) = inside, outside
        if fa > 1e-3 * drop:      # secant on ln(fall) through both ends
            guess = a + (b - a) * np.log(drop / fa) / np.log(fb / fa)
        else:                     # straight from the outside end, fall ∝ θ
            guess = b - np.log(fb / drop)
        lo, hi = min(a, b), max(a, b)
        guess = float(np.clip(guess, lo + 0.1 * (hi - lo), hi - 0.1 * (hi - lo)))
        f = fall(guess)
        if f <= drop:
            inside = (guess, f)
        else:
            outside = (guess, f)
    return float(np.exp(inside[0])), False, passes


def profile(lik: Likelihood, fit: Fit, j: int, offsets=(-2.0, -1.0, 1.0, 2.0)
            ) -> tuple[np.ndarray, np.ndarray]:
    """ln L along ln θ_j at the fit ± ``offsets`` σ, the other free parameters at
    their conditional optimum to second order (λ_o − I_oo⁻¹ I_oj Δ_j over the
    determined ones: the profile without re-optimising): returns θ_j and
    ln L − ln L_max."""
    lam = np.log(fit.theta)
    s = fit.sigma_log[j]
    F = fit.log_fisher
    others = fit.determined.copy()
    others[j] = False
    out_t, out_l = [], []
    for k in offsets:
        d = k * s
        t = lam.copy()
        t[j] += d
        if others.any():
            t[others] -= np.linalg.lstsq(F[np.ix_(others, others)], F[others, j] * d,
                                         rcond=1e-12)[0]
        t = np.clip(t, np.log(fit.lower), np.log(fit.upper))
        out_t.append(np.exp(t[j]))
        out_l.append(lik.evaluate(np.exp(t)).loglik - fit.best.loglik)
    return np.array(out_t), np.array(out_l)
