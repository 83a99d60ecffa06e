"""The statistics of a filter besides the paper's (``estimator.filters``), tallied
as a streamed run's windows pass, like ``tally.RunTally`` for the paper's:
summary.json's ``ekf`` section.  The Sun gaps are the paper filter's (the same
telemetry); the errors are against the same truth in the paper's coordinates."""

from __future__ import annotations

import numpy as np
from dynprop.estimator.kalman.consistency import chi2_bounds, nees, nis
from dynprop.estimator.kalman.filter import unpack
from dynprop.estimator.linear.model import H_WHEEL, N_STATES, R, Y

from ..records import FilterHistory
from ..samples import nees_rows
from ..units import RAD2DEG
from .statistics import SETTLED_S
from .tally import Mean, Rms

EKF_MEASUREMENTS = ("roll", "pitch", "yaw", "h")


class FilterTally:
    def __init__(self, name: str, measurements=EKF_MEASUREMENTS):
        self.name, self.measurements = name, measurements
        self.rms = {k: Rms() for k in ("yaw", "roll", "h")}
        self.nees, self.inside = Mean(), [0, 0]
        self.nees_settled = Mean()      # after the start-up (statistics.SETTLED_S)
        self.nis = [Mean() for _ in measurements]
        self.end_err: list[float] = []
        self.end_sigma: list[float] = []
        self.within = True
        self.backend = None
        self.bounds = chi2_bounds(N_STATES, 1)

    def add(self, f: FilterHistory, start: int, truth_model: np.ndarray | None, closed_gaps,
            t_s: np.ndarray | None = None) -> None:
        """One window's history of this filter from sample ``start`` on, against the
        truth in the model's states (None without a truth); ``t_s`` the window's times
        (since the run's start), for the NEES after the start-up."""
        self.backend = f.backend
        a = start
        v = nis(f.innovations, f.innovation_var)
        for i in range(len(self.measurements)):
            self.nis[i].add(v[:, i])
        if truth_model is None:
            return
        err = f.x - truth_model
        for _, b in closed_gaps:
            k = b - a
            self.end_err.append(float(err[k, Y] * RAD2DEG))
            self.end_sigma.append(float(f.sigma[k, Y] * RAD2DEG))
            self.within &= bool(abs(err[k, Y]) <= 3 * f.sigma[k, Y])
        self.rms["yaw"].add(err[:, Y])
        self.rms["roll"].add(err[:, R])
        self.rms["h"].add(err[:, H_WHEEL])
        k = nees_rows(a, a + len(f.x)) - a
        values = nees(f.x[k], unpack(f.P_nees), truth_model[k])
        self.nees.add(values)
        if t_s is not None:
            self.nees_settled.add(values[t_s[k] >= SETTLED_S])
        finite = values[np.isfinite(values)]
        self.inside[0] += int(np.sum((finite >= self.bounds[0]) & (finite <= self.bounds[1])))
        self.inside[1] += finite.size

    def summary(self) -> dict:
        """summary.json's section for this filter (docs/outputs.md)."""
        truth = self.rms["yaw"].count > 0
        return {
            "backend": self.backend,
            "yaw_error_rms_deg": self.rms["yaw"].value() * RAD2DEG if truth else None,
            "roll_error_rms_deg": self.rms["roll"].value() * RAD2DEG if truth else None,
            "h_error_rms_Nms": self.rms["h"].value() if truth else None,
            "yaw_error_at_gap_end_deg": self.end_err if truth else None,
            "yaw_sigma_at_gap_end_deg": self.end_sigma if truth else None,
            "yaw_within_3sigma_at_gap_ends": self.within if truth and self.end_err else None,
            "nees_mean": self.nees.value() if truth else None,
            "nees_mean_after_1h": self.nees_settled.value() if truth else None,
            "nees_fraction_inside_95": (self.inside[0] / self.inside[1]
                                        if truth and self.inside[1] else None),
            "nis_mean": {m: self.nis[i].value() for i, m in enumerate(self.measurements)},
        }
