"""The likelihood's per-step matrices for telemetry off the scenario's grid (jittered
tags, another cadence, gaps): each step propagates over its own Δt, as the filter
does there (``linear.steps``).

Q_d is linear in the spectral densities at every Δt (Eq. 32 is linear in Q, Eq. 34
in q), so per interval Q_d(θ) = Q_fixed(Δt) + Σ θ_j U_j(Δt), with U_j(Δt) the Q_d of
a unit θ_j over Δt (the closed form per interval: ``transition.propagate_many``).
``StepNoise`` evaluates Φ, Γ, Q_fixed, the unit wheel noise and every U_j once per
distinct interval, before any θ; a pass at θ then only sums them, per distinct
interval, and hands each step its row (``rows``).

Distinct intervals: the difference of two time tags carries the rounding of the tags
themselves (~1e-10 s at three days), so a file tagged to the millisecond has a
thousand-odd distinct float differences for each true one.  Intervals are taken to
``RESOLUTION_S`` (1 ns; Φ moves by ~1e-12 over it), which leaves a millisecond-tagged
file with ~100 distinct intervals.  A file with more than ``MAX_CACHED`` of them has
its tables evaluated per block of steps on each pass (slower, the same numbers).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..kalman.steps import N_UT, pack
from ..linear.model import ModelParams, ProcessNoise
from ..linear.steps import set_distinct, step_intervals
from ..linear.transition import _noise_matrix, propagate_many

RESOLUTION_S = 1e-9
MAX_CACHED = 16384        # distinct intervals held (~4.5 kB each with seven parameters)
BLOCK = 4096              # steps per block of parameter rows (~30 MB with eight directions)
NOISE_KEYS = ("q_x", "q_z", "q_w", "q_px", "q_pz", "q_cx", "q_cz")


def intervals(t_s) -> np.ndarray:
    """Each sample's step interval (``linear.steps.step_intervals``) to ``RESOLUTION_S``."""
    return np.round(step_intervals(t_s) / RESOLUTION_S) * RESOLUTION_S


@dataclass(frozen=True, eq=False)
class StepNoise:
    """The closed forms of a run's step intervals ``dt`` (one per sample) for the noise
    groups of a ``likelihood.NoiseModel``: per distinct interval Φ and Γ (column-major,
    81 each), the held keys' Q_d, the unit wheel-noise Q_d (q_w = 1) and each group's
    unit Q_d (packed, 45 each)."""

    params: ModelParams
    dt: np.ndarray
    groups: tuple[dict[str, float], ...]
    held: ProcessNoise
    distinct: np.ndarray = field(init=False)
    index: np.ndarray = field(init=False)
    _cache: tuple | None = field(init=False)

    def __post_init__(self):
        set_distinct(self, self.dt)
        object.__setattr__(self, "_cache", self._evaluate(np.arange(len(self.distinct)))
                           if len(self.distinct) <= MAX_CACHED else None)

    def __len__(self) -> int:
        return len(self.dt)

    @property
    def n_q(self) -> int:
        return len(self.groups)

    def _evaluate(self, used: np.ndarray) -> tuple[np.ndarray, ...]:
        zero = dict.fromkeys(NOISE_KEYS, 0.0)
        Qs = [_noise_matrix(self.params, self.held),
              _noise_matrix(self.params, ProcessNoise(**{**zero, "q_w": 1.0}))]
        Qs += [_noise_matrix(self.params, ProcessNoise(**{**zero, **g})) for g in self.groups]
        out = []
        for a in range(0, len(used), BLOCK):
            Phi, Gam, Qd = propagate_many(self.params, self.distinct[used[a:a + BLOCK]], Qs)
            m = len(Phi)
            out.append((np.swapaxes(Phi, 1, 2).reshape(m, -1),
                        np.swapaxes(Gam, 1, 2).reshape(m, -1), pack(Qd[0]), pack(Qd[1]),
                        np.stack([pack(U) for U in Qd[2:]], axis=1) if self.groups
                        else np.zeros((m, 0, N_UT))))
        return tuple(np.concatenate(parts) for parts in zip(*out, strict=True))

    def tables(self, used: np.ndarray) -> tuple[np.ndarray, ...]:
        """Φ, Γ, Q_fixed, unit Q_e (m, 81/81/45/45) and the units (m, n_q, 45) of the
        distinct intervals ``used``."""
        if self._cache is not None:
            return tuple(a[used] for a in self._cache)
        return self._evaluate(np.asarray(used))


def step_noise(params: ModelParams, t_s, groups, fixed: ProcessNoise) -> StepNoise:
    """``StepNoise`` of samples at times ``t_s`` for the named ``groups`` (θ_name sets
    each key of its group times its factor), the other keys held at ``fixed``'s."""
    return interval_noise(params, intervals(t_s), groups, fixed)


def interval_noise(params: ModelParams, dt, groups, fixed: ProcessNoise) -> StepNoise:
    """``step_noise`` of step intervals ``dt`` (``intervals``; the distinct ones will do:
    a likelihood reads each step's row by its interval)."""
    groups = tuple(dict(g) for g in (groups.values() if isinstance(groups, dict) else groups))
    seen = {k for g in groups for k in g}
    held = ProcessNoise(**{k: (0.0 if k in seen else getattr(fixed, k)) for k in NOISE_KEYS})
    return StepNoise(params, dt, groups, held)


def step_rows(table: StepNoise, steps: np.ndarray, theta: np.ndarray, tail: np.ndarray,
              directions: list[tuple[int | None, float, float]] | None,
              qd_of_theta: bool = True) -> np.ndarray:
    """The parameter rows of ``steps`` (``tuning.steps._params_sym``'s layout): Φ, Γ,
    Q_d(θ) = Q_fixed + Σ θ_j U_j (Q_fixed alone without ``qd_of_theta``: the step then
    forms it), Q_e, the units U_j, then ``tail`` (the q_w map and θ), then per
    direction (group index or None, ∂q_w, ∂θ_R) its U_v, ∂q_w and ∂θ_R."""
    return distinct_rows(table, table.index[steps], theta, tail, directions, qd_of_theta)


def distinct_rows(table: StepNoise, which: np.ndarray, theta: np.ndarray, tail: np.ndarray,
                  directions: list[tuple[int | None, float, float]] | None,
                  qd_of_theta: bool = True) -> np.ndarray:
    """``step_rows`` of steps given by their distinct intervals ``which`` (indices into
    ``table.distinct``)."""
    used, local = np.unique(which, return_inverse=True)
    phi, gam, fixed, qe, units = table.tables(used)
    m, n_q = len(used), table.n_q
    qd = fixed + np.einsum("j,mjk->mk", theta[:n_q], units) if qd_of_theta else fixed
    parts = [phi, gam, qd, qe, units.reshape(m, n_q * N_UT),
             np.broadcast_to(tail, (m, len(tail)))]
    for j, dqw, droll in directions or ():
        parts += [units[:, j] if j is not None else np.zeros((m, N_UT)),
                  np.full((m, 1), dqw), np.full((m, 1), droll)]
    return np.concatenate(parts, axis=1)[local]
