"""The trim loop (``trim.every_days``): the truth's tab moved mid-run changes its
solar torque and nothing else, a short loop run trims the mistrimmed case from its
own telemetry and then leaves the tab alone, and what the loop cannot do exits 2."""

from __future__ import annotations

import json

import numpy as np
import pytest

from scenarios.config import build
from scenarios.config.loader import load_scenario
from scenarios.files.csvio import read_csv
from sim.truth import TruthStream

from .test_cli_run import run_cli

DAY = 86400.0


def _stream(s):
    return TruthStream(build.build_spacecraft(s), build.orbit(s), build.build_environment(s),
                       build.build_control(s), build.build_initial(s), build.epoch(s),
                       s.duration_s, s.sample_interval_s,
                       rng=build.streams(s.seed, 0)["ripple"])


def test_retrim_changes_the_solar_torque_from_the_next_window_and_nothing_before():
    s = load_scenario("goes_next_mistrimmed", ["duration_s=2048"])   # κ = 1e-5 N m
    half = load_scenario("goes_next_mistrimmed", ["duration_s=2048",
                                                  "environment.solar.trim_tab_deg=18"])
    a, b = _stream(s), _stream(s)
    wa, wb = a.window(0, 2000), b.window(0, 2000)
    np.testing.assert_array_equal(wa.final_state, wb.final_state)
    a.retrim(build.build_environment(half).solar)                    # κ = 5e-6 N m
    na, nb = a.window(2000, 4001), b.window(2000, 4001)
    # The first sample of the next window starts from the same state: its solar
    # torque is exactly the new κ's share of the old one (shape × κ).
    assert nb.torques["solar"][0] @ nb.torques["solar"][0] > 0
    np.testing.assert_allclose(na.torques["solar"][0], 0.5 * nb.torques["solar"][0],
                               rtol=1e-12, atol=0)
    for name in ("gravity_gradient", "magnetic", "magnetic_control"):
        np.testing.assert_array_equal(na.torques[name][0], nb.torques[name][0])


@pytest.fixture(scope="module")
def loop_run(tmp_path_factory):
    """goes_next_mistrimmed for 3 days, trimmed from each day of its own telemetry."""
    out = tmp_path_factory.mktemp("loop") / "run"
    rc, stdout, err = run_cli("run", "goes_next_mistrimmed", "--duration-s", str(3 * DAY),
                              "--set", "trim.every_days=1", "--out", str(out))
    assert rc == 0, err
    return out


def test_the_loop_trims_after_the_first_day_and_then_holds(loop_run):
    c = read_csv(loop_run / "trim_loop.csv")
    assert list(c["day"]) == [0, 1, 2]
    assert c["trim_tab_deg"][0] == 16.0 and c["kappa_true_Nm"][0] == pytest.approx(1e-5)
    sigma_deg = c["kappa_sigma_Nm"][0] / 2.5e-6
    # The first day's estimate moves the tab to within 3σ of full trim (20°) …
    assert abs(c["trim_tab_deg"][1] - 20.0) <= 3 * sigma_deg and sigma_deg < 0.1
    assert abs(c["kappa_true_Nm"][1]) <= 3 * c["kappa_sigma_Nm"][0]
    # … after which κ̂ is consistent with zero and the tab stays.
    assert abs(c["kappa_Nm"][1]) <= 3 * c["kappa_sigma_Nm"][1] + abs(c["kappa_true_Nm"][1])
    assert c["trim_tab_deg"][2] == c["trim_tab_deg"][1]
    # The truth itself flew the move: its solar torque falls with κ (same shape).
    t = read_csv(loop_run / "truth.csv")
    day = (t["t_s"] // DAY).astype(int)
    rms = [np.sqrt(np.mean(t["solar_x_Nm"][day == d] ** 2 + t["solar_z_Nm"][day == d] ** 2))
           for d in (0, 2)]
    assert rms[0] > 5e-6
    assert rms[1] < 3 * c["kappa_sigma_Nm"][0]
    summary = json.loads((loop_run / "summary.json").read_text())["trim_loop"]
    assert summary["moves"] == 1 and summary["every_days"] == 1
    assert summary["trim_tab_deg_end"] == c["trim_tab_deg"][2]
    assert (loop_run / "plots" / "trim_loop.png").is_file()


def test_trim_refuses_a_loop_run_and_the_loop_must_be_shorter_than_the_run(loop_run):
    rc, stdout, err = run_cli("trim", str(loop_run))
    assert rc == 2 and stdout == "" and err.count("\n") == 1 and "every_days" in err
    assert not (loop_run / "trim").exists()
    rc, _, err = run_cli("run", "goes_next_mistrimmed", "--set", "trim.every_days=2",
                         "--out", str(loop_run.parent / "never"))
    assert rc == 2 and "trim.every_days" in err and err.count("\n") == 1
    assert not (loop_run.parent / "never").exists()
    # The loop steers the truth from the filter: a command without the filter refuses it.
    rc, _, err = run_cli("simulate", "goes_next_trim_loop", "--duration-s", str(2 * DAY),
                         "--set", "trim.every_days=1", "--out", str(loop_run.parent / "s"))
    assert rc == 2 and err.startswith("dynprop: error: trim.every_days")
    assert "only `dynprop run`" in err and err.count("\n") == 1
    assert not (loop_run.parent / "s").exists()


def test_trim_loop_csv_and_its_summary_keys_are_documented(loop_run):
    from .test_outputs_doc import _spans, csv_columns, json_keys, undocumented
    spans = _spans()
    assert not undocumented(csv_columns(loop_run / "trim_loop.csv"), spans)
    summary = json.loads((loop_run / "summary.json").read_text())
    assert not undocumented(sorted(json_keys(summary["trim_loop"])), spans)
