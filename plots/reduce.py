"""Reductions FOR DRAWING ONLY, shared by the run figures.

Runs are long (two days at 0.512 s is ~340,000 samples per trace).  Drawn as they
are, noisy traces become solid blobs and take seconds to render, so each trace is
reduced first: a slow trace to a min/max pair per pixel column (the same picture as
the full trace), a noisy one to its min/max band and RMS per time interval (what an
engineer reads off a noisy error), a point cloud to a stride subsample.  Every
function works on copies: the caller's arrays are never modified.

A time array may hold breaks: rows whose time (and every value) is NaN, each standing
for a telemetry gap between the rows either side (``scenarios/figures/marks.py``
puts them there).  No bin, interval or line spans a break, so nothing is drawn
across a gap.
"""

from __future__ import annotations

import numpy as np

NBINS = 2000          # drawing bins across the time axis (~1 per pixel column at 120 dpi)
MAX_DOTS = 10000      # points drawn for a per-sample scatter


def f64(a) -> np.ndarray:
    """A float array view/copy of ``a``; never written to."""
    return np.asarray(a, dtype=float)


def finite(a) -> np.ndarray:
    a = f64(a)
    return a[np.isfinite(a)]


def pct(a, q: float, default: float = 0.0) -> float:
    a = finite(a)
    return float(np.percentile(a, q)) if a.size else default


def max_abs(a, default: float = 0.0) -> float:
    a = finite(a)
    return float(np.max(np.abs(a))) if a.size else default


def bins(n: int, nbins: int = NBINS, t=None):
    """Start and end (inclusive) indices of ``nbins`` equal-count bins, or None if n is
    small.  With the time array ``t``, each break (a NaN time) is a bin of its own,
    so no bin reaches across a gap."""
    if n <= 2 * nbins:
        return None
    starts = np.linspace(0, n, nbins + 1)[:-1].astype(int)
    if t is not None:
        brk = np.flatnonzero(np.isnan(f64(t)))
        if brk.size:
            starts = np.unique(np.r_[starts, brk, brk + 1])
            starts = starts[starts < n]
    ends = np.r_[starts[1:], n] - 1
    return starts, ends


def breaks(t) -> np.ndarray:
    """Indices of the break rows (NaN times) of a time array."""
    return np.flatnonzero(np.isnan(f64(t)))


def minmax_line(t_h: np.ndarray, y) -> tuple[np.ndarray, np.ndarray]:
    """(x, y) to draw as a line: per bin the minimum then the maximum (NaN-aware).

    At one bin per pixel column this draws the same picture as the full trace.
    A bin with no finite value gives NaN, so data gaps stay gaps.
    """
    y = f64(y)
    b = bins(y.size, t=t_h)
    if b is None:
        return t_h, y
    starts, ends = b
    lo = np.fmin.reduceat(y, starts)
    hi = np.fmax.reduceat(y, starts)
    x = np.column_stack([t_h[starts], t_h[ends]]).ravel()
    return x, np.column_stack([lo, hi]).ravel()


def band(t_h: np.ndarray, lower, upper) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(x, lo, hi) for fill_between: the per-bin min of ``lower`` and max of ``upper``."""
    lower, upper = f64(lower), f64(upper)
    b = bins(lower.size, t=t_h)
    if b is None:
        return t_h, lower, upper
    starts, ends = b
    x = np.column_stack([t_h[starts], t_h[ends]]).ravel()
    return (x, np.repeat(np.fmin.reduceat(lower, starts), 2),
            np.repeat(np.fmax.reduceat(upper, starts), 2))


def nice_interval_s(span_s: float, n_target: int = 300, min_s: float = 0.0) -> float:
    """A round interval (1 s … 1 day) giving about ``n_target`` intervals over the span:
    enough to follow the σ envelope, few enough that each interval's band reads; and
    at least ``min_s`` (a statistic per interval wants several samples)."""
    for step in (1, 2, 5, 10, 15, 30, 60, 120, 300, 600, 900, 1800, 3600, 7200, 21600, 86400):
        if span_s / step <= n_target and step >= min_s:
            return float(step)
    return 86400.0


def interval_stats(t_s: np.ndarray, y, interval_s: float):
    """Per time interval: (x, lo, hi, rms) with x the interval's [start, end] pairs
    (each statistic repeated twice), for a band and a step-like line.  NaN-aware;
    an interval with no finite value gives NaN, and a break (NaN time) is an interval of
    its own, so the line breaks there."""
    t_s, y = f64(t_s), f64(y)
    timed = np.isfinite(t_s)
    k = np.full(t_s.size, -1, dtype=np.int64)
    k[timed] = np.floor((t_s[timed] - t_s[0]) / interval_s).astype(np.int64)
    starts = np.flatnonzero(np.r_[True, k[1:] != k[:-1]])
    ends = np.r_[starts[1:], y.size] - 1
    ok = np.isfinite(y)
    lo = np.fmin.reduceat(y, starts)
    hi = np.fmax.reduceat(y, starts)
    cnt = np.add.reduceat(ok.astype(np.int64), starts)
    ss = np.add.reduceat(np.where(ok, y * y, 0.0), starts)
    with np.errstate(invalid="ignore", divide="ignore"):
        rms = np.sqrt(ss / cnt)
    x = np.column_stack([t_s[starts], t_s[ends]]).ravel() / 3600.0
    return x, np.repeat(lo, 2), np.repeat(hi, 2), np.repeat(rms, 2)


def stride(t_h: np.ndarray, y, n_max: int = MAX_DOTS):
    """Every k-th finite sample, k chosen so at most ``n_max`` remain."""
    y = f64(y)
    ok = np.flatnonzero(np.isfinite(y))
    step = max(1, -(-ok.size // n_max))     # ceiling: at most n_max, as promised
    ok = ok[::step]
    return t_h[ok], y[ok]


def every(t_h: np.ndarray, y, n_max: int = MAX_DOTS):
    """Every k-th sample, NaN kept (a line drawn from it breaks where the data do):
    for smooth series such as running means.  Every break is kept, its value NaN."""
    y = f64(y)
    step = max(1, y.size // n_max)
    brk = breaks(t_h)
    if not brk.size:
        return t_h[::step], y[::step]
    idx = np.union1d(np.arange(0, y.size, step), brk)
    out = y[idx]
    out[np.isnan(f64(t_h)[idx])] = np.nan
    return t_h[idx], out


def running_mean(y, window: int) -> np.ndarray:
    """Centred running mean ignoring NaN; NaN where under half the window is finite."""
    y = f64(y)
    ok = np.isfinite(y)
    window = int(min(max(window, 1), y.size))
    c = np.r_[0.0, np.cumsum(np.where(ok, y, 0.0))]
    k = np.r_[0, np.cumsum(ok)]
    half = window // 2
    idx = np.arange(y.size)
    a = np.clip(idx - half, 0, y.size)
    b = np.clip(idx - half + window, 0, y.size)
    cnt = k[b] - k[a]
    out = np.full(y.size, np.nan)
    good = cnt >= max(1, window // 2)
    out[good] = (c[b] - c[a])[good] / cnt[good]
    return out


def window(t_s: np.ndarray, seconds: float) -> int:
    """Samples in ``seconds`` at the median step of ``t_s`` (breaks left out)."""
    dt = median_step(t_s)
    return max(1, int(round(seconds / dt))) if dt > 0 else 1


def median_step(t) -> float:
    """The median step between rows, breaks (NaN times) left out; 0 under two rows."""
    t = f64(t)
    d = np.diff(t[np.isfinite(t)])
    return float(np.median(d)) if d.size else 0.0


def runs_of(mask) -> list[tuple[int, int]]:
    """(first, last) indices, inclusive, of each run of True in ``mask``."""
    mask = np.asarray(mask, dtype=bool)
    edges = np.diff(np.r_[0, mask.astype(np.int8), 0])
    return list(zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1, strict=True))
