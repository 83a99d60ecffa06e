"""The scheduled events of a run (issue 45) on its page: marked on every time figure
as errors.png and season.png mark them (a thin band over a duration, a dashed line
at a command, in the kind's colour: ``figures.marks``) and listed in a table.

From summary.json's ``events`` (``figures.marks.summary_events``); a run without
events gets no mark, no legend entry and no table.
"""

from __future__ import annotations

from ..figures.marks import DURATION_EVENTS, EVENT_SHADES, event_label
from .cells import Table, cell, text

SUMMARY = "summary.json"


def _color(kind: str, opaque: bool = False) -> str:
    shade = EVENT_SHADES[kind]
    return shade.color if opaque else shade.rgba()


def shapes(events, scale: float, t0_s: float = 0.0) -> list[dict]:
    """One plotly shape per event across every panel (``yref: paper``), x = (t −
    ``t0_s``) / ``scale`` in the axis's units; each named ``event: <kind>``."""
    out = []
    for e in events:
        kind = e["kind"]
        if kind not in EVENT_SHADES:
            continue
        a = (float(e["t_s"]) - t0_s) / scale
        common = {"name": f"event: {kind}", "xref": "x", "yref": "paper", "y0": 0, "y1": 1,
                  "x0": a}
        if kind in DURATION_EVENTS:
            # Its edge drawn too: a 20-minute band on a year's axis still shows.
            out.append(common | {"type": "rect", "x1": (float(e["end_s"]) - t0_s) / scale,
                                 "fillcolor": _color(kind),
                                 "line": {"width": 1, "color": _color(kind)},
                                 "layer": "below"})
        else:
            out.append(common | {"type": "line", "x1": a, "layer": "above",
                                 "line": {"width": 1.5, "color": _color(kind, True),
                                          "dash": "dash"}})
    return out


def legend(events) -> list[dict]:
    """One legend entry per kind present (shapes have none of their own)."""
    kinds = [k for k in EVENT_SHADES if any(e["kind"] == k for e in events)]
    out = []
    for kind in kinds:
        entry = {"type": "scatter", "x": [None], "y": [None], "name": event_label(kind, events),
                 "legendgroup": f"event: {kind}", "hoverinfo": "skip"}
        if kind in DURATION_EVENTS:
            entry |= {"mode": "markers",
                      "marker": {"symbol": "square", "size": 12, "color": _color(kind)}}
        else:
            # A vertical tick for a vertical line (a "lines" trace of no point would
            # be an empty path).
            entry |= {"mode": "markers", "marker": {
                "symbol": "line-ns-open", "size": 14, "color": _color(kind, True),
                "line": {"width": 2, "color": _color(kind, True)}}}
        out.append(entry)
    return out


def _details(e: dict) -> str:
    """What the event does, from its kind's own fields."""
    if e["kind"] == "thruster" and e.get("torque_Nm") is not None:
        return "torque " + ", ".join(f"{v:.3g}" for v in e["torque_Nm"]) + " N m"
    if e["kind"] == "sensor_outage" and e.get("sensor"):
        return f"{e['sensor']} sensor out"
    if e.get("angle_deg") is not None:
        return f"to {e['angle_deg']:g}°"
    return "to the backup yaw wheel" if e["kind"] == "wheel_switch" else ""


def table(events) -> Table | None:
    """Every event of the run: its kind, start (UTC and s from the epoch), duration,
    what it does and its label (summary.json; the duration worked out here)."""
    if not events:
        return None
    rows = []
    for i, e in enumerate(events):
        key = f"events[{i}]"
        lasting = e["kind"] in DURATION_EVENTS
        rows.append([
            text(str(i + 1)), cell(e["kind"], SUMMARY, f"{key}.kind"),
            cell(e.get("utc"), SUMMARY, f"{key}.utc") if "utc" in e else text("—"),
            cell(e["t_s"], SUMMARY, f"{key}.t_s", "s"),
            cell(float(e["end_s"]) - float(e["t_s"]), unit="s") if lasting
            else text("— (a command)"),
            text(_details(e)),
            cell(e.get("label"), SUMMARY, f"{key}.label") if "label" in e else text("—")])
    return Table("event-list", ["event", "kind", "start (UTC)", "start (s from the epoch)",
                            "duration", "what", "label"], rows,
                 "Scheduled events (summary.json's events; each duration worked out here)")
