"""The paper's 9-state Kalman filter (Section 5) and an RTS smoother.

Each step, at t_k: sequential scalar measurement updates of roll, yaw and h,
each in Joseph form (Eq. 37, with the gain of Eq. 38 and the state update of
Eq. 36); a missing value (NaN) means no update.  Then propagation to t_{k+1}
with Eqs. 31–32: x⁻ = Φ x⁺ + Γ ū_k, P⁻ = Φ P⁺ Φᵀ + Q_d, with ū held over the step.

Joseph form (I − KG) P (I − KG)ᵀ + K R Kᵀ keeps P symmetric and positive
definite in floating point, where the short form (I − KG) P does not; with
scalar updates and G a unit row it costs little.

The step is one CasADi function (``kalman.steps``) rolled out by ``rollout``
(compiled once, Φ, Γ and Q_d entering as parameters), so a day of 0.512 s data
takes a fraction of a second; the tests hold it to a plain-numpy filter of their
own (tests/estimator/dense_reference.py).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..linear.model import N_STATES
from ..linear.steps import StepTable, roll_blocks
from .maneuver import Maneuver, filter_segments, smoother_segments
from .steps import _IU, N_UT, PHI_PATTERN, _engine, pack, pack_params, unpack


@dataclass(frozen=True)
class ExtraNoise:
    """Process noise added on chosen steps: step k adds ``scale[k] · Qd_unit``.

    For a telemetry dropout the wheel torque N_w* is bridged, not measured, so
    its uncertainty is added as the paper's wheel-torque noise q_w (Eq. 34, which
    drives ẏ and h together) on the bridged steps only: ``Qd_unit`` is Q_d for
    q_w = 1 (N m)² s and ``scale`` the q_w of each step (zero elsewhere, which
    leaves those steps bit for bit as without it).

    ``maneuver`` (``kalman.maneuver``): the response to a thruster-firing flag, which
    rides along with the dropout noise to every filter and smoother of the run
    (None: no flag, or one ignored)."""

    scale: np.ndarray       # (N,)
    Qd_unit: np.ndarray     # (9, 9)
    maneuver: Maneuver | None = None

    def cut(self, rows) -> ExtraNoise:
        """The same noise on samples ``rows`` only."""
        return ExtraNoise(self.scale[rows], self.Qd_unit,
                          None if self.maneuver is None else self.maneuver.cut(rows))


def _extra(extra: ExtraNoise | None, n: int) -> tuple[np.ndarray, np.ndarray]:
    if extra is None:
        return np.zeros(n), np.zeros((N_STATES, N_STATES))
    scale = np.asarray(extra.scale, dtype=float)
    if scale.shape != (n,) or not np.all(np.isfinite(scale) & (scale >= 0)):
        raise ValueError(f"extra noise scale must be ({n},), finite and non-negative")
    return scale, np.asarray(extra.Qd_unit, dtype=float)



@dataclass(frozen=True)
class Measurements:
    """Roll (rad), yaw (rad) and h (N m s) per sample, NaN where missing, and their
    variances (scalars or per-sample arrays; rad², rad², (N m s)²)."""

    roll_rad: np.ndarray
    yaw_rad: np.ndarray
    h_Nms: np.ndarray
    var_roll: float | np.ndarray
    var_yaw: float | np.ndarray
    var_h: float | np.ndarray

    def z(self) -> np.ndarray:
        return np.column_stack([self.roll_rad, self.yaw_rad, self.h_Nms]).astype(float)

    def r(self) -> np.ndarray:
        n = len(self.roll_rad)
        cols = [np.broadcast_to(np.asarray(v, dtype=float), (n,))
                for v in (self.var_roll, self.var_yaw, self.var_h)]
        r = np.column_stack(cols)
        if np.any(~np.isfinite(r) & np.isfinite(self.z())) or np.any(r[np.isfinite(r)] <= 0):
            raise ValueError("measurement variances must be positive and finite where "
                             "a measurement is present")
        return np.where(np.isfinite(r), r, 1.0)


class _PackedHistory:
    """σ and P views of a (N, 45) packed covariance history."""

    P_packed: np.ndarray

    @property
    def sigma(self) -> np.ndarray:
        """1σ of each state, (N, 9)."""
        return np.sqrt(self.P_packed[:, _DIAG])

    @property
    def P(self) -> np.ndarray:
        return unpack(self.P_packed)


_DIAG = [k for k, (i, j) in enumerate(zip(*_IU, strict=True)) if i == j]


@dataclass(frozen=True)
class FilterResult(_PackedHistory):
    """A-posteriori history at each sample, innovations ν and their variances S
    (columns roll, yaw, h; NaN where no update), and the prior after the last step."""

    x: np.ndarray          # (N, 9)
    P_packed: np.ndarray   # (N, 45), see ``unpack``
    innovations: np.ndarray
    innovation_var: np.ndarray
    x_next: np.ndarray
    P_next: np.ndarray
    backend: str


@dataclass(frozen=True)
class SmootherResult(_PackedHistory):
    x: np.ndarray
    P_packed: np.ndarray | None   # None from rts_smoother(covariance=False)


def _inputs(u, n) -> np.ndarray:
    if u is None:
        return np.zeros((n, N_STATES))
    u = np.asarray(u, dtype=float)
    if u.shape != (n, N_STATES) or not np.all(np.isfinite(u)):
        raise ValueError(f"inputs must be a finite ({n}, {N_STATES}) array (Eq. 12a)")
    return u


def kalman_filter(meas: Measurements, disc, x0, P0, u=None, backend: str | None = None,
                  chunk: int = 4096, rows=None, extra: ExtraNoise | None = None,
                  covariance_rows=None) -> FilterResult:
    """Run the filter over every sample.  ``disc`` has Φ, Γ, Q_d for the sample
    interval (``estimator.transition.discretize``); x0, P0 are the prior at the first
    sample; ``u`` the (N, 9) input vectors of Eq. 12a (zero if None).  With ``rows``
    (increasing sample indices) the history holds only those samples, bit for bit
    the full run's, without the full history's memory; with ``covariance_rows``
    instead, only ``P_packed`` is cut to those samples (the estimates, innovations and
    their variances stay at every sample), for a run that needs the covariance only
    where it forms the NEES.  ``extra`` adds process noise on chosen steps
    (``ExtraNoise``: a telemetry dropout) and carries the response to a maneuver flag
    (run segment by segment, ``maneuver.filter_segments``)."""
    m = None if extra is None else extra.maneuver
    if m is not None and m.active:
        def run(seg, inflated, x, P, seg_rows, seg_cov_rows):
            return kalman_filter(cut_measurements(meas, seg),
                                 m.discretization(_cut_disc(disc, seg), inflated), x, P,
                                 u=None if u is None else np.asarray(u)[seg],
                                 backend=backend, chunk=chunk, rows=seg_rows,
                                 extra=_plain(extra, seg), covariance_rows=seg_cov_rows)
        return filter_segments(m, run, x0, P0, rows, covariance_rows, _PER_SAMPLE)
    z, r = meas.z(), meas.r()
    n = len(z)
    x0, P0 = np.asarray(x0, dtype=float), np.asarray(P0, dtype=float)
    if x0.shape != (N_STATES,) or P0.shape != (N_STATES, N_STATES):
        raise ValueError("x0 must have 9 elements and P0 be 9×9")
    engine = _engine("filter", chunk, backend)
    s0 = np.concatenate([x0, pack(0.5 * (P0 + P0.T))])
    present = np.isfinite(z)
    scale, Qd_unit = _extra(extra, n)
    inputs = [np.where(present, z, 0.0), present.astype(float), r, _inputs(u, n), scale]
    if isinstance(disc, StepTable):
        return _filter_per_step(disc, engine.backend, chunk, s0, inputs, present, rows,
                                covariance_rows)
    p = pack_params(disc, Qd_unit)
    if covariance_rows is not None:
        if rows is not None:
            raise ValueError("rows and covariance_rows exclude each other")
        # x (9), then ν and S (3 each) after the packed covariance: every sample.
        last, aux, P = engine.run_columns(
            s0, inputs, p, np.r_[0:N_STATES, N_STATES + N_UT:engine.n_aux],
            np.asarray(covariance_rows, dtype=np.int64), np.arange(N_STATES, N_STATES + N_UT))
        nu, S = aux[:, N_STATES:N_STATES + 3], aux[:, N_STATES + 3:]
    else:
        rows = None if rows is None else np.asarray(rows, dtype=np.int64)
        last, aux = engine.run_kept(s0, inputs, p, rows)
        if rows is not None:
            present = present[rows]
        P = aux[:, N_STATES:N_STATES + N_UT]
        nu, S = aux[:, N_STATES + N_UT:N_STATES + N_UT + 3], aux[:, -3:]
    nu[~present] = np.nan
    S[~present] = np.nan
    return FilterResult(aux[:, :N_STATES], P, nu, S, last[:N_STATES], unpack(last[N_STATES:]),
                        engine.backend)


def rts_smoother(result: FilterResult, disc, u=None, backend: str | None = None,
                 chunk: int = 4096, extra: ExtraNoise | None = None,
                 covariance: bool = True, x_after: np.ndarray | None = None,
                 P_after: np.ndarray | None = None) -> SmootherResult:
    """Rauch–Tung–Striebel smoother over a stored filter history (with the
    filter's own ``u`` and ``extra``).  ``covariance=False`` smooths the state alone
    (``smoother_x_step``; ``P_packed`` is None), about four times faster; with it,
    ``x_after`` is the smoothed state one step after the history (where a following
    stretch, smoothed first, begins), from which the recursion goes back over every
    sample: the smoother of the joined history, without joining it.  Without it the
    last filtered state is its own smoothed value.  With ``covariance``, ``x_after``
    comes with ``P_after`` (packed), the smoothed covariance there.  A maneuver
    response in ``extra`` is the filter's, segment by segment
    (``maneuver.smoother_segments``)."""
    m = None if extra is None else extra.maneuver
    if m is not None and m.active:
        return _smooth_maneuver(m, result, disc, u, backend, chunk, extra, covariance,
                                x_after, P_after)
    n = len(result.x)
    if x_after is not None and covariance and P_after is None:
        raise ValueError("x_after with covariance needs P_after")
    if n < 2 and x_after is None:  # nothing to smooth: the last estimate is the smoothed one
        return SmootherResult(result.x.copy(),
                              result.P_packed.copy() if covariance else None)
    u = _inputs(u, n)
    scale, Qd_unit = _extra(extra, n)
    kind = "smoother" if covariance else "smoother_x"
    engine = _engine(kind, chunk, backend)
    # Backwards: step k uses the filter's k-th posterior and input, for k = n−2 … 0
    # (from n−1 when the smoothed state after the history is given).
    rev = slice(n - 2 if x_after is None else n - 1, None, -1)
    s0 = _smoother_start(result, covariance, x_after, P_after)
    backwards = [result.x[rev], result.P_packed[rev], u[rev], scale[rev]]
    if isinstance(disc, StepTable):
        if len(disc) != n:
            raise ValueError(f"the step table has {len(disc)} steps, the history {n}")
        # Step k's interval is that after sample k, read in the same reversed order.
        steps = np.arange(n)[rev]
        engine = _engine(kind + "_per_step", chunk, backend)
        _, aux, _ = roll_blocks(engine, s0, backwards, len(steps),
                                lambda a, b: _param_rows(disc, steps[a:b]),
                                np.arange(engine.n_aux), np.arange(0), np.arange(0))
    else:
        _, aux = engine.run_final(s0, backwards, pack_params(disc, Qd_unit))
    if x_after is not None:
        if covariance:
            return SmootherResult(aux[::-1, :N_STATES].copy(), aux[::-1, N_STATES:].copy())
        return SmootherResult(aux[::-1].copy(), None)
    xs = np.vstack([aux[::-1, :N_STATES], result.x[-1:]])
    if not covariance:
        return SmootherResult(xs, None)
    Ps = np.vstack([aux[::-1, N_STATES:], result.P_packed[-1:]])
    return SmootherResult(xs, Ps)


_PER_SAMPLE = ("x", "P_packed", "innovations", "innovation_var")


def cut_measurements(meas: Measurements, rows) -> Measurements:
    """The measurements of samples ``rows`` (a scalar variance stays)."""
    return Measurements(*(v[rows] if np.ndim(v) else v for v in
                          (meas.roll_rad, meas.yaw_rad, meas.h_Nms, meas.var_roll,
                           meas.var_yaw, meas.var_h)))


def _cut_disc(disc, rows):
    return disc.cut(rows) if isinstance(disc, StepTable) else disc


def _plain(extra: ExtraNoise, rows) -> ExtraNoise:
    """A segment's dropout noise, without the maneuver the segments already answer."""
    return ExtraNoise(extra.scale[rows], extra.Qd_unit)


def step_matrices(disc, k: int, extra: ExtraNoise | None) -> tuple[np.ndarray, ...]:
    """Φ, Γ and the total Q_d (with the dropout noise) of step k of ``disc``."""
    if isinstance(disc, StepTable):
        d = disc.block_of(disc.index[[k]])
        Phi, Gam, Qd, unit = d.Phi[0], d.Gamma[0], d.Qd[0], d.Qd_unit[0]
    else:
        Phi, Gam, Qd = disc.Phi, disc.Gamma, disc.Qd
        unit = None if extra is None else extra.Qd_unit
    e = 0.0 if extra is None else float(extra.scale[k])
    return Phi, Gam, Qd + e * unit if e else Qd


def _smooth_maneuver(m, result, disc, u, backend, chunk, extra, covariance, x_after,
                     P_after) -> SmootherResult:
    n = len(result.x)
    u = _inputs(u, n)

    def smooth(seg, inflated, xa, Pa):
        part = FilterResult(result.x[seg], result.P_packed[seg], result.innovations[seg],
                            result.innovation_var[seg], result.x_next, result.P_next,
                            result.backend)
        return rts_smoother(part, m.discretization(_cut_disc(disc, seg), inflated), u[seg],
                            backend, chunk, _plain(extra, seg), covariance, xa, Pa)

    def reset_step(k, inflated, xa, Pa):
        Phi, Gam, Q = step_matrices(m.discretization(disc, inflated), k, extra)
        return m.smoother_step(Phi, Gam, Q, result.x[k], unpack(result.P_packed[k]), u[k],
                               xa, Pa if covariance else None)

    x, P = smoother_segments(m, smooth, reset_step, covariance, x_after, P_after)
    return SmootherResult(x, P)


def _smoother_start(result, covariance: bool, x_after, P_after) -> np.ndarray:
    """Where the backward recursion starts: the last filtered state (and covariance),
    or the smoothed ones one step after the history."""
    if x_after is None:
        last = [result.x[-1], result.P_packed[-1]] if covariance else [result.x[-1]]
    else:
        last = [x_after, P_after] if covariance else [x_after]
    return np.concatenate([np.asarray(v, dtype=float) for v in last])


def _param_rows(table: StepTable, steps: np.ndarray) -> np.ndarray:
    """``pack_params`` of each of ``steps``' intervals, (len(steps), 252): each distinct
    interval evaluated once (``StepTable.block``), with its own unit wheel noise (the
    ``ExtraNoise.Qd_unit`` of that Δt)."""
    steps = np.asarray(steps)
    used, local = np.unique(table.index[steps], return_inverse=True)
    d = table.block_of(used)
    n = len(used)
    Phi, Gam = np.swapaxes(d.Phi, 1, 2), np.swapaxes(d.Gamma, 1, 2)  # column-major rows
    off = np.abs(np.where(PHI_PATTERN, 0.0, d.Phi)).max(initial=0.0)
    if off > 1e-12 * np.abs(d.Phi).max():
        raise ValueError(f"Phi has entries outside the structure of Eq. 15 ({off:g})")
    rows = np.concatenate([Phi.reshape(n, -1), Gam.reshape(n, -1), pack(d.Qd),
                           pack(d.Qd_unit)], axis=1)
    return rows[local]


def _filter_per_step(table: StepTable, backend: str, chunk: int, s0, inputs, present,
                     rows, covariance_rows) -> FilterResult:
    """``kalman_filter`` with each step's own interval (``steps``); the history
    kept as ``rows`` or ``covariance_rows`` say."""
    n = len(present)
    if len(table) != n:
        raise ValueError(f"the step table has {len(table)} steps, the telemetry {n}")
    engine = _engine("filter_per_step", chunk, backend)
    every_col = np.arange(engine.n_aux)
    if covariance_rows is not None:
        if rows is not None:
            raise ValueError("rows and covariance_rows exclude each other")
        cols = np.r_[0:N_STATES, N_STATES + N_UT:engine.n_aux]
        kept_rows, kept_cols = np.asarray(covariance_rows, np.int64), every_col[N_STATES:
                                                                               N_STATES + N_UT]
    elif rows is None:
        cols, kept_rows, kept_cols = every_col, np.arange(0), np.arange(0)
    else:
        cols, kept_rows, kept_cols = np.arange(0), np.asarray(rows, np.int64), every_col
    last, every, kept = roll_blocks(engine, s0, inputs, n,
                                    lambda a, b: _param_rows(table, np.arange(a, b)),
                                    cols, kept_rows, kept_cols)
    if covariance_rows is not None:
        x, P = every[:, :N_STATES], kept
        nu, S = every[:, N_STATES:N_STATES + 3], every[:, N_STATES + 3:]
    else:
        aux = every if rows is None else kept
        if rows is not None:
            present = present[kept_rows]
        x, P = aux[:, :N_STATES], aux[:, N_STATES:N_STATES + N_UT]
        nu, S = aux[:, N_STATES + N_UT:N_STATES + N_UT + 3], aux[:, -3:]
    nu, S = nu.copy(), S.copy()
    nu[~present] = np.nan
    S[~present] = np.nan
    return FilterResult(x, P, nu, S, last[:N_STATES], unpack(last[N_STATES:]), engine.backend)
