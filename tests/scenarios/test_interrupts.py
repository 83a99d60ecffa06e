"""Interrupts and kills leave nothing behind.

Ctrl-C reaches every process of the foreground group: the CLI prints one line and
no process prints a traceback.  A SIGKILL leaves a staging directory that nothing
could clean; the next command writing into the same parent removes it.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from scenarios.files.rundir import clean_stale, staged_run_dir
from scenarios.montecarlo.store import SetDirectory

REPO = Path(__file__).resolve().parents[2]

# A child of this test: a pool of forked workers and a background CSV writer, as a
# run has them, all busy when the harness sends Ctrl-C to the whole process group.
POOL_SCRIPT = r"""
import sys, time
from multiprocessing import get_context
import numpy as np
from scenarios.files.csvio import BackgroundWriter
from scenarios.workers import worker_pool

def busy(_):
    time.sleep(600)

def main():
    writer = BackgroundWriter(sys.argv[1], {"x": np.zeros(3_000_000)})
    try:
        with worker_pool(2, get_context("fork")) as pool:
            futures = [pool.submit(busy, k) for k in range(4)]
            time.sleep(0.5)
            print("ready", flush=True)
            for f in futures:
                f.result()
    except KeyboardInterrupt:
        writer.cancel()
        print("interrupted", file=sys.stderr)
        return 130

sys.exit(main())
"""


def _default_sigint():
    # A test runner may have started us with SIGINT ignored; a user's shell does not.
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _spawn(argv, **kw):
    return subprocess.Popen(argv, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, start_new_session=True, preexec_fn=_default_sigint,
                            **kw)


def test_ctrl_c_stops_forked_workers_without_a_traceback(tmp_path):
    proc = _spawn([sys.executable, "-c", POOL_SCRIPT, str(tmp_path / "x.csv")])
    assert proc.stdout.readline().strip() == "ready"
    os.killpg(proc.pid, signal.SIGINT)   # what Ctrl-C does: the whole group
    # Workers are terminated, not waited for: each would sleep 600 s, so a pool that
    # waits for them hits this hang guard (not a speed limit: the exit takes ~0.1 s).
    try:
        _, err = proc.communicate(timeout=120)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
        pytest.fail("Ctrl-C waited for the busy workers instead of terminating them")
    assert proc.returncode == 130
    assert err == "interrupted\n", err


def test_ctrl_c_during_a_run_prints_one_line_and_writes_nothing(tmp_path):
    """The run is interrupted once its staging directory holds plots/: the figures
    are being drawn by two forked workers then."""
    out = tmp_path / "runs" / "eq"
    proc = _spawn([sys.executable, "-m", "scenarios.cli", "run", "goes_next_equinox",
                   "--duration-s", "43200", "--out", str(out)])
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and proc.poll() is None:
        if any((p / "plots").exists() for p in out.parent.glob(".eq.stage-*")):
            break
        time.sleep(0.01)
    os.killpg(proc.pid, signal.SIGINT)
    stdout, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, (stdout, err)
    assert err == "dynprop: interrupted; nothing was written\n", err
    assert not out.parent.exists() or not any(out.parent.iterdir())


def _dead_pid() -> int:
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    return p.pid


def test_the_next_run_removes_a_stage_whose_owner_was_killed(tmp_path, capsys):
    host = socket.gethostname()
    pid = _dead_pid()
    stale = tmp_path / f".killed.stage-{host}-{pid}-abcd1234"
    (stale / "plots").mkdir(parents=True)
    (stale / "truth.csv").write_text("t_s\n0\n")
    live = tmp_path / f".busy.stage-{host}-{os.getpid()}-abcd1234"     # our own: alive
    live.mkdir()
    remote = tmp_path / f".far.stage-otherhost-{pid}-abcd1234"          # can't tell
    remote.mkdir()
    legacy = tmp_path / ".old-style.x1y2z3w4"                           # no owner in name
    legacy.mkdir()
    with staged_run_dir(tmp_path / "next") as stage:
        (stage / "a.txt").write_text("a")
    assert not stale.exists()
    assert live.is_dir() and remote.is_dir() and legacy.is_dir()
    assert (tmp_path / "next" / "a.txt").read_text() == "a"
    err = capsys.readouterr().err
    assert err == f"dynprop: note: removed {stale}, left by process {pid}, which is gone\n"


def test_a_stage_whose_owner_was_killed_but_not_yet_reaped_is_stale(tmp_path):
    """Right after a SIGKILL the owner may still exist: a two-gigabyte process takes a
    second or two to release its memory and be reaped (measured 1.6–1.9 s after
    `timeout -s KILL`), and a user's next command comes sooner.  A zombie never
    writes again, so its stage goes."""
    if not Path("/proc/self/stat").exists():
        pytest.skip("no /proc: a zombie cannot be told from a live process")
    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        os.kill(child.pid, signal.SIGKILL)
        for _ in range(1000):       # until the kernel has made it a zombie; not reaped
            state = Path(f"/proc/{child.pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
            if state == "Z":
                break
            time.sleep(0.01)
        assert state == "Z"
        stage = tmp_path / f".eq.stage-{socket.gethostname()}-{child.pid}-abcd1234"
        stage.mkdir()
        assert clean_stale(tmp_path) == [f"removed {stage}, left by process {child.pid}, "
                                         "which is gone"]
        assert not stage.exists()
    finally:
        child.wait()


def test_a_run_moved_aside_by_a_killed_force_is_put_back(tmp_path):
    """Killed between moving the previous run aside and renaming the new one in:
    the previous run is restored, not deleted."""
    pid = _dead_pid()
    aside = tmp_path / f".eq.old-{socket.gethostname()}-{pid}-abcd1234"
    aside.mkdir()
    (aside / "summary.json").write_text("{}")
    notes = clean_stale(tmp_path)
    assert (tmp_path / "eq" / "summary.json").read_text() == "{}"
    assert not aside.exists()
    assert len(notes) == 1 and notes[0].startswith(f"restored {tmp_path / 'eq'}")


def test_a_stage_whose_pid_was_reused_by_a_later_process_is_stale(tmp_path):
    """Our own pid, but a staging directory last written before this process started."""
    stage = tmp_path / f".eq.stage-{socket.gethostname()}-{os.getpid()}-abcd1234"
    stage.mkdir()
    long_ago = time.time() - 10 * 86400
    os.utime(stage, (long_ago, long_ago))
    if not Path(f"/proc/{os.getpid()}/stat").exists():
        pytest.skip("no /proc: the pid-reuse check needs the process start time")
    clean_stale(tmp_path)
    assert not stage.exists()


def test_a_run_killed_with_sigkill_leaves_nothing_after_the_next_run(tmp_path):
    runs = tmp_path / "runs"
    proc = _spawn([sys.executable, "-m", "scenarios.cli", "run", "goes_next_equinox",
                   "--duration-s", "43200", "--out", str(runs / "killed")])
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and not list(runs.glob(".killed.stage-*/telemetry.csv")):
        time.sleep(0.01)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.communicate()
    assert list(runs.glob(".killed.stage-*")), "the kill came too late to leave a stage"
    done = subprocess.run([sys.executable, "-m", "scenarios.cli", "simulate", "torque_free",
                           "--duration-s", "60", "--out", str(runs / "next")],
                          cwd=REPO, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert sorted(p.name for p in runs.iterdir()) == ["next"]
    assert "removed" in done.stderr and ".killed.stage-" in done.stderr
    # Its records in shared memory (scenarios.run.stream.handoff) went with the next command too.
    assert not list(Path("/dev/shm").glob(f"dynprop-{proc.pid}-*"))


def test_a_monte_carlo_set_cleans_what_a_kill_left_half_written(tmp_path):
    store = SetDirectory(tmp_path / "set")
    store.cases_dir.mkdir(parents=True)
    (store.out / "plots").mkdir()
    leftovers = [store.cases_dir / ".case-00003.json.k2j4h5g6",
                 store.out / ".montecarlo.json.a1b2c3d4", store.out / ".montecarlo.npz.x9y8z7w6",
                 store.out / ".scenario.yaml.q1w2e3r4", store.out / "plots" / ".mc_nees.png.tmp"]
    kept = [store.cases_dir / "case-00003.json", store.out / "montecarlo.json",
            store.out / "plots" / "mc_nees.png", store.out / "notes.txt"]
    for p in leftovers + kept:
        p.write_text("x")
    store.clean_temporaries()
    assert not any(p.exists() for p in leftovers)
    assert all(p.exists() for p in kept)
