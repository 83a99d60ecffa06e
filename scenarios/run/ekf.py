"""The filters beside the paper's (``estimator.filters``): the extended Kalman
filter on a whole telemetry file, and through a streamed run's windows.  Its
design and inputs are ``bridge.ekf``'s."""

from __future__ import annotations

import numpy as np
from dynprop.estimator.ekf.filter import EkfResult, ekf_filter
from dynprop.estimator.linear import model as em
from dynprop.estimator.linear.steps import step_intervals

from ..bridge.ekf import ekf_design, ekf_inputs, padded_ekf_inputs
from ..bridge.inputs import telemetry_inputs
from ..config import build
from ..config.schema import Scenario
from ..files.rundir import RunDirError
from ..records import TruthWindow
from ..units import DEG


def run_ekf(s: Scenario, roll, pitch, yaw, speeds, yaw_sigma=None, sun_head=None,
            rows=None, keep_nominal: bool = False, t_s=None, maneuver=None) -> EkfResult:
    """The EKF on telemetry arrays; ``t_s``: the samples' own times, for telemetry off
    the grid (each step its own Δt, ``estimator.ekf``); ``maneuver``: the
    thruster-firing flag (``bridge.ekf.ekf_maneuver``)."""
    params, _ = build.estimator_model(s)
    pm, wn, X0, P0 = ekf_design(s)
    inputs = ekf_inputs(s, params, roll, pitch, yaw, speeds, yaw_sigma, sun_head, t_s=t_s,
                        maneuver=maneuver)
    return ekf_filter(inputs, pm, wn, X0, P0, rows=rows, keep_nominal=keep_nominal,
                      dt_s=None if t_s is None else step_intervals(t_s))


def check_ekf_columns(s: Scenario, names) -> None:
    """The EKF beside the paper's filter needs the Earth sensor's pitch."""
    if "ekf" in s.estimator.filters and "pitch_deg" not in names:
        raise RunDirError("estimator.filters: the EKF measures pitch, and the telemetry has "
                          "no pitch_deg column; remove ekf or add the Earth sensor's pitch")


def other_filters(s: Scenario, columns: dict, rows=None, on_grid: bool = True
                  ) -> dict[str, EkfResult]:
    """The filters besides the paper's (``estimator.filters``) on telemetry.csv's
    columns, by name, their histories at ``rows`` (all samples if None); ``on_grid``
    False: the samples at their own times ``columns['t_s']``."""
    if "ekf" not in s.estimator.filters:
        return {}
    check_ekf_columns(s, columns)
    tel = telemetry_inputs(s, columns)
    return {"ekf": run_ekf(s, tel.roll_rad, columns["pitch_deg"] * DEG, tel.yaw_rad,
                           tel.speeds_radps, tel.yaw_sigma_rad, tel.sun_head, rows=rows,
                           t_s=None if on_grid else columns["t_s"],
                           maneuver=tel.maneuver)}


class EkfStream:
    """The EKF through a streamed run's windows (``stages.filtered``), each continuing
    from the state and covariance the previous one ended with, its inputs from the
    window padded as the paper filter's (``bridge.ekf.padded_ekf_inputs``)."""

    def __init__(self, s: Scenario, params: em.ModelParams):
        self.s, self.params = s, params
        self.pm, self.wn, self.X, self.P = ekf_design(s)
        self.prev_tail: tuple | None = None

    @staticmethod
    def _telemetry(w: TruthWindow) -> tuple:
        return (*w.measured, w.pitch_rad)

    def window(self, cur: TruthWindow, nxt: TruthWindow | None, pad: int, record=None
               ) -> EkfResult:
        """One window (``record``: off the grid, the file's cadence and first time)."""
        prev, after = self.prev_tail, None if nxt is None else self._telemetry(nxt)
        t_pad = None
        if cur.lead is not None:
            # A telemetry file's window, with its own padding (``records.TruthWindow``).
            prev = (*cur.lead.measured, cur.lead.pitch_rad)
            after, pad = (*cur.trail.measured, cur.trail.pitch_rad), len(cur.trail.t_s)
            if cur.steps is not None:
                t_pad = np.concatenate([cur.lead.t_s, cur.t_s, cur.trail.t_s])
        inputs = padded_ekf_inputs(self.s, self.params, prev, self._telemetry(cur), after, pad,
                                   t_pad, record)
        r = ekf_filter(inputs, self.pm, self.wn, self.X, self.P, dt_s=cur.steps)
        self.X, self.P = r.x_next, r.P_next
        self.prev_tail = tuple(None if v is None else v[-pad:] for v in self._telemetry(cur))
        return r
