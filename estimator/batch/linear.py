"""Batch least-squares attitude estimation: the alternative the paper's Section 5 sets
aside, built so it can be tested.

The solve-for vector is the paper's nine states at the batch epoch (Eq. 10: roll,
ṙ/ω_n, yaw, ẏ/ω_n, h, N_px, N_pz, N_cx, N_cz), fitted to the measurements the filter
uses (Earth-sensor roll, ground yaw with its per-sample variance, the tachometers'
h; Eq. 26) with an a priori (x̄, P̄) at the epoch:

    J(x_0) = Σ_k (z_k − h_k(x_0))ᵀ R_k⁻¹ (z_k − h_k(x_0)) + (x_0 − x̄)ᵀ P̄⁻¹ (x_0 − x̄).

There is no process noise: the model carries the state across the whole span, which
is the paper's point (a batch "must use at least one-third of an orbit ... the
dynamic models are not accurate enough to propagate across this interval without
accounting for process noise").  ``linear_batch`` minimises J for the paper's
linear model with the closed-form Φ (one weighted least-squares solve); the
nonlinear model's Gauss–Newton/Levenberg–Marquardt is ``batch.nonlinear``.  Both
share the normal-equation solve here (``solve_normal``): states without
information from the span (no yaw measurement: the constant yaw torque, Section 4)
are held at the a priori (``fixed``).

Consider covariance: P_c = P + S C Sᵀ, with S = ∂x̂/∂c the estimate's sensitivity
to consider parameters c of covariance C, the same data held (for the linear
model by central differences of the solve, ``consider_cases``).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import scipy.linalg

from ..kalman.filter import Measurements, _param_rows, kalman_filter
from ..kalman.steps import MEAS_STATES, N_UT, pack_params, unpack
from ..linear.model import N_STATES, NCZ, STATE_NAMES, ProcessNoise
from ..linear.steps import StepTable, roll_blocks
from ..linear.transition import Discretization


class BatchError(ValueError):
    """A batch that cannot be formed or solved, with a message for the user."""


@dataclass(frozen=True)
class Prior:
    """The a priori at the batch epoch: state x (9) and covariance P (9×9), and x's
    sensitivity S = ∂x/∂c (9×m) to the consider parameters when x is itself an
    estimate (a chained batch's: the previous solution), else None."""

    x: np.ndarray
    P: np.ndarray
    S: np.ndarray | None = None


@dataclass(frozen=True)
class BatchSolution:
    """One batch: the state and covariance at its epoch (sample 0 of its span), the
    consider covariance (None without consider parameters), the fit's figures, and
    the solution propagated over the span: x (n, 9) at every sample, the covariance
    (and consider covariance) at the requested ``rows`` (span-relative)."""

    x0: np.ndarray
    P0: np.ndarray
    P0_consider: np.ndarray | None
    converged: bool
    iterations: int
    cost: float
    costs: tuple[float, ...]
    residual_rms: np.ndarray        # roll (rad), yaw (rad), h (N m s); NaN if none
    residual_normalized: np.ndarray  # √(mean e²/r) per kind: ~1 where the fit is consistent
    n_measurements: np.ndarray      # of roll, yaw, h
    fixed: tuple[str, ...]          # states held at the a priori
    x: np.ndarray
    rows: np.ndarray
    P_rows: np.ndarray
    P_consider_rows: np.ndarray | None
    message: str = ""
    S_rows: np.ndarray | None = None   # ∂x/∂c at ``rows`` (the next chained a priori's S)


# --- the normal equations ---------------------------------------------------------

def fixed_states(n_yaw: int) -> tuple[int, ...]:
    """States the span cannot determine, held at the a priori: without a yaw
    measurement the constant yaw torque N_cz is unobservable (Section 4)."""
    return (NCZ,) if n_yaw == 0 else ()


def solve_normal(N: np.ndarray, g: np.ndarray, fixed=(), damping: float = 0.0
                 ) -> tuple[np.ndarray, np.ndarray]:
    """δ with (N + μ diag N) δ = g over the free states (``fixed`` ones get δ = 0), and
    N⁻¹ there (zero rows and columns for the fixed).  Jacobi-scaled Cholesky: the
    states' units span ten decades (rad, N m s, N m)."""
    n = len(g)
    free = np.array([i for i in range(n) if i not in set(fixed)])
    A = N[np.ix_(free, free)]
    d = np.sqrt(np.diag(A))
    if not np.all(np.isfinite(A)) or np.any(~(d > 0)):
        raise BatchError("no information on " + ", ".join(
            STATE_NAMES[int(free[i])] for i in np.flatnonzero(~(d > 0))) +
            " from the span's data, and no a priori to hold it")
    As = A / np.outer(d, d) + damping * np.eye(len(free))
    try:
        cf = scipy.linalg.cho_factor(As, lower=True)
    except np.linalg.LinAlgError:
        w, v = np.linalg.eigh(As)
        worst = free[np.argmax(np.abs(v[:, 0]))]
        raise BatchError(f"the normal equations are singular (smallest scaled eigenvalue "
                         f"{w[0]:.2g}): {STATE_NAMES[worst]} is not determined by the "
                         "span's data; give an a priori or a longer span") from None
    delta = np.zeros(n)
    delta[free] = scipy.linalg.cho_solve(cf, g[free] / d) / d
    inv = np.zeros((n, n))
    inv[np.ix_(free, free)] = scipy.linalg.cho_solve(cf, np.eye(len(free))) / np.outer(d, d)
    return delta, 0.5 * (inv + inv.T)


def with_prior(Lam: np.ndarray, b: np.ndarray, x: np.ndarray, prior: Prior | None,
               fixed=()) -> tuple[np.ndarray, np.ndarray, float]:
    """The information N = Λ + P̄⁻¹, the gradient g = b − P̄⁻¹(x − x̄) at x and the a
    priori's cost term (x − x̄)ᵀ P̄⁻¹ (x − x̄); a fixed state's own a-priori term drops
    out (it is held, not weighed)."""
    if prior is None:
        return Lam, b, 0.0
    Pi = np.linalg.inv(prior.P)
    Pi = 0.5 * (Pi + Pi.T)
    dx = x - prior.x
    dx[list(fixed)] = 0.0
    return Lam + Pi, b - Pi @ dx, float(dx @ Pi @ dx)


def covariance(N: np.ndarray, Ninv: np.ndarray, prior: Prior | None, fixed=()
               ) -> np.ndarray:
    """The solution's covariance.  The free states': N⁻¹.  A state held at the a priori
    keeps the a priori's σ, and that uncertainty is carried into the free states as a
    consider parameter's: with S = −N_ff⁻¹ N_fc (how the free estimate moves with the
    held value), P_ff = N_ff⁻¹ + S C Sᵀ, P_fc = S C, P_cc = C, C the a priori's
    covariance of the held states.  (Holding it as if known would make the free
    states' σ optimistic: 2.3× on yaw over 8 h without a yaw measurement.)"""
    P = Ninv.copy()
    if not fixed:
        return P
    held = list(fixed)
    if prior is None:
        P[held, held] = np.nan
        return P
    free = [i for i in range(len(P)) if i not in set(fixed)]
    C = prior.P[np.ix_(held, held)]
    S = -Ninv[np.ix_(free, free)] @ N[np.ix_(free, held)]
    P[np.ix_(free, free)] += S @ C @ S.T
    P[np.ix_(free, held)] = S @ C
    P[np.ix_(held, free)] = (S @ C).T
    P[np.ix_(held, held)] = C
    return 0.5 * (P + P.T)


# --- linear -----------------------------------------------------------------------

@dataclass(frozen=True)
class LinearData:
    """One span's data for the paper's model: the filter's measurements and inputs ū
    (Eq. 12a), and Φ, Γ for its sample interval (``Discretization``) or per sample
    (``StepTable``)."""

    meas: Measurements
    u: np.ndarray
    disc: Discretization | StepTable

    def __len__(self) -> int:
        return len(self.meas.roll_rad)


@lru_cache(maxsize=2)
def _linear_engine(per_step: bool):
    from dynprop.rollout.chunks import ChunkedRollout

    from ..linear.steps import per_step as per_step_of
    from .steps import linear_step
    step = linear_step()
    return ChunkedRollout(per_step_of(step) if per_step else step, 4096, 256, None)


def linear_normal(data: LinearData) -> tuple[np.ndarray, np.ndarray, float]:
    """Λ, b and c of the module doc about x_0 = 0 (one compiled pass)."""
    z, r = data.meas.z(), data.meas.r()
    n = len(z)
    present = np.isfinite(z)
    n2 = N_STATES**2
    s0 = np.zeros(n2 + N_STATES + N_UT + N_STATES + 1)
    s0[:n2] = np.eye(N_STATES).ravel(order="F")
    inputs = [np.where(present, z, 0.0), present.astype(float), r, np.asarray(data.u, float)]
    if isinstance(data.disc, StepTable):
        if len(data.disc) != n:
            raise ValueError(f"the step table has {len(data.disc)} steps, the data {n}")
        eng = _linear_engine(True)
        last, _, _ = roll_blocks(eng, s0, inputs, n,
                                 lambda a, b: _param_rows(data.disc, np.arange(a, b)),
                                 np.arange(0), np.arange(0), np.arange(0))
    else:
        eng = _linear_engine(False)
        last, _, _ = eng.run_columns(s0, inputs, pack_params(data.disc), np.arange(0),
                                     np.arange(0), np.arange(0))
    o = n2 + N_STATES
    return unpack(last[o:o + 45]), last[o + 45:o + 45 + N_STATES], float(last[-1])


def _no_noise(disc):
    if isinstance(disc, StepTable):
        return StepTable(disc.params, ProcessNoise(0.0, 0.0, 0.0), disc.dt)
    return dataclasses.replace(disc, Qd=np.zeros((N_STATES, N_STATES)))


def propagate_linear(data: LinearData, x0, P0, rows) -> tuple[np.ndarray, np.ndarray]:
    """x at every sample and P at ``rows`` of the span from (x0, P0) at its epoch: the
    filter's compiled step with no measurement and no process noise."""
    n = len(data)
    nan = np.full(n, np.nan)
    meas = Measurements(nan, nan, nan, 1.0, 1.0, 1.0)
    P0 = np.where(np.isfinite(P0), P0, 0.0)
    r = kalman_filter(meas, _no_noise(data.disc), x0, P0, data.u,
                      covariance_rows=np.asarray(rows, dtype=np.int64))
    return r.x, unpack(r.P_packed)


def measurement_counts(z: np.ndarray) -> np.ndarray:
    return np.isfinite(z).sum(axis=0)


def residual_stats(e: np.ndarray, z: np.ndarray, r: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray]:
    """RMS of the residuals e per measurement kind, and of e/√r (NaN where there is no
    measurement of a kind)."""
    rms, norm = np.full(3, np.nan), np.full(3, np.nan)
    for i in range(3):
        ok = np.isfinite(z[:, i])
        if ok.any():
            rms[i] = float(np.sqrt(np.mean(e[ok, i] ** 2)))
            norm[i] = float(np.sqrt(np.mean(e[ok, i] ** 2 / r[ok, i])))
    return rms, norm


def linear_start(data: LinearData, prior: Prior | None) -> np.ndarray:
    """The linear batch's x̂_0 alone (no propagation, no consider parameters): the
    nonlinear batch's starting point."""
    fixed = fixed_states(int(measurement_counts(data.meas.z())[1]))
    if prior is None and fixed:
        raise BatchError("no yaw measurement in the span: the constant yaw torque N_cz is "
                         "unobservable (Section 4) and there is no a priori to hold it")
    return _solve_linear(data, prior, fixed)[0]


def _solve_linear(data: LinearData, prior: Prior | None, fixed) -> tuple:
    Lam, b, c = linear_normal(data)
    x_ref = np.zeros(N_STATES) if prior is None else prior.x.copy()
    N, g, _ = with_prior(Lam, b - Lam @ x_ref, x_ref, prior, fixed)
    delta, Ninv = solve_normal(N, g, fixed)
    return x_ref + delta, Ninv, (Lam, b, c), N


@dataclass(frozen=True)
class ConsiderCase:
    """A consider parameter for the linear batch: its 1σ, and the span's data built
    with it at +δ and −δ (its model and preprocessing), for the central difference."""

    name: str
    sigma: float
    delta: float
    plus: LinearData
    minus: LinearData


def linear_batch(data: LinearData, prior: Prior | None, rows=(),
                 consider: tuple[ConsiderCase, ...] = ()) -> BatchSolution:
    """The paper's model fitted over the span in one weighted least-squares solve; the
    solution propagated over the span, with its covariance at ``rows``."""
    z = data.meas.z()
    counts = measurement_counts(z)
    fixed = fixed_states(int(counts[1]))
    if prior is None and fixed:
        raise BatchError("no yaw measurement in the span: the constant yaw torque N_cz is "
                         "unobservable (Section 4) and there is no a priori to hold it")
    x0, Ninv, (Lam, b, c), N = _solve_linear(data, prior, fixed)
    P0 = covariance(N, Ninv, prior, fixed)
    rows = np.asarray(rows, dtype=np.int64)
    x, P_rows = propagate_linear(data, x0, P0, rows)
    # J at the solution: the data's sum of squares (from the normal equations about 0)
    # and the a priori's term.
    cost = c - 2 * b @ x0 + x0 @ Lam @ x0 + with_prior(Lam, b, x0, prior, fixed)[2]
    P0c = Pc_rows = S_rows = None
    if consider:
        S0 = np.zeros((N_STATES, len(consider)))
        S_rows = np.zeros((len(rows), N_STATES, len(consider)))
        for j, case in enumerate(consider):
            ends = []
            for d, sign in ((case.plus, 1), (case.minus, -1)):
                # A chained a priori moves with c too: shift its mean by ±δ S̄.
                pj = prior if prior is None or prior.S is None else Prior(
                    prior.x + sign * case.delta * prior.S[:, j], prior.P)
                xj = _solve_linear(d, pj, fixed)[0]
                xh, _ = propagate_linear(d, xj, np.zeros((N_STATES, N_STATES)), rows[:0])
                ends.append((xj, xh[rows]))
            S0[:, j] = (ends[0][0] - ends[1][0]) / (2 * case.delta)
            S_rows[:, :, j] = (ends[0][1] - ends[1][1]) / (2 * case.delta)
        C = np.diag([case.sigma**2 for case in consider])
        P0c = P0 + S0 @ C @ S0.T
        Pc_rows = P_rows + np.einsum("kic,cd,kjd->kij", S_rows, C, S_rows)
    rms, norm = residual_stats(z - x[:, list(MEAS_STATES)], z, data.meas.r())
    return BatchSolution(x0, P0, P0c, True, 1, float(cost), (float(cost),), rms, norm, counts,
                         tuple(STATE_NAMES[i] for i in fixed), x, rows, P_rows, Pc_rows,
                         S_rows=S_rows)
