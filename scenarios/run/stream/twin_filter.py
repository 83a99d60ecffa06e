"""The paper's filter on the linear twin's telemetry in a streamed run, a window
behind the twin: a window is filtered once the next one's telemetry (the wheel-
torque derivative's padding) exists.  It runs in the producer process, beside the
twin, and hands on only what the summary and figures need (``records.TwinWindow``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from dynprop.estimator.kalman.consistency import nees
from dynprop.estimator.kalman.filter import unpack

from ...bridge.inputs import initial_prior, padded_filter_inputs
from ...records import FilterHistory, Measured, TwinWindow
from ...samples import nees_rows
from ..filtering import design_of, paper_filter


@dataclass(frozen=True)
class TwinTelemetry:
    """The twin over a window, before its filter: samples [start, start + n), its
    states (model coordinates) and its telemetry as the filter reads it."""

    index: int
    start: int
    n: int
    twin_model: np.ndarray
    measured: Measured

    def nees_samples(self) -> np.ndarray:
        """The window's samples (from 0) on which the NEES is formed."""
        return nees_rows(self.start, self.start + self.n) - self.start


class TwinFilter:
    def __init__(self, s, params, disc, plan):
        self.s, self.params, self.disc, self.plan = s, params, disc, plan
        self.prior = initial_prior(s, params)
        self.design = design_of(s)
        self.prev_tail: Measured | None = None
        self.cur: TwinTelemetry | None = None

    def push(self, rec: TwinTelemetry) -> list[TwinWindow]:
        done = [self._filter(self.cur, rec)] if self.cur is not None else []
        self.cur = rec
        return done

    def finish(self) -> list[TwinWindow]:
        return [self._filter(self.cur, None)] if self.cur is not None else []

    def _filter(self, cur: TwinTelemetry, nxt: TwinTelemetry | None) -> TwinWindow:
        pad = self.plan.pad
        meas, u, extra = padded_filter_inputs(self.s, self.params, self.prev_tail,
                                              cur.measured,
                                              None if nxt is None else nxt.measured, pad)
        # The covariance is kept only where the NEES is formed: the whole history
        # would be three quarters of the filter's output.
        k = cur.nees_samples()
        result = paper_filter(self.design, meas, self.disc, *self.prior, u=u, extra=extra,
                              sun_head=cur.measured.sun_head, covariance_rows=k)
        self.prior = (result.x_next, result.P_next)
        self.prev_tail = cur.measured.cut(slice(-pad, None))
        # Its NEES from the covariance the filter kept on those samples alone;
        # contiguous copies (not views of the filter's 60-column output): the record
        # crosses to the consumer (``handoff``), which sends contiguous arrays by
        # file and would pickle views through the pipe.
        return TwinWindow(
            cur.index, cur.twin_model,
            FilterHistory(np.ascontiguousarray(result.x), None,
                          np.ascontiguousarray(result.innovations),
                          np.ascontiguousarray(result.innovation_var), result.backend),
            nees(result.x[k], unpack(result.P_packed), cur.twin_model[k]))
