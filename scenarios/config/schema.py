"""The scenario schema: every key, its unit, its default (docs/scenario-reference.md).

``Scenario`` gathers the sections (``sections``: the physical ones; ``estimation``:
the filter, trim and output; ``montecarlo``: the dispersions) and checks what
spans several of them.  A scenario file only lists what it changes from the
GOES-Next defaults.  ``docs/scenario-reference.md`` is generated from these
definitions (``python -m dynprop.scenarios.config.reference``).
"""

from __future__ import annotations

import difflib
from typing import Annotated

import numpy as np
import yaml
from dynprop.sim import ephemeris
from pydantic import BaseModel, Field, Strict, field_validator, model_validator

from .. import __version__
from ..units import DAY_S
from .batch import Batch
from .estimation import (
    DEFAULT_OUTPUT_INTERVAL_S,
    TELEMETRY_AUTO_MAX_S,
    Estimator,
    ManeuverResponse,
    Output,
    Trim,
)
from .events import EventEntry, event_problems
from .management import MomentumManagement
from .montecarlo import MonteCarlo, check_dispersion
from .report import Report
from .sections import (
    Control,
    Disturbance,
    Environment,
    InitialState,
    Orbit,
    Sensors,
    Spacecraft,
    Telemetry,
    _Section,
)

# A year and a day: `dynprop run` streams a run a window at a time, so its memory
# does not grow with the duration.  The commands that hold whole arrays (simulate,
# montecarlo, linearization, run --montecarlo-case) check their own 30-day limit.
MAX_DURATION_S = 366 * DAY_S
# The sampled control loop loses its damping for steps above about 2.2 s and diverges
# by 2.5 s (one day from a 0.5 deg yaw offset: the attitude-rate transient still decays
# at 2.4 s and grows 40-fold at 2.5 s).  The step is capped at two 0.512 s samples, a
# factor of two inside that.
MAX_SAMPLE_INTERVAL_S = 1.024


def output_stride(s: Scenario) -> int:
    """Samples between output rows (``output.interval_s`` / ``sample_interval_s``)."""
    dt = s.sample_interval_s
    if s.output.interval_s is None:
        return max(1, round(DEFAULT_OUTPUT_INTERVAL_S / dt))
    return max(1, round(s.output.interval_s / dt))


def output_writes_telemetry(s: Scenario) -> bool:
    """Whether `dynprop run` writes telemetry.csv (``output.telemetry``, auto resolved)."""
    t = s.output.telemetry
    return t if isinstance(t, bool) else s.duration_s <= TELEMETRY_AUTO_MAX_S + 1e-9


class Scenario(_Section):
    name: str = Field(min_length=1, description="short identifier of the scenario")
    description: str = Field("", description="one line shown by `dynprop scenarios`")
    dynprop_version: None = Field(None, description="written into resolved scenarios; "
                                  "ignored on input")
    seed: int = Field(20260320, ge=0, description="root of every random stream")
    epoch_utc: str = Field("2026-03-20T12:00:00Z", description="ISO 8601 UTC start time in "
                           "1950–2049, where the solar ephemeris holds 0.01°; sets the Sun and "
                           "so the season")
    duration_s: float = Field(172800.0, gt=0, le=MAX_DURATION_S,
                              description="length of the run, at least one "
                              f"sample_interval_s and at most {MAX_DURATION_S / DAY_S:g} "
                              "days (s)")
    sample_interval_s: float = Field(
        0.512, gt=0, le=MAX_SAMPLE_INTERVAL_S, description="telemetry, control and "
        f"integration step, at most {MAX_SAMPLE_INTERVAL_S:g} s: the sampled control loop "
        "loses its damping above about 2.2 s and diverges by 2.5 s, and the cap keeps a "
        "factor of two inside that (s)")
    spacecraft: Spacecraft = Field(default_factory=Spacecraft)
    orbit: Orbit = Field(default_factory=Orbit)
    initial_state: InitialState = Field(default_factory=InitialState)
    environment: Environment = Field(default_factory=Environment)
    control: Control = Field(default_factory=Control)
    sensors: Sensors = Field(default_factory=Sensors)
    estimator: Estimator = Field(default_factory=Estimator)
    montecarlo: MonteCarlo = Field(default_factory=MonteCarlo)
    output: Output = Field(default_factory=Output)
    trim: Trim = Field(default_factory=Trim)
    momentum_management: MomentumManagement = Field(default_factory=MomentumManagement)
    telemetry: Telemetry = Field(default_factory=Telemetry)
    batch: Batch = Field(default_factory=Batch)
    report: Report = Field(default_factory=Report)
    events: Annotated[tuple[EventEntry, ...], Strict(False)] = Field(
        (), description="scheduled events, a list of entries (below): thruster firings, "
        "sensor outages, trim-tab and array-offset commands")

    @field_validator("dynprop_version", mode="before")
    @classmethod
    def _ignore_version(cls, v):
        return None

    def __str__(self) -> str:
        """The resolved YAML: every key with its value, as scenario.yaml holds it."""
        return resolved_yaml(self)

    @field_validator("epoch_utc")
    @classmethod
    def _epoch(cls, v: str) -> str:
        epoch = ephemeris.parse_epoch(v)
        if not 1950 <= epoch.year < 2050:
            raise ValueError("must be in 1950–2049, where the solar ephemeris holds 0.01°")
        return v

    @model_validator(mode="after")
    def _whole_scenario_checks(self):
        # Checks across keys; every problem is reported, one line each (the loader
        # splits them), each naming its own key path.
        problems = []
        if self.duration_s < self.sample_interval_s:
            # A run needs a step to propagate over; a shorter one writes one-row files.
            problems.append(f"duration_s: {self.duration_s:g} s is shorter than one "
                            f"sample_interval_s ({self.sample_interval_s:g} s)")
        interval = self.output.interval_s
        if interval is not None:
            ratio = interval / self.sample_interval_s
            k = round(ratio)
            if k < 1 or abs(ratio - k) > 1e-9 * ratio:
                near = sorted({max(1, int(np.floor(ratio))), max(1, int(np.ceil(ratio)))})
                problems.append(f"output.interval_s: {interval:g} s is not a whole multiple of "
                                f"sample_interval_s ({self.sample_interval_s:g} s); nearest: "
                                + " or ".join(f"{m * self.sample_interval_s:g}" for m in near))
        f = self.estimator.filters
        if f[0] != "paper" or len(set(f)) != len(f):
            problems.append(f"estimator.filters: {f} must start with paper (every comparison is "
                            "against the paper's filter) and name each filter once")
        every = self.trim.every_days
        if every is not None and every * DAY_S >= self.duration_s:
            problems.append(f"trim.every_days: {every} days is not shorter than the run "
                            f"({self.duration_s / DAY_S:g} days): the tab would never move")
        if every is not None and self.momentum_management.solar.enabled:
            problems.append("trim.every_days: the trim loop and momentum_management.solar both "
                            "move the tab; use one")
        if self.batch.overlap_h >= self.batch.span_h:
            problems.append(f"batch.overlap_h: {self.batch.overlap_h:g} h must be shorter than "
                            f"batch.span_h ({self.batch.span_h:g} h)")
        problems += event_problems(self)
        for key, d in self.montecarlo.dispersions.items():
            try:
                check_dispersion(key, leaf_value(self, key), d)
            except ValueError as exc:
                problems.append(str(exc))
        if problems:
            raise ValueError("\n".join(problems))
        return self


def leaf_value(scenario: BaseModel, key: str):
    """The value at a dotted key path; ValueError naming it if it is not a leaf key."""
    node = scenario
    for part in key.split("."):
        if isinstance(node, tuple) and part.isdigit() and int(part) < len(node):
            node = node[int(part)]     # an entry of a list (events.0.time_s)
            continue
        if not isinstance(node, BaseModel) or part not in type(node).model_fields:
            match = difflib.get_close_matches(key, leaf_paths(type(scenario))
                                              + _entry_paths(scenario), n=1)
            hint = f"; did you mean '{match[0]}'?" if match else ""
            raise ValueError(f"montecarlo.dispersions.{key}: no such scenario key{hint}")
        node = getattr(node, part)
    if isinstance(node, BaseModel):
        raise ValueError(f"montecarlo.dispersions.{key}: is a section, not a value")
    return node


def _entry_paths(scenario: BaseModel) -> list[str]:
    """The dotted key paths of the keys of each entry of a list of sections
    (``events.0.time_s``), which ``leaf_paths`` cannot know."""
    return [f"{name}.{i}.{key}" for name in type(scenario).model_fields
            if isinstance(entries := getattr(scenario, name), tuple)
            for i, entry in enumerate(entries) if isinstance(entry, BaseModel)
            for key in type(entry).model_fields]


def leaf_paths(model: type[BaseModel], prefix: str = "") -> list[str]:
    """Every dotted key path of ``model`` that holds a value (not a section)."""
    paths = []
    for name, field in model.model_fields.items():
        sub = field.annotation
        if isinstance(sub, type) and issubclass(sub, BaseModel):
            paths += leaf_paths(sub, f"{prefix}{name}.")
        else:
            paths.append(f"{prefix}{name}")
    return paths


# Keys added after run directories and Monte Carlo sets existed, written only when
# they differ from their defaults (``resolved_yaml``): (where, key, default).
_LATER_KEYS = (*((("sensors", *head), key, default) for head in
                 (("earth",), ("tachometer",), ("sun", "dss"), ("sun", "cass1"), ("sun", "cass2"))
                 for key, default in (("outlier_rate", 0.0), ("outlier_size", 20.0))),
               (("estimator",), "outlier_gate_chi2", None),
               (("estimator",), "maneuver", ManeuverResponse().model_dump(mode="json")),
               (("estimator",), "known_torques", []),
               # The array offset (issue 45): absent means the paper's array, Sun-normal.
               (("environment", "solar"), "array_offset_deg", 0.0),
               (("environment", "solar"), "offset_effectiveness_Nm_per_deg", 5e-7),
               (("environment", "solar"), "untrimmed_offset_torque_Nm", 0.0),
               # The standby yaw wheel (issue 45's wheel_switch): absent means none.
               (("spacecraft", "yaw_wheel"), "standby", False))


def resolved_yaml(scenario: Scenario) -> str:
    """Every key with its value, defaults filled, stamped with this version; loads
    back to the same scenario.  The exceptions: ``environment.disturbance``,
    ``telemetry``, ``batch``, ``report``, ``events`` (each entry with its own keys
    only), ``momentum_management``, ``estimator.bias_states``, the outlier keys,
    ``estimator.maneuver``, the array offset's and ``spacecraft.yaw_wheel.standby``
    (``_LATER_KEYS``) are written only
    when they differ from their defaults, so that a scenario without them resolves to
    the very text it did before they existed (its run directories, and the digest that
    resumes a Monte Carlo set, unchanged)."""
    data = scenario.model_dump(mode="json")
    if scenario.environment.disturbance == Disturbance():
        del data["environment"]["disturbance"]
    if scenario.telemetry == Telemetry():
        del data["telemetry"]
    if scenario.batch == Batch():
        del data["batch"]
    if scenario.report == Report():
        del data["report"]
    if scenario.events:
        # Each entry as written: its kind's keys, not every kind's nulls.
        data["events"] = [{k: v for k, v in e.items() if v is not None}
                          for e in data["events"]]
    else:
        del data["events"]
    if scenario.momentum_management == MomentumManagement():
        del data["momentum_management"]
    if scenario.estimator.bias_states == type(scenario.estimator.bias_states)():
        del data["estimator"]["bias_states"]
    for where, key, default in _LATER_KEYS:
        node = data
        for part in where:
            node = node[part]
        if node.get(key, default) == default:
            node.pop(key, None)
    data["dynprop_version"] = __version__
    return yaml.safe_dump(data, sort_keys=False, allow_unicode=True, width=100)
