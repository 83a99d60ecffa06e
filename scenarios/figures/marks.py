"""What the PNG figures (``run``) and the review page (``review.run_figures``) both
mark on a run's time axis, decided once here: the telemetry gaps, where nothing is
drawn, and the colours of every shaded or marked kind (``plots.palette``, the one
scheme; the page reads it from here, since only ``figures`` imports ``plots``).

A telemetry gap is a stretch of time with no telemetry row: a hole in an
`estimate` input file, or a long dropout.  Off the filter's grid comparison.npz has
no row there; on it the filter's rows go on, predicting, with no telemetry value.
Either way the figures draw the same thing: the rows inside the gap are left out
and one break (a row whose time and values are all NaN) stands between the rows
either side, so no line, band or bin joins them (``plots.reduce``; plotly.js
breaks a line at a NaN too).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from dynprop.plots.events import event_label
from dynprop.plots.palette import DURATION_EVENTS, EVENT_SHADES, PALETTE, Shade

__all__ = ["PALETTE", "Shade", "Cut", "cut_at_gaps", "telemetry_gaps", "telemetry_present",
           "DURATION_EVENTS", "EVENT_SHADES", "event_label", "summary_events", "shifted"]

# A stretch without a telemetry row longer than this many of the file's usual steps
# is a gap: well above a jittered or thinned cadence (a lost row doubles a step),
# and at a day's drawing scale still a sliver.
GAP_STEPS = 10.0
# comparison.npz's keys that are not one value per row.
NOT_ROWS = frozenset({"screened_t_s", "output_interval_s"})


def telemetry_present(c: Mapping) -> np.ndarray:
    """Rows holding any telemetry value (comparison.npz's ``tel_*`` series: roll,
    pitch, yaw, the tachometers); every row when the telemetry is not stored."""
    n = len(c["t_s"])
    keys = [k for k in c if k.startswith("tel_") and k.endswith(("_deg", "_rpm"))
            and k != "tel_yaw_sigma_deg"]
    if not keys:
        return np.ones(n, dtype=bool)
    present = np.zeros(n, dtype=bool)
    for k in keys:
        present |= np.isfinite(np.asarray(c[k], dtype=float))
    return present


def telemetry_gaps(t_s, present) -> list[tuple[int, int]]:
    """(i, j): the row before and the row after each telemetry gap, consecutive rows
    holding telemetry more than ``GAP_STEPS`` of their median step apart."""
    t = np.asarray(t_s, dtype=float)
    rows = np.flatnonzero(np.asarray(present, dtype=bool))
    if rows.size < 3:
        return []
    step = np.diff(t[rows])
    usual = float(np.median(step))
    wide = np.flatnonzero(step > GAP_STEPS * usual) if usual > 0 else np.empty(0, int)
    return [(int(rows[k]), int(rows[k + 1])) for k in wide]


@dataclass(frozen=True, eq=False)
class Cut(Mapping):
    """comparison.npz's rows as the figures draw them: the rows inside telemetry gaps
    left out and a break in each gap.  Read per key, as the page reads the file (a
    year's arrays are not held at once)."""
    source: Mapping
    take: np.ndarray                    # source row of each drawn row; -1 at a break
    gaps_s: tuple[tuple[float, float], ...]   # each gap's (last row before, first after), s
    n: int                              # the source's rows (its t_s read once, not per key)

    def rows(self, a) -> np.ndarray:
        """A per-row array cut: NaN at the breaks, and a boolean True at a break only
        when it is on both sides (a yaw outage that runs through the gap)."""
        a = np.asarray(a)
        out = a[self.take]
        brk = self.take < 0
        if not brk.any():
            return out
        if out.dtype == bool:
            out[brk] = out[np.flatnonzero(brk) - 1] & out[np.flatnonzero(brk) + 1]
            return out
        out = out.astype(np.result_type(out.dtype, np.float32))
        out[brk] = np.nan
        return out

    def __getitem__(self, key):
        a = self.source[key]
        if (not self.gaps_s or key in NOT_ROWS or np.ndim(a) == 0
                or len(a) != self.n):
            return a
        return self.rows(a)

    def __contains__(self, key) -> bool:
        return key in self.source

    def __iter__(self):
        return iter(self.source)

    def __len__(self) -> int:
        return len(self.source)


def cut_at_gaps(c: Mapping) -> Cut:
    """``c`` (comparison.npz, or a dict of its arrays) cut at its telemetry gaps."""
    t = np.asarray(c["t_s"], dtype=float)
    gaps = telemetry_gaps(t, telemetry_present(c))
    keep = np.ones(t.size, dtype=bool)
    for i, j in gaps:
        keep[i + 1:j] = False
    idx = np.flatnonzero(keep)
    take = np.insert(idx, np.searchsorted(idx, [i for i, _ in gaps], side="right"), -1)
    return Cut(c, take, tuple((float(t[i]), float(t[j])) for i, j in gaps), t.size)


def summary_events(summary: Mapping | None) -> list[dict]:
    """summary.json's scheduled events (dicts with kind, t_s, end_s, ...: issue 45),
    which errors.png, season.png and the page mark; none without the key (a run
    without events: nothing is drawn, nothing changes)."""
    items = (summary or {}).get("events") or []
    return [e for e in items if isinstance(e, dict) and {"kind", "t_s"} <= set(e)]


def shifted(events: list[dict], t0_s: float) -> list[dict]:
    """``events`` with their times counted from ``t0_s`` (a day axis's first day)."""
    return [e | {"t_s": e["t_s"] - t0_s}
            | ({"end_s": e["end_s"] - t0_s} if e.get("end_s") is not None else {})
            for e in events]
