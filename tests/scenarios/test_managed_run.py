"""`dynprop run goes_next_year` over a day and an hour (issue 45): the on-board solar
loop's first command, against what the scenario's imbalances say it should be, and
the run directory as dynprop's own (``--force`` replaces it).

The first command moves the tab from 19.6° towards full trim (20°: κ = 5e-5 −
2.5e-6 · 20 = 0) and the offset from 0 towards 1° (κ_o = 5e-7 − 5e-7 · 1 = 0), each
past its null by the −H/τ unloading term, which is small after one day.  Seen
failing with the command's sign flipped (the tab to 19.2°) and with
momentum_management.csv left out of ``rundir.OWN_FILES`` (``--force`` refused).
`dynprop trim` refuses the run: its tab moved as it flew."""

from __future__ import annotations

import json

import pandas as pd
import pytest

from .test_cli_run import run_cli

pytestmark = pytest.mark.surface


def test_the_first_command_heads_for_both_nulls_and_force_replaces_the_run(tmp_path):
    out = tmp_path / "year"
    args = ("run", "goes_next_year", "--duration-s", "90000", "--out", str(out))
    rc, _, err = run_cli(*args)
    assert rc == 0, err
    rows = pd.read_csv(out / "momentum_management.csv", comment="#")
    assert list(rows.t_s) == [86400.0]
    # Day 0 sees the 1e-6 N m tab residual and the 5e-7 N m offset imbalance; the
    # command cancels them, plus H/τ (a few percent of a degree here).
    assert 19.95 < rows.trim_tab_deg[0] < 20.1
    assert 0.9 < rows.array_offset_deg[0] < 1.3
    summary = json.loads((out / "summary.json").read_text())
    assert summary["momentum_management"]["solar"]["file"] == "momentum_management.csv"
    assert summary["checks"]["linear_range"]["passed"]
    rc, _, err = run_cli("trim", str(out))
    assert rc == 2 and "moved its tab or array offset" in err and "momentum_management" in err
    rc, _, err = run_cli(*args, "--force")
    assert rc == 0, err


def test_trim_refuses_a_run_whose_events_move_the_tab():
    """`dynprop trim` fits one κ over its batch: a run whose tab moved cannot give one
    (seen failing with the events left out of ``_moved_tab``)."""
    from dynprop.scenarios.config.loader import load_scenario
    from dynprop.scenarios.trim.report import _moved_tab
    assert _moved_tab(load_scenario("goes_next_events")) == "trim_tab events"
    assert _moved_tab(load_scenario("goes_next_equinox")) == ""
