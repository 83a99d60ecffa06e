"""`estimator.filters: [paper, ekf]` in a Monte Carlo set: each case reduces the EKF
beside the paper's filter, `run --montecarlo-case K` reproduces the set's case bit
for bit, and the ensemble's ekf section holds the same statistics as the paper's."""

from __future__ import annotations

import json
import shlex

import numpy as np
import pytest

from .mc_helpers import GAP_SET, assert_same_arrays, load_npz, montecarlo, ran, run_cli
from .test_outputs_doc import _spans, json_keys, undocumented

EKF_SET = (*GAP_SET, "--set", "estimator.filters=[paper, ekf]")


@pytest.fixture(scope="module")
def ekf_set(tmp_path_factory):
    out = tmp_path_factory.mktemp("ekf") / "set"
    rc, stdout, err = montecarlo(out, 3, *EKF_SET)
    assert rc == 0, err
    assert ran(stdout) == ("ran", 3, 3)
    assert "EKF: averaged NEES" in stdout
    return out


def test_run_montecarlo_case_reproduces_the_sets_ekf_bit_for_bit(ekf_set, tmp_path):
    argv = shlex.split(json.loads((ekf_set / "montecarlo.json").read_text())["reproduce_case"])
    out = tmp_path / "case2"
    rc, _, err = run_cli(*argv[1:-1], "2", "--out", out)
    assert rc == 0, err
    mine = json.loads((out / "montecarlo_case.json").read_text())
    assert mine == json.loads((ekf_set / "cases" / "case-00002.json").read_text())
    assert "nees_mean_ekf" in mine and mine["yaw_error_ekf_at_gap_end_deg"]
    a = load_npz(out / "montecarlo_case.npz")
    assert {"err_ekf", "sigma_ekf", "nees_ekf"} <= set(a)
    assert_same_arrays(a, load_npz(ekf_set / "cases" / "case-00002.npz"))
    assert (out / "estimate_ekf.csv").is_file()


def test_the_ensemble_reports_the_ekf_beside_the_paper(ekf_set):
    summary = json.loads((ekf_set / "montecarlo.json").read_text())
    e = summary["ekf"]
    # Near Earth pointing the two filters' yaw σ and gap-end statistics agree.
    p_rms, e_rms = (x["rms_after_convergence"]["yaw_deg"] for x in (summary, e))
    assert e_rms["filter_sigma_rms"] == pytest.approx(p_rms["filter_sigma_rms"], rel=0.2)
    assert len(e["gap_end_yaw"]) == len(summary["gap_end_yaw"]) >= 1
    records = [json.loads((ekf_set / "cases" / f"case-0000{k}.json").read_text())
               for k in range(3)]
    errs = np.array([r["yaw_error_ekf_at_gap_end_deg"][0] for r in records])
    assert e["gap_end_yaw"][0]["rms_deg"] == pytest.approx(np.sqrt(np.mean(errs**2)),
                                                           rel=1e-12)
    # The ekf section is the paper's statistics again: no key of its own.
    paper = {k: v for k, v in summary.items() if k != "ekf"}
    assert json_keys(e) <= json_keys(paper, skip={"dispersions"})
    assert not undocumented(sorted(json_keys(records[0])), _spans())
