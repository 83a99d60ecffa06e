"""The paper filter's likelihood of its own telemetry, and its derivatives in the
noise parameters: what noise tuning (``estimator.tuning.maximum``) maximises.

Prediction-error decomposition (Schweppe 1965): the filter (``kalman``) updates
with roll, yaw and h in turn, and each present scalar measurement has an
innovation ν with variance S, independent of the earlier ones if the model is
right, so

    ln L(θ) = −½ Σ (ln 2πS + ν²/S).

Q_d is linear in the spectral densities (Eq. 32 is linear in Q, Eq. 34 in q), so
Q_d(θ) = Q_fixed + Σ_j θ_j U_j with U_j the Q_d of a unit θ_j: the closed forms are
evaluated once per parameter, and each θ is one pass of a compiled step built once,
with θ in its parameter vector.  θ may also hold a scale on the roll variance R.

The score pass carries, besides x and P, their forward sensitivities ∂x/∂θ_j and
∂P/∂θ_j (CasADi ``jtimes`` on the step's own expressions, so they differentiate
exactly what the filter computes) and accumulates the score ∂ln L/∂θ and the
expected (Fisher) information of the innovations (Gupta & Mehra 1974, IEEE TAC
19(6), Eq. 27)

    I_jk = Σ ½ ∂_j S ∂_k S / S² + ∂_j ν ∂_k ν / S,

so one pass gives ln L, its gradient and a Newton-type curvature.  The compiled
steps are in ``tuning.steps``.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from dynprop.rollout.chunks import ChunkedRollout

from ..kalman.filter import Measurements
from ..kalman.steps import N_UT, pack
from ..linear.model import N_STATES, ModelParams, ProcessNoise
from ..linear.steps import per_step, roll_blocks
from ..linear.transition import process_noise_integral
from .intervals import BLOCK, StepNoise, distinct_rows
from .samples import ArraySamples, Samples
from .steps import N_ACC, N_BASE, likelihood_step, n_fisher, score_step, score_step_ad

LOG_2PI = float(np.log(2 * np.pi))
NOISE_KEYS = ("q_x", "q_z", "q_w", "q_px", "q_pz", "q_cx", "q_cz")
# Samples per block of a pass: a multiple of the rollout's 4096-step chunk, ~13 MB of
# inputs and innovations.
PASS_BLOCK = 1 << 16


@dataclass(frozen=True, eq=False)
class NoiseModel:
    """Which noise parameters θ a likelihood varies, and how Q_d and R follow them.

    ``groups[j]`` maps the ``ProcessNoise`` keys that θ_j sets to their factor
    (q_x = q_z = θ_j for a tied pair); keys in no group keep ``fixed``'s value.
    ``units[j]`` is Q_d for θ_j = 1, ``Qd_fixed`` the held keys' Q_d.  With
    ``roll``, θ has one more element: a factor on the roll variance R_roll."""

    names: tuple[str, ...]
    groups: tuple[dict[str, float], ...]
    fixed: ProcessNoise
    units: np.ndarray        # (n_q, 9, 9)
    Qd_fixed: np.ndarray     # (9, 9)
    unit_w: np.ndarray       # (9, 9): Q_d of q_w = 1, what a bridged dropout adds per unit
    roll: bool

    @property
    def n_q(self) -> int:
        return len(self.groups)

    @property
    def n(self) -> int:
        return self.n_q + int(self.roll)

    def Qd(self, theta) -> np.ndarray:
        """Q_d(θ) = Q_fixed + Σ θ_j U_j."""
        theta = np.asarray(theta, dtype=float)[:self.n_q]
        return self.Qd_fixed + np.tensordot(theta, self.units, axes=1)

    def process_noise(self, theta) -> ProcessNoise:
        """The ``ProcessNoise`` at θ (the roll factor, if any, is not part of it)."""
        theta = np.asarray(theta, dtype=float)
        values = {k: getattr(self.fixed, k) for k in NOISE_KEYS}
        for j, g in enumerate(self.groups):
            for k, c in g.items():
                values[k] = c * float(theta[j])
        return ProcessNoise(**values)

    def theta_of(self, q: ProcessNoise, roll_factor: float = 1.0) -> np.ndarray:
        """θ that reproduces ``q`` on the tuned keys (a group takes its first key)."""
        theta = [getattr(q, next(iter(g))) / next(iter(g.values())) for g in self.groups]
        return np.array(theta + ([roll_factor] if self.roll else []), dtype=float)


def noise_model(params: ModelParams, dt: float, groups: dict[str, dict[str, float]],
                fixed: ProcessNoise, roll: bool = False) -> NoiseModel:
    """The ``NoiseModel`` of named parameter ``groups`` (θ_name sets each key of its
    group times its factor), the other keys held at ``fixed``'s values."""
    seen = [k for g in groups.values() for k in g]
    unknown = sorted(set(seen) - set(NOISE_KEYS))
    if unknown or len(seen) != len(set(seen)):
        raise ValueError(f"each process-noise key may be tuned once; got {seen}")
    zero = dict.fromkeys(NOISE_KEYS, 0.0)
    units = np.array([process_noise_integral(params, ProcessNoise(**{**zero, **g}), dt)
                      for g in groups.values()]).reshape(len(groups), N_STATES, N_STATES)
    held = {k: (0.0 if k in seen else getattr(fixed, k)) for k in NOISE_KEYS}
    unit_w = process_noise_integral(params, ProcessNoise(**{**zero, "q_w": 1.0}), dt)
    return NoiseModel(tuple(groups), tuple(dict(g) for g in groups.values()), fixed, units,
                      process_noise_integral(params, ProcessNoise(**held), dt), unit_w, roll)


@lru_cache(maxsize=16)
def _engine(kind: str, n_q: int, roll: bool, backend: str | None, k: int = 0,
            per: bool = False) -> ChunkedRollout:
    if kind == "score":
        step = score_step(n_q, roll, k)
    else:
        step = {"ll": likelihood_step, "score_ad": score_step_ad}[kind](n_q, roll)
    # Off the grid each step reads its own parameter row (``linear.steps.per_step``).
    return ChunkedRollout(per_step(step) if per else step, 4096, 256, backend)


@dataclass(frozen=True)
class Evaluation:
    """ln L at θ, with the sums it is made of per measurement kind (roll, yaw, h):
    the count of updates, Σ ln S and the normalised innovation squares Σ ν²/S; and,
    from a score pass, the gradient ∂ln L/∂θ and the Fisher information."""

    theta: np.ndarray
    loglik: float
    counts: np.ndarray
    sum_log_S: np.ndarray
    sum_nis: np.ndarray
    score: np.ndarray | None = None
    fisher: np.ndarray | None = None
    subset: np.ndarray | None = None    # the parameters ``score`` and ``fisher`` are of


class Likelihood:
    """The telemetry, prior and model of one filter run, ready to be evaluated at any
    θ: ``evaluate`` (one pass), ``score`` (one pass with sensitivities) and
    ``innovations`` (ν and S at every sample; ``innovation_blocks`` a block at a
    time).  Nothing is rebuilt per θ.

    ``disc`` is the one step's ``Discretization`` on the scenario's grid, or for
    telemetry off it a ``intervals.StepNoise`` of the steps' own Φ, Γ and unit Q_d
    (of the same groups as ``model``) per distinct interval, whose rows each pass
    reads per step.  The samples are read ``block`` at a time (``samples.Samples``;
    whole arrays here, anything else through ``of_samples``), the filter's state
    carried from block to block as it is from step to step: the same numbers."""

    def __init__(self, meas: Measurements, disc, x0, P0, model: NoiseModel, u=None,
                 bridge_noise: np.ndarray | None = None, backend: str | None = None,
                 block: int = PASS_BLOCK):
        dt = disc.dt if isinstance(disc, StepNoise) else None
        self._setup(ArraySamples(meas, u, bridge_noise, dt), disc, x0, P0, model, backend,
                    block)

    @classmethod
    def of_samples(cls, samples: Samples, disc, x0, P0, model: NoiseModel,
                   backend: str | None = None, block: int = PASS_BLOCK) -> Likelihood:
        """The likelihood of ``samples`` read a block at a time (a record too long to
        hold whole)."""
        self = cls.__new__(cls)
        self._setup(samples, disc, x0, P0, model, backend, block)
        return self

    def _setup(self, samples: Samples, disc, x0, P0, model: NoiseModel, backend, block):
        self.samples, self.block = samples, int(block)
        self.model, self.n_samples = model, int(samples.n)
        self.counts = np.asarray(samples.counts, dtype=float)
        x0, P0 = np.asarray(x0, dtype=float), np.asarray(P0, dtype=float)
        self.s0 = np.concatenate([x0, pack(0.5 * (P0 + P0.T))])
        qw_coef = [g.get("q_w", 0.0) for g in model.groups]
        qw_fixed = 0.0 if any(qw_coef) else model.fixed.q_w
        self.backend = backend
        self.steps = disc if isinstance(disc, StepNoise) else None
        if self.steps is not None:
            if self.steps.groups != model.groups:
                raise ValueError("the step table must hold the model's groups")
            self._qw_map = np.array([qw_fixed, *qw_coef], dtype=float)
            return
        self._p_head = np.concatenate([
            np.asarray(disc.Phi, float).ravel(order="F"),
            np.asarray(disc.Gamma, float).ravel(order="F"),
            np.zeros(N_UT), pack(model.unit_w),
            *(pack(U) for U in model.units), [qw_fixed], qw_coef])
        n2 = 2 * N_STATES**2
        self._qd = slice(n2, n2 + N_UT)

    def _check(self, theta) -> np.ndarray:
        theta = np.asarray(theta, dtype=float)
        if theta.shape != (self.model.n,) or not np.all(np.isfinite(theta) & (theta >= 0)):
            raise ValueError(f"θ must be {self.model.n} finite non-negative numbers")
        return theta

    def _which(self, dt: np.ndarray | None, start: int) -> np.ndarray:
        """The step table's distinct interval of each step of a block."""
        if dt is None:
            raise ValueError("telemetry off the grid needs each step's interval")
        d = self.steps.distinct
        which = np.minimum(np.searchsorted(d, dt), len(d) - 1)
        if not np.array_equal(d[which], dt):
            raise ValueError(f"a step interval from sample {start} is not in the step table")
        return which

    def _pass(self, kind: str, theta, s0, keep: bool, k: int = 0, idx=(), p=None,
              qd_of_theta: bool = True):
        """One pass, a block at a time: yields (start, the block's inputs, its aux if
        ``keep``, the state after it).  On the grid every step reads ``p``; off it each
        step its own parameter row, made a few thousand steps at a time
        (``intervals.distinct_rows``)."""
        m = self.model
        x = np.asarray(s0, dtype=float)
        per = self.steps is not None
        eng = _engine(kind, m.n_q, m.roll, self.backend, k, per=per)
        if per:
            theta = self._check(theta)
            tail = np.concatenate([self._qw_map, theta])
            directions = [(j, m.groups[j].get("q_w", 0.0), 0.0) if j < m.n_q
                          else (None, 0.0, 1.0) for j in idx]
        none = np.arange(0)
        for start in range(0, self.n_samples, self.block):
            stop = min(start + self.block, self.n_samples)
            inputs, dt = self.samples.block(start, stop)
            aux = None
            if per:
                which = self._which(dt, start)

                def params_of(a, b, which=which):
                    return distinct_rows(self.steps, which[a:b], theta, tail, directions,
                                         qd_of_theta)
                x, aux, _ = roll_blocks(eng, x, inputs, stop - start, params_of,
                                        np.arange(eng.n_aux) if keep else none, none, none,
                                        BLOCK)
            elif keep:
                x, aux = eng.run_final(x, inputs, p)
            else:
                x, _, _ = eng.run_columns(x, inputs, p, none, none, none)
            yield start, inputs, aux, x

    def _last(self, *args, **kw) -> np.ndarray:
        """The state after a pass (``_pass``'s arguments)."""
        last = np.asarray(args[2], dtype=float)
        for *_, state in self._pass(*args, **kw):
            last = state
        return last

    def _p(self, theta) -> np.ndarray:
        theta = self._check(theta)
        p = np.concatenate([self._p_head, theta])
        p[self._qd] = pack(self.model.Qd(theta))
        return p

    def _finish(self, theta, acc) -> Evaluation:
        log_s, nis = acc[:3], acc[3:]
        ll = -0.5 * float(np.sum(log_s + nis) + LOG_2PI * self.counts.sum())
        return Evaluation(np.array(theta, float), ll, self.counts.copy(), log_s.copy(),
                          nis.copy())

    def evaluate(self, theta) -> Evaluation:
        """ln L at θ: one filter pass, no history kept."""
        s0 = np.concatenate([self.s0, np.zeros(N_ACC)])
        p = None if self.steps is not None else self._p(theta)
        last = self._last("ll", theta, s0, False, p=p)
        return self._finish(theta, last[N_BASE:N_BASE + N_ACC])

    def score(self, theta, subset=None, derived: bool = True) -> Evaluation:
        """ln L, its gradient in θ and the Fisher information: one pass.  With
        ``subset`` (indices into θ) only those parameters' gradient and information
        (``Evaluation.subset``), at the cost of that many directions.
        ``derived=False`` takes all of them by differentiating the step itself
        (``score_step_ad``: the tests' reference, slower)."""
        n = self.model.n
        idx = np.arange(n) if subset is None else np.asarray(subset, dtype=np.int64)
        k = len(idx) if derived else n
        s0 = np.concatenate([self.s0, np.zeros(N_ACC + N_BASE * k + k + n_fisher(k))])
        p = None
        if self.steps is None:
            p = self._p(theta)
            if derived:
                p = np.concatenate([p, self._directions(idx)])
            else:     # the step forms Q_d(θ) itself from Q_fixed
                p[self._qd] = pack(self.model.Qd_fixed)
        if derived:
            last = self._last("score", theta, s0, False, k, idx, p=p)
        else:
            last = self._last("score_ad", theta, s0, False, p=p, qd_of_theta=False)
        ev = self._finish(theta, last[N_BASE:N_BASE + N_ACC])
        i = N_BASE + N_ACC + N_BASE * k
        F = np.zeros((k, k))
        F[np.triu_indices(k)] = last[i + k:]
        F = F + np.triu(F, 1).T
        return Evaluation(ev.theta, ev.loglik, ev.counts, ev.sum_log_S, ev.sum_nis,
                          last[i:i + k].copy(), F, idx if derived else np.arange(n))

    def _directions(self, idx) -> np.ndarray:
        """The parameters of unit directions ``idx``: U_j, ∂q_w/∂θ_j, ∂θ_R/∂θ_j."""
        m = self.model
        out = []
        for j in idx:
            if j < m.n_q:
                out += [pack(m.units[j]), [m.groups[j].get("q_w", 0.0)], [0.0]]
            else:
                out += [np.zeros(N_UT), [0.0], [1.0]]
        return np.concatenate(out) if out else np.zeros(0)

    def innovation_blocks(self, theta):
        """ν and S (k, 3: roll, yaw, h) at θ, NaN where no update, a block of samples
        at a time: yields (first sample, ν, S)."""
        s0 = np.concatenate([self.s0, np.zeros(N_ACC)])
        p = None if self.steps is not None else self._p(theta)
        for start, inputs, aux, _ in self._pass("ll", theta, s0, True, p=p):
            absent = inputs[1] == 0.0
            nu, S = aux[:, :3].copy(), aux[:, 3:].copy()
            nu[absent] = np.nan
            S[absent] = np.nan
            yield start, nu, S

    def innovations(self, theta) -> tuple[np.ndarray, np.ndarray]:
        """ν and S (N, 3: roll, yaw, h) at θ, NaN where no update."""
        blocks = [b[1:] for b in self.innovation_blocks(theta)]
        if not blocks:
            return np.zeros((0, 3)), np.zeros((0, 3))
        return tuple(np.concatenate(parts) for parts in zip(*blocks, strict=True))


__all__ = ["Evaluation", "Likelihood", "NoiseModel", "likelihood_step",
           "noise_model", "score_step", "score_step_ad"]
