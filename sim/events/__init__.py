"""Scheduled events of a run (``schedule``): what ``sim.truth`` and ``sim.telemetry``
fly and sense at set times.  A package of its own since ``sim/`` holds its 16
modules (tests/test_layering.py)."""

from .schedule import (
    COMMAND_KINDS,
    DURATION_KINDS,
    KINDS,
    SENSORS,
    Event,
    Schedule,
    repeated,
)

__all__ = ["COMMAND_KINDS", "DURATION_KINDS", "KINDS", "SENSORS", "Event", "Schedule",
           "repeated"]
