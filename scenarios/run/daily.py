"""daily.csv: one row per simulated day of a streamed run, tallied at the full
sample rate as the windows pass (``tally``'s module doc).  Day k covers
t ∈ [k, k+1) days from the run's start; a Sun gap is filed under the day it ends.
"""

from __future__ import annotations

from datetime import timedelta

import numpy as np
from dynprop.estimator.linear.model import H_WHEEL, R, Y

from ..records import Window
from ..units import DAY_S, RAD2DEG
from .event_days import day_columns


class DailyTally:
    """One row of daily.csv per simulated day (day k: t in [k, k+1) days)."""

    def __init__(self, s, epoch, n_samples: int, eq55_deg: float,
                 span_s: tuple[float, float] | None = None, events=(), t0_s: float = 0.0):
        """``span_s``: a file off the scenario's grid, its first and last sample's
        times; its days and gaps are then counted by time, not by index.  ``events``:
        summary.json's list (``event_days``), counted per day from ``t0_s``, the first
        sample's time; none adds no column."""
        dt = s.sample_interval_s
        self.dt = dt
        self.span = span_s
        # The run's last sample, at exactly k days, closes day k−1 (a year has 365 rows).
        length = (n_samples - 1) * dt if span_s is None else span_s[1] - span_s[0]
        self.n_days = max(1, int(np.ceil(length / DAY_S - 1e-9)))
        self.events = list(events)
        self.t0 = t0_s if span_s is None else span_s[0]
        self.length = length
        self.shadow_known = True
        self.epoch, self.eq55 = epoch, eq55_deg
        d = self.n_days
        self.sums = {k: np.zeros(d) for k in ("roll", "yaw", "h", "nees", "yaw_linear", "diff")}
        self.counts = {k: np.zeros(d, dtype=np.int64) for k in self.sums}
        self.eclipse = np.zeros(d, dtype=np.int64)
        self.gap = np.full((d, 4), np.nan)  # start, end (samples, or h off the grid),
        # the error and σ at its end

    def _day(self, idx, t_s=None) -> np.ndarray:
        """The day of samples ``idx`` (off the grid: of their times ``t_s``)."""
        if self.span is not None:
            return np.minimum(((np.asarray(t_s) - self.span[0]) // DAY_S).astype(np.int64),
                              self.n_days - 1)
        return np.minimum((np.asarray(idx) * self.dt // DAY_S).astype(np.int64),
                          self.n_days - 1)

    def _add(self, key: str, day, values) -> None:
        ok = np.isfinite(values)
        self.sums[key] += np.bincount(day[ok], np.asarray(values)[ok], self.n_days)
        self.counts[key] += np.bincount(day[ok], minlength=self.n_days)

    def add(self, w: Window, err, err_lin, nees_idx, gaps_closed, gap_hours=None,
            end_errors: dict | None = None) -> None:
        """``gap_hours``: off the grid, each closed gap's (start, end) in hours;
        ``end_errors``: a sparse truth's yaw error judged at each gap end (deg, by end
        sample; None where not tested)."""
        a = w.start
        n = len(w.t_s)
        day = self._day(np.arange(a, a + n), w.t_s)
        if w.shadow is None:
            self.shadow_known = False       # a telemetry file: whether in shadow is unknown
        else:
            self.eclipse += np.bincount(day[w.shadow < 1.0], minlength=self.n_days)
        if err is not None:
            self._add("roll", day, np.square(err[:, R] * RAD2DEG))
            self._add("yaw", day, np.square(err[:, Y] * RAD2DEG))
            self._add("h", day, np.square(err[:, H_WHEEL]))
            self._add("nees", day[nees_idx - a], w.nees_real)
        if err_lin is not None:
            self._add("yaw_linear", day, np.square(err_lin[:, Y] * RAD2DEG))
            if err is not None:
                self._add("diff", day, np.square((err[:, Y] - err_lin[:, Y]) * RAD2DEG))
        sig = w.real.sigma
        for i, (ga, gb) in enumerate(gaps_closed):
            if gb >= a + n or gb < a:
                continue
            d = int(day[gb - a])
            # On the grid in samples (hours at the end); off it in hours already.
            start, end = (ga, gb) if gap_hours is None else gap_hours[i]
            if np.isnan(self.gap[d, 0]) or end - start > self.gap[d, 1] - self.gap[d, 0]:
                e = np.nan if err is None else err[gb - a, Y] * RAD2DEG
                if end_errors is not None:
                    e = np.nan if end_errors.get(gb) is None else end_errors[gb]
                self.gap[d] = (start, end, e, sig[gb - a, Y] * RAD2DEG)

    def columns(self) -> dict[str, np.ndarray]:
        d = np.arange(self.n_days)

        def mean(key, root=False):
            with np.errstate(invalid="ignore", divide="ignore"):
                v = self.sums[key] / self.counts[key]
            v[self.counts[key] == 0] = np.nan
            return np.sqrt(v) if root else v

        doy = np.array([(self.epoch + timedelta(days=int(k))).timetuple().tm_yday for k in d],
                       dtype=float)
        to_h = self.dt / 3600.0 if self.span is None else 1.0
        out = {
            "day": d.astype(float), "day_of_year": doy,
            "sun_gap_start_h": self.gap[:, 0] * to_h, "sun_gap_end_h": self.gap[:, 1] * to_h,
            "sun_gap_length_h": (self.gap[:, 1] - self.gap[:, 0]) * to_h,
            "gap_end_yaw_error_deg": self.gap[:, 2], "gap_end_yaw_sigma_deg": self.gap[:, 3],
            "eq55_sigma_yaw_deg": np.full(self.n_days, self.eq55),
            "eclipse_min": self.eclipse * self.dt / 60.0 if self.shadow_known
            else np.full(self.n_days, np.nan),
            "roll_error_rms_deg": mean("roll", True), "yaw_error_rms_deg": mean("yaw", True),
            "h_error_rms_Nms": mean("h", True), "nees_mean": mean("nees"),
            "yaw_error_rms_linear_deg": mean("yaw_linear", True),
            "yaw_error_rms_real_minus_linear_deg": mean("diff", True),
        }
        if self.events:     # without events, the columns of before issue 45 alone
            out |= day_columns(self.events, self.n_days, self.t0, self.t0 + self.length)
        return out
