"""``estimator.known_torques: [magnetic_control]`` (issue 45): the torquers' commanded
dipoles reach telemetry.csv, and the torque the filter is told is the one the truth
flew.

The reference is the truth's own ``magnetic_control`` torque (truth.csv), formed in
the compiled step from the true attitude; the filter's known torque
(``bridge.inputs.known_torques``) is m × B of the field model at Earth pointing, so
the two agree to the attitude error (~1e-4 rad).
Seen failing with the cross product reversed in ``known_torques`` (B × m: every
sample −1× the truth's)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from dynprop.scenarios.bridge.inputs import known_torques
from dynprop.scenarios.config.loader import load_scenario

from .test_cli_run import run_cli

pytestmark = pytest.mark.surface


@pytest.fixture(scope="module")
def managed(tmp_path_factory):
    out = tmp_path_factory.mktemp("known") / "run"
    rc, _, err = run_cli("run", "goes_next_equinox", "--duration-s", "14400", "--out", str(out),
                         "--set", "momentum_management.magnetic.enabled=true",
                         "--set", "estimator.known_torques=[magnetic_control]")
    assert rc == 0, err
    return out


def test_the_known_torque_is_the_one_the_truth_flew(managed):
    tel = pd.read_csv(managed / "telemetry.csv", comment="#")
    truth = pd.read_csv(managed / "truth.csv", comment="#")
    rows = tel.set_index("t_s").loc[truth.t_s]
    m = rows[["torquer_x_Am2", "torquer_y_Am2", "torquer_z_Am2"]].to_numpy()
    s = load_scenario(managed / "scenario.yaml")
    known = known_torques(s, m)       # what the filter is told, (N, 2) roll and yaw
    flown = truth[["magnetic_control_x_Nm", "magnetic_control_y_Nm",
                   "magnetic_control_z_Nm"]].to_numpy()
    scale = np.max(np.abs(flown[:, [0, 2]]))
    assert scale > 1e-8                      # the torquers work in this run
    # Attitude error at most ~0.03° here: |ΔB| / |B| ≲ 5e-4 of the torque's scale.
    np.testing.assert_allclose(known, flown[:, [0, 2]], rtol=0, atol=1e-3 * scale)


def test_the_columns_are_written_only_when_needed(managed, tmp_path):
    out = tmp_path / "plain"
    rc, _, err = run_cli("run", "goes_next_equinox", "--duration-s", "3600", "--out", str(out))
    assert rc == 0, err
    plain = pd.read_csv(out / "telemetry.csv", comment="#", nrows=2)
    assert not any(c.startswith("torquer_") for c in plain.columns)
    assert {"torquer_x_Am2", "torquer_y_Am2", "torquer_z_Am2"} <= set(
        pd.read_csv(managed / "telemetry.csv", comment="#", nrows=2).columns)


def test_a_file_command_refuses_known_torques_in_one_line(managed, tmp_path):
    """`estimate` reads a file whose readers do not carry the dipoles: one line, exit 2,
    nothing written (it was an internal error before)."""
    out = tmp_path / "est"
    rc, _, err = run_cli("estimate", str(managed / "telemetry.csv"), "--scenario",
                         "goes_next_equinox", "--set",
                         "estimator.known_torques=[magnetic_control]", "--out", str(out))
    assert rc == 2 and len(err.strip().splitlines()) == 1 and "known_torques" in err
    assert not out.exists()
