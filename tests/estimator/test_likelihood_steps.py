"""The likelihood off the scenario's grid (``tuning.intervals``: each step its own Φ, Γ
and Q_d(θ) = Q_fixed(Δt) + Σ θ_j U_j(Δt)) against independent references:

- ν and S against the production filter's per-step path (``kalman.kalman_filter`` with
  a ``linear.steps.StepTable`` of the whole ``ProcessNoise`` θ sets, its Q_d from the
  closed form at once, not as a sum of units), and ln L against the sum of the
  Gaussian terms of those ν and S;
- the hand-derived score and information against CasADi's AD of the whole step, and
  the score against central differences of ``evaluate``.

The record is test_likelihood's (the linear model's telemetry with dropouts, a yaw
gap, inputs and bridged-dropout noise), re-tagged at 0.512 s ± 20 ms to the
millisecond, as a ground system's clock would tag it, with 400 rows (205 s) cut out.
"""

from __future__ import annotations

import numpy as np
import pytest

from estimator.kalman.filter import ExtraNoise, kalman_filter
from estimator.linear.steps import StepTable, step_intervals
from estimator.tuning.intervals import step_noise
from estimator.tuning.likelihood import Likelihood, noise_model

from . import test_likelihood as on_grid
from .lik_helpers import DT, P0, PARAMS, R_ROLL, measurements, noise_at
from .test_likelihood import CASES, FIXED, N, terms_scale, theta_points

record = on_grid.record      # test_likelihood's record (fixture), drawn once for this module

KEEP = np.r_[0:2000, 2400:N]


@pytest.fixture(scope="module")
def times() -> np.ndarray:
    rng = np.random.default_rng(43)
    return np.round(np.arange(N) * DT + rng.uniform(-0.02, 0.02, N), 3)[KEEP]


def off_grid(record, times, groups, roll) -> Likelihood:
    model = noise_model(PARAMS, DT, groups, FIXED, roll)
    meas = measurements(record["z"][KEEP], var_yaw=record["var_yaw"][KEEP])
    return Likelihood(meas, step_noise(PARAMS, times, groups, FIXED), record["x0"], P0, model,
                      u=record["u"][KEEP], bridge_noise=record["e"][KEEP])


@pytest.mark.parametrize("case", list(CASES))
def test_off_grid_innovations_and_loglik_are_the_per_step_filters(record, times, case):
    """At θ moved off the data's noise, ν and S equal those of ``kalman_filter`` stepping
    each sample over its own interval with the noise θ sets (roll variance scaled,
    ``ExtraNoise`` of max(e − q_w, 0), whose unit Q_d the per-step path takes per
    interval), and ln L is −½ Σ (ln 2πS + ν²/S) of them.

    Tolerance: the likelihood takes the intervals to 1 ns (``intervals.RESOLUTION_S``)
    where the filter takes the float differences of the tags (~1e-13 s apart here), and
    sums Q_d from units; both move ν by ~1e-13 √S.  Measured ≤ 1.3e-13 √S for ν, 4e-15
    for S; bound 1e-9.  A step given the nominal interval in place of its own, or Q_d
    without Σ θ_j U_j, moves ν by far more than that."""
    groups, roll = CASES[case]
    lik = off_grid(record, times, groups, roll)
    theta = theta_points(groups, roll)[1]
    nu, S = lik.innovations(theta)
    q = noise_at(groups, FIXED, theta)
    meas = measurements(record["z"][KEEP], var_roll=R_ROLL * (theta[-1] if roll else 1.0),
                        var_yaw=record["var_yaw"][KEEP])
    extra = ExtraNoise(np.maximum(record["e"][KEEP] - q.q_w, 0.0), np.zeros((9, 9)))
    res = kalman_filter(meas, StepTable(PARAMS, q, step_intervals(times)), record["x0"], P0,
                        u=record["u"][KEEP], extra=extra)
    ok = np.isfinite(res.innovations)
    assert np.array_equal(ok, np.isfinite(nu))
    assert np.abs(nu[ok] - res.innovations[ok]).max() <= 1e-9 * np.sqrt(S[ok]).min()
    assert np.abs(S[ok] / res.innovation_var[ok] - 1).max() <= 1e-9
    ll = -0.5 * np.sum(np.log(2 * np.pi * res.innovation_var[ok])
                       + res.innovations[ok] ** 2 / res.innovation_var[ok])
    assert lik.evaluate(theta).loglik == pytest.approx(ll, rel=1e-12)


@pytest.mark.parametrize("case", ["xz_tied+w+cz+roll", "x+2z, w, px"])
def test_off_grid_score_is_the_derivative_of_the_likelihood(record, times, case):
    """Off the grid, the derived score and information equal CasADi's AD of the whole
    per-step step (bound 1e-10 of √I_jj, as on the grid; measured ≤ 1e-13), and the
    score in ln θ equals Richardson-extrapolated central differences of ``evaluate``
    (test_likelihood's bound: 1e-6 √I_jj in ln θ plus 2δ/h of rounding).  A direction
    given the nominal interval's unit Q_d in place of each step's would fail both."""
    groups, roll = CASES[case]
    lik = off_grid(record, times, groups, roll)
    h = 1e-3
    for theta in theta_points(groups, roll):
        d, a = lik.score(theta), lik.score(theta, derived=False)
        root = np.sqrt(np.diag(a.fisher))
        assert np.all(np.abs(d.score - a.score) <= 1e-10 * root), (d.score, a.score)
        assert np.abs((d.fisher - a.fisher) / np.outer(root, root)).max() <= 1e-10
        nu, S = lik.innovations(theta)
        rounding = 1e-14 * terms_scale(S, nu)
        for j in range(len(theta)):
            def at(step, j=j, theta=theta):
                t = theta.copy()
                t[j] *= np.exp(step)
                return lik.evaluate(t).loglik
            fd = (4 * (at(h) - at(-h)) / (2 * h) - (at(2 * h) - at(-2 * h)) / (4 * h)) / 3
            tol = 1e-6 * root[j] * theta[j] + 2 * rounding / h
            assert abs(d.score[j] * theta[j] - fd) <= tol, (case, j, d.score[j] * theta[j], fd)
