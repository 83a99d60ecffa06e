"""The bias-states study's reduction of two Monte Carlo sets
(``scenarios.studies.bias_states``), on case records written here."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.stats import chi2

from scenarios.studies.bias_states import compare


def _set(path, records):
    (path / "cases").mkdir(parents=True)
    for k, r in enumerate(records):
        (path / "cases" / f"case-{k:05d}.json").write_text(json.dumps(r))
    return path


def _case(err, sig, bias=None, nees=None):
    r = {"status": "ok", "yaw_error_at_gap_end_deg": err, "yaw_sigma_at_gap_end_deg": sig}
    if bias is not None:
        r |= {"bias_states": bias, "nees_mean_augmented": nees, "nees_dof_augmented": 11}
    return r


def test_the_study_reduces_gap_ends_biases_and_the_ensemble_nees(tmp_path):
    plain = _set(tmp_path / "a", [_case([0.03, -0.04], [0.05, 0.05]),
                                  _case([0.2], [0.05]), {"status": "failed"}])
    b = {"dss_yaw": {"estimate_deg": 0.045, "truth_deg": 0.05, "sigma_deg": 0.01,
                     "error_over_sigma": -0.5}}
    biased = _set(tmp_path / "b", [_case([0.01], [0.05], b, 10.0),
                                   _case([-0.02], [0.05], b, 12.0)])
    out = compare(plain, biased)
    a = out["without_bias_states"]
    assert a["cases"] == 2 and a["gap_ends"] == 3          # the failed case left out
    assert a["yaw_error_rms_deg"] == pytest.approx(np.sqrt((0.03**2 + 0.04**2 + 0.2**2) / 3))
    assert a["within_3sigma"] == pytest.approx(2 / 3)      # 0.2 is 4σ
    w = out["with_bias_states"]
    assert w["biases"]["dss_yaw"]["estimate_error_rms_deg"] == pytest.approx(0.005)
    nees = w["nees_augmented"]
    assert nees["mean"] == 11.0
    # The mean of 2 draws of χ²(11) is χ²(22)/2.
    assert nees["bounds_95"] == pytest.approx(list(chi2.ppf([0.025, 0.975], 22) / 2))
    assert nees["verdict"] == "not rejected"


def test_no_gap_end_is_not_tested(tmp_path):
    a = _set(tmp_path / "a", [_case([], [])])
    b = _set(tmp_path / "b", [_case([], [], {"dss_yaw": {"estimate_deg": 0.0, "truth_deg": None,
                                                       "sigma_deg": 0.01,
                                                       "error_over_sigma": None}}, None)])
    out = compare(a, b)
    assert out["without_bias_states"]["gap_ends"] == 0
    assert "not_tested" in out["without_bias_states"]
    assert out["with_bias_states"]["biases"]["dss_yaw"]["cases"] == 0
    assert out["with_bias_states"]["nees_augmented"] is None
