"""`dynprop montecarlo` sets: failing cases, bit-for-bit reproduction of a case by
`dynprop run --montecarlo-case`, resuming a killed set, set identity, dask, kept
trajectories and the written results.

Sets are kept short (2 h to 1 d, 2–8 cases) so the module runs in well under a minute.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import shlex
import shutil
import signal
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy import stats

from estimator.consistency import chi2_bounds
from scenarios.loader import ScenarioError, load_scenario
from scenarios.montecarlo.dispersions import draw_case

from .mc_helpers import (
    DT,
    DYNPROP,
    FIGURES,
    GAP_SET,
    PNG_MAGIC,
    STATES,
    TWIN_SET,
    YAW,
    assert_one_line,
    assert_same_arrays,
    case_files,
    dispersions_override,
    load_npz,
    montecarlo,
    ran,
    run_cli,
    scenario_of,
    snapshot,
)

# --------------------------------------------------------------------------- 4. failing cases

NOISY_EARTH = {"sensors.earth.noise_deg": {"distribution": "normal", "sigma": 1.0}}
FAIL_RUNS = 4


@pytest.fixture(scope="module")
def failing_set(tmp_path_factory):
    """A set where an Earth-sensor noise of 0.01° ± 1° goes negative in some cases."""
    base = [dispersions_override(NOISY_EARTH)]
    for seed in range(20260320, 20260340):
        s = load_scenario("goes_next_equinox", [*base, f"seed={seed}"])
        bad = [k for k in range(FAIL_RUNS) if not _ok(s, k)]
        if 0 < len(bad) < FAIL_RUNS:
            break
    else:  # pragma: no cover - 20 seeds × 4 cases, each failing with probability ~½
        pytest.fail("no seed gives both failing and succeeding cases")
    args = ("--seed", str(seed), "--duration-s", "7200", "--set",
            "montecarlo.converged_after_h=1", "--set", dispersions_override(NOISY_EARTH))
    out = tmp_path_factory.mktemp("failing") / "set"
    rc, stdout, err = montecarlo(out, FAIL_RUNS, *args)
    return {"out": out, "args": args, "bad": bad, "scenario": s,
            "good": [k for k in range(FAIL_RUNS) if k not in bad],
            "rc": rc, "stdout": stdout, "stderr": err}


def _ok(s, k) -> bool:
    try:
        draw_case(s, k)
    except ScenarioError:
        return False
    return True


def test_failing_cases_are_recorded_and_do_not_stop_the_set(failing_set):
    f = failing_set
    out, bad, good = f["out"], f["bad"], f["good"]
    assert f["rc"] == 1, f["stderr"]
    assert ran(f["stdout"]) == ("ran", FAIL_RUNS, FAIL_RUNS)
    for k in bad:
        assert f"case {k} failed" in f["stderr"]
        rec = json.loads((out / "cases" / f"case-{k:05d}.json").read_text())
        assert rec["case"] == k and rec["status"] == "failed"
        assert "sensors.earth.noise_deg" in rec["error"]
        # The record says what was drawn: the negative noise that made the case fail.
        assert rec["dispersed"]["sensors.earth.noise_deg"] < 0
        assert not (out / "cases" / f"case-{k:05d}.npz").exists()
    for k in good:
        rec = json.loads((out / "cases" / f"case-{k:05d}.json").read_text())
        assert rec["status"] == "ok"
        noise = rec["dispersed"]["sensors.earth.noise_deg"]
        assert noise >= 0
        assert rec["dispersed"] == draw_case(f["scenario"], k)[0]
        assert (out / "cases" / f"case-{k:05d}.npz").is_file()
    summary = json.loads((out / "montecarlo.json").read_text())
    assert summary["runs_requested"] == FAIL_RUNS
    assert summary["runs_ok"] == len(good) and summary["runs_failed"] == len(bad)
    assert summary["runs_missing"] == 0
    assert [x["case"] for x in summary["failed"]] == bad
    assert all("sensors.earth.noise_deg" in x["error"] for x in summary["failed"])
    assert summary["nees"]["runs"] == len(good)
    for name in FIGURES:
        assert (out / "plots" / name).read_bytes().startswith(PNG_MAGIC)


def test_retry_failed_reruns_only_the_failed_cases(failing_set, tmp_path):
    f = failing_set
    out = tmp_path / "set"
    shutil.copytree(f["out"], out)
    good_files = [out / "cases" / f"case-{k:05d}.{ext}" for k in f["good"]
                  for ext in ("json", "npz")]
    before = snapshot(good_files)
    # A plain rerun leaves failures alone (and still reports them) ...
    rc, stdout, err = montecarlo(out, FAIL_RUNS, *f["args"])
    assert rc == 1 and ran(stdout) == ("resumed", 0, FAIL_RUNS)
    assert all(f"case {k} failed" in err for k in f["bad"])
    # ... --retry-failed runs exactly those again (they fail again: same draws).
    rc, stdout, err = montecarlo(out, FAIL_RUNS, *f["args"], "--retry-failed")
    assert rc == 1, err
    assert ran(stdout) == ("resumed", len(f["bad"]), FAIL_RUNS)
    assert snapshot(good_files) == before
    for k in f["bad"]:
        rec = json.loads((out / "cases" / f"case-{k:05d}.json").read_text())
        assert rec["status"] == "failed" and "sensors.earth.noise_deg" in rec["error"]


def test_run_reproduces_a_case_without_the_twin_and_refuses_a_failing_one(failing_set,
                                                                         tmp_path):
    f = failing_set
    k = f["good"][0]
    out = tmp_path / "case"
    # The command montecarlo.json advertises, quoted for a shell (the dispersion has spaces).
    command = json.loads((f["out"] / "montecarlo.json").read_text())["reproduce_case"]
    argv = shlex.split(command)
    assert argv == ["dynprop", "run", "goes_next_equinox", *f["args"], "--montecarlo-case",
                    "K"]
    rc, _, err = run_cli(*argv[1:-1], k, "--out", out)
    assert rc == 0, err
    mine = json.loads((out / "montecarlo_case.json").read_text())
    theirs = json.loads((f["out"] / "cases" / f"case-{k:05d}.json").read_text())
    assert mine == theirs
    assert "yaw_error_rms_linear_deg" not in mine    # linear_twin is off in this set
    assert_same_arrays(load_npz(out / "montecarlo_case.npz"),
                       load_npz(f["out"] / "cases" / f"case-{k:05d}.npz"))
    # A case whose draw is unphysical is bad input for `dynprop run`.
    out2 = tmp_path / "bad"
    rc, _, err = run_cli("run", "goes_next_equinox", *f["args"], "--montecarlo-case",
                         f["bad"][0], "--out", out2)
    assert rc == 2 and "sensors.earth.noise_deg" in assert_one_line(err)
    assert not out2.exists()


# --------------------------------------------------------------------------- 5. reproduction


@pytest.fixture(scope="module")
def twin_set(tmp_path_factory) -> Path:
    """3 cases of 10 h with the linear twin; case 1 keeps its whole trajectories."""
    out = tmp_path_factory.mktemp("twin") / "set"
    rc, stdout, err = montecarlo(out, 3, *TWIN_SET, "--keep-trajectories", "1")
    assert rc == 0, err
    assert ran(stdout) == ("ran", 3, 3)
    return out


def test_run_montecarlo_case_reproduces_the_sets_case_bit_for_bit(twin_set, tmp_path):
    summary = json.loads((twin_set / "montecarlo.json").read_text())
    # The advertised command, with K = 1.
    argv = shlex.split(summary["reproduce_case"])
    assert argv[:2] == ["dynprop", "run"] and argv[-2:] == ["--montecarlo-case", "K"]
    out = tmp_path / "case1"
    rc, _, err = run_cli(*argv[1:-1], "1", "--out", out)
    assert rc == 0, err
    mine = json.loads((out / "montecarlo_case.json").read_text())
    theirs = json.loads((twin_set / "cases" / "case-00001.json").read_text())
    assert mine == theirs
    assert "yaw_error_rms_linear_deg" in mine and mine["status"] == "ok"
    a = load_npz(out / "montecarlo_case.npz")
    assert {"err_linear", "nees_linear"} <= set(a)
    assert_same_arrays(a, load_npz(twin_set / "cases" / "case-00001.npz"))
    # scenario.yaml is the nominal scenario, case_scenario.yaml the dispersed one.
    nominal = yaml.safe_load((out / "scenario.yaml").read_text())
    flown = yaml.safe_load((out / "case_scenario.yaml").read_text())
    s = scenario_of(argv[3:-2])
    assert nominal["spacecraft"]["inertia_kgm2"] == [list(r) for r in
                                                     s.spacecraft.inertia_kgm2]
    for key, value in theirs["dispersed"].items():
        node = flown
        for part in key.split("."):
            node = node[part]
        assert node == value, key
    assert flown["estimator"] == nominal["estimator"]


def test_the_same_set_in_another_directory_is_byte_identical(twin_set, tmp_path):
    out = tmp_path / "again"
    # One worker instead of two and no kept trajectory: the cases must not notice.
    rc, stdout, err = montecarlo(out, 3, *TWIN_SET, workers=1)
    assert rc == 0, err
    a, b = case_files(twin_set / "cases"), case_files(out / "cases")
    assert set(a) - set(b) == {"case-00001.full.npz"} and set(b) <= set(a)
    for name in b:
        assert a[name] == b[name], name
    assert json.loads((out / "montecarlo.json").read_text()) == \
        json.loads((twin_set / "montecarlo.json").read_text())


def test_set_records_carry_the_seed_and_the_drawn_values(twin_set):
    s = scenario_of(TWIN_SET)
    for k in range(3):
        rec = json.loads((twin_set / "cases" / f"case-{k:05d}.json").read_text())
        assert rec["case"] == k and rec["seed"] == s.seed and rec["spawn_key"] == [k]
        values, flying = draw_case(s, k)
        assert rec["dispersed"] == values
        assert rec["epoch_utc"] == flying.epoch_utc


# --------------------------------------------------------------------------- 6. resume


def test_a_killed_set_resumes_with_its_finished_cases_untouched(tmp_path):
    runs = 8
    args = ["montecarlo", "goes_next_equinox", "--runs", str(runs), "--workers", "1",
            "--duration-s", "86400"]   # ~0.4 s a case
    out = tmp_path / "killed"
    cases = out / "cases"
    log = tmp_path / "first.log"
    with open(log, "wb") as logf:
        proc = subprocess.Popen([str(DYNPROP), *args, "--out", str(out)], stdout=logf,
                                stderr=subprocess.STDOUT, start_new_session=True)
        try:
            deadline = time.monotonic() + 180
            done = 0
            while time.monotonic() < deadline and proc.poll() is None:
                done = len(list(cases.glob("case-*.json"))) if cases.is_dir() else 0
                if done >= 2:
                    break
                time.sleep(0.01)
        finally:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(timeout=60)
    finished = sorted(cases.glob("case-*.json")) if cases.is_dir() else []
    if len(finished) >= runs:
        pytest.skip("the set finished before it could be killed")
    assert len(finished) >= 2, f"no 2 cases within 180 s: {log.read_text()}"
    stored = [int(p.stem.split("-")[1]) for p in finished]
    kept = [cases / f"case-{k:05d}.{ext}" for k in stored for ext in ("json", "npz")]
    before = snapshot(kept)

    rerun = subprocess.run([str(DYNPROP), *args, "--out", str(out)], capture_output=True,
                           text=True, timeout=300)
    assert rerun.returncode == 0, rerun.stderr
    assert ran(rerun.stdout) == ("resumed", runs - len(finished), runs)
    assert snapshot(kept) == before
    assert [p.name for p in cases.iterdir() if p.name.startswith(".")] == []
    assert sorted(p.name for p in cases.glob("case-*.json")) == \
        [f"case-{k:05d}.json" for k in range(runs)]

    whole = tmp_path / "whole"
    rc, stdout, err = run_cli(*args[:4], "--workers", "2", *args[6:], "--out", whole)
    assert rc == 0, err
    assert ran(stdout) == ("ran", runs, runs)
    assert case_files(cases) == case_files(whole / "cases")
    assert json.loads((out / "montecarlo.json").read_text()) == \
        json.loads((whole / "montecarlo.json").read_text())


# --------------------------------------------------------------------------- 7. set identity


def test_another_scenario_in_the_same_out_is_refused_and_force_starts_over(twin_set,
                                                                          tmp_path):
    out = tmp_path / "set"
    shutil.copytree(twin_set, out)
    everything = sorted(p for p in out.rglob("*") if p.is_file())
    before = snapshot(everything)
    for extra, key in ((("--seed", "7"), "seed"),
                       (("--set", "montecarlo.linear_twin=false"), "montecarlo.linear_twin"),
                       (("--set", "montecarlo.grid_s=120"), "montecarlo.grid_s"),
                       (("--set", "initial_state.yaw_deg=0.1"), "initial_state.yaw_deg")):
        rc, stdout, err = montecarlo(out, 3, *TWIN_SET, *extra)
        assert rc == 2, (extra, stdout, err)
        assert_one_line(err)
        assert f"({key} differs)" in err, err
        assert "--force" in err
    rc, _, err = run_cli("montecarlo", "goes_next_equinox", "--runs", 3, "--duration-s",
                         "30000", "--out", out)
    assert rc == 2 and "duration_s" in assert_one_line(err)
    assert snapshot(everything) == before
    # A directory that is not a set at all.
    other = tmp_path / "other"
    other.mkdir()
    (other / "notes.txt").write_text("mine")
    rc, _, err = montecarlo(other, 1, *TWIN_SET)
    assert rc == 2 and "not a Monte Carlo set" in assert_one_line(err)
    assert (other / "notes.txt").read_text() == "mine"
    # --force replaces the old set by the new one.
    rc, stdout, err = montecarlo(out, 1, *GAP_SET, "--seed", "7", "--force")
    assert rc == 0, err
    assert ran(stdout) == ("ran", 1, 1)
    assert sorted(p.name for p in (out / "cases").iterdir()) == ["case-00000.json",
                                                                 "case-00000.npz"]
    rec = json.loads((out / "cases" / "case-00000.json").read_text())
    assert rec["seed"] == 7
    assert yaml.safe_load((out / "scenario.yaml").read_text())["seed"] == 7
    assert json.loads((out / "montecarlo.json").read_text())["runs_requested"] == 1


def test_ensemble_settings_and_more_runs_resume_without_rerunning(twin_set, tmp_path):
    out = tmp_path / "set"
    shutil.copytree(twin_set, out)
    old = sorted((out / "cases").iterdir())
    before = snapshot(old)
    # Only the NEES test's start changes: no case runs again.
    later = [a.replace("converged_after_h=1", "converged_after_h=2") for a in TWIN_SET]
    rc, stdout, err = montecarlo(out, 3, *later)
    assert rc == 0, err
    assert ran(stdout) == ("resumed", 0, 3)
    assert snapshot(old) == before
    summary = json.loads((out / "montecarlo.json").read_text())
    assert summary["converged_after_h"] == 2
    assert yaml.safe_load((out / "scenario.yaml").read_text())["montecarlo"][
        "converged_after_h"] == 2
    # The NEES mean now counts from 2 h: recompute it from the stored cases.
    arrays = [load_npz(out / "cases" / f"case-{k:05d}.npz") for k in range(3)]
    t = arrays[0]["t_s"]
    avg = np.mean([a["nees"].astype(float) for a in arrays], axis=0)
    assert summary["nees"]["mean_after_convergence"] == pytest.approx(
        avg[t >= 7200].mean(), rel=1e-12)
    # More runs: only the new case runs; the set's first cases are untouched.
    rc, stdout, err = montecarlo(out, 4, *TWIN_SET)
    assert rc == 0, err
    assert ran(stdout) == ("resumed", 1, 4)
    assert snapshot(old) == before
    assert (out / "cases" / "case-00003.json").is_file()
    assert json.loads((out / "montecarlo.json").read_text())["runs_ok"] == 4
    # Fewer runs: the ensemble uses cases 0 … N−1 only, and nothing runs.
    rc, stdout, err = montecarlo(out, 2, *TWIN_SET)
    assert rc == 0 and ran(stdout) == ("resumed", 0, 2)
    summary = json.loads((out / "montecarlo.json").read_text())
    assert summary["runs_ok"] == 2 and summary["nees"]["runs"] == 2
    assert summary["nees"]["bounds_95"] == pytest.approx(chi2_bounds(9, 2), rel=1e-12)


# --------------------------------------------------------------------------- 8. dask


def test_dask_cluster_gives_the_local_cases_exactly(twin_set, tmp_path):
    distributed = pytest.importorskip("distributed")
    out = tmp_path / "dask"
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                       host="127.0.0.1", dashboard_address=None)
    try:
        rc, stdout, err = run_cli("montecarlo", "goes_next_equinox", "--runs", 3,
                                  *TWIN_SET, "--scheduler", cluster.scheduler_address,
                                  "--out", out)
    finally:
        cluster.close()
    assert rc == 0, err
    assert ran(stdout) == ("ran", 3, 3)
    for k in range(3):
        stem = f"case-{k:05d}"
        assert json.loads((out / "cases" / f"{stem}.json").read_text()) == \
            json.loads((twin_set / "cases" / f"{stem}.json").read_text())
        assert_same_arrays(load_npz(out / "cases" / f"{stem}.npz"),
                           load_npz(twin_set / "cases" / f"{stem}.npz"))
    assert json.loads((out / "montecarlo.json").read_text()) == \
        json.loads((twin_set / "montecarlo.json").read_text())


# --------------------------------------------------------------------------- 10. trajectories


def test_kept_trajectories_hold_the_grid_errors_exactly(twin_set):
    cases = twin_set / "cases"
    assert sorted(p.name for p in cases.glob("*.full.npz")) == ["case-00001.full.npz"]
    full = load_npz(cases / "case-00001.full.npz")
    grid = load_npz(cases / "case-00001.npz")
    stride = round(60 / DT)            # montecarlo.grid_s = 60 s in whole samples
    assert len(full["t_s"]) == math.ceil(36000 / DT)
    assert len(grid["t_s"]) == math.ceil(len(full["t_s"]) / stride)
    np.testing.assert_allclose(full["t_s"][::stride], grid["t_s"], rtol=0, atol=1e-9)
    for name in ("err", "err_linear", "sigma"):
        assert full[name].dtype == np.float32
        assert np.array_equal(full[name][::stride], grid[name]), name
    assert full["truth"].shape == full["err"].shape
    assert np.all(np.isfinite(full["truth"]))


def test_keeping_another_trajectory_reruns_only_that_case(twin_set, tmp_path):
    out = tmp_path / "set"
    shutil.copytree(twin_set, out)
    cases = out / "cases"
    others = [p for p in cases.iterdir() if not p.name.startswith("case-00002")]
    before = snapshot(others)
    record = (cases / "case-00002.json").read_bytes()
    arrays = load_npz(cases / "case-00002.npz")
    rc, stdout, err = montecarlo(out, 3, *TWIN_SET, "--keep-trajectories", "2")
    assert rc == 0, err
    assert ran(stdout) == ("resumed", 1, 3)
    assert snapshot(others) == before
    assert (cases / "case-00002.json").read_bytes() == record
    assert_same_arrays(load_npz(cases / "case-00002.npz"), arrays)
    full = load_npz(cases / "case-00002.full.npz")
    assert np.array_equal(full["err"][::round(60 / DT)], arrays["err"])
    # Asking again for a trajectory that is kept runs nothing.
    rc, stdout, err = montecarlo(out, 3, *TWIN_SET, "--keep-trajectories", "1,2")
    assert rc == 0 and ran(stdout) == ("resumed", 0, 3)


# --------------------------------------------------------------------------- 11. results


def test_set_writes_figures_and_montecarlo_json(twin_set):
    for name in FIGURES:
        png = (twin_set / "plots" / name).read_bytes()
        assert png.startswith(PNG_MAGIC) and len(png) > 10_000, name
    summary = json.loads((twin_set / "montecarlo.json").read_text(),
                         parse_constant=lambda c: pytest.fail(f"montecarlo.json holds {c}"))
    assert summary["scenario"] == "goes_next_equinox"
    assert summary["runs_requested"] == 3 and summary["runs_ok"] == 3
    assert summary["runs_failed"] == 0 and summary["failed"] == []
    m = summary["runs_ok"]
    lo, hi = stats.chi2.ppf([0.025, 0.975], 9 * m) / m
    assert summary["nees"]["bounds_95"] == pytest.approx([lo, hi], rel=1e-10)
    assert summary["nees"]["bounds_95"] == list(chi2_bounds(9, m))
    assert tuple(summary["nees"]["per_state_mean_after_convergence"]) == STATES
    assert all(v > 0 for v in summary["nees"]["per_state_mean_after_convergence"].values())
    assert summary["grid_s"] == pytest.approx(round(60 / DT) * DT, rel=1e-12)
    assert summary["converged_after_h"] == 1
    # Recompute the ensemble figures from the stored cases.
    arrays = [load_npz(twin_set / "cases" / f"case-{k:05d}.npz") for k in range(3)]
    t = arrays[0]["t_s"]
    conv = t >= 3600
    nees_avg = np.mean([a["nees"].astype(float) for a in arrays], axis=0)
    assert summary["nees"]["mean_after_convergence"] == pytest.approx(nees_avg[conv].mean(),
                                                                      rel=1e-12)
    inside = np.mean((nees_avg[conv] >= lo) & (nees_avg[conv] <= hi))
    assert summary["nees"]["fraction_after_convergence"]["inside"] == pytest.approx(inside)
    err = np.array([a["err"].astype(float) for a in arrays])
    assert summary["rms_after_convergence"]["yaw_deg"]["ensemble_rms"] == pytest.approx(
        math.sqrt(np.mean(err[:, conv, YAW] ** 2)), rel=1e-12)
    assert "linear" in summary["nees"]
    # One whole night gap, ~1.3–9.1 h into every case (whole-day epoch shifts move it
    # by minutes at most).
    (gap,) = summary["gap_end_yaw"]
    assert gap["n"] == 3
    assert 0.5 < gap["start_h_median"] < 2.5 and 8 < gap["end_h_median"] < 10
    assert gap["predicted_sigma_deg"] > 0
    assert "linear" in gap
    with np.load(twin_set / "montecarlo.npz") as fig:
        assert np.array_equal(fig["t_s"], t)
        assert fig["nees_avg"] == pytest.approx(nees_avg, rel=1e-12)


def test_an_unreachable_scheduler_exits_2_and_writes_nothing(tmp_path, monkeypatch):
    from scenarios.montecarlo import execute
    monkeypatch.setattr(execute, "CONNECT_TIMEOUT_S", 1.0)
    out = tmp_path / "set"
    rc, _, err = run_cli("montecarlo", "goes_next_equinox", "--runs", 2, "--duration-s", 600,
                         "--scheduler", "tcp://127.0.0.1:1", "--out", out)
    assert rc == 2
    assert assert_one_line(err).startswith("dynprop: error: --scheduler tcp://127.0.0.1:1: ")
    assert not out.exists()


def test_plot_redraws_a_sets_figures_from_its_results(twin_set, tmp_path):
    out = tmp_path / "set"
    shutil.copytree(twin_set, out)
    cases_before = case_files(out / "cases")
    shutil.rmtree(out / "plots")
    rc, stdout, err = run_cli("plot", out)
    assert rc == 0, err
    for name in FIGURES:
        assert (out / "plots" / name).read_bytes().startswith(PNG_MAGIC)
        assert str(out / "plots" / name) in stdout
    assert case_files(out / "cases") == cases_before


def test_set_files_get_the_users_usual_permissions(twin_set):
    umask = os.umask(0)
    os.umask(umask)
    for path in [twin_set / "montecarlo.json", *(twin_set / "cases").iterdir(),
                 *(twin_set / "plots").iterdir()]:
        assert path.stat().st_mode & 0o777 == 0o666 & ~umask, path
