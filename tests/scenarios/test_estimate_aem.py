"""`dynprop estimate --truth X.aem`: an attitude history (a CCSDS AEM, another tool's or
`dynprop export --what truth`'s) as the truth.

It holds the attitude only, so the roll, yaw and pitch errors (and the gap-end verdict)
are formed and everything needing rates, momentum or the torque states (their
errors, NEES) is null and "not tested".  The reference is the same estimate with the
run's truth.csv: the AEM's quaternions carry 12 decimals (≤ 5e-13 per component, an
angle of ~1e-12 rad = 6e-11°), truth.csv's angles 10 significant digits, so the
errors agree to 1e-9° (float32 in comparison.npz: 1e-8°).
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from scenarios.cli import main
from scenarios.config.loader import load_scenario
from scenarios.run.stream.directory import stream_to_directory

# 17:00 local at 75° W on the equinox: a night Sun gap ends inside 14 h.
RUN = ["duration_s=50400", "epoch_utc=2026-03-20T22:00:00Z", "output.interval_s=64",
       "output.telemetry=true"]


@pytest.fixture(scope="module")
def both(tmp_path_factory):
    out = tmp_path_factory.mktemp("aemtruth")
    run = out / "run"
    run.mkdir()
    stream_to_directory(load_scenario("goes_next_equinox", RUN), run, processes=1,
                        progress=False)
    aem = out / "truth.aem"
    assert main(["export", str(run), "--format", "aem", "--what", "truth", "--out",
                 str(aem)]) == 0
    dirs = {}
    for name, truth in (("csv", run / "truth.csv"), ("aem", aem)):
        dirs[name] = out / name
        assert main(["estimate", str(run / "telemetry.csv"), "--scenario",
                     str(run / "scenario.yaml"), "--truth", str(truth), "--out",
                     str(dirs[name])]) == 0
    return out, dirs


def test_aem_truth_gives_the_csv_truths_errors(both):
    _, dirs = both
    a, b = (json.loads((dirs[k] / "summary.json").read_text()) for k in ("csv", "aem"))
    for key in ("yaw_error_rms_deg", "roll_error_rms_deg", "yaw_error_rms_smoothed_deg"):
        assert b[key] == pytest.approx(a[key], rel=0, abs=1e-9), key
    assert len(a["yaw_error_at_gap_end_deg"]) >= 1
    assert b["yaw_error_at_gap_end_deg"] == pytest.approx(a["yaw_error_at_gap_end_deg"],
                                                          rel=0, abs=1e-9)
    assert b["checks"]["gap_end_yaw_within_3sigma"]["passed"] == \
        a["checks"]["gap_end_yaw_within_3sigma"]["passed"]
    for key in ("pitch_error_rms_deg", "pitch_error_max_abs_after_1h_deg"):
        assert b["pitch"][key] == pytest.approx(a["pitch"][key], rel=0, abs=1e-9), key
    with np.load(dirs["csv"] / "comparison.npz") as x, \
            np.load(dirs["aem"] / "comparison.npz") as y:
        for key, cols in (("err_real", [0, 2]), ("err_pitch", [0])):
            np.testing.assert_allclose(y[key][:, cols], x[key][:, cols], rtol=0, atol=1e-8)


def test_aem_truth_leaves_what_it_lacks_not_tested(both):
    _, dirs = both
    b = json.loads((dirs["aem"] / "summary.json").read_text())
    assert b["telemetry"]["truth_holds"] == "attitude only"
    for key in ("h_error_rms_Nms", "nees_mean", "nees_mean_after_1h"):
        assert b[key] is None, key
    assert b["pitch"]["nees_mean"] is None
    assert b["nees_mean_per_state"]["h_Nms"] is None
    assert b["nees_mean_per_state"]["yaw_deg"] is not None
    check = b["checks"]["nees"]
    assert check["verdict"] == "not tested" and "attitude only" in check["detail"]
    assert not any(w["check"] == "nees" for w in b["warnings"])


def _drop_data_rows(text: str, first: int, n: int) -> str:
    lines = text.splitlines(keepends=True)
    start = next(i for i, line in enumerate(lines) if line.strip() == "DATA_START") + 1
    return "".join(lines[:start + first] + lines[start + first + n:])


@pytest.mark.surface
@pytest.mark.parametrize("case, change, needle", [
    ("unknown frame", lambda t: t.replace("REF_FRAME_A = EME2000", "REF_FRAME_A = TOD"),
     "REF_FRAME_A = TOD"),
    ("reversed quaternion flag", lambda t: t.replace(
        "ATTITUDE_TYPE = QUATERNION", "ATTITUDE_TYPE = QUATERNION\nQUATERNION_TYPE = FIRST"),
     "QUATERNION_TYPE = FIRST"),
    ("gap", lambda t: _drop_data_rows(t, 100, 5), "a gap of 384 s"),
])
def test_a_bad_aem_truth_exits_2_naming_the_line_and_writes_nothing(both, tmp_path, capsys,
                                                                     case, change, needle):
    out, _ = both
    bad = tmp_path / "bad.aem"
    bad.write_text(change((out / "truth.aem").read_text()))
    dest = tmp_path / "est"
    rc = main(["estimate", str(out / "run" / "telemetry.csv"), "--scenario",
               str(out / "run" / "scenario.yaml"), "--truth", str(bad), "--out", str(dest)])
    err = capsys.readouterr().err
    assert rc == 2, case
    lines = err.strip().splitlines()
    assert len(lines) == 1 and f"{bad}:" in lines[0] and needle in lines[0], (case, err)
    assert "Traceback" not in err
    assert not dest.exists()
