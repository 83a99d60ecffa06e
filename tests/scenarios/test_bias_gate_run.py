"""Sensor-bias states and innovation gating in `dynprop run` and `dynprop estimate`
(``scenarios.run.filtering``): the augmented filter takes the paper filter's place
when the scenario switches either on, and its biases and rejections reach
estimate.csv and summary.json."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from scenarios.files.csvio import read_csv

from .test_cli_run import GAP_EPOCH, run_cli, run_dir

# 13 h runs judged on 3σ verdicts and binomial bands,
# far above any last-bit difference: the compiled pass runs them, the VM pass skips them.
pytestmark = pytest.mark.slow_in_vm

BIASES = ("--set", "estimator.bias_states.earth_roll.model=constant",
          "--set", "estimator.bias_states.dss_yaw.model=constant",
          "--set", "sensors.earth.roll_bias_deg=0.01",
          "--set", "sensors.sun.dss.out_of_plane_bias_deg=0.02")
OUTLIERS = tuple(a for key in ("sensors.earth", "sensors.sun.dss", "sensors.sun.cass1",
                               "sensors.sun.cass2", "sensors.tachometer")
                 for a in ("--set", f"{key}.outlier_rate=0.001"))


def _summary(d: Path) -> dict:
    return json.loads((d / "summary.json").read_text())


@pytest.fixture(scope="module")
def biased_run(tmp_path_factory) -> Path:
    """13 h with a night Sun gap, the truth's Earth roll and DSS β biases set, and the
    filter estimating both."""
    return run_dir(tmp_path_factory, "biased", "goes_next_equinox", 46800, "--set",
                   GAP_EPOCH, *BIASES)[0]


def test_bias_states_are_reported_against_the_truths(biased_run):
    s = _summary(biased_run)
    b = s["bias_states"]
    assert set(b) == {"earth_roll", "dss_yaw"}
    assert b["earth_roll"]["truth_deg"] == pytest.approx(0.01, rel=1e-12)
    assert b["dss_yaw"]["truth_deg"] == pytest.approx(0.02, rel=1e-12)
    for name, entry in b.items():
        assert entry["model"] == "constant"
        assert abs(entry["error_over_sigma"]) < 3, name
        # A constant bias trades against the constant torque (rank 9 of 10): σ stays
        # near its 0.01° prior rather than collapsing.
        assert 0.001 < entry["sigma_deg"] <= 0.01 + 1e-12
    assert s["outliers"] is None
    assert s["yaw_within_3sigma_at_gap_ends"] is True
    est = read_csv(biased_run / "estimate.csv")
    for name in ("earth_roll", "dss_yaw"):
        assert np.all(np.isfinite(est[f"bias_{name}_deg"]))
        assert est[f"sigma_bias_{name}_deg"][-1] == pytest.approx(b[name]["sigma_deg"],
                                                                  rel=1e-9)


def test_bias_error_over_sigma_is_the_estimate_minus_the_truth(biased_run):
    """summary.json's ``error_over_sigma`` against (estimate − truth)/σ formed here
    from estimate.csv's last bias and σ and the truths this run set (0.01°, 0.02°):
    the same to 1e-8 (the CSV's ten significant digits, no cancellation: the error
    is most of the truth).  Its sign is known besides: the bias trades against the
    constant torque, so σ stays near its 0.01° prior and the filter barely leaves
    the prior's zero.  A scalar Gaussian update that shrinks the prior's σ₀
    (scenario.yaml) to σ leaves the mean (σ/σ₀)² of the way from the data's
    estimate to the prior's zero: error ≈ −(σ/σ₀)² · truth, i.e.
    e/σ ≈ −σ · truth/σ₀², with a spread of √(1 − σ²/σ₀²) in e/σ from the data's
    own noise; held within 3 of those (measured −0.91 and −1.91 against −0.95 and
    −1.95; (truth − estimate)/σ is +0.91 and +1.91)."""
    b = _summary(biased_run)["bias_states"]
    est = read_csv(biased_run / "estimate.csv")
    priors = yaml.safe_load((biased_run / "scenario.yaml").read_text())[
        "estimator"]["bias_states"]
    for name, truth in (("earth_roll", 0.01), ("dss_yaw", 0.02)):
        sigma0 = priors[name]["sigma_deg"]   # the prior's 1σ about its zero estimate
        value, sigma = est[f"bias_{name}_deg"][-1], est[f"sigma_bias_{name}_deg"][-1]
        z = b[name]["error_over_sigma"]
        assert z == pytest.approx((value - truth) / sigma, rel=1e-8), name
        expected, spread = -sigma * truth / sigma0**2, np.sqrt(1 - (sigma / sigma0) ** 2)
        assert abs(z - expected) < 3 * spread, (name, z, expected, spread)


def test_estimate_on_the_runs_telemetry_reproduces_its_biases(biased_run, tmp_path):
    """The run's filter, streamed, and `estimate` on its telemetry.csv, held whole:
    the same estimates, biases included (the filter reads the file's exact values)."""
    out = tmp_path / "est"
    rc, _, err = run_cli("estimate", str(biased_run / "telemetry.csv"), "--scenario",
                         str(biased_run / "scenario.yaml"), "--out", str(out))
    assert rc == 0, err
    run, est = read_csv(biased_run / "estimate.csv"), read_csv(out / "estimate.csv")
    for name in ("yaw_deg", "roll_deg", "bias_earth_roll_deg", "sigma_bias_dss_yaw_deg"):
        np.testing.assert_array_equal(est[name], run[name])
    assert _summary(out)["bias_states"]["dss_yaw"]["truth_deg"] is None   # no --truth


def test_the_paper_filter_stays_without_them(tmp_path_factory):
    run = run_dir(tmp_path_factory, "plain", "goes_next_equinox", 3600)[0]
    s = _summary(run)
    assert s["bias_states"] is None and s["outliers"] is None
    assert not [c for c in read_csv(run / "estimate.csv") if c.startswith("bias_")]


def test_gating_keeps_gap_end_yaw_with_injected_outliers(tmp_path_factory):
    """0.1% of every reading 20σ off (roll and pitch, each Sun angle, each wheel): a
    χ²(1) gate of 25 rejects about as many as were injected where the filter reads
    them (roll: one in 1000 samples; h: either wheel, two in 1000) and the Sun-gap-end
    yaw stays within 3σ.  Binomial 5σ bands on the counts; a few extra yaw rejections
    come from a ground yaw built of a spiked Earth-sensor roll or pitch."""
    run = run_dir(tmp_path_factory, "outliers", "goes_next_equinox", 46800, "--set",
                  GAP_EPOCH, *OUTLIERS, "--set", "estimator.outlier_gate_chi2=25")[0]
    s = _summary(run)
    n = len(read_csv(run / "telemetry.csv")["t_s"])
    rejected = s["outliers"]["rejected"]
    for name, p in (("roll", 1e-3), ("h", 2e-3)):
        expected = n * p
        assert abs(rejected[name] - expected) < 5 * np.sqrt(expected) + 2, (name, rejected)
    assert rejected["yaw"] > 0
    by_head = s["outliers"]["rejected_yaw_by_head"]
    # The DSS's 20σ is 0.084°, below its 0.125° quantum and well inside the σ the
    # filter gives its yaw (the quantisation counted once per 600 s): its spikes pass.
    assert sum(by_head.values()) == rejected["yaw"] and by_head["cass1"] > 0
    assert s["yaw_within_3sigma_at_gap_ends"] is True


def test_a_monte_carlo_case_judges_the_augmented_state_against_its_truth():
    """A case's ``bias_states`` and augmented NEES, from the rows a case keeps and from
    its full history: the same figures (the NEES is formed on the same grid samples),
    and the NEES of a consistent filter, not the 1e9 of errors paired with the wrong
    samples' truth (a bug this caught).  Bound: a 10 h case's converged mean of 11
    states over ~70 correlated grid points, well inside 4 × 11."""
    from scenarios.config.loader import load_scenario
    from scenarios.montecarlo.case import run_case

    from .mc_helpers import GAP_SET
    s = load_scenario("goes_next_equinox", [
        f"duration_s={GAP_SET[1]}", GAP_SET[3], GAP_SET[5],
        "estimator.bias_states.earth_roll.model=constant",
        "estimator.bias_states.dss_yaw.model=constant"])
    kept, full = (run_case(s, 1, keep_full=k)["record"] for k in (False, True))
    assert kept["status"] == full["status"] == "ok", kept.get("error")
    assert kept["nees_dof_augmented"] == 11
    assert 2 < kept["nees_mean_augmented"] < 44
    assert kept["nees_mean_augmented"] == pytest.approx(full["nees_mean_augmented"],
                                                        rel=1e-9)
    for name in ("earth_roll", "dss_yaw"):
        entry = kept["bias_states"][name]
        assert entry["truth_deg"] is not None
        assert abs(entry["error_over_sigma"]) < 3
        # Signed as the run's is: (estimate − truth)/σ, from the case's own figures.
        assert entry["error_over_sigma"] == pytest.approx(
            (entry["estimate_deg"] - entry["truth_deg"]) / entry["sigma_deg"], rel=1e-12)
