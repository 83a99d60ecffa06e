"""The statistics of a streamed run, tallied at the full sample rate window by
window.

``RunTally`` gathers what summary.json reports (``files.summary.RunStatistics``):
sums of squares, NEES and NIS sums and counts, the Sun gaps and the errors at
their ends.  For a run of one window every figure is computed by the very numpy
operation ``statistics.whole_run_statistics`` applies to the whole arrays, so the
two agree bit for bit; over several windows the sums are added window by window
(the last bits of a long sum depend on its order).  ``daily.DailyTally`` does the
same per simulated day for daily.csv, ``filter_tally.FilterTally`` for a filter
beside the paper's.
"""

from __future__ import annotations

import numpy as np
from dynprop.estimator.kalman.consistency import chi2_bounds, nis
from dynprop.estimator.linear.model import H_WHEEL, N_STATES, R, Y

from ..files.summary import RunStatistics
from ..records import Window
from ..samples import END_SIGMA_MATCH
from ..units import HOUR_S, RAD2DEG
from .statistics import SETTLED_S, truth_extremes


def _sq_sum(a) -> tuple[float, int]:
    """(Σ a², count) over the finite values, as ``np.nanmean(np.square(a))`` sums."""
    sq = np.square(a)
    finite = ~np.isnan(sq)
    return np.sum(np.where(finite, sq, 0.0)), int(np.sum(finite))


class Rms:
    def __init__(self):
        self.total, self.count = 0.0, 0

    def add(self, a) -> None:
        s, n = _sq_sum(a)
        self.total, self.count = self.total + s, self.count + n

    def value(self) -> float:
        return float(np.sqrt(self.total / self.count)) if self.count else float("nan")


class Mean:
    """Mean of the finite values (``statistics.mean_or_none``)."""

    def __init__(self):
        self.total, self.count = 0.0, 0

    def add(self, a) -> None:
        a = np.asarray(a, dtype=float)
        a = a[np.isfinite(a)]
        self.total, self.count = self.total + np.sum(a), self.count + a.size

    def value(self) -> float | None:
        return float(self.total / self.count) if self.count else None


class GapTracker:
    """Sun gaps (``samples.sun_gaps``) found as the windows pass: a yaw outage of at
    least ``min_s``; its end is the first sample with yaw again.  With ``step_s`` (a
    file off the grid, whose median step it is) gaps are measured in time, as
    ``samples.sun_gaps_at`` measures them, and ``hours`` holds each one's (start, end)
    in hours from ``t0_s``."""

    def __init__(self, dt_s: float, min_s: float, step_s: float | None = None,
                 t0_s: float = 0.0):
        self.dt_s, self.min_s, self.step, self.t0 = dt_s, min_s, step_s, t0_s
        self.open_since: int | None = None
        self.gaps: list[tuple[int, int]] = []
        self.hours: list[list[float]] = []
        self.open_at = self.last_t = None   # (time before, start time) of the open gap

    def _long(self, a: int, b: int, times=None) -> bool:
        if times is None:
            return (b - a) * self.dt_s >= self.min_s   # the predicate of samples.sun_gaps
        before, _, after = times
        return after - before - self.step >= self.min_s

    def add(self, start: int, present: np.ndarray, t_s=None) -> list[tuple[int, int]]:
        """The gaps (global first missing, first present again) closing in this window
        (``t_s``: its samples' times, off the grid)."""
        missing = ~np.asarray(present, dtype=bool)
        n = len(missing)
        timed = self.step is not None
        closed, times = [], []

        def opened(a: int) -> tuple[float, float]:
            # The time of the last sample before the gap, and of its first.
            k = a - start
            before = t_s[k - 1] if k > 0 else (self.last_t if self.last_t is not None
                                               else t_s[0] - self.step)
            return before, t_s[k]

        if n and self.open_since is not None and not missing[0]:
            closed.append((self.open_since, start))     # closed at the window's start
            times.append((*self.open_at, t_s[0]) if timed else None)
            self.open_since = None
        edges = start + np.flatnonzero(np.diff(np.r_[0, missing.astype(int), 0]))
        for a, b in zip(edges[::2], edges[1::2], strict=True):
            a, b = int(a), int(b)
            carried = a == start and self.open_since is not None
            at = self.open_at if carried else (opened(a) if timed else None)
            if carried:
                a = self.open_since
            self.open_since = None
            if b == start + n:              # still open at the window's end
                self.open_since, self.open_at = a, at
                break
            closed.append((a, b))
            times.append((*at, t_s[b - start]) if timed else None)
        if timed and n:
            self.last_t = t_s[-1]
        keep = [self._long(a, b, tm) for (a, b), tm in zip(closed, times, strict=True)]
        if timed:
            self.hours.extend([float(tm[1] - self.t0) / 3600, float(tm[2] - self.t0) / 3600]
                              for tm, k in zip(times, keep, strict=True) if k)
        closed = [g for g, k in zip(closed, keep, strict=True) if k]
        self.gaps.extend(closed)
        return closed

    def finish(self, n: int) -> None:
        if self.open_since is not None:
            if self.step is None:
                if self._long(self.open_since, n):
                    self.gaps.append((self.open_since, n))
            else:
                before, first = self.open_at
                end = self.last_t + self.step
                if self._long(self.open_since, n, (before, first, end)):
                    self.gaps.append((self.open_since, n))
                    self.hours.append([float(first - self.t0) / 3600,
                                       float(end - self.t0) / 3600])
        self.open_since = None


class RunTally:
    """summary.json's statistics over a streamed run (see the module doc)."""

    def __init__(self, s, truth: bool = True, twin: bool = True, step_s: float | None = None,
                 t0_s: float = 0.0):
        """``step_s``, ``t0_s``: a file off the grid (``GapTracker``)."""
        self.s, self.truth, self.twin = s, truth, twin
        dt = s.sample_interval_s
        self.t0 = t0_s
        self.gaps = GapTracker(dt, s.estimator.sun_gap_min_h * HOUR_S, step_s, t0_s)
        self.rms = {k: Rms() for k in ("yaw", "roll", "h", "yaw_linear", "yaw_smoothed")}
        self.cmp = {k: (Rms(), Rms(), Rms()) for k in ("roll_deg", "yaw_deg", "h_Nms")}
        self.max_diff = {k: 0.0 for k in self.cmp}
        self.per_state, self.per_state_n = np.zeros(N_STATES), 0
        self.nees = {k: Mean() for k in ("real", "linear")}
        self.nees_settled = Mean()      # the real run's, after the start-up (checks.py)
        self.nees_inside = {k: [0, 0] for k in ("real", "linear")}
        self.nis = {k: [Mean() for _ in range(3)] for k in ("real", "linear")}
        self.ends = {"err": [], "err_linear": [], "sigma": []}
        self.within = True
        self.judged = 0                 # gap ends whose error was judged
        # A truth file's rows at only some samples: where each gap end was judged (its
        # time, or None), the errors judged in the latest window (by gap end) and the
        # last common row seen (global sample, yaw error, yaw σ, time).
        self.compared_at: list[float | None] = []
        self.end_errors: dict[int, float | None] = {}
        self.last_row: tuple[int, float, float, float] | None = None
        self.truth_max = {"roll": (0.0, 0.0), "yaw": (0.0, 0.0)}
        self.backend = None
        self.bounds = chi2_bounds(N_STATES, 1)

    def add(self, w: Window, err, err_lin, nees_idx) -> list[tuple[int, int]]:
        """Adds one window; returns the Sun gaps that closed in it."""
        a = w.start
        real = w.real
        self.backend = real.backend
        sig = real.sigma
        nees_real, nees_lin = w.nees_real, w.nees_linear
        present = np.isfinite(w.measured.yaw_rad)
        closed = self.gaps.add(a, present, w.t_s)
        self.end_errors = {}
        for ga, b in closed:
            k = b - a
            self.ends["sigma"].append(float(sig[k, Y] * RAD2DEG))
            if self.truth and w.truth_rows is not None:
                self._judge_at_row(w, err, ga, b)
            elif self.truth:
                self.ends["err"].append(float(err[k, Y] * RAD2DEG))
                self.within &= bool(abs(err[k, Y]) <= 3 * sig[k, Y])
                self.judged += 1
                self.compared_at.append(float(w.t_s[k]))
            if self.twin:
                self.ends["err_linear"].append(float(err_lin[k, Y] * RAD2DEG))
        for name in ("real", "linear"):
            result = real if name == "real" else w.linear
            if result is not None:
                v = nis(result.innovations, result.innovation_var)
                for m in range(3):
                    self.nis[name][m].add(v[:, m])
        if self.truth:
            self.rms["yaw"].add(err[:, Y])
            self.rms["roll"].add(err[:, R])
            self.rms["h"].add(err[:, H_WHEEL])
            k = nees_idx - a
            ratio = (err[k] / np.maximum(sig[k], 1e-300)) ** 2
            self.per_state = self.per_state + np.sum(ratio, axis=0)
            self.per_state_n += len(ratio)
            self._nees("real", nees_real)
            self.nees_settled.add(nees_real[self._settled(w, nees_idx)])
            rows = slice(None) if w.truth_rows is None else w.truth_rows
            top = truth_extremes(w.truth_model[rows], w.t_s[rows])
            self.truth_max = {k: max(self.truth_max[k], top[k], key=lambda v: v[0])
                              for k in top}
            if w.smoothed_x is not None:
                self.rms["yaw_smoothed"].add(w.smoothed_x[:, Y] - w.truth_model[:, Y])
        if self.twin:
            self.rms["yaw_linear"].add(err_lin[:, Y])
            self._nees("linear", nees_lin)
            if self.truth:
                for name, k in (("roll_deg", R), ("yaw_deg", Y), ("h_Nms", H_WHEEL)):
                    r, lin, diff = self.cmp[name]
                    r.add(err[:, k])
                    lin.add(err_lin[:, k])
                    d = err[:, k] - err_lin[:, k]
                    diff.add(d)
                    self.max_diff[name] = max(self.max_diff[name], float(np.max(np.abs(d))))
        return closed

    def _judge_at_row(self, w: Window, err, gap_start: int, b: int) -> None:
        """A gap end judged at the last common row at or before it, when that row is
        inside the gap and the yaw σ there is the end's (``run.estimate_truth``'s rule,
        the last row carried across windows)."""
        a, sig = w.start, w.real.sigma
        rows = w.truth_rows
        i = int(np.searchsorted(rows, b - a, side="right")) - 1
        if i >= 0:
            r = int(rows[i])
            row = (a + r, err[r, Y], sig[r, Y], w.t_s[r])
        else:
            row = self.last_row
        ok = row is not None and row[0] >= gap_start and \
            abs(row[2] / sig[b - a, Y] - 1.0) <= END_SIGMA_MATCH
        e = float(row[1] * RAD2DEG) if ok else None
        self.ends["err"].append(e)
        self.end_errors[b] = e
        self.compared_at.append(float(row[3]) if ok else None)
        if ok:
            self.judged += 1
            self.within &= bool(abs(row[1]) <= 3 * row[2])

    def end_window(self, w: Window, err) -> None:
        """Carries a sparse truth's last common row of the window to the next."""
        if self.truth and w.truth_rows is not None and len(w.truth_rows):
            r = int(w.truth_rows[-1])
            self.last_row = (w.start + r, err[r, Y], w.real.sigma[r, Y], w.t_s[r])

    def _settled(self, w: Window, idx) -> np.ndarray:
        """Which of the samples ``idx`` are past the start-up (by time off the grid)."""
        if self.gaps.step is None:
            return idx * self.s.sample_interval_s >= SETTLED_S
        return w.t_s[idx - w.start] - self.t0 >= SETTLED_S

    def _nees(self, name: str, values) -> None:
        self.nees[name].total += np.sum(values)
        self.nees[name].count += len(values)
        v = values[np.isfinite(values)]
        self.nees_inside[name][0] += int(np.sum((v >= self.bounds[0]) & (v <= self.bounds[1])))
        self.nees_inside[name][1] += v.size

    def statistics(self, n_samples: int) -> RunStatistics:
        """The run's statistics, once every window is in."""
        self.gaps.finish(n_samples)
        truth, twin = self.truth, self.twin

        def when(ok, value):
            return value() if ok else None

        def inside(name):
            k, n = self.nees_inside[name]
            return float(k / n) if n else float("nan")

        def comparison():
            return {name: {"rms_real": r.value() * f, "rms_linear": lin.value() * f,
                           "rms_difference": d.value() * f,
                           "max_abs_difference": self.max_diff[name] * f}
                    for (name, (r, lin, d)), f in zip(self.cmp.items(),
                                                       (RAD2DEG, RAD2DEG, 1.0), strict=True)}

        return RunStatistics(
            gaps=self.gaps.gaps, end_sigma=self.ends["sigma"],
            nis={m: self.nis["real"][i].value() for i, m in enumerate(("roll", "yaw", "h"))},
            yaw_rms=when(truth, lambda: self.rms["yaw"].value() * RAD2DEG),
            per_state=when(truth, lambda: self.per_state / self.per_state_n),
            yaw_rms_linear=when(twin, lambda: self.rms["yaw_linear"].value() * RAD2DEG),
            roll_rms=when(truth, lambda: self.rms["roll"].value() * RAD2DEG),
            h_rms=when(truth, lambda: self.rms["h"].value()),
            yaw_rms_smoothed=when(truth and self.rms["yaw_smoothed"].count > 0,
                                  lambda: self.rms["yaw_smoothed"].value() * RAD2DEG),
            end_err=when(truth, lambda: self.ends["err"]),
            end_err_linear=when(twin, lambda: self.ends["err_linear"]),
            ends_within=when(truth and self.judged > 0, lambda: self.within),
            comparison=when(truth and twin, comparison),
            nees_mean=when(truth, lambda: float(self.nees["real"].total
                                                / self.nees["real"].count)),
            nees_mean_linear=when(twin, lambda: float(self.nees["linear"].total
                                                      / self.nees["linear"].count)),
            nees_mean_settled=when(truth, self.nees_settled.value),
            nees_inside=when(truth, lambda: inside("real")),
            nees_inside_linear=when(twin, lambda: inside("linear")),
            nis_linear=when(twin, lambda: {m: self.nis["linear"][i].value()
                                           for i, m in enumerate(("roll", "yaw", "h"))}),
            truth_max=when(truth, lambda: self.truth_max),
        )
