"""A telemetry file cut into the run's windows: `estimate`'s source for the engine
(``engine``), in place of `run`'s producer.

The plan is `run`'s (``plan.make_plan``) on the file's samples: one window up to two
days, else whole days.  Off the scenario's grid a "day" is the rows whose times fall
in it, and the output stride, the padding and the smoother's overlap are counted in
the file's own median step.  Each window carries its own padding (``records.
Padding``): ``pad`` samples either side, reaching further back or on to the nearest
sample with every wheel read, so that a dropout across the window's edge is bridged
between the same two readings as in the whole file (``estimator.kalman.preprocess``
interpolates the wheel momentum between readings and needs one at each end).
"""

from __future__ import annotations

import numpy as np

from ...bridge.coordinates import model_truth, pitch_truth, truth_torques
from ...bridge.inputs import telemetry_inputs
from ...config.schema import Scenario, output_stride
from ...files.truth_file import TruthFromFile, truth_at
from ...records import Padding, TruthWindow
from ...units import DAY_S, DEG
from .plan import SINGLE_WINDOW_S, SMOOTHER_OVERLAP_S, Plan, make_plan

SEARCH_ROWS = 4096   # rows read at a time looking for the nearest wheel reading
DAY_SEARCH_ROWS = 1 << 20


def file_plan(s: Scenario, source, window_samples: int | None = None) -> Plan:
    """The windows of a telemetry file (see the module doc)."""
    if source.regular:
        return make_plan(s, source.n, window_samples)
    step = source.median_step_s()
    n = source.n
    t = source.columns(0, 1, ["t_s"])["t_s"][0], source.columns(n - 1, n, ["t_s"])["t_s"][0]
    if window_samples is not None:
        starts = list(range(0, n, window_samples))
        if len(starts) > 1 and n - starts[-1] < window_samples // 2:
            starts.pop()
    elif t[1] - t[0] <= SINGLE_WINDOW_S + 1e-9:
        starts = [0]
    else:
        starts = _day_starts(source, t[0], t[1])
    bounds = list(zip(starts, starts[1:] + [n], strict=True))
    stride = max(1, round(s.sample_interval_s * output_stride(s) / step))
    pad = int(round(s.estimator.wheel_torque_window_s / step)) // 2 + 2
    overlap = max(pad, int(round(SMOOTHER_OVERLAP_S / step)))
    return Plan(n, bounds, stride, pad, overlap, (step, float(t[0])))


def _day_starts(source, t0: float, t_last: float) -> list[int]:
    """The first row of each whole day from ``t0``; a last day under half a day joins
    the one before (``plan.window_bounds``' rule, in time)."""
    n_days = int(np.ceil((t_last - t0) / DAY_S - 1e-9))
    edges = t0 + DAY_S * np.arange(1, n_days)
    if n_days > 1 and t_last - edges[-1] < DAY_S / 2:
        edges = edges[:-1]
    starts, a = [0], 0
    for edge in edges:
        while True:
            b = min(a + DAY_SEARCH_ROWS, source.n)
            t = source.columns(a, b, ["t_s"])["t_s"]
            k = int(np.searchsorted(t, edge))
            if k < len(t) or b == source.n:
                starts.append(a + k)
                a += k
                break
            a = b
    return sorted(set(starts))


def _wheels_read(cols: dict, names: list[str]) -> np.ndarray:
    return np.all([np.isfinite(cols[c]) for c in names], axis=0)


def padding_bounds(source, wheels: list[str], start: int, stop: int, pad: int
                   ) -> tuple[int, int]:
    """[lo, hi): ``pad`` samples either side of [start, stop), widened to the nearest
    sample before (after) with every wheel read."""
    n = source.n
    lo = max(0, start - pad)
    while lo > 0:
        a = max(0, lo - SEARCH_ROWS)
        ok = np.flatnonzero(_wheels_read(source.columns(a, lo + 1, wheels), wheels))
        if ok.size:
            lo = a + int(ok[-1])
            break
        lo = a
    hi = min(n, stop + pad)
    while hi < n:
        b = min(n, hi + SEARCH_ROWS)
        ok = np.flatnonzero(_wheels_read(source.columns(hi - 1, b, wheels), wheels))
        if ok.size:
            hi = hi + int(ok[0])
            break
        hi = b
    return lo, hi


def _padding(s: Scenario, source, a: int, b: int) -> Padding:
    cols = source.columns(a, b)
    return Padding(cols["t_s"], telemetry_inputs(s, cols),
                   cols["pitch_deg"] * DEG if "pitch_deg" in cols else None)


class FileTruth:
    """A truth.csv beside the telemetry, placed on the file's samples as a window
    needs it: on the grid at the samples it has a row for (matched once against the
    whole grid, ``truth_file.common_samples``), off it interpolated to each window's
    times.  The columns are read once; a run's truth.csv (every output.interval_s) is
    small beside its telemetry."""

    def __init__(self, s: Scenario, path, cols: dict, source, t0_s: float):
        self.s, self.path, self.cols = s, path, cols
        self.regular = source.regular
        self.placed = None
        if source.regular:
            grid = np.broadcast_to(np.float64(t0_s), (source.n,))   # its first time, length
            self.placed = truth_at(path, s, cols, grid, True)
        self.every = self.placed is not None and self.placed.every_sample(source.n)
        self.file_rows = len(cols["t_s"])
        self.rows_seen: list[np.ndarray] = []      # global samples with a row (sparse)
        self.t_seen: list[np.ndarray] = []

    def window(self, start: int, stop: int, t_s: np.ndarray) -> TruthFromFile | None:
        """The truth on samples [start, stop) (times ``t_s``), rows local; None if it
        has none there."""
        if self.placed is None:
            from ...files.rundir import RunDirError
            try:
                w = truth_at(self.path, self.s, self.cols, t_s, False)
            except RunDirError:
                if t_s[-1] < self.cols["t_s"][0] or t_s[0] > self.cols["t_s"][-1]:
                    return None     # the truth ends before (begins after) this window
                raise
            return w
        p = self.placed
        i0, i1 = np.searchsorted(p.rows, [start, stop])
        if i0 == i1:
            return None
        return TruthFromFile(p.t_s[i0:i1], p.euler_rad[i0:i1], p.w_br_radps[i0:i1],
                             p.h_Nms[i0:i1], {k: v[i0:i1] for k, v in p.torques.items()},
                             p.rows[i0:i1] - start, p.file_rows)


def _truth_fields(s: Scenario, params, truth: FileTruth | None, start: int, stop: int,
                  t_s: np.ndarray, k: np.ndarray) -> dict:
    """A window's truth fields (``records.TruthWindow``): the states at every sample
    (NaN where the truth has no row), the output rows' Euler angles, the rows."""
    if truth is None:
        return {"truth_model": None, "pitch_truth": None, "euler_rows": None}
    n = stop - start
    w = truth.window(start, stop, t_s)
    model, pitch, euler = (np.full((n, 9), np.nan), np.full((n, 3), np.nan),
                           np.full((n, 3), np.nan))
    rows = np.zeros(0, dtype=np.int64)
    if w is not None:
        tt = truth_torques(w, s.estimator.model_torques, params.omega0_radps)
        rows = w.rows
        model[rows], pitch[rows] = model_truth(params, w, tt), pitch_truth(w, tt)
        euler[rows] = w.euler_rad
        truth.rows_seen.append(start + rows)
        truth.t_seen.append(t_s[rows])
    every = len(rows) == n
    return {"truth_model": model, "pitch_truth": pitch, "euler_rows": euler[k],
            "truth_rows": None if every else rows}


def file_windows(s: Scenario, source, plan: Plan, truth: FileTruth | None = None):
    """The plan, then one ``records.TruthWindow`` per window of the file (with the
    truth file's states when given)."""
    from ...config import build
    params, _ = build.estimator_model(s)
    yield plan
    wheels = [c for c in source.names if c.startswith("wheel") and c.endswith("_rpm")]
    for index, (start, stop) in enumerate(plan.bounds):
        cols = source.columns(start, stop)
        lo, hi = padding_bounds(source, wheels, start, stop, plan.pad)
        k = np.arange(-(-start // plan.stride) * plan.stride, stop, plan.stride) - start
        t = _truth_fields(s, params, truth, start, stop, cols["t_s"], k)
        yield TruthWindow(
            index, start, stop, cols["t_s"], telemetry_inputs(s, cols),
            cols["pitch_deg"] * DEG if "pitch_deg" in cols else None,
            {c: v[k] for c, v in cols.items() if c != "t_s"},
            t["truth_model"], t["pitch_truth"], None, t["euler_rows"],
            steps=source.steps(start, stop), truth_rows=t.get("truth_rows"),
            lead=_padding(s, source, lo, start), trail=_padding(s, source, stop, hi))
