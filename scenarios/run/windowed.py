"""A telemetry file (``files.telemetry_source``) read window by window, for the
commands that filter it without holding it whole: `batch` and `trim` (issue 44).

A record of up to two days (``Windows.whole_s``, `run`'s single window) is one
window, preprocessed whole exactly as before; a longer one is cut by time into
windows of ``Windows.window_s``, a remainder under half a window joining the last.
A window's filter inputs are formed from its samples padded with ``pad`` samples of
each neighbour (the wheel-torque fit's half window and one, as `run` pads), and
further out to the nearest sample where every column that preprocessing bridges with
a straight line is present (the wheels; roll and pitch where interpolated): a
derivative, or a dropout's bridge, across a window boundary is then the whole
record's, bit for bit.  What preprocessing measures over a whole record is measured
over the padded window instead, as `run`'s windows measure it: a dropout's wheel
noise (``preprocess.dropout_wheel_noise``) and, off the grid, the cadence the wheel
torque is resampled to (``preprocess.wheel_torque_at``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from dynprop.estimator.kalman.filter import ExtraNoise

from ..config import build
from ..config.schema import Scenario
from ..units import DAY_S
from .stream.plan import SINGLE_WINDOW_S, SMOOTHER_OVERLAP_S

SCAN_ROWS = 4096    # rows read at a time when looking past a dropout for a present sample
# A file's own tags jitter about their grid: two days and a few tens of ms are two days.
TAG_SLACK_S = 1.0


@dataclass(frozen=True)
class Windows:
    """How a record is cut: whole up to ``whole_s``, else in windows of ``window_s``,
    a smoother running ``overlap_s`` past each (a test makes them small to put window
    boundaries where it wants them)."""

    whole_s: float = SINGLE_WINDOW_S
    window_s: float = DAY_S
    overlap_s: float = SMOOTHER_OVERLAP_S


DAYS = Windows()    # `run`'s: whole up to two days, else days


class ArraySource:
    """Whole columns (a dict of telemetry.csv's names) as the window readers ask for
    them (``TelemetrySource.columns``): the reference a streamed source is held to."""

    def __init__(self, cols: dict[str, np.ndarray], regular: bool = True):
        self.cols = cols
        self.regular = regular
        self.names = tuple(cols)
        self.n = len(cols["t_s"])

    def columns(self, start: int, stop: int, names=None) -> dict[str, np.ndarray]:
        return {c: self.cols[c][start:stop] for c in (names or self.names)}


def window_bounds(t_s: np.ndarray, lo: int, hi: int, windows: Windows = DAYS
                  ) -> list[tuple[int, int]]:
    """[start, stop) sample ranges cutting samples [lo, hi) of ``t_s`` (module doc)."""
    t = t_s[lo:hi]
    length = float(t[-1] - t[0])
    if length <= windows.whole_s + TAG_SLACK_S:
        return [(lo, hi)]
    marks = t[0] + windows.window_s * np.arange(1, int(length // windows.window_s) + 1)
    starts = [lo] + [lo + int(i) for i in np.searchsorted(t, marks)]
    starts = sorted(set(i for i in starts if i < hi))
    if len(starts) > 1 and t[-1] - t_s[starts[-1]] < 0.5 * windows.window_s:
        starts.pop()
    return list(zip(starts, starts[1:] + [hi], strict=True))


def pad_samples(s: Scenario, step_s: float) -> int:
    """Samples of each neighbour a window's inputs need: the wheel-torque (and pitch)
    fit's half window and one (``stream.plan.make_plan``'s pad on the grid)."""
    return int(round(s.estimator.wheel_torque_window_s / step_s)) // 2 + 1


def wheel_names(s: Scenario) -> list[str]:
    return [f"wheel{i + 1}_rpm" for i in range(len(build.yaw_factors(s)))]


def _present(source, i: int, bound: int, needed: list[str], step: int) -> int:
    """The first sample from ``i`` in direction ``step`` (±1), not past ``bound``,
    with every column of ``needed`` present; ``bound`` if none is."""
    while True:
        a, b = (i, min(i + SCAN_ROWS, bound + 1)) if step > 0 else (max(i - SCAN_ROWS + 1,
                                                                           bound), i + 1)
        cols = source.columns(a, b, needed)
        ok = np.logical_and.reduce([np.isfinite(cols[c]) for c in needed])
        hits = np.flatnonzero(ok)
        if hits.size:
            return a + int(hits[0] if step > 0 else hits[-1])
        if (b - 1 if step > 0 else a) == bound:
            return bound
        i = b if step > 0 else a - 1


def padded_range(source, a: int, b: int, lo: int, hi: int, pad: int, needed: list[str]
                 ) -> tuple[int, int]:
    """The samples [c, d) ⊇ [a, b) a window's inputs are formed from, inside [lo, hi):
    ``pad`` more on each side, then out to a sample with ``needed`` present."""
    c, d = max(lo, a - pad), min(hi, b + pad)
    if needed:
        c = _present(source, c, lo, needed, -1)
        d = _present(source, d - 1, hi - 1, needed, 1) + 1
    return c, d


def used_names(source, s: Scenario, extra: tuple[str, ...] = ()) -> list[str]:
    """The columns ``bridge.inputs.telemetry_inputs`` reads (and ``extra``), those the
    file has."""
    want = {"t_s", "roll_deg", "yaw_deg", "yaw_sigma_deg", "sun_head", "maneuver",
            *wheel_names(s), *extra}
    return [c for c in source.names if c in want]


def cut_inputs(meas, u: np.ndarray, extra: ExtraNoise | None, sl: slice):
    """``filter_inputs``' measurements, inputs and dropout noise on ``sl`` only (as
    ``bridge.inputs.padded_filter_inputs`` cuts a padded window)."""
    meas = type(meas)(*(v[sl] if np.ndim(v) else v for v in
                        (meas.roll_rad, meas.yaw_rad, meas.h_Nms, meas.var_roll, meas.var_yaw,
                         meas.var_h)))
    return meas, u[sl], None if extra is None else extra.cut(sl)
