"""The batch least-squares fit (``batch``) with the full nonlinear gyrostat: the EKF's
process model (``ekf.model``, ``eom``), solved by Gauss–Newton with
Levenberg–Marquardt damping.

Each iteration is one compiled pass over the span (``batch.steps.nonlinear_step``):
the RK4 rollout from the current x_0, the residuals, and their Jacobian from the
forward sensitivities of that rollout, summed into the normal equations.  The step
δ solves (N + μ diag N) δ = g; it is taken if it lowers the cost J, and μ shrinks
tenfold, else μ grows tenfold and δ is recomputed from the same normal equations.
The fit has converged when the undamped Gauss–Newton step is below
``tolerance_sigma`` of its own σ, √(gᵀ N⁻¹ g) ≤ tol (the cost's decrease it
promises is then below tol²/2, of a cost of about the number of measurements); it
stops unconverged after ``max_iterations`` passes, or when μ exceeds ``MU_MAX``
(no step along the gradient lowers the cost).  A last pass at the solution carries
the consider parameters' sensitivities and the paper-coordinate history.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from dynprop.rollout.chunks import ChunkedRollout

from ..ekf import model as m
from ..linear.model import N_STATES, STATE_NAMES
from ..linear.steps import per_step, roll_blocks, step_params, substeps
from . import steps as bs
from .linear import (
    BatchError,
    BatchSolution,
    Prior,
    covariance,
    fixed_states,
    measurement_counts,
    residual_stats,
    solve_normal,
    with_prior,
)

MU_MAX = 1e8
MU_START = 1e-4
FULL_PASS_BELOW = 3.0   # σ: after a Gauss–Newton step this small the next is likely the last


def _xx(p) -> tuple[np.ndarray, np.ndarray]:
    """The solve-for block of a pass's normal equations (without the consider
    parameters' rows and columns)."""
    return p.Lam[:N_STATES, :N_STATES], p.b[:N_STATES]


@dataclass(frozen=True)
class NonlinearData:
    """One span's data for the nonlinear model, per sample: z (N, 3: roll, yaw in rad,
    h in N m s; NaN where missing) and their variances r (N, 3), the EKF's inputs u
    (N, 5: H, Ḣ, N_w*, N_x*, N_z*), the Earth sensor's pitch and pitch rate (N, 2,
    smoothed), the pass parameters (``batch.steps.pack_batch_params``) and, off the
    grid, each sample's interval ``dt_s`` (N,)."""

    z: np.ndarray
    r: np.ndarray
    u: np.ndarray
    pitch: np.ndarray
    params: np.ndarray
    dt_s: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.z)


@dataclass(frozen=True)
class Options:
    max_iterations: int = 20
    tolerance_sigma: float = 0.01


@lru_cache(maxsize=8)
def _engine(n_consider: int, with_paper: bool, per: bool) -> ChunkedRollout:
    step = bs.nonlinear_step(n_consider, with_paper)
    return ChunkedRollout(per_step(step) if per else step, 4096, 256, None)


@dataclass(frozen=True)
class _Pass:
    Lam: np.ndarray
    b: np.ndarray
    cost: float
    res: np.ndarray            # (N, 3), 0 where absent
    x: np.ndarray | None       # (N, 9) paper coordinates
    T: np.ndarray | None       # (len(rows), 9, k): ∂x/∂(x_0, c) at rows


def _substeps(data: NonlinearData):
    """Each sample's interval cut into RK4 steps no longer than the nominal one
    (``steps.substeps``, the EKF's rule), and the sub-step each sample starts; on
    the grid, one step each (``h`` None)."""
    if data.dt_s is None:
        n = len(data)
        return np.arange(n), np.arange(n), None
    return substeps(data.dt_s, float(data.params[m.DT_INDEX]))


def run_pass(data: NonlinearData, x0: np.ndarray, n_consider: int = 0,
             with_paper: bool = False, rows=()) -> _Pass:
    """One compiled pass from the paper-coordinate x0 at the span's first sample."""
    k = N_STATES + n_consider
    wn = float(data.params[-1])
    X0, Psi0 = bs.initial_map()(x0, data.pitch[0], wn)
    Psi = np.zeros((m.NX, k))
    Psi[:, :N_STATES] = np.asarray(Psi0)
    nlam = k * (k + 1) // 2
    s0 = np.concatenate([np.asarray(X0).ravel(), Psi.ravel(order="F"), np.zeros(nlam + k + 1)])
    src, first, h = _substeps(data)
    fresh = np.zeros(len(src), dtype=bool)
    fresh[first] = True
    z = np.asarray(data.z, dtype=float)[src]
    present = np.isfinite(z) & fresh[:, None]
    # The pitch at each (sub-)step's end: the Earth sensor's, interpolated in time
    # inside a long interval.
    t_sub = np.r_[0.0, np.cumsum(h)] if h is not None else None
    if t_sub is None:
        pitch_next = np.vstack([data.pitch[1:], data.pitch[-1:]])
    else:
        t_samp = t_sub[first]
        pitch_next = np.column_stack([np.interp(t_sub[1:], t_samp, data.pitch[:, j])
                                      for j in range(2)])
    inputs = [np.where(present, z, 0.0), present.astype(float),
              np.where(present, np.asarray(data.r, dtype=float)[src], 1.0),
              np.asarray(data.u, dtype=float)[src], pitch_next]
    eng = _engine(n_consider, with_paper, h is not None)
    n_every = 3 + (N_STATES if with_paper else 0)
    cols = np.arange(n_every)
    kept = first[np.asarray(rows, dtype=np.int64)] if with_paper else np.arange(0)
    row_cols = np.arange(n_every, eng.n_aux) if with_paper else np.arange(0)
    if h is None:
        last, every, at_rows = eng.run_columns(s0, inputs, np.asarray(data.params, float),
                                               cols, kept, row_cols)
    else:
        last, every, at_rows = roll_blocks(eng, s0, inputs, len(src),
                                           step_params(data.params, m.DT_INDEX, h), cols,
                                           kept, row_cols)
    every = every[first]
    o = m.NX + m.NX * k
    iu = np.triu_indices(k)
    Lam = np.zeros((k, k))
    Lam[iu] = last[o:o + nlam]
    Lam = Lam + np.triu(Lam, 1).T
    b, cost = last[o + nlam:o + nlam + k], float(last[-1])
    if not np.isfinite(cost):
        raise FloatingPointError("the rollout left the finite numbers")
    return _Pass(Lam, b, cost, every[:, :3],
                 every[:, 3:] if with_paper else None,
                 at_rows.reshape(len(kept), k, N_STATES).transpose(0, 2, 1)
                 if with_paper else None)


def nonlinear_batch(data: NonlinearData, prior: Prior | None, x_start: np.ndarray,
                    rows=(), consider_sigma: np.ndarray | None = None,
                    options: Options = Options()) -> BatchSolution:
    """Gauss–Newton/Levenberg–Marquardt from ``x_start`` (module doc); the solution
    propagated over the span with its covariance at ``rows``, and with
    ``consider_sigma`` (``batch.steps.CONSIDER_NONLINEAR``'s 1σ) the consider
    covariance."""
    z = np.asarray(data.z, dtype=float)
    counts = measurement_counts(z)
    fixed = fixed_states(int(counts[1]))
    if prior is None and fixed:
        raise BatchError("no yaw measurement in the span: the constant yaw torque N_cz is "
                         "unobservable (Section 4) and there is no a priori to hold it")
    x = np.asarray(x_start, dtype=float).copy()
    if prior is not None:
        x[list(fixed)] = prior.x[list(fixed)]
    n_c = 0 if consider_sigma is None else bs.N_C
    rows = np.asarray(rows, dtype=np.int64)

    def full_pass(at):
        return run_pass(data, at, n_c, with_paper=True, rows=rows)

    cur = run_pass(data, x)
    N, g, prior_cost = with_prior(*_xx(cur), x, prior, fixed)
    J = cur.cost + prior_cost
    costs, mu, passes, converged, message = [J], MU_START, 1, False, ""
    while True:
        _, Ninv = solve_normal(N, g, fixed)
        decrement = float(np.sqrt(max(g @ Ninv @ g, 0.0)))
        if decrement <= options.tolerance_sigma:
            converged = True
            break
        if passes >= options.max_iterations:
            message = (f"not converged after {passes} iterations: the last Gauss–Newton "
                       f"step was {decrement:.3g} σ (tolerance {options.tolerance_sigma} σ)")
            break
        delta, _ = solve_normal(N, g, fixed, damping=mu)
        trial_x = x + delta
        try:
            # Near the solution the next pass is likely the last: make it the one that
            # also carries the consider and paper-coordinate sensitivities, so that
            # converging costs no separate final pass.
            trial = (full_pass if decrement < FULL_PASS_BELOW else
                     lambda at: run_pass(data, at))(trial_x)
            passes += 1
            tN, tg, tprior = with_prior(*_xx(trial), trial_x, prior, fixed)
            tJ = trial.cost + tprior
        except FloatingPointError:
            passes += 1
            tJ = np.inf
        if tJ < J:
            x, cur, N, g, J = trial_x, trial, tN, tg, tJ
            costs.append(J)
            mu = max(mu / 10, 1e-12)
        else:
            mu *= 10
            if mu > MU_MAX:
                message = ("not converged: no step lowers the cost (Levenberg–Marquardt "
                           f"damping above {MU_MAX:g}) after {passes} iterations")
                break
    _, Ninv = solve_normal(N, g, fixed)
    P0 = covariance(N, Ninv, prior, fixed)
    final = cur if cur.x is not None else full_pass(x)
    T = final.T
    Tx = T[:, :, :N_STATES]
    P_rows = np.einsum("kia,ab,kjb->kij", Tx, np.nan_to_num(P0), Tx)
    P0c = Pc_rows = S_rows = None
    if n_c:
        # S = ∂x̂_0/∂c = N⁻¹ (P̄⁻¹ S̄ − Λ_xc): the data's part, and a chained a priori's
        # own sensitivity S̄ through its weight (the fixed states' rows: held at x̄).
        S0 = -Ninv @ final.Lam[:N_STATES, N_STATES:]
        if prior is not None and prior.S is not None:
            Pi = np.linalg.inv(prior.P)
            S0 = S0 + Ninv @ (0.5 * (Pi + Pi.T)) @ prior.S
            S0[list(fixed)] = prior.S[list(fixed)]
        C = np.diag(np.square(consider_sigma))
        P0c = P0 + S0 @ C @ S0.T
        S_rows = Tx @ S0 + T[:, :, N_STATES:]
        Pc_rows = P_rows + np.einsum("kic,cd,kjd->kij", S_rows, C, S_rows)
    rms, norm = residual_stats(final.res, z, np.asarray(data.r, dtype=float))
    return BatchSolution(x, P0, P0c, converged, passes, float(J), tuple(costs), rms, norm,
                         counts, tuple(STATE_NAMES[i] for i in fixed),
                         final.x, rows, P_rows, Pc_rows, message, S_rows)
