"""Telemetry at any cadence: the filters' steps with each sample's own Δt.

The paper's closed-form Φ (Eqs. 15–23), Γ (Eq. 31) and Q_d (Eq. 32) hold for any
interval, so a filter need not step on a fixed grid: after the update at t_k it
propagates over Δt_k = t_{k+1} − t_k, whatever that is (0.512 s, 1.0 s, a
jittered 0.49 s or a three-hour gap).  ``StepTable`` holds the step intervals and
evaluates the closed forms once per distinct Δt: a file at one cadence has one, a
file with gaps a handful, a jittered file one per step (evaluated vectorised, a
block of steps at a time, so memory stays bounded).

``per_step`` turns a compiled step whose last argument is the parameter vector
(the same for every step) into one that reads it per step, so one rollout covers
steps of different Δt; ``roll_blocks`` feeds it a block of parameter rows at a
time.  A file on one fixed cadence does not come here: the filter runs with one
``Discretization`` exactly as on the scenario's grid.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

import casadi as ca
import numpy as np

from .model import ModelParams, ProcessNoise
from .transition import _noise_matrix, propagate_many

BLOCK = 16384   # steps per block: its parameter rows (252 doubles each) are ~30 MB


def step_intervals(t_s) -> np.ndarray:
    """Δt after each sample (N,): t_{k+1} − t_k, and for the last sample, whose
    propagation only forms the prior after the run, the step before it."""
    t = np.asarray(t_s, dtype=float)
    if t.ndim != 1 or len(t) < 2:
        raise ValueError("need at least two sample times")
    dt = np.diff(t)
    if not np.all(np.isfinite(dt) & (dt > 0)):
        raise ValueError("sample times must be finite and increasing")
    return np.r_[dt, dt[-1]]


@dataclass(frozen=True, eq=False)
class Discretized:
    """Φ, Γ, Q_d and the unit wheel-noise Q_d (q_w = 1, ``kalman.ExtraNoise``) at each
    of ``dt`` (arrays of shape (len(dt), 9, 9))."""

    dt: np.ndarray
    Phi: np.ndarray
    Gamma: np.ndarray
    Qd: np.ndarray
    Qd_unit: np.ndarray


def discretize_many(p: ModelParams, q: ProcessNoise, dt) -> Discretized:
    """The closed forms of ``transition.discretize`` at every interval of ``dt``,
    vectorised (about 15 µs per interval)."""
    dt = np.asarray(dt, dtype=float).reshape(-1)
    if not np.all(np.isfinite(dt) & (dt > 0)):
        raise ValueError("step intervals must be positive and finite")
    unit_q = ProcessNoise(q_x=0.0, q_z=0.0, q_w=1.0)
    Phi, Gam, (Qd, unit) = propagate_many(p, dt, [_noise_matrix(p, q),
                                                  _noise_matrix(p, unit_q)])
    return Discretized(dt, Phi, Gam, Qd, unit)


def set_distinct(table, dt) -> None:
    """``table.dt`` (checked: 1-D, positive, finite) and its ``distinct`` intervals with
    each step's ``index`` into them, set on a frozen dataclass ``table``."""
    dt = np.asarray(dt, dtype=float)
    if dt.ndim != 1 or not np.all(np.isfinite(dt) & (dt > 0)):
        raise ValueError("step intervals must be a 1-D array, positive and finite")
    distinct, index = np.unique(dt, return_inverse=True)
    object.__setattr__(table, "dt", dt)
    object.__setattr__(table, "distinct", distinct)
    object.__setattr__(table, "index", index)


@dataclass(frozen=True, eq=False)
class StepTable:
    """The step intervals of a run (``dt``, one per sample) and the model they are
    discretised with.  ``distinct`` and ``index`` give each step's interval as one
    of the distinct ones; the closed forms are evaluated per block of steps
    (``block``), for the distinct intervals of that block only."""

    params: ModelParams
    noise: ProcessNoise
    dt: np.ndarray
    distinct: np.ndarray = field(init=False)
    index: np.ndarray = field(init=False)

    def __post_init__(self):
        set_distinct(self, self.dt)

    @classmethod
    def from_times(cls, params: ModelParams, noise: ProcessNoise, t_s) -> StepTable:
        return cls(params, noise, step_intervals(t_s))

    def __len__(self) -> int:
        return len(self.dt)

    def block_of(self, used: np.ndarray) -> Discretized:
        """The discretisation of the distinct intervals ``used`` (indices into
        ``distinct``): a block's worth, evaluated together."""
        return discretize_many(self.params, self.noise, self.distinct[used])

    def cut(self, rows: slice) -> StepTable:
        return StepTable(self.params, self.noise, self.dt[rows])


@lru_cache(maxsize=16)
def per_step(step: ca.Function) -> ca.Function:
    """``step`` (``(s, in_1 … in_m, p) -> (s_next, aux)``) with p read per step:
    ``(s, in_1 … in_m, p, unused) -> (s_next, aux)``, the same expressions (inlined,
    so the compiled code is as lean), for ``rollout.ChunkedRollout``, whose last
    argument is the per-run parameter vector (here one unused number)."""
    args = step.sx_in()
    unused = ca.SX.sym("unused")
    outs = step.call(args)
    # Renamed: the VM's chunk function (``rollout.chunks``) calls its own parameter p.
    names = [step.name_in(i) for i in range(step.n_in())]
    names[-1] += "_step"
    return ca.Function(f"{step.name()}_per_step", [*args, unused], outs,
                       [*names, "unused"], [step.name_out(0), step.name_out(1)])


def roll_blocks(engine, s0: np.ndarray, inputs: list[np.ndarray], n_steps: int,
                params_of, columns: np.ndarray, rows: np.ndarray, row_columns: np.ndarray,
                block: int = BLOCK) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``ChunkedRollout.run_columns`` of a ``per_step`` engine, the parameter rows made
    a block at a time by ``params_of(start, stop)`` ((stop − start, n_p)), so a
    jittered day never holds a parameter row per sample."""
    rows = np.asarray(rows, dtype=np.int64)
    every = np.empty((n_steps, len(columns)))
    kept = np.empty((len(rows), len(row_columns)))
    x = np.asarray(s0, dtype=float).reshape(-1)
    unused = np.zeros(1)
    for start in range(0, n_steps, block):
        stop = min(start + block, n_steps)
        lo, hi = np.searchsorted(rows, [start, stop])
        x, e, k = engine.run_columns(x, [a[start:stop] for a in inputs]
                                     + [params_of(start, stop)], unused, columns,
                                     rows[lo:hi] - start, row_columns)
        every[start:stop], kept[lo:hi] = e, k
    return x, every, kept


def substeps(dt_s, nominal_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each interval of ``dt_s`` cut into equal integration sub-steps no longer than
    ``nominal_s`` (an RK4 step is accurate only over a small part of the nutation
    period): for each sub-step the sample it belongs to (``src``) and its length
    (``h``), and the sub-step each sample starts (``first``)."""
    dt = np.asarray(dt_s, dtype=float)
    subs = np.maximum(np.ceil(dt / nominal_s * (1 - 1e-12)), 1).astype(np.int64)
    first = np.r_[0, np.cumsum(subs)[:-1]]
    src = np.repeat(np.arange(len(dt)), subs)
    return src, first, (dt / subs)[src]


def step_params(base: np.ndarray, index: int, h: np.ndarray):
    """``roll_blocks``' ``params_of`` for a per-step parameter vector: ``base`` with entry
    ``index`` (the step length) set to each step's ``h``."""
    base = np.asarray(base, dtype=float)

    def params_of(a, b):
        p = np.repeat(base[None, :], b - a, axis=0)
        p[:, index] = h[a:b]
        return p
    return params_of
