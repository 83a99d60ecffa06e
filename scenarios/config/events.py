"""The scenario's ``events`` list: thruster firings, sensor outages and ground commands
at set times (docs/scenario-reference.md, docs/conventions.md).

Each entry is one ``EventEntry``; ``schedule`` expands them, periodic ones repeated to
the run's end, into the simulator's ``sim.events.Schedule``, and ``event_problems``
says, one line per problem naming ``events[i].<key>``, what makes a list unflyable:
an occurrence starting outside the run, two of one kind at once, a key the kind
does not have or one it needs left out.
"""

from __future__ import annotations

from typing import Literal

from dynprop.sim.ephemeris import parse_epoch
from dynprop.sim.events import DURATION_KINDS, SENSORS, Event, Schedule, repeated
from pydantic import Field, field_validator

from ..units import DAY_S
from .sections import Vec3, _Section

# Each kind's own keys and which of them it needs; every kind has kind, time_s or
# time_utc, every_days and label.
KIND_KEYS = {"thruster": ("duration_s", "torque_Nm"),
             "sensor_outage": ("duration_s", "sensor"),
             "trim_tab": ("angle_deg",), "array_offset": ("angle_deg",), "wheel_switch": ()}
COMMON_KEYS = ("kind", "time_s", "time_utc", "every_days", "label")


class EventEntry(_Section):
    """One entry of `events`, at `time_s` (seconds from `epoch_utc`) or `time_utc`,
    exactly one of the two, within the run. By kind: `thruster` (a body torque
    `torque_Nm` held for `duration_s`: station keeping, a momentum dump; telemetry.csv's
    `maneuver` column is 1 while it fires), `sensor_outage` (`sensor` reads nothing
    for `duration_s`: its telemetry columns are empty), `trim_tab` and `array_offset`
    (the solar array's tab or offset commanded to `angle_deg` from the first sample at
    or after the time on) and `wheel_switch` (from the first sample at or after the
    time on, the yaw control flies on the backup yaw wheel, the canted pair keeping the
    pitch control; needs `spacecraft.yaw_wheel.standby`, once a run). A key another
    kind uses is an error. Two occurrences of one kind may not overlap (outages: of one
    sensor; commands: at one time)."""

    kind: Literal["thruster", "sensor_outage", "trim_tab", "array_offset",
                  "wheel_switch"] = Field(description="what happens")
    time_s: float | None = Field(None, description="start, seconds from epoch_utc (s)")
    time_utc: str | None = Field(None, description="start as an ISO 8601 UTC time, "
                                 "instead of time_s")
    duration_s: float | None = Field(None, gt=0, description="thruster and sensor_outage: "
                                     "how long (s)")
    torque_Nm: Vec3 | None = Field(None, description="thruster: body roll, pitch and yaw "
                                   "torque held over the duration (N m)")
    sensor: Literal["earth", "sun", "tachometer"] | None = Field(
        None, description="sensor_outage: 'earth' (roll_deg, pitch_deg empty), 'sun' "
        "(yaw_deg, yaw_sigma_deg, sun_head and every head's angles empty) or 'tachometer' "
        "(every wheel's speed empty)")
    angle_deg: float | None = Field(None, description="trim_tab, array_offset: the "
                                    "commanded angle, absolute, not a change (deg)")
    every_days: float | None = Field(None, gt=0, description="repeat every this many days "
                                     "from the start until the run's end (days)")
    label: str | None = Field(None, description="text shown with the event in the outputs")

    @field_validator("time_utc")
    @classmethod
    def _utc(cls, v: str | None) -> str | None:
        if v is not None:
            try:
                parse_epoch(v)
            except ValueError:
                raise ValueError("must be an ISO 8601 UTC time with its zone, such as "
                                 "2026-03-20T14:00:00Z") from None
        return v

    def given(self) -> list[str]:
        """The keys the entry sets (not None)."""
        return [k for k in type(self).model_fields if getattr(self, k) is not None]


def start_s(entry: EventEntry, epoch_utc: str) -> float:
    """The entry's (first) start in seconds from the scenario's epoch."""
    if entry.time_utc is not None:
        return (parse_epoch(entry.time_utc) - parse_epoch(epoch_utc)).total_seconds()
    return float(entry.time_s)


def _event(entry: EventEntry, t_s: float) -> Event:
    return Event(entry.kind, t_s, entry.duration_s or 0.0, entry.torque_Nm, entry.sensor,
                 entry.angle_deg, entry.label or "")


def occurrences(entries, epoch_utc: str, duration_s: float) -> list[tuple[int, Event]]:
    """(entry index, occurrence) of every entry, periodic ones repeated to the run's
    end (``sim.events.repeated``)."""
    out = []
    for i, e in enumerate(entries):
        every = None if e.every_days is None else e.every_days * DAY_S
        out += [(i, ev) for ev in repeated(_event(e, start_s(e, epoch_utc)), every,
                                           duration_s)]
    return out


def schedule(s) -> Schedule:
    """The scenario's events as the simulator flies them (empty without any)."""
    return Schedule(tuple(ev for _, ev in occurrences(s.events, s.epoch_utc, s.duration_s)))


def _keys_problems(i: int, e: EventEntry) -> list[str]:
    where = f"events[{i}]"
    own = KIND_KEYS[e.kind]
    out = [f"{where}.{k}: not a key of a {e.kind} event (its keys: "
           + ", ".join((*COMMON_KEYS, *own)) + ")"
           for k in e.given() if k not in COMMON_KEYS and k not in own]
    out += [f"{where}.{k}: required for a {e.kind} event" for k in own
            if getattr(e, k) is None]
    if (e.time_s is None) == (e.time_utc is None):
        out.append(f"{where}.time_s: give the start as time_s or time_utc, exactly one")
    return out


def _wheel_problems(s) -> list[str]:
    """A wheel switch needs the standby yaw wheel on board, and happens once."""
    switches = [i for i, e in enumerate(s.events) if e.kind == "wheel_switch"]
    yaw_wheel = s.spacecraft.yaw_wheel
    out = []
    if yaw_wheel.standby and s.spacecraft.configuration == "backup":
        out.append("spacecraft.yaw_wheel.standby: the backup configuration already flies the "
                   "yaw wheel; standby is for the nominal one")
    elif switches and not yaw_wheel.standby:
        out.append(f"events[{switches[0]}].kind: a wheel_switch needs the backup yaw wheel on "
                   "board from the start: set spacecraft.yaw_wheel.standby: true")
    out += [f"events[{i}].kind: a second wheel_switch (events[{switches[0]}] switched "
            "already); there is one backup yaw wheel" for i in switches[1:]]
    out += [f"events[{i}].every_days: a wheel_switch happens once" for i in switches
            if s.events[i].every_days is not None]
    return out


def _clash(kind: str) -> str:
    return ("at the same time" if kind not in DURATION_KINDS
            else "of the same sensor at once" if kind == "sensor_outage" else "at once")


def event_problems(s) -> list[str]:
    """One line per problem of ``s.events`` (the module doc), each naming its key."""
    problems, valid = _wheel_problems(s), []
    for i, e in enumerate(s.events):
        own = _keys_problems(i, e)
        problems += own
        if not own:
            valid.append(i)
    # The entries whose keys are whole are timed; the others have said their lines.
    occ = [(valid[k], ev) for k, ev in occurrences([s.events[i] for i in valid], s.epoch_utc,
                                                    s.duration_s)]
    for i in valid:
        e = s.events[i]
        t0 = start_s(e, s.epoch_utc)
        if not 0 <= t0 < s.duration_s:
            key = "time_utc" if e.time_utc is not None else "time_s"
            problems.append(f"events[{i}].{key}: starts at {t0:g} s from epoch_utc, outside "
                            f"the run [0, {s.duration_s:g}) s")
    groups: dict[tuple, list[tuple[int, Event]]] = {}
    for i, ev in occ:
        groups.setdefault((ev.kind, ev.sensor), []).append((i, ev))
    seen = set()
    for (kind, _), items in groups.items():
        items.sort(key=lambda x: x[1].t_s)
        for (i, a), (j, b) in zip(items[:-1], items[1:], strict=True):
            clash = b.t_s < a.end_s if kind in DURATION_KINDS else b.t_s == a.t_s
            if not clash or (i, j) in seen:
                continue
            seen.add((i, j))
            e = s.events[j]
            if i == j:
                problems.append(f"events[{j}].every_days: {e.every_days:g} days repeats it "
                                f"before it ends ({e.duration_s:g} s)")
                continue
            key = "time_utc" if e.time_utc is not None else "time_s"
            span = f"{a.t_s:g}–{a.end_s:g} s" if kind in DURATION_KINDS else f"{a.t_s:g} s"
            problems.append(f"events[{j}].{key}: its {kind} at {b.t_s:g} s overlaps "
                            f"events[{i}]'s at {span}: two {kind} events {_clash(kind)}")
    return problems


__all__ = ["SENSORS", "EventEntry", "event_problems", "occurrences", "schedule", "start_s"]
