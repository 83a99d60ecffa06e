"""The colours of what the time figures shade and mark, one scheme for the PNG
figures and the review page (which reads this module through
``scenarios/figures/marks.py``: only ``figures`` imports ``plots``).

Each kind is a colour and an opacity: matplotlib draws it with ``alpha``, plotly.js
as ``rgba()``, so over white both give the same tint, and where two kinds overlap
(a telemetry gap inside a Sun gap) both show.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Shade:
    color: str      # "#rrggbb"
    alpha: float

    def mpl(self) -> dict:
        """Keyword arguments for matplotlib (axvspan, fill_between, plot)."""
        return {"color": self.color, "alpha": self.alpha}

    def rgba(self) -> str:
        """The same tint as a CSS colour (plotly.js)."""
        c = self.color.lstrip("#")
        r, g, b = (int(c[i:i + 2], 16) for i in (0, 2, 4))
        return f"rgba({r}, {g}, {b}, {self.alpha:g})"


PALETTE = {
    # No head sees the Sun for sun_gap_min_h or more: 0.85 grey over white.
    "sun_gap": Shade("#000000", 0.15),
    # A shorter yaw outage (the noon band, a yaw dropout): pale blue.
    "outage": Shade("#1f6fb4", 0.20),
    # No telemetry row at all: nothing is drawn across it.  Amber, apart from both.
    "telemetry_gap": Shade("#ffa000", 0.35),
    # A value the telemetry screen turned into a dropout: tick marks, opaque.
    "screened": Shade("#e7298a", 1.0),
    "eclipse": Shade("#3c3c8c", 0.20),
}

# The scheduled events (issue 45), each kind its own colour and name, the same in the
# PNG figures and on the page: a duration is a thin band (its edges drawn, so a
# 20-minute outage still shows on a year's axis), a command a vertical line.
EVENT_SHADES = {
    "thruster": Shade("#b8860b", 0.45),         # dark gold
    "sensor_outage": Shade("#17becf", 0.40),    # cyan
    "trim_tab": Shade("#8c564b", 0.95),         # brown
    "array_offset": Shade("#6a3d9a", 0.95),     # violet
    "wheel_switch": Shade("#1b9e77", 0.95),     # teal green
}
EVENT_LABELS = {
    "thruster": "thruster firing (scheduled event)",
    "sensor_outage": "sensor outage (scheduled event)",
    "trim_tab": "trim-tab command",
    "array_offset": "solar-array offset command",
    "wheel_switch": "switch to the backup yaw wheel",
}
DURATION_EVENTS = ("thruster", "sensor_outage")
