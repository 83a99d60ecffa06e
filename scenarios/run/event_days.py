"""The scheduled events (issue 45) as daily.csv counts them: per day of the run the
seconds inside a thruster event (``maneuver_s``), the seconds with a sensor out
(``outage_s``) and the commands given (``commands``: trim_tab, array_offset,
wheel_switch).

Read from the list summary.json's ``events`` holds (docs/outputs.md): dicts with at
least ``kind``, ``t_s`` and ``end_s`` (s from the epoch), periodic entries already
expanded.  Worked out from the events' times, not from the samples: an event
covers [t_s, end_s), cut at the day's bounds and at the run's end, so one across
midnight splits its seconds between the two days.
"""

from __future__ import annotations

import numpy as np

from ..units import DAY_S

# daily.csv's columns, in their order, and the kinds each counts.
DURATIONS = {"maneuver_s": ("thruster",), "outage_s": ("sensor_outage",)}
COMMANDS = ("trim_tab", "array_offset", "wheel_switch")
COLUMNS = (*DURATIONS, "commands")


def event_dicts(s) -> list[dict]:
    """The scenario's events as summary.json lists them (every occurrence, by time);
    [] for a scenario without any, which then writes what it wrote before issue 45.
    The one place the run's outputs get the list from: wired to the events' own
    expansion (the function that writes summary.json's ``events``)."""
    if not s.events:
        return []
    from ..files.summary import events_list
    return events_list(s)


def _union(spans) -> list[tuple[float, float]]:
    """The spans merged where they overlap (two sensors out at once count once)."""
    out: list[list[float]] = []
    for a, b in sorted(spans):
        if out and a <= out[-1][1]:
            out[-1][1] = max(out[-1][1], b)
        else:
            out.append([a, b])
    return [(a, b) for a, b in out]


def day_seconds(spans, edges: np.ndarray) -> np.ndarray:
    """Per day (between consecutive ``edges``, s), the seconds of the union of ``spans``
    ([start, end) each) inside it."""
    total = np.zeros(len(edges) - 1)
    for a, b in _union(spans):
        total += np.clip(np.minimum(b, edges[1:]) - np.maximum(a, edges[:-1]), 0.0, None)
    return total


def day_columns(events, n_days: int, t0_s: float, end_s: float) -> dict[str, np.ndarray]:
    """daily.csv's event columns for ``n_days`` days from ``t0_s`` (day k: [t0 + k, t0 +
    k + 1) days), the run ending at ``end_s``: the seconds of each day inside a
    thruster event, those with any sensor out, and the commands given in it."""
    edges = t0_s + DAY_S * np.arange(n_days + 1, dtype=float)
    stop = min(float(end_s), float(edges[-1]))
    out = {}
    for column, kinds in DURATIONS.items():
        spans = [(max(float(e["t_s"]), t0_s), min(float(e["end_s"]), stop))
                 for e in events if e["kind"] in kinds]
        out[column] = day_seconds([(a, b) for a, b in spans if b > a], edges)
    times = np.array([float(e["t_s"]) for e in events if e["kind"] in COMMANDS
                      and t0_s <= float(e["t_s"]) <= stop])
    day = np.minimum(((times - t0_s) // DAY_S).astype(np.int64), n_days - 1)
    out["commands"] = np.bincount(day, minlength=n_days).astype(float)
    return out
