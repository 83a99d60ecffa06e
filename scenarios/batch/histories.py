"""The paper's filter and its RTS smoother beside the batches, on a telemetry source
read window by window and kept only at the samples `dynprop batch` compares (issue
44: a month of telemetry without its covariance histories).

The filter runs over the windows of ``run.windowed`` (the record whole up to two
days, else half days), each window's inputs formed from its padded samples, carrying
its prior from one window to the next: the whole record's filter, bit for bit, but
for a dropout's wheel noise, measured on the padded window (as `run` measures it).

The smoother runs, with its covariance, over each window and the samples that follow
it for ``Windows.overlap_s`` (``stream.plan.SMOOTHER_OVERLAP_S``, 12 h), from the
filtered state at their end: at a window's end it has seen 12 h of later data, as
`run`'s windows have (each day is smoothed over 12 h of the next), and the last window
is smoothed to the record's end.  A record of one window is smoothed whole, as
before.  Two windows' filter histories are held at a time, and one window's smoothed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from dynprop.estimator.kalman.filter import ExtraNoise
from dynprop.estimator.linear.model import N_STATES
from dynprop.estimator.linear.steps import StepTable
from dynprop.estimator.linear.transition import discretize

from ..bridge.inputs import filter_inputs, initial_prior, telemetry_inputs
from ..config import build
from ..config.schema import Scenario
from ..run.filtering import (
    design_of,
    head,
    paper_filter,
    paper_smoother,
    smoothed_full_P,
    smoothed_full_x,
)
from ..run.stream.plan import SMOOTHER_OVERLAP_S
from ..run.windowed import (
    Windows,
    cut_inputs,
    pad_samples,
    padded_range,
    used_names,
    wheel_names,
    window_bounds,
)

# Half days: a window and the 12 h after it, smoothed together, are a day's history.
WINDOWS = Windows(window_s=SMOOTHER_OVERLAP_S)


@dataclass(frozen=True)
class Histories:
    """The filter's and the smoother's estimates and 1σ (model units, nine states)
    at ``rows`` (global sample indices)."""

    rows: np.ndarray
    filter_x: np.ndarray
    filter_sigma: np.ndarray
    smoother_x: np.ndarray
    smoother_sigma: np.ndarray

    def filter_sigma_at(self) -> dict[int, float]:
        """The filter's yaw σ by row, as ``run.estimate_truth.gap_end_rows`` reads it."""
        return dict(zip(self.rows.tolist(), self.filter_sigma[:, 2], strict=True))


@dataclass(frozen=True)
class _Piece:
    a: int
    b: int
    result: object          # FilterResult (or BiasedResult)
    u: np.ndarray
    extra: ExtraNoise | None


def _at(rows: np.ndarray, a: int, b: int) -> tuple[np.ndarray, np.ndarray]:
    """Positions in ``rows`` of the rows in [a, b), and those rows counted from a."""
    i, j = np.searchsorted(rows, [a, b])
    return np.arange(i, j), rows[i:j] - a


def _smooth(design, pieces: list[_Piece], stop: int, disc, source, params, noise):
    """The smoother over the samples of ``pieces`` from the first's start to ``stop``,
    of the first piece: the later ones smoothed first, from the filtered state at
    ``stop``, each earlier one continuing from the smoothed state and covariance where
    the next begins (``x_after``, ``P_after``: the joined history's smoother, bit for
    bit, without joining it)."""
    after = None
    for p in reversed([p for p in pieces if p.a < stop]):
        m = min(p.b, stop) - p.a
        result = head(p.result, m) if m < p.b - p.a else p.result
        extra = None if p.extra is None else p.extra.cut(slice(0, m))
        d = disc if disc is not None else StepTable(params, noise, source.steps(p.a, p.a + m))
        sm = paper_smoother(design, result, d, u=p.u[:m], extra=extra,
                            x_after=None if after is None else after[0],
                            P_after=None if after is None else after[1])
        after = (smoothed_full_x(sm)[0], smoothed_full_P(sm)[0])
    return sm


def histories_at(s: Scenario, source, t: np.ndarray, rows: np.ndarray,
                 windows: Windows = WINDOWS) -> Histories:
    """The filter and the smoother on ``source`` (a ``TelemetrySource``, samples at
    times ``t``) at ``rows`` (module doc)."""
    params, noise = build.estimator_model(s)
    design = design_of(s)
    regular, n = source.regular, source.n
    disc = discretize(params, noise, s.sample_interval_s) if regular else None
    step = s.sample_interval_s if regular else source.median_step_s()
    pad = pad_samples(s, step)
    overlap = max(pad, int(round(windows.overlap_s / step)))
    names, needed = used_names(source, s), wheel_names(s)
    # Off the grid each window's N_w* is resampled onto the file's own points.
    record = None if regular else (step, float(t[0]))
    rows = np.asarray(rows, dtype=np.int64)
    fx, fs, sx, ss = (np.full((len(rows), N_STATES), np.nan) for _ in range(4))
    prior = initial_prior(s, params)
    bounds = window_bounds(t, 0, n, windows)
    pending: list[_Piece] = []
    for j, (a, b) in enumerate(bounds):
        c, d = padded_range(source, a, b, 0, n, pad, needed)
        cols = source.columns(c, d, names)
        tel = telemetry_inputs(s, cols)
        sl = slice(a - c, b - c)
        own_t = None if regular else np.asarray(cols["t_s"], dtype=float)
        meas, u, extra = cut_inputs(*filter_inputs(s, params, *tel.readings, t_s=own_t,
                                                   record=record), sl)
        wdisc = disc if regular else StepTable(params, noise, source.steps(a, b))
        result = paper_filter(design, meas, wdisc, *prior, u=u, extra=extra,
                              sun_head=None if tel.sun_head is None else tel.sun_head[sl])
        del cols, tel
        prior = (result.x_next, result.P_next)
        at, local = _at(rows, a, b)
        fx[at], fs[at] = result.x[local], result.sigma[local]
        pending.append(_Piece(a, b, result, u, extra))
        last = j == len(bounds) - 1
        # Each window once the 12 h after it are filtered (or the record has ended).
        while pending and (last or pending[0].b + overlap <= b):
            p = pending[0]
            sm = _smooth(design, pending, min(b, p.b + overlap), disc, source, params, noise)
            at, local = _at(rows, p.a, p.b)
            sx[at], ss[at] = sm.x[local], sm.sigma[local]
            pending.pop(0)
    return Histories(rows, fx, fs, sx, ss)
