"""The filters' response to a maneuver flag: a thruster firing that the model does not know.

A thruster event holds a body torque over its duration D; the telemetry says only
when, by a flag set at each sample t_k whose step to t_{k+1} the thruster fires over
(the torque's zero-order hold, as every step input).  The paper's model (Eq. 9) has
no such torque, and the filter meets it in one of three ways (``RESPONSES``):

``inflate``, a white torque.  Eq. 45 sets the intensity of the white roll and yaw
torques as the torque's mean square times its correlation time, q = ⟨N²⟩ T.  A
thruster torque of at most τ, held for at most D_max, has ⟨N²⟩ ≤ τ² and no
correlation beyond D_max, so q_m = τ² D_max ((N m)² s) is added to q_x and q_z
(Eq. 34) on every flagged step and nowhere else.  A white torque of intensity q_m
over a flagged stretch of length D gives the angular momentum a variance q_m D
(Eq. 35, E[w(t) w(t')] = q δ(t − t')), which covers the impulse's square whenever
D ≤ D_max:

    q_m D = τ² D_max D ≥ τ² D² = (τ D)².

In the model's scaled rates (ṙ/ω_n, ẏ/ω_n: momentum over H, Q[ṙ, ṙ] = q_x/H² in
Eq. 34) that is a rate variance q_m D/H² against (τ D/H)²; and over a stretch longer
than the nutation period (2π/ω_n, about 100 s) the torque mostly turns the momentum
and the attitude with it, by the impulse over H, whose variance is again q_m D/H².

``reset``.  At the first sample after a flagged stretch the prior's attitude block
(r, ṙ/ω_n, y, ẏ/ω_n) goes back to the initial prior's (``estimator.initial_sigma``)
and its correlation with the other states to zero; the estimate is kept.  The
attitude as well as the rates: a torque held longer than the nutation period turns
the momentum by impulse/H (0.01 N m for 600 s on 124 N m s is 2.8°) and leaves the
rates only the nutation that follows (τ/H, about 0.005°/s), so a reset of the rates
alone would leave the filter sure of a yaw the impulse has moved.  Roll is measured
at every sample and recovers at once; yaw, in a Sun gap, through the orbit-rate
coupling, as at the start of a run.  h (measured) and the torque states (the
environment's torques, which a thruster does not change) are left alone.  As a model,
which the smoother needs: over the step into that sample the attitude is drawn
afresh, x[a] = x̂⁻[a] + w with w ~ N(0, P0[a, a]) independent of the past: Φ's
attitude rows are zero for that step and Q_d's attitude block is P0's
(``Maneuver.smoother_step``).

``ignore``: nothing (docs/validation.md shows what follows).

The run is cut into segments at each change of the flag (and after each reset), and
each segment is filtered and smoothed as before (``filter_segments``,
``smoother_segments``): no compiled step changes, and telemetry without a flag runs
exactly as it did.  An unknown flag (NaN) counts as firing: inflating costs little,
trusting the model through an unknown impulse much.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..linear.model import RDOT, YDOT, ModelParams, ProcessNoise, R, Y
from ..linear.steps import StepTable
from ..linear.transition import Discretization, discretize

RESPONSES = ("inflate", "reset", "ignore")
ATTITUDE = (R, RDOT, Y, YDOT)


def firing(flag) -> np.ndarray:
    """The flag as booleans: anything but 0 is firing, NaN (unknown) included."""
    return np.asarray(flag, dtype=float) != 0


def maneuver_intensity(torque_Nm: float, max_duration_s: float) -> float:
    """q_m = τ² D_max ((N m)² s), the white torque that covers the impulse τ D of any
    flagged stretch D ≤ D_max (module doc)."""
    return float(torque_Nm) ** 2 * float(max_duration_s)


def _pack(P: np.ndarray) -> np.ndarray:
    i, j = np.triu_indices(P.shape[-1])
    return P[..., i, j]


def _unpack(p: np.ndarray) -> np.ndarray:
    p = np.asarray(p, dtype=float)
    n = int(round((np.sqrt(8 * p.shape[-1] + 1) - 1) / 2))
    i, j = np.triu_indices(n)
    P = np.zeros(p.shape[:-1] + (n, n))
    P[..., i, j] = p
    P[..., j, i] = p
    return P


@dataclass(frozen=True, eq=False)
class Maneuver:
    """The response per step k (the step from sample k): ``inflate[k]``, the step adds
    the white torque ``noise`` (q_x = q_z = q_m); ``reset[k]``, the prior at sample
    k + 1 has its ``states`` block set to ``prior`` and their correlations to zero.
    ``params`` discretises ``noise`` at a step's Δt.  ``states`` and ``prior``
    default to the paper's attitude (``ATTITUDE``); the EKF gives its own."""

    inflate: np.ndarray
    reset: np.ndarray
    noise: ProcessNoise | None
    params: ModelParams | None
    prior: np.ndarray
    states: tuple[int, ...] = ATTITUDE

    @classmethod
    def of(cls, flag, response: str, q_m: float, params: ModelParams | None,
           prior: np.ndarray, states: tuple[int, ...] = ATTITUDE) -> Maneuver | None:
        """The response to ``flag`` (N,) (None for ``ignore``).  A reset needs the flag
        of the sample after each step: the last sample's is not known here and no
        reset follows it, so a window's maneuver is formed on its padded telemetry
        and ``cut`` to it."""
        if response not in RESPONSES:
            raise ValueError(f"response must be one of {RESPONSES}, not {response!r}")
        if response == "ignore":
            return None
        f = firing(flag)
        if f.ndim != 1:
            raise ValueError("the maneuver flag must be one value per sample")
        off = np.zeros(len(f), dtype=bool)
        if response == "inflate":
            if not (np.isfinite(q_m) and q_m > 0):
                raise ValueError("the maneuver's torque intensity must be positive")
            return cls(f, off, ProcessNoise(q_x=float(q_m), q_z=float(q_m), q_w=0.0),
                       params, np.asarray(prior, dtype=float), tuple(states))
        reset = off.copy()
        reset[:-1] = f[:-1] & ~f[1:]
        return cls(off, reset, None, params, np.asarray(prior, dtype=float), tuple(states))

    def __post_init__(self):
        k = len(self.states)
        if np.shape(self.prior) != (k, k):
            raise ValueError(f"the reset prior must be {k}×{k}")
        if np.shape(self.inflate) != np.shape(self.reset):
            raise ValueError("inflate and reset must have one value per sample")

    def __len__(self) -> int:
        return len(self.inflate)

    @property
    def active(self) -> bool:
        """Whether any step responds (a window without a firing runs as before)."""
        return bool(self.inflate.any() or self.reset.any())

    def cut(self, rows) -> Maneuver:
        return replace(self, inflate=self.inflate[rows], reset=self.reset[rows])

    def reset_prior(self, P: np.ndarray) -> np.ndarray:
        """P with the ``states`` block the prior's and their correlations zero."""
        P = np.array(P, dtype=float, copy=True)
        i = list(self.states)
        P[i, :] = 0.0
        P[:, i] = 0.0
        P[np.ix_(i, i)] = self.prior
        return P

    def discretization(self, disc, inflated: bool):
        """``disc`` (a ``Discretization`` or a ``StepTable``) with the white torque added
        to Q_d when ``inflated``."""
        if not inflated:
            return disc
        if isinstance(disc, StepTable):
            n = disc.noise
            return StepTable(disc.params, replace(n, q_x=n.q_x + self.noise.q_x,
                                                  q_z=n.q_z + self.noise.q_z), disc.dt)
        added = discretize(self.params, self.noise, disc.dt).Qd
        return Discretization(disc.dt, disc.Phi, disc.Gamma, disc.Qd + added)

    def smoother_step(self, Phi, Gamma, Q, x, P, u, x_after, P_after=None):
        """The RTS step back over a reset, from the smoothed state (and packed P) at
        sample k + 1 to sample k, whose filtered x and P (full) are given, with the
        step's Φ, Γ and total Q_d (any number of states n; Γ n×9): the model of the
        module doc, Φ_r = Φ with the reset rows zero, and the prediction the filter
        made (the estimate kept, its P reset).  Returns the smoothed x and P (packed;
        None without ``P_after``)."""
        x, P, u = (np.asarray(v, dtype=float) for v in (x, P, u))
        x_pred = Phi @ x + Gamma @ u
        P_pred = self.reset_prior(Phi @ P @ Phi.T + Q)
        Phi_r = np.array(Phi, dtype=float, copy=True)
        Phi_r[list(self.states), :] = 0.0
        C = np.linalg.solve(P_pred, Phi_r @ P).T        # P Φ_rᵀ P_pred⁻¹
        xs = x + C @ (np.asarray(x_after, dtype=float) - x_pred)
        if P_after is None:
            return xs, None
        Ps = P + C @ (_unpack(P_after) - P_pred) @ C.T
        return xs, _pack(0.5 * (Ps + Ps.T))


@dataclass(frozen=True)
class Segment:
    """Samples ``rows`` of one kind: every step inflated or none, and whether the prior
    after the last one is reset."""

    rows: slice
    inflated: bool
    reset_after: bool


def segments(m: Maneuver) -> list[Segment]:
    """The run cut where the inflation changes and after each reset."""
    n = len(m)
    cuts = np.flatnonzero((m.inflate[1:] != m.inflate[:-1]) | m.reset[:-1]) + 1
    bounds = [0, *cuts.tolist(), n]
    return [Segment(slice(a, b), bool(m.inflate[a]), bool(m.reset[b - 1]))
            for a, b in zip(bounds[:-1], bounds[1:], strict=True)]


def local_rows(rows, seg: slice):
    """The sample indices ``rows`` inside ``seg``, counted from its start (None stays)."""
    if rows is None:
        return None
    rows = np.asarray(rows, dtype=np.int64)
    return rows[(rows >= seg.start) & (rows < seg.stop)] - seg.start


def filter_segments(m: Maneuver, run, x0, P0, rows, covariance_rows,
                    per_sample: tuple[str, ...]):
    """A filter over ``m``'s segments: ``run(seg, inflated, x0, P0, rows,
    covariance_rows)`` filters the samples ``seg`` from the prior x0, P0 (rows local
    to it) and returns a result with ``x_next``, ``P_next``; each segment starts from
    the prior the one before ended with, reset where the response says.  The results'
    ``per_sample`` fields are joined; the prior after the last is the run's."""
    parts, x, P = [], x0, P0
    for seg in segments(m):
        part = run(seg.rows, seg.inflated, x, P, local_rows(rows, seg.rows),
                   local_rows(covariance_rows, seg.rows))
        x, P = part.x_next, part.P_next
        if seg.reset_after:
            P = m.reset_prior(P)
        parts.append(part)
    joined = {f: np.concatenate([getattr(p, f) for p in parts])
              for f in per_sample if getattr(parts[-1], f) is not None}
    return replace(parts[-1], x_next=x, P_next=P, **joined)


def smoother_segments(m: Maneuver, smooth, reset_step, covariance: bool, x_after=None,
                      P_after=None) -> tuple[np.ndarray, np.ndarray | None]:
    """An RTS smoother over ``m``'s segments, the last first: ``smooth(seg, inflated,
    x_after, P_after)`` smooths the samples ``seg`` (a result with ``x`` and packed
    ``P_packed``) from the smoothed state after them (None at the history's end);
    ``reset_step(k, inflated, x_after, P_after)`` is the step back over a reset
    into sample k + 1 (``Maneuver.smoother_step``).  Returns the smoothed x and P."""
    xs, Ps = [], []
    after = (x_after, P_after)
    for seg in reversed(segments(m)):
        a, b = seg.rows.start, seg.rows.stop
        tail_x, tail_P = [], []
        if seg.reset_after and after[0] is not None:
            xk, Pk = reset_step(b - 1, seg.inflated, *after)
            after, b = (xk, Pk), b - 1
            tail_x, tail_P = [xk[None]], [Pk[None]] if covariance else []
        head_x, head_P = [], []
        if b > a:
            r = smooth(slice(a, b), seg.inflated, *after)
            head_x, head_P = [r.x], [r.P_packed] if covariance else []
            after = (r.x[0], r.P_packed[0] if covariance else None)
        xs = head_x + tail_x + xs
        Ps = head_P + tail_P + Ps
    return np.concatenate(xs), np.concatenate(Ps) if covariance else None
