"""Scheduled events (issue 45) in the outputs: daily.csv's per-day ``maneuver_s``,
``outage_s`` and ``commands``, the marks on errors.png and season.png, and the
review page's shapes and events table.

The events reach the run's engine through ``run.event_days.event_dicts`` (the
scenario's expanded list, as summary.json's ``events`` holds it); here it is
replaced by a list written by hand, so the outputs are checked against seconds
counted by hand (an event across midnight, one past the run's end, two sensors out
at once) and, for random events, against an independent count on a 1 s grid.  The
run without events is the same scenario, seed and samples: its daily.csv must hold
the old columns alone, with the same values.  The tests on those two runs check
wiring against hand counts, no reference number: ``surface`` (the compiled pass
runs them).
"""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from matplotlib.colors import to_rgba

from scenarios.run import event_days
from scenarios.run.event_days import DURATIONS, day_columns

from .test_cli_run import run_cli

DAY = 86400.0
# 175,000 samples of 1.024 s: 2.07 days, three rows of daily.csv (so season.png too).
DURATION_S = 179200.0
CHEAP = ("--set", "sample_interval_s=1.024", "--set", "output.telemetry=false")
EVENTS = [
    {"kind": "sensor_outage", "t_s": 3600.0, "end_s": 4800.0, "utc": "2026-03-20T13:00:00Z",
     "label": None, "sensor": "earth"},
    {"kind": "sensor_outage", "t_s": 4200.0, "end_s": 5000.0, "utc": "2026-03-20T13:10:00Z",
     "label": None, "sensor": "sun"},
    {"kind": "trim_tab", "t_s": 36000.0, "end_s": 36000.0, "utc": "2026-03-20T22:00:00Z",
     "label": "tab trim", "angle_deg": 2.5},
    {"kind": "thruster", "t_s": 86000.0, "end_s": 87000.0, "utc": "2026-03-21T11:53:20Z",
     "label": "east-west station keeping", "torque_Nm": [1e-3, 0.0, 2e-3]},
    {"kind": "wheel_switch", "t_s": 88000.0, "end_s": 88000.0, "utc": "2026-03-21T12:26:40Z",
     "label": None},
    {"kind": "array_offset", "t_s": 172800.0, "end_s": 172800.0,
     "utc": "2026-03-22T12:00:00Z", "label": None, "angle_deg": -1.0},
    {"kind": "thruster", "t_s": 179000.0, "end_s": 179600.0, "utc": "2026-03-22T13:43:20Z",
     "label": "momentum dump", "torque_Nm": [0.0, 0.0, -1e-3]},
]
# By hand: outages 3600–5000 s merged (1400 s); the first firing 400 s before midnight
# and 600 s after; the last cut at the run's end, 179200 s (200 s); the array command
# at exactly two days opens day 2.
BY_HAND = {"maneuver_s": [400.0, 600.0, 200.0], "outage_s": [1400.0, 0.0, 0.0],
           "commands": [1.0, 1.0, 1.0]}
COMMANDS = ("trim_tab", "wheel_switch", "array_offset")


# ------------------------------------------------------------------ daily.csv


def test_event_seconds_split_at_midnight_by_hand():
    got = day_columns(EVENTS, 3, 0.0, DURATION_S)
    assert list(got) == ["maneuver_s", "outage_s", "commands"]
    for column, want in BY_HAND.items():
        np.testing.assert_array_equal(got[column], want, err_msg=column)


def _sampled(events, n_days, t0, end):
    """The same figures counted on a 1 s grid: each second [t, t + 1) from t0 to the
    run's end inside an event's [start, end), filed under the day of t."""
    t = np.arange(t0, end, 1.0)
    day = ((t - t0) // DAY).astype(int)
    out = {}
    for column, kinds in (("maneuver_s", ("thruster",)), ("outage_s", ("sensor_outage",))):
        inside = np.zeros(t.size, dtype=bool)
        for e in events:
            if e["kind"] in kinds:
                inside |= (t >= e["t_s"]) & (t < e["end_s"])
        out[column] = np.bincount(day[inside], minlength=n_days).astype(float)
    starts = np.array([e["t_s"] for e in events if e["kind"] in COMMANDS])
    out["commands"] = np.array([np.sum((starts >= t0 + k * DAY) & (starts < t0 + (k + 1) * DAY))
                                for k in range(n_days)], dtype=float)
    return out


@pytest.mark.parametrize("t0", [0.0, 5000.0])
def test_event_seconds_agree_with_a_count_on_a_one_second_grid(t0):
    """Random events on whole seconds over 4.5 days (from a file's first tag ``t0``
    as well as from the epoch): the interval arithmetic against counting seconds."""
    rng = np.random.default_rng(45)
    n_days, end = 5, t0 + 4.5 * DAY
    events = []
    for kind in ("thruster", "sensor_outage", "sensor_outage", *COMMANDS):
        for start in rng.integers(int(t0), int(end), size=6):
            length = 0 if kind in COMMANDS else int(rng.integers(60, 30000))
            events.append({"kind": kind, "t_s": float(start), "end_s": float(start + length)})
    got = day_columns(events, n_days, t0, end)
    want = _sampled(events, n_days, t0, end)
    assert want["maneuver_s"].sum() > 0 and want["outage_s"].sum() > 0
    for column in want:
        np.testing.assert_array_equal(got[column], want[column], err_msg=column)


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """The same 2.07 days without and with events (``event_dicts`` answering
    ``EVENTS``); then ``EVENTS`` written into the second's summary.json, as the run
    writes them, for its figures and page."""
    base = tmp_path_factory.mktemp("event-marks")
    out = {}
    for name, events in (("plain", []), ("events", EVENTS)):
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr("scenarios.run.stream.engine.event_dicts", lambda s, e=events: list(e))
            rc, _, err = run_cli("run", "goes_next_equinox", "--duration-s", str(DURATION_S),
                                 *CHEAP, "--out", str(base / name))
        assert rc == 0, err
        out[name] = base / name
    path = out["events"] / "summary.json"
    summary = json.loads(path.read_text())
    path.write_text(json.dumps(summary | {"events": EVENTS}, indent=2))
    return out


def test_event_dicts_is_empty_without_events_and_is_the_summarys_with_them():
    from dynprop.scenarios.config.loader import load_scenario
    from dynprop.scenarios.files.summary import events_list
    assert event_days.event_dicts(load_scenario("goes_next_equinox")) == []
    s = load_scenario("goes_next_events")
    assert event_days.event_dicts(s) == events_list(s) and len(events_list(s)) == 4


@pytest.mark.surface
def test_daily_csv_gains_the_event_columns_only_with_events(runs):
    plain = pd.read_csv(runs["plain"] / "daily.csv")
    marked = pd.read_csv(runs["events"] / "daily.csv")
    assert len(marked) == 3
    assert not set(BY_HAND) & set(plain.columns)
    assert list(marked.columns) == list(plain.columns) + list(BY_HAND)
    pd.testing.assert_frame_equal(marked[plain.columns], plain)
    for column, want in BY_HAND.items():
        np.testing.assert_array_equal(marked[column].to_numpy(), want, err_msg=column)


@pytest.mark.surface
def test_the_event_columns_and_keys_are_documented(runs):
    from .test_outputs_doc import _spans, csv_columns, json_keys, undocumented
    spans = _spans()
    assert not undocumented(csv_columns(runs["events"] / "daily.csv"), spans)
    assert not undocumented(sorted(json_keys({"events": EVENTS})), spans)


# ------------------------------------------------------------------ the PNGs


def _event_artists(ax, kind: str):
    """The bands (patches) or lines on ``ax`` in ``kind``'s colour."""
    from plots.palette import EVENT_SHADES
    color = to_rgba(EVENT_SHADES[kind].color)[:3]
    patches = [p for p in ax.patches if to_rgba(p.get_facecolor())[:3] == color]
    lines = [ln for ln in ax.lines if to_rgba(ln.get_color())[:3] == color]
    return patches, lines


def _band_x(patch) -> tuple[float, float]:
    x = patch.get_path().transformed(patch.get_patch_transform()).vertices[:, 0] \
        if hasattr(patch, "get_patch_transform") else patch.get_path().vertices[:, 0]
    return float(x.min()), float(x.max())


def _same(got, want, what) -> None:
    got, want = np.asarray(got, dtype=float), np.asarray(want, dtype=float)
    assert got.shape == want.shape, (what, got, want)
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-9, err_msg=str(what))


def _check_marks(fig, to_x, events=EVENTS) -> None:
    """Every panel: a band over each firing and outage, a line at each command, at
    ``to_x`` of their times; the figure's legend: one entry per kind."""
    panels = [ax for ax in fig.axes if ax.axison]
    for ax in panels:
        for kind in {e["kind"] for e in events}:
            ours = [e for e in events if e["kind"] == kind]
            patches, lines = _event_artists(ax, kind)
            if kind in DURATIONS["maneuver_s"] + DURATIONS["outage_s"]:
                _same(sorted(_band_x(p) for p in patches),
                      sorted((to_x(e["t_s"]), to_x(e["end_s"])) for e in ours), kind)
            else:
                _same(sorted(ln.get_xdata()[0] for ln in lines),
                      sorted(to_x(e["t_s"]) for e in ours), kind)
    labels = [t.get_text() for leg in fig.legends for t in leg.get_texts()]
    for word in ("thruster", "sensor outage", "trim-tab", "offset", "backup yaw wheel"):
        assert sum(word in s for s in labels) == 1, (word, labels)
    assert any("earth, sun" in s for s in labels), labels


def _no_marks(fig) -> None:
    from plots.palette import EVENT_SHADES
    for ax in fig.axes:
        for kind in EVENT_SHADES:
            assert _event_artists(ax, kind) == ([], []), kind


@pytest.mark.surface
def test_errors_png_marks_each_event(runs):
    from scenarios.figures.run import run_figure
    _check_marks(run_figure(runs["events"], "errors"), lambda t: t / 3600.0)
    _no_marks(run_figure(runs["plain"], "errors"))


@pytest.mark.surface
def test_season_png_marks_each_event(runs):
    from scenarios.figures.run import run_figure
    fig = run_figure(runs["events"], "season")
    doy = pd.read_csv(runs["events"] / "daily.csv")["day_of_year"].iloc[0]
    # Day k's point at its day of year, the day spanning ± half a day about it.
    _check_marks(fig, lambda t: doy - 0.5 + t / DAY)
    _no_marks(run_figure(runs["plain"], "season"))


# ------------------------------------------------------------------ the page


def _page(directory: Path) -> tuple[str, dict]:
    rc, _, err = run_cli("report", str(directory))
    assert rc == 0, err
    html = (directory / "report.html").read_text()
    specs = re.findall(r'<script type="application/json" class="plot-spec" '
                       r'data-target="plot-([^"]+)"[^>]*>(.*?)</script>', html, re.S)
    return html, {name: json.loads(text.replace("<\\/", "</")) for name, text in specs}


def _shapes(figure: dict, kind: str) -> list[dict]:
    return [s for s in figure["layout"].get("shapes", []) if s.get("name") == f"event: {kind}"]


@pytest.mark.surface
def test_page_marks_and_lists_each_event(runs, tmp_path):
    from .test_report import check_numbers
    html, figures = _page(runs["events"])
    time_figures = {k: f for k, f in figures.items() if k != "season"}
    assert {"errors", "consistency", "torques", "telemetry"} <= set(time_figures)
    for name, f in figures.items():
        # Hours on a 2-day page; on the season's, days of the run, day k over k ± 0.5.
        scale, at = (DAY, 0.5) if name == "season" else (3600.0, 0.0)
        for kind in {e["kind"] for e in EVENTS}:
            ours = [e for e in EVENTS if e["kind"] == kind]
            got = sorted((s["x0"], s["x1"]) for s in _shapes(f, kind))
            ends = "end_s" if kind in ("thruster", "sensor_outage") else "t_s"
            _same(got, sorted((e["t_s"] / scale - at, e[ends] / scale - at) for e in ours),
                  (name, kind))
        legend = [t["name"] for t in f["data"] if t.get("showlegend", True) and
                  t.get("legendgroup", "").startswith("event: ")]
        assert len(legend) == 5, (name, legend)
    rows = re.search(r'<table id="event-list">.*?<tbody>(.*?)</tbody>', html, re.S).group(1)
    rows = re.findall(r"<tr>(.*?)</tr>", rows, re.S)
    assert len(rows) == len(EVENTS)
    for row, e in zip(rows, EVENTS, strict=True):
        assert e["kind"] in row and e["utc"] in row
        if e["kind"] in ("thruster", "sensor_outage"):
            assert f">{e['end_s'] - e['t_s']:g} s<" in row
    # Every cell naming summary.json holds its value (the table's kind, UTC, start, label).
    assert check_numbers(runs["events"] / "report.html") > 100
    plain, plain_figures = _page(runs["plain"])
    assert 'id="event-list"' not in plain and 'id="events"' not in plain
    assert not any(s.get("name", "").startswith("event: ")
                   for f in plain_figures.values() for s in f["layout"].get("shapes", []))


@pytest.mark.surface
def test_the_figures_follow_summary_events_alone(runs, tmp_path):
    """The events run with summary.json's ``events`` taken out: errors.png and
    season.png are the plain run's files, byte for byte, though its daily.csv holds
    the event columns (what marks an event is summary.json's list, nothing else)."""
    from scenarios.figures import save_figure
    from scenarios.figures.run import run_figure
    copy = Path(shutil.copytree(runs["events"], tmp_path / "copy"))
    summary = json.loads((copy / "summary.json").read_text())
    del summary["events"]
    (copy / "summary.json").write_text(json.dumps(summary))
    for name in ("errors", "season"):
        drawn = save_figure(run_figure(copy, name), tmp_path / f"{name}.png")
        assert drawn.read_bytes() == (runs["plain"] / "plots" / f"{name}.png").read_bytes(), name
