"""The consumer's stages of a streamed run (``stream.windows_of`` chains them): the
paper's filter on each truth window and the RTS smoother over it.

Each stage is a generator over window records: it yields the ``Plan`` first, then
one record per window, and looks one window ahead where the padding or the
smoother's overlap needs the next window's first samples.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from dynprop.estimator.ekf.filter import EkfResult
from dynprop.estimator.kalman.consistency import nees
from dynprop.estimator.kalman.filter import ExtraNoise, FilterResult, unpack
from dynprop.estimator.linear.steps import StepTable
from dynprop.estimator.linear.transition import discretize

from ...bridge.inputs import initial_prior, padded_filter_inputs
from ...config import build
from ...config.schema import Scenario
from ...records import FilterHistory, TruthWindow
from ...samples import nees_rows
from ..ekf import EkfStream
from ..filtering import (
    bias_columns,
    design_of,
    head,
    paper_filter,
    paper_smoother,
    smoothed_full_P,
    smoothed_full_x,
    stretch,
)
from ..pitch import PitchHistory, PitchStream, history_at


@dataclass(frozen=True)
class Filtered:
    """A truth window through the paper's filter (and the EKF beside it when the
    scenario asks), with the inputs its smoother needs, and through the pitch filter."""

    window: TruthWindow
    real: FilterResult
    u: np.ndarray
    extra: ExtraNoise | None
    ekf: EkfResult | None
    pitch: PitchHistory | None
    disc: object                # the window's Φ, Γ, Q_d (one step, or a StepTable)
    pitch_rows: PitchHistory | None = None   # at a sparse truth's rows


def filtered(s: Scenario, records):
    """The paper's filter on each truth window, continuing from the prior the
    previous window ended with.  The twin is filtered in the producer
    (``twin_filter.TwinFilter``)."""
    plan = next(records)
    yield plan
    params, noise = build.estimator_model(s)
    disc = discretize(params, noise, s.sample_interval_s)
    prior = initial_prior(s, params)
    design = design_of(s)
    ekf = EkfStream(s, params) if "ekf" in s.estimator.filters else None
    pitch = PitchStream(s)
    prev_tail, cur = None, next(records, None)
    rows_before = 0     # a sparse truth's rows in the windows before
    while cur is not None:
        p_rows = None
        # The last window needs no look-ahead (and waiting for the stream's end would
        # hold it up until the producer is done with its files).
        nxt = None if plan.is_last(cur.index) else next(records, None)
        # A file's window brings its own padding (``records.TruthWindow``); a run's
        # is its neighbours' samples.
        own = cur.lead is not None
        lead = cur.lead.measured if own else prev_tail
        trail = cur.trail.measured if own else None if nxt is None else nxt.measured
        pad = len(cur.trail.t_s) if own else plan.pad
        t_pad = None if cur.steps is None else np.concatenate(
            [cur.lead.t_s, cur.t_s, cur.trail.t_s])
        meas, u, extra = padded_filter_inputs(s, params, lead, cur.measured, trail, pad, t_pad,
                                              plan.record)
        w_disc = disc if cur.steps is None else StepTable(params, noise, cur.steps)
        result = paper_filter(design, meas, w_disc, *prior, u=u, extra=extra,
                              sun_head=cur.measured.sun_head)
        prior = (result.x_next, result.P_next)
        e = None if ekf is None else ekf.window(cur, nxt, plan.pad, plan.record)
        # Reduced at once to what the files and tallies read (its covariance history
        # is not kept): the NEES on the NEES samples against the window's truth.
        p = None
        if cur.pitch_rad is not None:
            speeds = cur.measured.speeds_radps
            r = pitch.window(cur.pitch_rad, speeds,
                             trail.speeds_radps if trail is not None else None, pad,
                             lead=cur.lead.measured.speeds_radps if own else None,
                             t_s=t_pad, steps=cur.steps, record=plan.record)
            if cur.truth_rows is None:
                p = PitchHistory.of(r, cur.pitch_truth, nees_local(cur))
            else:
                # A truth at some samples only: the filter's own history (no NEES), and
                # at the truth's rows, its NEES on every NEES_STRIDE-th row counted
                # from the file's first (``run.pitch.history_at``'s rows).
                m = len(cur.truth_rows)
                p = PitchHistory.of(r, None, [])
                p_rows = history_at(r, cur.truth_rows, cur.pitch_truth[cur.truth_rows],
                                    first=rows_before)
                rows_before += m
        # The next window's derivative needs only the last samples of this one.
        prev_tail = cur.measured.cut(slice(-plan.pad, None))
        yield Filtered(cur, result, u, extra, e, p, w_disc, p_rows)
        cur = nxt


@dataclass(frozen=True)
class Smoothed:
    """What the summary and files need of a filtered window once it is smoothed:
    the filters' estimates, σ and innovations and the real filter's NEES on the NEES
    samples (formed here, before the window's twin record comes, which the consumer
    would otherwise wait for idle), not the covariance history."""

    window: TruthWindow
    real: FilterHistory
    nees_real: np.ndarray | None
    smoothed_x: np.ndarray | None
    filters: dict[str, FilterHistory]
    pitch: PitchHistory | None
    smoothed_sigma: np.ndarray | None = None
    pitch_rows: PitchHistory | None = None


def nees_local(w: TruthWindow) -> np.ndarray:
    """The window's samples (local) its NEES is formed on: every ``NEES_STRIDE``-th,
    or, with a truth file's rows at only some samples, each of those."""
    if w.truth_rows is not None:
        return w.truth_rows
    return nees_rows(w.start, w.start + len(w.t_s)) - w.start


def _lighten(f: Filtered, smoothed_x: np.ndarray | None,
             smoothed_sigma: np.ndarray | None = None) -> Smoothed:
    w, real = f.window, f.real
    k = nees_local(w)
    filters = {}
    if f.ekf is not None:
        e = f.ekf
        filters["ekf"] = FilterHistory(e.x, e.sigma, e.innovations, e.innovation_var,
                                       e.backend, P_nees=e.P_packed[k])
    return Smoothed(w, FilterHistory(real.x, real.sigma, real.innovations, real.innovation_var,
                                     real.backend, None, bias_columns(real, slice(None)),
                                     getattr(real, "rejected", None)),
                    None if w.truth_model is None else
                    nees(real.x[k], unpack(real.P_packed[k]), w.truth_model[k]), smoothed_x,
                    filters, f.pitch, smoothed_sigma, f.pitch_rows)


# A smoothed covariance is formed this many samples at a time, backwards, each
# stretch continuing from the smoothed x and P where the later one begins: the same
# steps as one pass, so the same bits, without a window's whole P history twice.
SMOOTH_PIECE = 16_384


def smooth_pieces(design, result, disc, u, extra, covariance: bool, after: dict,
                  piece: int = SMOOTH_PIECE):
    """``paper_smoother`` of a history with the smoothed (full) x and P after it
    (``after``: ``x_after``, ``P_after``; empty at the run's end): the smoothed x and,
    with ``covariance``, 1σ (the paper's nine states), and the smoothed full x and P
    at its first sample.  Without ``covariance``, in one pass as `run` smooths."""
    n = len(result.x)
    if not covariance:
        r = paper_smoother(design, result, disc, u=u, extra=extra, covariance=False,
                           **after)
        return r.x, None, {"x_after": smoothed_full_x(r)[0]}
    x, sigma = np.empty((n, 9)), np.empty((n, 9))
    for b in range(n, 0, -piece):
        a = max(0, b - piece)
        rows = slice(a, b)
        d = disc.cut(rows) if isinstance(disc, StepTable) else disc
        r = paper_smoother(design, stretch(result, rows), d, u=u[rows], covariance=True,
                           extra=None if extra is None else extra.cut(rows),
                           **after)
        x[rows], sigma[rows] = r.x, r.sigma
        after = {"x_after": smoothed_full_x(r)[0], "P_after": smoothed_full_P(r)[0]}
    return x, sigma, after


def smoothed(s: Scenario, records, smooth: bool = True, covariance: bool = False):
    """The RTS smoother over each window and ``plan.overlap`` samples of the next
    (one window: the whole run, exactly ``rts_smoother``).  ``covariance``: with the
    smoothed 1σ too (a telemetry file's smoothed.csv), continued across windows from
    the overlap's smoothed covariance."""
    plan = next(records)
    yield plan
    design = design_of(s)
    cur = next(records, None)
    while cur is not None:
        nxt = None if plan.is_last(cur.window.index) else next(records, None)
        x = sigma = None
        if smooth:
            after = {}
            if nxt is not None:
                # The overlap first, from its filtered end; then this window from the
                # smoothed state where the overlap begins (no joined copy of the two).
                m = min(plan.overlap, len(nxt.window.t_s))
                d = nxt.disc if not isinstance(nxt.disc, StepTable) else \
                    nxt.disc.cut(slice(0, m))
                extra = None if nxt.extra is None else nxt.extra.cut(slice(0, m))
                _, _, after = smooth_pieces(design, head(nxt.real, m), d, nxt.u[:m], extra,
                                            covariance, {})
            x, sigma, _ = smooth_pieces(design, cur.real, cur.disc, cur.u, cur.extra,
                                        covariance, after)
        yield _lighten(cur, x, sigma)
        cur = nxt
