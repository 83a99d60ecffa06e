"""The scenario's ``events`` list (docs/scenario-reference.md): each bad entry gets one
line naming ``events[i].<key>`` and exit status 2; a good list becomes the schedule the
truth flies (periodic entries repeated to the run's end, UTC times from the epoch);
resolved scenario.yaml keeps it; summary.json lists it; Monte Carlo disperses it."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta

import pytest

from scenarios.config import build
from scenarios.config.loader import ScenarioError, load_scenario, validate
from scenarios.config.schema import resolved_yaml
from scenarios.files.summary import events_list
from scenarios.montecarlo.dispersions import draw_case

from .test_bad_input import check_refused

DAY = 86400.0

BAD = """\
name: bad_events
duration_s: 86400
events:
  - {kind: thruster, time_s: 90000, duration_s: 60, torque_Nm: [0.01, 0, 0]}
  - {kind: thruster, time_s: 100, duration_s: 60, torque_Nm: [0.01, .nan, 0]}
  - {kind: sensor_outage, time_s: 10, duration_s: 60, sensor: moon}
  - {kind: sensor_outage, time_s: 10, duration_s: 600, sensor: earth}
  - {kind: sensor_outage, time_s: 300, duration_s: 60, sensor: earth}
  - {kind: trim_tab, time_s: 10, angle_deg: 1, sensor: sun}
  - {kind: thruster, time_s: 5000, torque_Nm: [0, 0, 1e-3]}
  - {kind: trim_tab, time_s: 20, angle_deg: 2, duraton_s: 5}
"""


def test_each_bad_entry_gets_one_line_naming_its_key(capsys, tmp_path):
    """Issue 45's list: an event outside the run, overlapping events of one kind, an
    unknown sensor, a non-finite torque; and a key of another kind, a missing number,
    a misspelt key (with the closest one).  One line each, exit 2, nothing written."""
    lines = check_refused(capsys, tmp_path, BAD)
    path = tmp_path / "bad.yaml"
    expected = {
        "events[1].torque_Nm": "must be a list of 3 finite numbers",
        "events[2].sensor": "must be 'earth', 'sun' or 'tachometer', got moon",
        "events[7].duraton_s": "unknown key; did you mean 'duration_s'?",
    }
    for key, text in expected.items():
        (line,) = [x for x in lines if x.startswith(f"{key}:")]
        assert text in line, line
    assert f"events[7].duraton_s: unknown key; did you mean 'duration_s'? ({path}:11)" in lines
    # The whole-list checks come once the entries themselves are whole.
    fixed = BAD.replace(".nan", "0").replace("moon", "sun").replace(", duraton_s: 5", "")
    lines = check_refused(capsys, tmp_path, fixed)
    assert "events[0].time_s: starts at 90000 s from epoch_utc, outside the run " \
           "[0, 86400) s" in lines
    assert any(x.startswith("events[4].time_s: its sensor_outage at 300 s overlaps "
                            "events[3]'s at 10–610 s") for x in lines), lines
    assert any(x.startswith("events[5].sensor: not a key of a trim_tab event") for x in lines)
    assert "events[6].duration_s: required for a thruster event" in lines
    # One problem, one line: the sun outage at 10 s does not clash with the earth one.
    assert not any(x.startswith("events[2]") for x in lines), lines
    assert len(lines) == 4, lines


@pytest.mark.parametrize("events, key, text", [
    ([{"kind": "trim_tab", "time_s": 10, "angle_deg": 1},
      {"kind": "trim_tab", "time_s": 10, "angle_deg": 2}],
     "events[1].time_s", "two trim_tab events at the same time"),
    ([{"kind": "thruster", "time_s": 10, "duration_s": 7200, "torque_Nm": [0, 0, 1e-3],
       "every_days": 0.05}], "events[0].every_days", "repeats it before it ends"),
    ([{"kind": "trim_tab", "time_s": 10, "time_utc": "2026-03-20T12:00:00Z",
       "angle_deg": 1}], "events[0].time_s", "exactly one"),
    ([{"kind": "trim_tab", "time_utc": "2026-03-20T11:59:59Z", "angle_deg": 1}],
     "events[0].time_utc", "starts at -1 s from epoch_utc, outside the run"),
    ([{"kind": "trim_tab", "time_s": DAY, "angle_deg": 1}],     # [0, duration): the end is out
     "events[0].time_s", "starts at 86400 s from epoch_utc, outside the run [0, 86400) s"),
    ([{"kind": "trim_tab", "time_s": 10, "angle_deg": float("inf")}],
     "events[0].angle_deg", "finite"),
    ([{"kind": "thruster", "time_s": 10, "duration_s": 0, "torque_Nm": [0, 0, 1]}],
     "events[0].duration_s", "greater than 0"),
    ([{"kind": "wheel_switch", "time_s": 10}], "events[0].kind",
     "needs the backup yaw wheel on board from the start: set spacecraft.yaw_wheel.standby"),
    ([{"kind": "wheel_switch", "time_s": 10}, {"kind": "wheel_switch", "time_s": 20}],
     "events[1].kind", "a second wheel_switch"),
    ([{"kind": "wheel_switch", "time_s": 10, "every_days": 0.5}], "events[0].every_days",
     "a wheel_switch happens once"),
    ([{"kind": "wheel_switch", "time_s": 10, "angle_deg": 1}], "events[0].angle_deg",
     "not a key of a wheel_switch event"),
])
def test_a_bad_list_is_one_line_on_its_key(events, key, text):
    standby = not text.startswith("needs the backup")
    with pytest.raises(ScenarioError) as info:
        validate({"name": "x", "duration_s": DAY, "events": events,
                  "spacecraft": {"yaw_wheel": {"standby": standby}}})
    (line,) = info.value.problems
    assert line.startswith(f"{key}:") and text in line, line


GOOD = {"name": "x", "duration_s": 30 * DAY, "epoch_utc": "2026-03-20T12:00:00Z", "events": [
    {"kind": "thruster", "time_s": 3600.0, "duration_s": 600.0,
     "torque_Nm": [0.0, 0.0, 1e-3], "every_days": 14, "label": "east-west station keeping"},
    {"kind": "sensor_outage", "time_utc": "2026-03-22T02:30:00Z", "duration_s": 1200.0,
     "sensor": "earth"},
    {"kind": "trim_tab", "time_s": 10 * DAY, "angle_deg": 18.5}]}


def test_every_days_gives_an_occurrence_each_period_to_the_runs_end():
    """14-day station keeping over 30 days: days 0, 14 and 28 (the next, day 42, is
    past the end); the outage's UTC time is 1 day 14.5 h after the epoch."""
    sched = build.build_schedule(validate(GOOD))
    thrusts = [e.t_s for e in sched.of_kind("thruster")]
    assert thrusts == [3600.0, 3600.0 + 14 * DAY, 3600.0 + 28 * DAY]
    (outage,) = sched.of_kind("sensor_outage")
    assert outage.t_s == DAY + 14.5 * 3600 and outage.end_s == outage.t_s + 1200.0
    assert [e.t_s for e in sched.events] == sorted(e.t_s for e in sched.events)
    assert len(sched.events) == 5


def test_summary_lists_every_occurrence():
    s = validate(GOOD)
    listed = events_list(s)
    epoch = datetime(2026, 3, 20, 12, tzinfo=UTC)
    assert [e["kind"] for e in listed] == ["thruster", "sensor_outage", "trim_tab",
                                          "thruster", "thruster"]
    for e in listed:
        utc = (epoch + timedelta(seconds=e["t_s"])).strftime("%Y-%m-%dT%H:%M:%SZ")
        assert e["utc"] == utc
    assert listed[0] == {"kind": "thruster", "t_s": 3600.0, "end_s": 4200.0,
                         "utc": "2026-03-20T13:00:00Z", "label": "east-west station keeping",
                         "duration_s": 600.0, "torque_Nm": [0.0, 0.0, 1e-3]}
    assert listed[2] == {"kind": "trim_tab", "t_s": 10 * DAY, "end_s": 10 * DAY,
                         "utc": "2026-03-30T12:00:00Z", "label": None, "angle_deg": 18.5}


def test_resolved_yaml_holds_events_only_when_there_are_some(tmp_path):
    s = validate(GOOD)
    path = tmp_path / "s.yaml"
    path.write_text(resolved_yaml(s))
    assert load_scenario(path) == s
    assert "duration_s: null" not in path.read_text()       # each entry its own keys
    assert "events" not in resolved_yaml(validate({"name": "x"}))


def test_monte_carlo_disperses_an_events_time_and_torque():
    """events.<i>.<key> like any numeric key: a uniform offset with low = high is that
    offset exactly, per component for a vector."""
    raw = dict(GOOD, montecarlo={"dispersions": {
        "events.0.time_s": {"distribution": "uniform", "low": 120, "high": 120},
        "events.0.torque_Nm": {"distribution": "uniform", "low": [1e-4, 0, -1e-4],
                               "high": [1e-4, 0, -1e-4]}}})
    values, case = draw_case(validate(raw), 3)
    assert case.events[0].time_s == 3720.0
    assert case.events[0].torque_Nm == pytest.approx((1e-4, 0.0, 9e-4), abs=1e-18)
    assert build.build_schedule(case).of_kind("thruster")[1].t_s == 3720.0 + 14 * DAY
    with pytest.raises(ScenarioError, match=r"events\.1\.time_s: not a numeric key"):
        validate(dict(GOOD, montecarlo={"dispersions": {
            "events.1.time_s": {"distribution": "normal", "sigma": 1}}}))


def test_standby_is_for_the_nominal_configuration():
    """The backup configuration flies the yaw wheel already: standby there is a line."""
    with pytest.raises(ScenarioError) as info:
        validate({"name": "x", "spacecraft": {"configuration": "backup",
                                               "yaw_wheel": {"standby": True}}})
    (line,) = info.value.problems
    assert line.startswith("spacecraft.yaw_wheel.standby: the backup configuration"), line


def test_standby_adds_wheel_3_and_leaves_the_resolved_yaml_alone_when_off(tmp_path):
    """standby: the yaw wheel along +z at 0 rpm is wheel 3, its spin inertia in h's
    factors (h = Σ I_w,i a_i·ẑ Ω_i, Eq. 2); off, scenario.yaml does not name it (the
    digest of a Monte Carlo set unchanged), on, it does and loads back."""
    plain = validate({"name": "x"})
    assert "standby" not in resolved_yaml(plain)
    s = validate({"name": "x", "spacecraft": {"yaw_wheel": {"standby": True}}})
    sc = build.build_spacecraft(s)
    assert sc.n_wheels == 3 and sc.standby_wheel == 2
    assert tuple(sc.wheels[2].axis) == (0.0, 0.0, 1.0) and sc.wheels[2].speed_radps == 0.0
    assert build.yaw_factors(s)[2] == 0.008626
    assert list(build.yaw_factors(s)[:2]) == list(build.yaw_factors(plain))
    path = tmp_path / "s.yaml"
    path.write_text(resolved_yaml(s))
    assert "standby: true" in path.read_text() and load_scenario(path) == s
