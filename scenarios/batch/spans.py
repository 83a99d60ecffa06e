"""Chained batches over a telemetry record: the spans, each batch's a priori, the
solve (``estimator.batch``, ``estimator.batch.nonlinear``), and the solutions joined
into one history.

Span j fits the samples with t in [t_0 + j (L − O), t_0 + j (L − O) + L), L the span
and O the overlap.  Its a priori is, with ``batch.apriori: chain``, the previous
batch's solution and covariance propagated to its epoch (as Orekit's sequential
batch takes it; the first batch, and any after an unconverged one, take the
filter's prior), else the filter's prior.  Each solution is propagated one sample
past its span, so the next epoch's a priori exists without overlap.  A sample
belongs to the latest batch whose epoch is not after it: with an overlap, the
later batch's solution there (the earlier one's is the overlap comparison).  A
remainder shorter than half a span is fitted by the last batch, not by one of its
own.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from dynprop.estimator.batch.linear import (
    BatchError,
    BatchSolution,
    LinearData,
    Prior,
    linear_batch,
    linear_start,
)
from dynprop.estimator.batch.nonlinear import NonlinearData, Options, nonlinear_batch
from dynprop.estimator.kalman.filter import Measurements
from dynprop.estimator.linear.model import N_STATES
from dynprop.estimator.linear.steps import StepTable

from ..bridge.batch import linear_consider, linear_data, nonlinear_consider, nonlinear_data
from ..bridge.inputs import initial_prior
from ..config import build
from ..config.schema import Scenario
from ..records import Measured
from ..units import RAD2DEG

PAPER_MIN_SPAN_H = 8.0   # Section 5: "at least one-third of an orbit, or 8 hours"


@dataclass(frozen=True)
class Span:
    index: int
    a: int          # first sample fitted
    b: int          # one past the last sample fitted
    stop: int       # one past the last sample of the propagated history

    @property
    def fitted(self) -> slice:
        return slice(self.a, self.b)


def plan_spans(t_s: np.ndarray, span_h: float, overlap_h: float) -> list[Span]:
    """The spans of ``t_s`` (module doc); a span that would hold fewer than two
    samples is a ``BatchError`` naming the telemetry's spacing."""
    t = np.asarray(t_s, dtype=float)
    span_s, overlap_s = span_h * 3600.0, overlap_h * 3600.0
    steps = np.diff(t)
    if len(t) < 2:
        raise BatchError("the telemetry has fewer than two samples: nothing to fit")
    if span_s < 2 * steps.max():
        raise BatchError(f"batch.span_h: {span_h:g} h is shorter than the data allow: the "
                         f"telemetry's samples are up to {steps.max():g} s apart, and a span "
                         "needs at least two of them (and the paper's 8 h to see yaw "
                         "through roll)")
    bounds, j = [], 0
    while True:
        start = t[0] + j * (span_s - overlap_s)
        a, b = (int(v) for v in np.searchsorted(t, [start, start + span_s]))
        if bounds and t[-1] - start < 0.5 * span_s:
            # A remainder under half a span joins the last batch (a 48 h run's sample
            # at exactly 48 h is not a batch of its own).
            bounds[-1] = (bounds[-1][0], len(t))
            break
        bounds.append((a, b))
        if b >= len(t):
            break
        j += 1
    return [Span(i, a, b, min(b + 1, len(t))) for i, (a, b) in enumerate(bounds)]


def _cut_linear(d: LinearData, span: Span) -> LinearData:
    sl = slice(span.a, span.stop)
    extra = span.stop - span.b    # the sample past the span: propagated, not fitted
    meas = d.meas

    def cut(v, blank):
        if not np.ndim(v):
            return v
        v = np.array(v[sl], dtype=float)
        if extra and blank:
            v[-extra:] = np.nan
        return v

    m = Measurements(cut(meas.roll_rad, True), cut(meas.yaw_rad, True), cut(meas.h_Nms, True),
                     cut(meas.var_roll, False), cut(meas.var_yaw, False),
                     cut(meas.var_h, False))
    disc = d.disc.cut(sl) if isinstance(d.disc, StepTable) else d.disc
    return LinearData(m, d.u[sl], disc)


def _cut_nonlinear(d: NonlinearData, span: Span) -> NonlinearData:
    sl = slice(span.a, span.stop)
    z = d.z[sl].copy()
    z[span.b - span.a:] = np.nan
    return NonlinearData(z, d.r[sl], d.u[sl], d.pitch[sl], d.params,
                         None if d.dt_s is None else d.dt_s[sl])


@dataclass(frozen=True)
class BatchRun:
    """Every batch of a record and the joined history at ``rows`` (global sample
    indices): x (NaN where the owning batch did not converge), the owner of each
    row, and the covariance with and without the consider parameters; and each
    batch's overlap comparison with the one before (``overlap``).  The solutions keep
    their epoch figures only (their histories are read into these as each is solved)."""

    scenario: Scenario
    model: str
    spans: list[Span]
    solutions: list[BatchSolution]
    priors: list[str]          # where each batch's a priori came from
    x_rows: np.ndarray
    owner_rows: np.ndarray
    rows: np.ndarray
    P_rows: np.ndarray
    P_consider_rows: np.ndarray
    overlaps: list[dict | None]

    @property
    def sigma_rows(self) -> np.ndarray:
        """1σ of each state at ``rows`` (R, 9); NaN where the batch did not converge."""
        return np.sqrt(np.diagonal(self.P_rows, axis1=1, axis2=2))

    @property
    def sigma_consider_rows(self) -> np.ndarray:
        """The same with the consider parameters."""
        return np.sqrt(np.diagonal(self.P_consider_rows, axis1=1, axis2=2))


def _check_lengths(span_h: float, overlap_h: float) -> None:
    # The command line checks its --span-h and --overlap-h; dynprop.batch() and other
    # callers come here directly (a NaN or infinite span made an IndexError).
    if not (np.isfinite(span_h) and span_h > 0):
        raise BatchError(f"batch.span_h: {span_h:g} h must be a positive number of hours")
    if not (np.isfinite(overlap_h) and overlap_h >= 0):
        raise BatchError(f"batch.overlap_h: {overlap_h:g} h must be a positive number of "
                         "hours or 0")
    if overlap_h >= span_h:
        raise BatchError(f"batch.overlap_h: {overlap_h:g} h must be shorter than batch.span_h "
                         f"({span_h:g} h)")


def solve_spans(s: Scenario, tel: Measured, pitch_rad, rows=(), t_s=None,
                model: str | None = None, span_h: float | None = None,
                overlap_h: float | None = None, on_grid: bool = True) -> BatchRun:
    """Every batch of the telemetry ``tel`` (SI, at times ``t_s``; on the scenario's
    grid unless ``on_grid`` is False), by ``batch``'s settings unless given: the
    record's data formed whole and cut span by span (``batch.span_data`` forms each
    span's from a file instead)."""
    model = model or s.batch.model
    n = len(tel.roll_rad)
    t = np.asarray(t_s, dtype=float) if t_s is not None else s.sample_interval_s * np.arange(n)
    own_t = None if on_grid else t
    whole = {}

    def data_of(sp: Span) -> SpanData:
        if not whole:
            whole["lin"] = linear_data(s, tel, own_t)
            whole["cases"] = linear_consider(s, tel, own_t) if model == "linear" else ()
            whole["nl"] = (nonlinear_data(s, tel, pitch_rad, own_t) if model == "nonlinear"
                           else None)
        return cut_span(whole["lin"], whole["cases"], whole["nl"], sp)

    return solve_chain(s, t, data_of, rows, model, span_h, overlap_h)


@dataclass(frozen=True)
class SpanData:
    """What a batch fits: the paper model's data over the span and the sample past it,
    the consider cases' (linear model), the nonlinear model's (or None)."""

    linear: LinearData
    cases: tuple
    nonlinear: NonlinearData | None


def cut_span(lin: LinearData, cases: tuple, nl: NonlinearData | None, sp: Span) -> SpanData:
    """The span ``sp`` of data formed over more samples (``sp`` counted from their
    first)."""
    return SpanData(_cut_linear(lin, sp),
                    tuple(type(c)(c.name, c.sigma, c.delta, _cut_linear(c.plus, sp),
                                  _cut_linear(c.minus, sp)) for c in cases),
                    None if nl is None else _cut_nonlinear(nl, sp))


def _lengths(s: Scenario, span_h, overlap_h) -> tuple[float, float]:
    return (s.batch.span_h if span_h is None else span_h,
            s.batch.overlap_h if overlap_h is None else overlap_h)


def _overlap(tail: np.ndarray | None, x: np.ndarray) -> dict | None:
    """A batch against the one before where both fitted the samples (``tail``: the
    earlier one's states there): the RMS and largest difference of their roll and
    yaw, the overlap comparison of definitive solutions."""
    if tail is None or not len(tail):
        return None
    d = (x[:len(tail)] - tail)[:, [0, 2]] * RAD2DEG
    return {"samples": int(len(tail)),
            "roll_rms_deg": float(np.sqrt(np.mean(d[:, 0] ** 2))),
            "yaw_rms_deg": float(np.sqrt(np.mean(d[:, 1] ** 2))),
            "roll_max_deg": float(np.max(np.abs(d[:, 0]))),
            "yaw_max_deg": float(np.max(np.abs(d[:, 1])))}


def _light(sol: BatchSolution) -> BatchSolution:
    """A solution without its histories (read into the ``BatchRun`` already): empty
    arrays of their own, not views, which would keep the span's history alive."""
    empty = np.empty((0, N_STATES, N_STATES))
    return replace(sol, x=np.empty((0, N_STATES)), P_rows=empty,
                   P_consider_rows=None if sol.P_consider_rows is None else empty,
                   S_rows=None)


def solve_chain(s: Scenario, t: np.ndarray, data_of, rows=(), model: str | None = None,
                span_h: float | None = None, overlap_h: float | None = None) -> BatchRun:
    """Every batch of a record at times ``t``, in turn, ``data_of(span)`` giving each
    one's ``SpanData``: only one span's data and solution are held at a time."""
    cfg = s.batch
    model = model or cfg.model
    span_h, overlap_h = _lengths(s, span_h, overlap_h)
    _check_lengths(span_h, overlap_h)
    spans = plan_spans(t, span_h, overlap_h)
    params, _ = build.estimator_model(s)
    x_bar, P_bar = initial_prior(s, params)
    sigma_c = nonlinear_consider(s)
    rows = np.asarray(rows, dtype=np.int64)
    # A sample belongs to the latest batch whose epoch is not after it.
    owner_rows = np.searchsorted([sp.a for sp in spans], rows, side="right") - 1
    x_rows = np.full((len(rows), N_STATES), np.nan)
    P_rows = np.full((len(rows), N_STATES, N_STATES), np.nan)
    Pc_rows = np.full_like(P_rows, np.nan)
    solutions, priors, overlaps = [], [], []
    prior, source = Prior(x_bar, P_bar), "the filter's prior (estimator.initial_sigma)"
    options = Options(cfg.max_iterations, cfg.tolerance_sigma)
    tail = None       # the previous converged batch's states over this one's overlap
    for sp in spans:
        nxt = spans[sp.index + 1] if sp.index + 1 < len(spans) else None
        mine = np.flatnonzero((rows >= sp.a) & (rows < sp.stop) & (owner_rows == sp.index))
        local = rows[mine] - sp.a
        want = np.unique(np.r_[local, [nxt.a - sp.a] if nxt is not None else []]
                         ).astype(np.int64)
        data = data_of(sp)
        if model == "linear":
            sol = linear_batch(data.linear, prior, want, data.cases)
        else:   # from the linear batch's solution
            sol = nonlinear_batch(data.nonlinear, prior, linear_start(data.linear, prior),
                                  want, sigma_c, options)
        del data
        overlaps.append(_overlap(tail, sol.x) if sol.converged else None)
        tail = (sol.x[nxt.a - sp.a:min(sp.b, nxt.b) - sp.a].copy()
                if nxt is not None and sol.converged else None)
        if sol.converged:
            x_rows[mine] = sol.x[local]
            at = np.searchsorted(want, local)
            P_rows[mine] = sol.P_rows[at]
            if sol.P_consider_rows is not None:
                Pc_rows[mine] = sol.P_consider_rows[at]
        solutions.append(_light(sol))
        priors.append(source)
        if nxt is None:
            break
        if cfg.apriori == "chain" and sol.converged:
            k = int(np.searchsorted(want, nxt.a - sp.a))
            P = sol.P_rows[k]
            S = None if sol.S_rows is None else sol.S_rows[k]
            prior = Prior(sol.x[nxt.a - sp.a].copy(), 0.5 * (P + P.T), S)
            source = f"batch {sp.index}, propagated to this epoch"
        else:
            prior = Prior(x_bar, P_bar)
            source = ("the filter's prior (estimator.initial_sigma)" if cfg.apriori != "chain"
                      else f"the filter's prior: batch {sp.index} did not converge")
    return BatchRun(s, model, spans, solutions, priors, x_rows, owner_rows, rows, P_rows,
                    Pc_rows, overlaps)
