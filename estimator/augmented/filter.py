"""The paper's filter (``kalman``) with sensor-bias states and outlier gating.

State x_a = [x (Eq. 10), b]: b any of the Earth sensor's roll bias (z_roll = r + b)
and a ground-yaw bias per Sun-sensor head (z_yaw = y + b_head, the head of each yaw
sample given by ``sun_head``: 0 DSS, 1 CASS1, 2 CASS2).  Each bias is a random
constant or a random walk of density q_b (rad²/s), so Φ_a = blockdiag(Φ, I),
Γ_a = [Γ; 0], Q_d,a = blockdiag(Q_d, diag(q_b Δt)) and Q_e,a = blockdiag(Q_e, 0) in
Eqs. 31–32; ū stays the paper's (Eq. 12a).  The updates are the paper's sequential
scalar ones (Eqs. 36–38, Joseph form) with the bias in the measurement row, and, with
a threshold γ, a measurement whose ν²/S exceeds γ (χ²(1): 25 is 5σ) is rejected and
flagged instead of applied, so one spike cannot pull an estimate that takes hours
to recover (the slow torque states and the biases remember it).

What the data cannot separate (``augmented_model`` and ``measurement_row`` give F_a
and G for ``estimator.analysis.observability``): a constant roll offset δ held by the constant
torque N_cx = −ω0 H δ (Eq. 11) reads as r + b unchanged when b = −δ, so with roll, yaw
and h the augmented model has rank 9 of 10 per such bias (likewise yaw, N_cz and a yaw
bias), and a constant bias is known only as well as the prior on the constant torque
allows; a second head without a bias state, seen as well, makes a yaw bias observable.
The steps are compiled
(``augmented.steps``); the tests hold them to a plain-numpy filter and smoother of
their own (tests/estimator/dense_reference.py).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..kalman.filter import (
    ExtraNoise,
    Measurements,
    _extra,
    _inputs,
    cut_measurements,
    step_matrices,
)
from ..kalman.maneuver import filter_segments, smoother_segments
from ..kalman.steps import pack_params
from ..linear.model import N_STATES, ModelParams, dynamics_matrix
from .model import BIAS_NAMES, YAW_HEADS, augmented_dynamics, augmented_rows
from .steps import N_MEAS, engine, n_packed, yaw_bias_columns


@dataclass(frozen=True)
class BiasModel:
    """The bias states after the paper's nine, in ``BIAS_NAMES`` order: prior 1σ (rad)
    and random-walk density q_b (rad²/s; 0 for a random constant)."""

    names: tuple[str, ...]
    sigma0_rad: tuple[float, ...]
    walk_rad2ps: tuple[float, ...]

    def __post_init__(self) -> None:
        names = tuple(self.names)
        if len(set(names)) != len(names) or any(n not in BIAS_NAMES for n in names) \
                or list(names) != sorted(names, key=BIAS_NAMES.index):
            raise ValueError(f"bias names must be distinct, of {BIAS_NAMES}, in that order")
        if not (len(self.sigma0_rad) == len(self.walk_rad2ps) == len(names)):
            raise ValueError("one sigma0 and one walk density per bias")
        s, q = np.asarray(self.sigma0_rad, float), np.asarray(self.walk_rad2ps, float)
        # σ0 > 0: the smoother's Cholesky solve needs a positive definite prediction.
        if not (np.all(np.isfinite(s) & (s > 0)) and np.all(np.isfinite(q) & (q >= 0))):
            raise ValueError("sigma0 must be positive and walk densities non-negative")

    @classmethod
    def of(cls, **biases: tuple[float, float]) -> BiasModel:
        """``BiasModel.of(earth_roll=(σ0, q), dss_yaw=(σ0, q))`` in any keyword order."""
        names = tuple(n for n in BIAS_NAMES if n in biases)
        if len(names) != len(biases):
            raise ValueError(f"unknown bias among {sorted(biases)}; known: {BIAS_NAMES}")
        return cls(names, tuple(float(biases[n][0]) for n in names),
                   tuple(float(biases[n][1]) for n in names))



def _names(bias: BiasModel | None) -> tuple[str, ...]:
    return () if bias is None else tuple(bias.names)


def pack(P: np.ndarray) -> np.ndarray:
    """Upper triangle (row-major) of symmetric (..., n, n) -> (..., n(n+1)/2); for
    n = 9 the paper filter's ``kalman.pack``."""
    i, j = np.triu_indices(P.shape[-1])
    return P[..., i, j]


def unpack(p: np.ndarray) -> np.ndarray:
    """Inverse of ``pack``, n from the packed length."""
    p = np.asarray(p)
    n = int(round((np.sqrt(8 * p.shape[-1] + 1) - 1) / 2))
    if n_packed(n) != p.shape[-1]:
        raise ValueError(f"{p.shape[-1]} is not a packed triangle's length")
    i, j = np.triu_indices(n)
    P = np.zeros(p.shape[:-1] + (n, n))
    P[..., i, j] = p
    P[..., j, i] = p
    return P


class _PackedHistory:
    """σ and P views of a (N, n(n+1)/2) packed covariance history (``kalman``'s, any n)."""

    P_packed: np.ndarray

    @property
    def sigma(self) -> np.ndarray:
        n = self.x.shape[-1]
        i, j = np.triu_indices(n)
        return np.sqrt(self.P_packed[:, i == j])

    @property
    def P(self) -> np.ndarray:
        return unpack(self.P_packed)


@dataclass(frozen=True)
class AugmentedResult(_PackedHistory):
    """A-posteriori history, innovations ν and variances S (roll, yaw, h; NaN where
    absent, kept where present but rejected), ``rejected`` (N, 3) by the gate, and the
    prior after the last step.  States: the paper's nine, then ``names``."""

    x: np.ndarray               # (N, 9 + nb)
    P_packed: np.ndarray        # (N, n(n+1)/2), see ``unpack``
    innovations: np.ndarray
    innovation_var: np.ndarray
    rejected: np.ndarray        # (N, 3) bool
    x_next: np.ndarray
    P_next: np.ndarray
    backend: str
    names: tuple[str, ...]


@dataclass(frozen=True)
class AugmentedSmootherResult(_PackedHistory):
    x: np.ndarray
    P_packed: np.ndarray | None    # None with covariance=False
    names: tuple[str, ...]


def augmented_prior(x0, P0, bias: BiasModel | None) -> tuple[np.ndarray, np.ndarray]:
    """The paper's 9-state prior with each bias appended: zero mean, diag(σ0²), and no
    correlation with the attitude (nothing is known of a bias before the data)."""
    x0, P0 = np.asarray(x0, dtype=float), np.asarray(P0, dtype=float)
    if x0.shape != (N_STATES,) or P0.shape != (N_STATES, N_STATES):
        raise ValueError("x0 must have 9 elements and P0 be 9×9")
    names = _names(bias)
    s0 = np.asarray(bias.sigma0_rad if names else (), dtype=float)
    P = np.zeros((N_STATES + len(names),) * 2)
    P[:N_STATES, :N_STATES] = P0
    P[N_STATES:, N_STATES:] = np.diag(s0**2)
    return np.concatenate([x0, np.zeros(len(names))]), P


def _prior(x0, P0, bias) -> tuple[np.ndarray, np.ndarray]:
    n = N_STATES + len(_names(bias))
    x0, P0 = np.asarray(x0, dtype=float), np.asarray(P0, dtype=float)
    if x0.shape == (N_STATES,) and P0.shape == (N_STATES, N_STATES):
        return augmented_prior(x0, P0, bias)
    if x0.shape != (n,) or P0.shape != (n, n):
        raise ValueError(f"x0, P0 must be 9-state or augmented ({n},), ({n}, {n})")
    return x0, P0


def augmented_params(disc, bias: BiasModel | None, Qd_unit=None,
                     gate_chi2: float | None = None) -> np.ndarray:
    """The steps' parameter vector for one step length: the paper step's
    (``kalman.steps.pack_params``: Φ, Γ, Q_d, Q_e), each bias's q_b Δt (Eq. 32 for a
    random walk), and γ when gating.  A run of several Δt calls it once per segment."""
    walk = np.asarray(bias.walk_rad2ps if _names(bias) else (), dtype=float) * disc.dt
    gate = () if gate_chi2 is None else (_gate(gate_chi2),)
    return np.concatenate([pack_params(disc, Qd_unit), walk, gate])


def _gate(gate_chi2) -> float:
    g = float(gate_chi2)
    if not (np.isfinite(g) and g > 0):
        raise ValueError("gate_chi2 must be positive and finite (None: no gating)")
    return g


def head_selector(sun_head, yaw_present: np.ndarray, bias: BiasModel | None) -> np.ndarray:
    """(N, n_yaw_bias) one-hot of each yaw sample's head over the yaw-bias states, zero
    rows where the head has none.  A present yaw needs a head code when there are
    yaw-bias states (which bias it carries would be a guess)."""
    names = _names(bias)
    cols = [names[c - N_STATES] for c in yaw_bias_columns(names)]
    sel = np.zeros((len(yaw_present), len(cols)))
    if not cols:
        return sel
    if sun_head is None:
        raise ValueError("sun_head is needed with yaw-bias states")
    head = np.asarray(sun_head, dtype=float)
    if head.shape != yaw_present.shape:
        raise ValueError(f"sun_head must be ({len(yaw_present)},)")
    known = np.isfinite(head)
    if np.any(yaw_present & ~known) or np.any(~np.isin(head[known], (0, 1, 2))):
        raise ValueError("sun_head must be 0, 1 or 2 wherever yaw is present")
    for j, name in enumerate(cols):
        sel[:, j] = known & (head == YAW_HEADS.index(name))
    return sel


def _filter_inputs(meas: Measurements, u, extra, sun_head, bias):
    z, r = meas.z(), meas.r()
    n = len(z)
    present = np.isfinite(z)
    scale, Qd_unit = _extra(extra, n)
    inputs = [np.where(present, z, 0.0), present.astype(float), r, _inputs(u, n), scale]
    sel = head_selector(sun_head, present[:, 1], bias)
    if sel.shape[1]:
        inputs.append(sel)
    return inputs, present, Qd_unit


def _roll(eng, s0, inputs, p, rows=None, covariance_rows=None):
    """One rollout of the filter's step with parameters ``p`` (``augmented_params``):
    the final state [x⁻, P⁻ packed] and, per kept sample, aux's columns before P
    ([x⁺, ν, S, rejected]) and the packed P⁺: at ``rows`` (all if None), or every
    sample's columns and P at ``covariance_rows`` only.  A run with one Δt per segment
    calls it per segment, carrying the final state."""
    # n from the carried state's length, n + n(n+1)/2: a caller needs no bias model here.
    n = next(k for k in range(N_STATES, N_STATES + len(BIAS_NAMES) + 1)
             if k + n_packed(k) == np.size(s0))
    front = n + 3 * N_MEAS
    if covariance_rows is not None:
        if rows is not None:
            raise ValueError("rows and covariance_rows exclude each other")
        return eng.run_columns(s0, inputs, p, np.arange(front),
                               np.asarray(covariance_rows, dtype=np.int64),
                               np.arange(front, eng.n_aux))
    last, aux = eng.run_kept(s0, inputs, p,
                             None if rows is None else np.asarray(rows, dtype=np.int64))
    return last, aux[:, :front], aux[:, front:]


def augmented_filter(meas: Measurements, disc, x0, P0, u=None, *, bias: BiasModel | None,
                     sun_head=None, gate_chi2: float | None = None,
                     extra: ExtraNoise | None = None, rows=None, covariance_rows=None,
                     backend: str | None = None, chunk: int = 4096) -> AugmentedResult:
    """``kalman.kalman_filter`` on the state with ``bias``'s states appended (None: the
    paper's nine) and, with ``gate_chi2`` = γ, each present measurement with ν²/S > γ
    rejected (``rejected``; None: no gate, not even the comparison).  ``sun_head`` (N,)
    names the head of each yaw sample (0 DSS, 1 CASS1, 2 CASS2; NaN where no yaw),
    needed with yaw-bias states.  x0, P0: the paper's nine (biases appended by
    ``augmented_prior``) or the augmented state.  ``rows``, ``covariance_rows``,
    ``extra`` as in ``kalman_filter`` (its maneuver response too)."""
    m = None if extra is None else extra.maneuver
    if m is not None and m.active:
        def run(seg, inflated, x, P, seg_rows, seg_cov_rows):
            return augmented_filter(
                cut_measurements(meas, seg), m.discretization(disc, inflated), x, P,
                None if u is None else np.asarray(u)[seg], bias=bias,
                sun_head=None if sun_head is None else np.asarray(sun_head)[seg],
                gate_chi2=gate_chi2, extra=ExtraNoise(extra.scale[seg], extra.Qd_unit),
                rows=seg_rows, covariance_rows=seg_cov_rows, backend=backend, chunk=chunk)
        return filter_segments(m, run, *_prior(x0, P0, bias), rows, covariance_rows,
                               ("x", "P_packed", "innovations", "innovation_var",
                                "rejected"))
    names = _names(bias)
    inputs, present, Qd_unit = _filter_inputs(meas, u, extra, sun_head, bias)
    x0, P0 = _prior(x0, P0, bias)
    eng = engine("filter", names, gate_chi2 is not None, chunk, backend)
    s0 = np.concatenate([x0, pack(0.5 * (P0 + P0.T))])
    last, front, P = _roll(eng, s0, inputs, augmented_params(disc, bias, Qd_unit, gate_chi2),
                           rows, covariance_rows)
    if rows is not None:
        present = present[np.asarray(rows, dtype=np.int64)]
    n = N_STATES + len(names)
    nu, S = front[:, n:n + N_MEAS], front[:, n + N_MEAS:n + 2 * N_MEAS]
    nu[~present] = np.nan
    S[~present] = np.nan
    rejected = front[:, n + 2 * N_MEAS:] > 0.5
    return AugmentedResult(front[:, :n], P, nu, S, rejected, last[:n], unpack(last[n:]),
                           eng.backend, names)


def augmented_smoother(result: AugmentedResult, disc, u=None, *, bias: BiasModel | None,
                       extra: ExtraNoise | None = None, covariance: bool = True,
                       x_after: np.ndarray | None = None, backend: str | None = None,
                       chunk: int = 4096, P_after: np.ndarray | None = None
                       ) -> AugmentedSmootherResult:
    """``kalman.rts_smoother`` on the augmented state, over the filter's stored
    posteriors (which already hold the gate's decisions, so it has no gate of its
    own); ``covariance``, ``x_after`` and ``P_after`` as there."""
    names = _names(bias)
    if tuple(result.names) != names:
        raise ValueError(f"the filter ran with biases {result.names}, not {names}")
    n = len(result.x)
    m = None if extra is None else extra.maneuver
    if m is not None and m.active:
        return _smooth_maneuver(result, disc, _inputs(u, n), bias, extra, covariance,
                                x_after, P_after, backend, chunk)
    if x_after is not None and covariance and P_after is None:
        raise ValueError("x_after with covariance needs P_after")
    if n < 2 and x_after is None:
        return AugmentedSmootherResult(result.x.copy(),
                                       result.P_packed.copy() if covariance else None, names)
    u = _inputs(u, n)
    scale, Qd_unit = _extra(extra, n)
    eng = engine("smoother" if covariance else "smoother_x", names, False, chunk, backend)
    # Backwards: step k uses the filter's k-th posterior and input, k = n−2 … 0 (from
    # n−1 when the smoothed state after the history is given).
    rev = slice(n - 2 if x_after is None else n - 1, None, -1)
    if x_after is None:
        last = [result.x[-1], result.P_packed[-1]] if covariance else [result.x[-1]]
    else:
        last = [x_after, P_after] if covariance else [x_after]
    s0 = np.concatenate([np.asarray(v, dtype=float) for v in last])
    _, aux = eng.run_final(s0, [result.x[rev], result.P_packed[rev], u[rev], scale[rev]],
                           augmented_params(disc, bias, Qd_unit))
    k = result.x.shape[1]
    if x_after is not None:
        if covariance:
            return AugmentedSmootherResult(aux[::-1, :k].copy(), aux[::-1, k:].copy(), names)
        return AugmentedSmootherResult(aux[::-1].copy(), None, names)
    xs = np.vstack([aux[::-1, :k], result.x[-1:]])
    if not covariance:
        return AugmentedSmootherResult(xs, None, names)
    return AugmentedSmootherResult(xs, np.vstack([aux[::-1, k:], result.P_packed[-1:]]),
                                   names)


def _smooth_maneuver(result: AugmentedResult, disc, u, bias, extra: ExtraNoise, covariance,
                     x_after, P_after, backend, chunk) -> AugmentedSmootherResult:
    """``augmented_smoother`` over the segments of ``extra``'s maneuver response
    (``kalman.maneuver.smoother_segments``), the reset step on the augmented state
    (Φ_a = blockdiag(Φ, I), Γ_a = [Γ; 0], Q_d,a = blockdiag(Q_d, diag(q_b Δt)))."""
    m, names = extra.maneuver, _names(bias)
    walk = np.asarray(bias.walk_rad2ps if names else (), dtype=float) * disc.dt

    def smooth(seg, inflated, xa, Pa):
        part = AugmentedResult(result.x[seg], result.P_packed[seg], result.innovations[seg],
                               result.innovation_var[seg], result.rejected[seg],
                               result.x_next, result.P_next, result.backend, result.names)
        return augmented_smoother(part, m.discretization(disc, inflated), u[seg], bias=bias,
                                  extra=ExtraNoise(extra.scale[seg], extra.Qd_unit),
                                  covariance=covariance, x_after=xa, backend=backend,
                                  chunk=chunk, P_after=Pa)

    def reset_step(k, inflated, xa, Pa):
        Phi, Gam, Q = step_matrices(m.discretization(disc, inflated), k, extra)
        nb = len(names)
        Phi_a = np.block([[Phi, np.zeros((N_STATES, nb))], [np.zeros((nb, N_STATES)),
                                                             np.eye(nb)]])
        Q_a = np.block([[Q, np.zeros((N_STATES, nb))], [np.zeros((nb, N_STATES)),
                                                        np.diag(walk)]])
        return m.smoother_step(Phi_a, np.vstack([Gam, np.zeros((nb, N_STATES))]), Q_a,
                               result.x[k], unpack(result.P_packed[k]), u[k], xa,
                               Pa if covariance else None)

    x, P = smoother_segments(m, smooth, reset_step, covariance, x_after, P_after)
    return AugmentedSmootherResult(x, P, names)


def measurement_row(bias: BiasModel | None, kind: str, head: int | None = None
                    ) -> np.ndarray:
    """G row of one measurement ('roll', 'yaw' from ``head``, 'h') on the augmented
    state: e_r + e_earth_roll, e_y + e_(head's bias), e_h (a term only where the
    state exists); ``observability.augmented_rows``'s, the one definition."""
    label = f"yaw:{YAW_HEADS[head].removesuffix('_yaw')}" if kind == "yaw" and \
        head is not None else kind
    return augmented_rows([label], _names(bias))[0]


def augmented_model(p: ModelParams, bias: BiasModel | None) -> np.ndarray:
    """F_a = blockdiag(F (Eq. 11b), 0): the biases are constant between noise, for
    ``estimator.analysis.observability`` with rows from ``measurement_row``."""
    return augmented_dynamics(dynamics_matrix(p), len(_names(bias)))
