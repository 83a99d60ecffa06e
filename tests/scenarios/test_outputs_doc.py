"""docs/outputs.md names every column and key the commands write.

Each CSV column, each summary.json and batch.json key (at any depth), each
comparison.npz key and each Monte Carlo case-record key written by a short
`simulate`, `run`, `run --montecarlo-case`, `estimate` and `batch` must appear in
the document as a `code` span, literally or through a placeholder (`wheel<i>_rpm`,
`<head>_alpha_deg`, `<source>_x_Nm` with the source itself named,
`sigma_<state column>`)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from .test_cli_run import run_cli

DOC = Path(__file__).resolve().parents[2] / "docs" / "outputs.md"
# Values of these keys are user data (the scenario keys dispersed), not names.
USER_DATA = {"dispersed"}


def _spans() -> set[str]:
    return set(re.findall(r"`([^`\n]+)`", DOC.read_text()))


# Placeholders with a fixed shape; `<source>` and `<state column>` are checked
# against the names the document lists (``undocumented``).
PLACEHOLDERS = {"<i>": r"\d+", "<head>": "(?:dss|cass1|cass2)"}


def _patterns(spans: set[str]) -> list[re.Pattern]:
    out = []
    for span in spans:
        if any(p in span for p in PLACEHOLDERS):
            rx = re.escape(span)
            for p, sub in PLACEHOLDERS.items():
                rx = rx.replace(re.escape(p), sub)
            out.append(re.compile(rx + r"\Z"))
    return out


def undocumented(names, spans: set[str]) -> list[str]:
    pats = _patterns(spans)
    missing = []
    for name in names:
        if name in spans:
            continue
        if name.startswith("sigma_") and name[6:] in spans:
            continue
        if name.startswith("sigma_consider_") and name[15:] in spans:
            continue  # `dynprop batch`'s σ with the consider parameters
        if name.endswith("_Nm") and name[:-5] in spans and name[-4] in "xyz":
            continue  # <source>_<axis>_Nm with the source named
        if not any(p.match(name) for p in pats):
            missing.append(name)
    return missing


def json_keys(obj, skip=USER_DATA) -> set[str]:
    keys = set()
    if isinstance(obj, dict):
        for k, v in obj.items():
            keys.add(k)
            if k not in skip:
                keys |= json_keys(v, skip)
    elif isinstance(obj, list):
        for v in obj:
            keys |= json_keys(v, skip)
    return keys


def csv_columns(path: Path) -> list[str]:
    header = next(line for line in path.read_text().splitlines() if not line.startswith("#"))
    return header.split(",")


@pytest.fixture(scope="module")
def written(tmp_path_factory) -> dict[str, Path]:
    """Ten minutes of each command (a Monte Carlo case included; `run` at its default
    output cadence, whose comparison.npz has the envelopes, and at every sample; a
    scenario with a disturbance torque)."""
    base = tmp_path_factory.mktemp("outputs-doc")
    dirs = {}
    for name, argv in (("run", ("run", "goes_next_equinox", "--duration-s", "600")),
                       # every sample, which `estimate --truth` needs of truth.csv
                       ("run_full", ("run", "goes_next_equinox", "--duration-s", "600",
                                     "--set", "output.interval_s=0.512")),
                       ("case", ("run", "goes_next_equinox", "--duration-s", "600",
                                 "--montecarlo-case", "1")),
                       ("simulate", ("simulate", "backup_wheel", "--duration-s", "600")),
                       # truth.csv's disturbance columns, written only with a disturbance
                       ("simulate_torques", ("simulate", "goes_next_paper_torques",
                                             "--duration-s", "600"))):
        rc, _, err = run_cli(*argv, "--out", str(base / name))
        assert rc == 0, err
        dirs[name] = base / name
    rc, _, err = run_cli("estimate", str(dirs["run_full"] / "telemetry.csv"), "--scenario",
                         str(dirs["run_full"] / "scenario.yaml"), "--truth",
                         str(dirs["run_full"] / "truth.csv"), "--out", str(base / "estimate"))
    assert rc == 0, err
    dirs["estimate"] = base / "estimate"
    rc, _, err = run_cli("batch", str(dirs["run_full"]), "--out", str(base / "batch"))
    assert rc == 0, err
    dirs["batch"] = base / "batch"
    return dirs


def test_every_csv_column_is_documented(written):
    spans = _spans()
    for d in written.values():
        for csv in sorted(d.glob("*.csv")):
            assert not undocumented(csv_columns(csv), spans), csv.name


def test_every_summary_and_case_key_is_documented(written):
    spans = _spans()
    for d in written.values():
        for name in ("summary.json", "montecarlo_case.json", "batch.json"):
            if (d / name).is_file():
                keys = json_keys(json.loads((d / name).read_text()))
                assert not undocumented(sorted(keys), spans), f"{d.name}/{name}"


def test_every_summary_has_the_run_summarys_keys(written):
    """One key set for every summary.json (docs/outputs.md): a Monte Carlo case's and
    `estimate`'s have every key of `run`'s, the output keys (output_interval_s,
    telemetry_written, daily) included, and add only their own."""
    def keys(name):
        return set(json.loads((written[name] / "summary.json").read_text()))
    run = keys("run")
    assert {"output_interval_s", "telemetry_written", "daily"} <= run
    assert keys("case") - run == {"montecarlo_case", "dispersed"}
    assert run <= keys("case")
    assert keys("estimate") - run == {"telemetry"} and run <= keys("estimate")
    case = json.loads((written["case"] / "summary.json").read_text())
    # Every sample kept, telemetry.csv written, no daily.csv: what the case directory holds.
    assert case["output_interval_s"] == case_sample_interval(written["case"])
    assert case["telemetry_written"] is True and (written["case"] / "telemetry.csv").is_file()
    assert case["daily"] is None and not (written["case"] / "daily.csv").exists()


def case_sample_interval(d: Path) -> float:
    import yaml
    return yaml.safe_load((d / "scenario.yaml").read_text())["sample_interval_s"]


def test_every_comparison_key_is_documented(written):
    spans = _spans()
    for d in (written["run"], written["estimate"]):
        with np.load(d / "comparison.npz") as c:
            assert not undocumented(sorted(c.files), spans), d.name


def test_the_check_sees_an_undocumented_name():
    """The matcher is not vacuous: names the document does not hold are caught,
    placeholders match only their own shape."""
    spans = _spans()
    assert undocumented(["wheel1_rpm", "dss_alpha_deg", "solar_y_Nm", "sigma_yaw_deg"],
                        spans) == []
    assert undocumented(["yaw_error_rms_furlongs", "bogus_x_Nm", "sigma_bogus",
                         "wheel1_rad"], spans) == ["yaw_error_rms_furlongs", "bogus_x_Nm",
                                                    "sigma_bogus", "wheel1_rad"]
