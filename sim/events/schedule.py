"""Scheduled events of a run: thruster firings, sensor outages and ground commands.

A scenario's ``events`` list (docs/scenario-reference.md) becomes a ``Schedule``:
every occurrence of every entry, periodic entries already repeated to the run's end,
sorted by time.  The truth and the telemetry ask it about their samples, a window
at a time, never about the whole run at once (a year at 0.512 s is 61.6 M samples).

Sample k, at time t_k, is inside an event when t0 ≤ t_k < t0 + duration; the step
from t_k holds that sample's torque (zero-order hold, as every step input).  A
command at t applies from the first sample with t_k ≥ t: the step from that sample
on flies the new setting.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

KINDS = ("thruster", "sensor_outage", "trim_tab", "array_offset", "wheel_switch")
# Kinds that last a duration; the others are commands, instantaneous.
DURATION_KINDS = ("thruster", "sensor_outage")
COMMAND_KINDS = ("trim_tab", "array_offset", "wheel_switch")
SENSORS = ("earth", "sun", "tachometer")


@dataclass(frozen=True)
class Event:
    """One occurrence: its kind, start ``t_s`` (s from the epoch) and, by kind,
    ``duration_s`` (thruster, sensor_outage; 0 for a command), ``torque_Nm`` (thruster:
    body roll, pitch, yaw torque held over the duration), ``sensor`` (sensor_outage:
    earth, sun or tachometer), ``angle_deg`` (trim_tab, array_offset: the commanded
    absolute angle) and an optional ``label``."""

    kind: str
    t_s: float
    duration_s: float = 0.0
    torque_Nm: tuple[float, float, float] | None = None
    sensor: str | None = None
    angle_deg: float | None = None
    label: str = ""

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"event kind {self.kind!r} is not one of {', '.join(KINDS)}")
        if not np.isfinite(self.t_s) or not np.isfinite(self.duration_s) \
                or self.duration_s < 0:
            raise ValueError("event time and duration must be finite, the duration not "
                             "negative")
        if self.kind == "thruster" and (self.torque_Nm is None or len(self.torque_Nm) != 3
                                        or not np.all(np.isfinite(self.torque_Nm))):
            raise ValueError("a thruster event needs 3 finite torque components")
        if self.kind == "sensor_outage" and self.sensor not in SENSORS:
            raise ValueError(f"sensor_outage sensor must be one of {', '.join(SENSORS)}")

    @property
    def end_s(self) -> float:
        return self.t_s + self.duration_s

    def inside(self, t_s: np.ndarray) -> np.ndarray:
        """Which of the samples ``t_s`` lie inside it: t0 ≤ t_k < t0 + duration."""
        return (t_s >= self.t_s) & (t_s < self.end_s)


def repeated(event: Event, every_s: float | None, run_end_s: float) -> tuple[Event, ...]:
    """``event`` and, every ``every_s`` seconds after it, its repetitions that start
    before ``run_end_s`` (just the event when ``every_s`` is None)."""
    if every_s is None:
        return (event,)
    count = max(1, int(np.ceil((run_end_s - event.t_s) / every_s)))
    starts = event.t_s + every_s * np.arange(count)
    return tuple(Event(event.kind, float(t), event.duration_s, event.torque_Nm, event.sensor,
                       event.angle_deg, event.label) for t in starts if t < run_end_s) \
        or (event,)


@dataclass(frozen=True)
class Schedule:
    """Every occurrence of a run's events, sorted by time (ties keep their order)."""

    events: tuple[Event, ...] = ()

    def __post_init__(self) -> None:
        ordered = tuple(sorted(self.events, key=lambda e: e.t_s))
        object.__setattr__(self, "events", ordered)

    def __bool__(self) -> bool:
        return bool(self.events)

    def of_kind(self, *kinds: str) -> tuple[Event, ...]:
        return tuple(e for e in self.events if e.kind in kinds)

    def _during(self, events, t_s: np.ndarray) -> list[Event]:
        # Only the occurrences that reach into the samples' span are tested sample by
        # sample: a window meets a few of a year's.
        if not len(t_s):
            return []
        lo, hi = float(np.min(t_s)), float(np.max(t_s))
        return [e for e in events if e.t_s <= hi and e.end_s > lo]

    def thruster_torque(self, t_s) -> np.ndarray:
        """(N, 3) body torque of the thruster events at the samples ``t_s`` (N m)."""
        t_s = np.asarray(t_s, dtype=float)
        out = np.zeros((len(t_s), 3))
        for e in self._during(self.of_kind("thruster"), t_s):
            out[e.inside(t_s)] += np.asarray(e.torque_Nm, dtype=float)
        return out

    def maneuver(self, t_s) -> np.ndarray:
        """(N,) whether each sample is inside a thruster event."""
        t_s = np.asarray(t_s, dtype=float)
        out = np.zeros(len(t_s), dtype=bool)
        for e in self._during(self.of_kind("thruster"), t_s):
            out |= e.inside(t_s)
        return out

    def outage(self, sensor: str, t_s) -> np.ndarray:
        """(N,) whether ``sensor`` (earth, sun, tachometer) is out at each sample."""
        if sensor not in SENSORS:
            raise ValueError(f"sensor must be one of {', '.join(SENSORS)}, got {sensor!r}")
        t_s = np.asarray(t_s, dtype=float)
        out = np.zeros(len(t_s), dtype=bool)
        outages = [e for e in self.of_kind("sensor_outage") if e.sensor == sensor]
        for e in self._during(outages, t_s):
            out |= e.inside(t_s)
        return out

    def commands(self, t_from: float, t_to: float) -> tuple[Event, ...]:
        """The trim_tab, array_offset and wheel_switch occurrences with
        t_from ≤ t < t_to, in time order."""
        return tuple(e for e in self.of_kind(*COMMAND_KINDS) if t_from <= e.t_s < t_to)
