"""`dynprop montecarlo` sets: failing cases, bit-for-bit reproduction of a case by
`dynprop run --montecarlo-case`, resuming a killed set, set identity, dask, kept
trajectories and the written results.

Sets are kept short (2 h to 10 h, 2–8 cases) so the module runs in well under a minute.
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

from estimator.kalman.consistency import chi2_bounds
from scenarios.config.loader import ScenarioError, load_scenario
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
    predicted_sun_gaps_h,
    ran,
    run_cli,
    scenario_of,
    snapshot,
)


@pytest.fixture
def no_set_figures(monkeypatch):
    """For the tests about cases and montecarlo.json only: a set's three figures are
    not drawn (1–2 s a set).  The figures are drawn, and checked, by twin_set,
    failing_set, test_ensemble_settings… and test_plot_redraws…"""
    from scenarios.montecarlo import runset
    monkeypatch.setattr(runset, "draw_figures",
                        lambda plots, *args: plots.mkdir(exist_ok=True))


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


def test_retry_failed_reruns_only_the_failed_cases(failing_set, tmp_path, no_set_figures):
    """Identity is the requirement for the good cases' files: they are not rewritten."""
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
    """Identity is the requirement here: `dynprop run --montecarlo-case K` is the
    set's case K, bit for bit, on the same machine."""
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
    """Identity is the requirement here: `--montecarlo-case K` against the set's case K."""
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


def test_the_same_set_in_another_directory_is_byte_identical(twin_set, tmp_path,
                                                            no_set_figures):
    """Identity is the requirement here: the same set, rerun on the same machine."""
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


def test_a_killed_set_resumes_with_its_finished_cases_untouched(tmp_path, no_set_figures):
    """Identity is the requirement here: stored cases are not rewritten, and the
    resumed set equals one run whole on the same machine."""
    runs = 8
    # 3 h cases: ~0.1 s each after the first (which loads the compiled code), so the
    # kill after two cases still leaves six to run, and the three sets stay fast.
    args = ["montecarlo", "goes_next_equinox", "--runs", str(runs), "--workers", "1",
            "--duration-s", "10800"]
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
                                                                          tmp_path,
                                                                          no_set_figures):
    """A refused command leaves every file as it was (identity of the bytes)."""
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
    """Stored cases are not rewritten (identity of their bytes); the ensemble figures
    follow the new settings."""
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
    # The same doubles summed in another order: ≲ 2000·ε.
    assert summary["nees"]["mean_after_convergence"] == pytest.approx(
        avg[t >= 7200].mean(), rel=1e-12)
    # More runs: only the new case runs; the set's first cases are untouched.
    rc, stdout, err = montecarlo(out, 4, *TWIN_SET)
    assert rc == 0, err
    assert ran(stdout) == ("resumed", 1, 4)
    assert snapshot(old) == before
    assert (out / "cases" / "case-00003.json").is_file()
    assert json.loads((out / "montecarlo.json").read_text())["runs_ok"] == 4
    # Fewer runs: a set only grows. Nothing runs, every stored case is summarized,
    # and the console says so (never a summary silently rewritten for fewer cases).
    rc, stdout, err = montecarlo(out, 2, *TWIN_SET)
    assert rc == 0 and ran(stdout) == ("resumed", 0, 4)
    assert "holds 4 cases; --runs 2 adds none" in err
    summary = json.loads((out / "montecarlo.json").read_text())
    assert summary["runs_ok"] == 4 and summary["nees"]["runs"] == 4
    # The same function of the same arguments (written through JSON, which round-trips).
    assert summary["nees"]["bounds_95"] == pytest.approx(chi2_bounds(9, 4), rel=1e-12)


# --------------------------------------------------------------------------- 8. dask


def test_dask_cluster_gives_the_local_cases_exactly(twin_set, tmp_path, no_set_figures):
    """Identity is the requirement here: dask workers on this machine against the
    local processes."""
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
    """Identity is the requirement here: the grid arrays are the kept rows of the
    full trajectories."""
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


def test_keeping_another_trajectory_reruns_only_that_case(twin_set, tmp_path,
                                                         no_set_figures):
    """Identity is the requirement here: a case rerun to keep its trajectory gives the
    same record and grid arrays, and its full rows hold the grid rows exactly."""
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
    # The same scipy quantiles, divided by M: a few ulps (1e-10 allows other scipy).
    assert summary["nees"]["bounds_95"] == pytest.approx([lo, hi], rel=1e-10)
    assert summary["nees"]["bounds_95"] == list(chi2_bounds(9, m))
    assert tuple(summary["nees"]["per_state_mean_after_convergence"]) == STATES
    # 117 samples of 0.512 s: one product (the first grid time is 0).
    assert summary["grid_s"] == pytest.approx(round(60 / DT) * DT, rel=1e-12)
    assert summary["converged_after_h"] == 1
    assert "linear" in summary["nees"]
    t = load_npz(twin_set / "cases" / "case-00000.npz")["t_s"]
    with np.load(twin_set / "montecarlo.npz") as fig:
        assert np.array_equal(fig["t_s"], t)
        assert fig["nees_avg"].shape == t.shape
    # The numbers: test_set_statistics_are_those_of_the_stored_cases.


def _fraction_slack(values, *bounds) -> float:
    """Share of ``values`` within 1e-12 (relative) of a bound: those a recomputation
    with other rounding may put on the other side."""
    v = np.asarray(values, dtype=float)
    near = np.zeros(v.shape, dtype=bool)
    for b in bounds:
        near |= np.abs(v - b) <= 1e-12 * np.abs(b)
    return float(near.mean()) + 1e-15


def test_set_statistics_are_those_of_the_stored_cases(twin_set):
    """montecarlo.json recomputed from the stored cases: their grid arrays (float32,
    widened to float64 as the ensemble does) and their records (JSON doubles).  The
    inputs are the same doubles, only the order of the float64 sums may differ:
    1e-12 relative (sums of at most ~2000 positive terms: ≲ 2000·eps = 4e-13)."""
    summary = json.loads((twin_set / "montecarlo.json").read_text())
    m = summary["runs_ok"]
    arrays = [load_npz(twin_set / "cases" / f"case-{k:05d}.npz") for k in range(m)]
    records = [json.loads((twin_set / "cases" / f"case-{k:05d}.json").read_text())
               for k in range(m)]
    t = arrays[0]["t_s"]
    conv = t >= 3600
    lo, hi = summary["nees"]["bounds_95"]
    err = np.array([a["err"].astype(float) for a in arrays])          # (M, G, 9)
    sig = np.array([a["sigma"].astype(float) for a in arrays])
    for key, nees_key in (("nees", "nees"), ("linear", "nees_linear")):
        stat = summary["nees"] if key == "nees" else summary["nees"]["linear"]
        avg = np.mean([a[nees_key].astype(float) for a in arrays], axis=0)
        assert stat["mean_after_convergence"] == pytest.approx(avg[conv].mean(), rel=1e-12)
        frac = stat["fraction_after_convergence"]
        slack = _fraction_slack(avg[conv], lo, hi)
        assert frac["inside"] == pytest.approx(np.mean((avg[conv] >= lo) & (avg[conv] <= hi)),
                                               rel=0, abs=slack)
        assert frac["below"] == pytest.approx(np.mean(avg[conv] < lo), rel=0, abs=slack)
        assert frac["above"] == pytest.approx(np.mean(avg[conv] > hi), rel=0, abs=slack)
    per_state = np.mean(np.mean((err / sig) ** 2, axis=0)[conv], axis=0)
    assert list(summary["nees"]["per_state_mean_after_convergence"].values()) == \
        pytest.approx(per_state.tolist(), rel=1e-12)
    assert summary["nees"]["points_after_convergence"] == conv.sum()
    b_lo, b_hi = summary["nees"]["per_state_bounds_95"]
    assert summary["nees"]["per_state_test_95"] == {
        name: "below" if v < b_lo else "above" if v > b_hi else "inside"
        for name, v in zip(STATES, per_state, strict=True)}
    for name, k in (("roll_deg", 0), ("yaw_deg", YAW), ("h_Nms", 4)):
        r = summary["rms_after_convergence"][name]
        assert r["ensemble_rms"] == pytest.approx(
            math.sqrt(np.mean(err[:, conv, k] ** 2)), rel=1e-12), name
        assert r["filter_sigma_rms"] == pytest.approx(
            math.sqrt(np.mean(sig[:, conv, k] ** 2)), rel=1e-12), name
    # The pitch filter's 3-state figures, kept apart from the 9-state ones.
    p = summary["pitch"]
    nees_p = np.mean([a["nees_pitch"].astype(float) for a in arrays], axis=0)
    assert p["nees"]["dof"] == 3
    assert p["nees"]["bounds_95"] == pytest.approx(
        [stats.chi2.ppf(0.025, 3 * m) / m, stats.chi2.ppf(0.975, 3 * m) / m], rel=1e-9)
    assert p["nees"]["mean_after_convergence"] == pytest.approx(nees_p[conv].mean(), rel=1e-12)
    err_p = np.array([a["err_pitch"].astype(float) for a in arrays])
    assert p["rms_after_convergence"]["pitch_deg"]["ensemble_rms"] == pytest.approx(
        math.sqrt(np.mean(err_p[:, conv, 0] ** 2)), rel=1e-12)
    for r, a in zip(records, arrays, strict=True):
        assert r["nees_mean_pitch"] == pytest.approx(
            a["nees_pitch"].astype(float)[conv].mean(), rel=1e-6)
    with np.load(twin_set / "montecarlo.npz") as fig:
        nees_avg = np.mean([a["nees"].astype(float) for a in arrays], axis=0)
        assert fig["nees_avg"] == pytest.approx(nees_avg, rel=1e-12)
        assert fig["rms"] == pytest.approx(np.sqrt(np.mean(err**2, axis=0)), rel=1e-12)

    # The yaw error at the end of the one night gap, from the case records.
    (gap,) = summary["gap_end_yaw"]
    assert gap["gap"] == 1 and gap["n"] == m
    assert gap["start_h_median"] == pytest.approx(
        np.median([r["sun_gaps_h"][0][0] for r in records]), rel=1e-12)
    assert gap["end_h_median"] == pytest.approx(
        np.median([r["gap_end_h"][0] for r in records]), rel=1e-12)
    sig_end = np.array([r["yaw_sigma_at_gap_end_deg"][0] for r in records])
    for stat, key in ((gap, "yaw_error_at_gap_end_deg"),
                      (gap["linear"], "yaw_error_linear_at_gap_end_deg")):
        e = np.array([r[key][0] for r in records])
        assert stat["n"] == m
        assert stat["mean_deg"] == pytest.approx(e.mean(), rel=1e-12), key
        assert stat["std_deg"] == pytest.approx(e.std(ddof=1), rel=1e-12), key
        assert stat["rms_deg"] == pytest.approx(math.sqrt(np.mean(e**2)), rel=1e-12), key
        # Type-7 sample quantiles (numpy's default, interpolating between order statistics).
        srt = np.sort(np.abs(e))
        for name, p in (("1sigma", 0.682689492), ("2sigma", 0.954499736),
                        ("3sigma", 0.997300204)):
            h = (m - 1) * p
            j = int(math.floor(h))
            q = srt[j] + (h - j) * (srt[min(j + 1, m - 1)] - srt[j])
            assert stat["abs_quantile_deg"][name] == pytest.approx(q, rel=1e-12), (key, name)
            # Its distribution-free 95% interval: order statistics X_(r) ≤ ξ_p < X_(s)
            # with Binomial(m, p) tails of at most 2.5% each; 3 cases leave it open above.
            r = max((i for i in range(1, m + 1) if stats.binom.sf(i - 1, m, p) >= 0.975),
                    default=0)
            assert stat["abs_quantile_level"][name] == p
            assert stat["abs_quantile_ci95_deg"][name] == [srt[r - 1] if r else 0.0, None]
        assert stat["predicted_sigma_deg"] == pytest.approx(
            math.sqrt(np.mean(sig_end**2)), rel=1e-12), key
        for j in (1, 2, 3):
            assert stat["fraction_within"][f"{j}sigma"] == pytest.approx(
                np.mean(np.abs(e) <= j * sig_end), rel=0,
                abs=_fraction_slack(np.abs(e) / (j * sig_end), 1.0))


def test_case_records_are_those_of_their_arrays_and_the_sun(twin_set):
    """Each case record against its own grid arrays (float32: within 2⁻²⁴ of the
    doubles the record was computed from), the kept trajectory of case 1 at the gap
    end, and the Sun-gap edges against the Sun's hour angle on the case's epoch."""
    f32 = 2.0**-24
    s = scenario_of(TWIN_SET)
    for k in range(3):
        rec = json.loads((twin_set / "cases" / f"case-{k:05d}.json").read_text())
        a = load_npz(twin_set / "cases" / f"case-{k:05d}.npz")
        err, conv = a["err"].astype(float), a["t_s"] >= 3600
        for key, col in (("roll_error_rms_deg", 0), ("yaw_error_rms_deg", YAW),
                         ("h_error_rms_Nms", 4)):
            assert rec[key] == pytest.approx(math.sqrt(np.mean(err[:, col] ** 2)),
                                             rel=f32 + 1e-12), (k, key)
        assert rec["yaw_error_rms_linear_deg"] == pytest.approx(
            math.sqrt(np.mean(a["err_linear"][:, YAW].astype(float) ** 2)), rel=f32 + 1e-12)
        assert rec["yaw_error_max_abs_deg"] == pytest.approx(np.abs(err[:, YAW]).max(),
                                                             rel=f32 + 1e-12)
        assert rec["nees_mean"] == pytest.approx(a["nees"][conv].astype(float).mean(),
                                                 rel=f32 + 1e-12)
        assert rec["nees_mean_linear"] == pytest.approx(
            a["nees_linear"][conv].astype(float).mean(), rel=f32 + 1e-12)
        # Epochs move by whole days: the gap moves with the equation of time only.
        (gap,) = rec["sun_gaps_h"]
        (predicted,) = predicted_sun_gaps_h(s, rec["epoch_utc"])
        assert gap == pytest.approx(predicted, abs=2 / 60), (k, rec["epoch_utc"])
        assert rec["gap_end_h"] == [gap[1]]
    # The gap-end error is the filter's at the first sample with yaw again.
    rec = json.loads((twin_set / "cases" / "case-00001.json").read_text())
    full = load_npz(twin_set / "cases" / "case-00001.full.npz")
    b = int(round(rec["gap_end_h"][0] * 3600 / DT))
    (e,) = rec["yaw_error_at_gap_end_deg"]
    (sig,) = rec["yaw_sigma_at_gap_end_deg"]
    assert e == pytest.approx(float(full["err"][b, YAW]), rel=f32)
    assert sig == pytest.approx(float(full["sigma"][b, YAW]), rel=f32)
    assert full["sigma"][b, YAW] < full["sigma"][b - 1, YAW]     # after its first yaw update
    assert rec["yaw_error_linear_at_gap_end_deg"][0] == pytest.approx(
        float(full["err_linear"][b, YAW]), rel=f32)


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
