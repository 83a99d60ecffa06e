"""The linear twin of a streamed run (``stream.producer``), and the filter's
inputs on a window padded with its neighbours' samples.

The twin is the paper's model (Eq. 11) propagated exactly from the truth's state,
under the truth's torques, and sensed with the same noise draws
(``pipeline.linear_twin``), here a window at a time: its state and generators
are carried, and its torque states are set to each window's fit (``stream``'s
module doc says why).  Its filter runs a window behind it, since a window's
wheel-torque derivative needs the next window's first samples.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
from dynprop.estimator import model as em
from dynprop.estimator.consistency import nees
from dynprop.estimator.kalman import ExtraNoise, kalman_filter, unpack

from ..files.decimate import output_rows
from ..files.summary import NEES_STRIDE
from .whole import (
    filter_inputs,
    initial_prior,
    model_truth,
    propagate_lti_final,
    sense_twin,
    twin_input,
)


def twin_window(s, params, disc, rec, h_next, x_prev, rngs, suite, mt) -> np.ndarray:
    """The twin over one window (``pipeline.linear_twin`` with carried state and
    generators); fills ``twin_model`` and ``twin_meas`` and returns the next state."""
    truth, tt = rec["truth"], rec["tt"]
    u = twin_input(params, mt, tt, truth.h_Nms, s.sample_interval_s, h_next)
    if x_prev is None:
        x0 = model_truth(params, truth, tt, [0])[0]
    else:
        x0 = x_prev.copy()
        x0[em.NPX:] = tt.torque_states[0]     # the new window's fit (module doc)
    twin, x_next = propagate_lti_final(disc.Phi, disc.Gamma, x0, u)
    tel = sense_twin(s, truth, twin, suite, rngs)
    head = np.where(tel.yaw_head >= 0, tel.yaw_head, np.nan)
    rec["twin_model"] = twin
    rec["twin_meas"] = (tel.roll_rad, tel.yaw_rad, tel.wheel_speeds_radps, tel.yaw_sigma_rad,
                        head)
    return x_next


class TwinFilter:
    """The paper's filter on the twin's telemetry, a window behind the twin: a window
    is filtered once the next one's telemetry (the derivative's padding) exists."""

    def __init__(self, s, params, disc, plan):
        self.s, self.params, self.disc, self.plan = s, params, disc, plan
        self.prior = initial_prior(s, params)
        self.prev = self.cur = None

    def push(self, rec: dict) -> list[dict]:
        done = self._filter(self.cur, rec) if self.cur is not None else []
        self.cur = rec
        return done

    def finish(self) -> list[dict]:
        return self._filter(self.cur, None) if self.cur is not None else []

    def _filter(self, cur: dict, nxt: dict | None) -> list[dict]:
        meas, u, extra = padded_inputs(self.s, self.params, self.plan, self.prev, cur, nxt,
                                        "twin_meas")
        # The covariance is kept only where the NEES is formed (lighten_twin): the
        # whole history would be three quarters of the filter's output.
        result = kalman_filter(meas, self.disc, *self.prior, u=u, extra=extra,
                               covariance_rows=nees_rows(cur))
        self.prior = (result.x_next, result.P_next)
        self.prev = {"twin_meas": tuple(None if v is None else v[-self.plan.pad:]
                                        for v in cur["twin_meas"])}
        cur["linear"] = result
        lighten_twin(cur)
        return [{k: cur[k] for k in ("index", "twin_model", "linear", "nees_linear")}]


def lighten_twin(rec: dict) -> None:
    """What the summary and figures need of the twin's filter, once the next window
    no longer needs its telemetry: its NEES (computed here, from the covariance the
    filter kept on those samples alone), estimates and innovations."""
    lin, k = rec["linear"], nees_rows(rec)
    rec["nees_linear"] = nees(lin.x[k], unpack(lin.P_packed), rec["twin_model"][k])
    # Contiguous copies (not views of the filter's 60-column output): the record
    # crosses to the consumer (``handoff``), which sends contiguous arrays by file
    # and would pickle views through the pipe.
    rec["linear"] = SimpleNamespace(x=np.ascontiguousarray(lin.x),
                                    innovations=np.ascontiguousarray(lin.innovations),
                                    innovation_var=np.ascontiguousarray(lin.innovation_var),
                                    backend=lin.backend)
    rec.pop("twin_meas", None)
    rec.pop("linear_in", None)


def nees_rows(rec: dict) -> np.ndarray:
    """The window's samples (from 0) on which the NEES is formed."""
    a, n = rec["start"], len(rec["t_s"])
    return output_rows(a, a + n, NEES_STRIDE) - a


def padded_inputs(s, params, plan, prev, cur, nxt, key: str):
    """Filter inputs of ``cur`` from its telemetry padded with ``plan.pad`` samples of
    each neighbour, so the wheel-torque derivative equals the whole run's."""
    lo = 0 if prev is None else plan.pad
    n = len(cur[key][0])

    def cut(m, which):
        arrays = m[key]
        if which == "tail":
            return [None if v is None else v[-plan.pad:] for v in arrays]
        if which == "head":
            return [None if v is None else v[:plan.pad] for v in arrays]
        return list(arrays)

    pieces = ([cut(prev, "tail")] if prev is not None else []) + [cut(cur, "all")] + \
        ([cut(nxt, "head")] if nxt is not None else [])
    joined = [None if pieces[0][i] is None else np.concatenate([p[i] for p in pieces])
              for i in range(len(pieces[0]))]
    meas, u, extra = filter_inputs(s, params, *joined)
    sl = slice(lo, lo + n)
    meas = type(meas)(*(v[sl] if np.ndim(v) else v for v in
                        (meas.roll_rad, meas.yaw_rad, meas.h_Nms, meas.var_roll, meas.var_yaw,
                         meas.var_h)))
    if extra is not None:
        extra = ExtraNoise(extra.scale[sl], extra.Qd_unit)
    return meas, u[sl], extra
