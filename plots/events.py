"""The scheduled events of a run (issue 45) marked on a figure's time axis: a thin
band over each event with a duration (thruster, sensor_outage), a vertical line at
each command (trim_tab, array_offset, wheel_switch), in the kind's colour
(``palette.EVENT_SHADES``) and with one legend entry per kind.

Draws only what it is given: events as plain dicts with ``kind``, ``t_s`` and
``end_s`` (summary.json's ``events``), placed by the caller's map from seconds to
the axis's units.
"""

from __future__ import annotations

from collections.abc import Callable

from .palette import DURATION_EVENTS, EVENT_LABELS, EVENT_SHADES

# Above the shadings (zorder 0) and under the data (traces from 1 up): an event marks
# where something happened; it never hides an error.
BAND_Z, LINE_Z = 0.5, 0.8


def event_label(kind: str, events) -> str:
    """The legend's name of a kind; a sensor outage's names its sensors."""
    label = EVENT_LABELS.get(kind, kind)
    if kind == "sensor_outage":
        sensors = sorted({str(e.get("sensor")) for e in events
                          if e["kind"] == kind and e.get("sensor")})
        if sensors:
            label = f"{label}: {', '.join(sensors)}"
    return label


def mark_events(ax, events, to_x: Callable[[float], float], label: bool = True) -> int:
    """Each event of ``events`` on ``ax`` at ``to_x(seconds)``; ``label``: the first of
    each kind carries its legend entry (``decor.figure_legend`` keeps one per name).
    Returns the marks drawn."""
    seen: set[str] = set()
    drawn = 0
    for e in events or ():
        kind = e["kind"]
        shade = EVENT_SHADES.get(kind)
        if shade is None:
            continue
        name = event_label(kind, events) if label and kind not in seen else None
        seen.add(kind)
        a = to_x(float(e["t_s"]))
        if kind in DURATION_EVENTS:
            # The edge drawn too: a band narrower than a pixel still shows as a line.
            ax.axvspan(a, to_x(float(e["end_s"])), facecolor=shade.color,
                       edgecolor=shade.color, alpha=shade.alpha, lw=0.8, zorder=BAND_Z,
                       label=name)
        else:
            ax.axvline(a, color=shade.color, alpha=shade.alpha, lw=1.1, ls=(0, (5, 2)),
                       zorder=LINE_Z, label=name)
        drawn += 1
    return drawn
