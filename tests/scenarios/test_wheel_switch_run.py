"""A wheel switch through `dynprop run`: 13 h from 17:00 local on the equinox (one whole
night Sun gap, 3.25–11.1 h in, and its end), the backup yaw wheel on board and given
the yaw control 2 h in.  The filter reads h from all three tachometers
(``build.yaw_factors``), so its h is the truth's total yaw wheel momentum before and
after the switch, and the gap's end is within 3σ.  The filter's q_w is the yaw
wheel's ripple on h plus the pair's, G/2 (1 + 2 sin²c) (docs/conventions.md), as a
scenario that switches sets it."""

from __future__ import annotations

import contextlib
import io
import json

import numpy as np
import pytest

from scenarios.cli import main
from scenarios.files.csvio import read_csv

from .test_bad_input import check_refused

SWITCH_S = 7200.0
SCENARIO = f"""\
name: wheel_switch
epoch_utc: "2026-03-20T22:00:00Z"
duration_s: 46800
spacecraft:
  yaw_wheel:
    standby: true
estimator:
  process_noise:
    q_w: 3.005e-7
events:
  - {{kind: wheel_switch, time_s: {SWITCH_S}, label: yaw control to the backup wheel}}
"""


@pytest.fixture(scope="module")
def switched(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("wheel_switch")
    path = tmp / "s.yaml"
    path.write_text(SCENARIO)
    err = io.StringIO()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
        assert main(["run", str(path), "--out", str(tmp / "run")]) == 0, err.getvalue()
    return tmp / "run"


@pytest.mark.slow_in_vm
def test_gap_end_within_3_sigma_and_h_is_the_total_across_the_switch(switched):
    """Independent references: truth.csv's h (the step's Σ I_w Ω_i a_i·ẑ over the three
    wheels) and its yaw.  The filter's h error after the first hour is its σ's size:
    its mean square over its σ² is near 1 (measured 1.0), as is the whole NEES (not
    rejected); without wheel 3 in the filter's h, the yaw wheel's momentum after the
    switch (±0.01 N m s, 300 σ_h) would be missing."""
    summary = json.loads((switched / "summary.json").read_text())
    assert len(summary["sun_gaps_h"]) == 1
    assert summary["yaw_within_3sigma_at_gap_ends"] is True
    err, sigma = summary["yaw_error_at_gap_end_deg"][0], summary["yaw_sigma_at_gap_end_deg"][0]
    assert abs(err) < 3 * sigma
    truth, est = read_csv(switched / "truth.csv"), read_csv(switched / "estimate.csv")
    assert np.array_equal(truth["t_s"], est["t_s"])
    z = (est["h_Nms"] - truth["h_Nms"]) / est["sigma_h_Nms"]
    late = truth["t_s"] > 3600
    assert 0.3 < np.mean(z[late] ** 2) < 3, np.mean(z[late] ** 2)
    after = truth["t_s"] >= SWITCH_S
    assert np.ptp(truth["wheel3_rpm"][after]) > 1.0          # the yaw wheel carries h
    assert np.max(np.abs(truth["wheel3_rpm"][~after])) < 1e-3  # idle at 0 rpm before
    assert summary["events"][0]["kind"] == "wheel_switch"
    assert 2.7 < summary["nees_mean_after_1h"] < 19.02


@pytest.mark.surface
def test_a_switch_without_the_backup_wheel_is_refused(capsys, tmp_path):
    lines = check_refused(capsys, tmp_path, SCENARIO.replace("standby: true", "standby: false"))
    assert lines == ["events[0].kind: a wheel_switch needs the backup yaw wheel on board from "
                     "the start: set spacecraft.yaw_wheel.standby: true"], lines
