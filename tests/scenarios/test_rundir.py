"""Run directories are written whole or not at all (docs/outputs.md)."""

import pytest

from scenarios.files.rundir import RunDirError, staged_run_dir


def test_failed_write_leaves_previous_run_intact(tmp_path):
    out = tmp_path / "run"
    out.mkdir()
    (out / "truth.csv").write_text("old")
    with pytest.raises(RuntimeError), staged_run_dir(out, force=True) as stage:
        (stage / "truth.csv").write_text("half")
        raise RuntimeError("disk full")
    assert (out / "truth.csv").read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["run"]


def test_out_must_be_a_directory(tmp_path):
    f = tmp_path / "file"
    f.write_text("x")
    with pytest.raises(RunDirError), staged_run_dir(f):
        pass


def test_swap_failure_restores_previous_run(tmp_path, monkeypatch):
    import os

    from scenarios.files import rundir
    out = tmp_path / "run"
    out.mkdir()
    (out / "truth.csv").write_text("old")
    real_replace = os.replace
    calls = []

    def flaky_replace(src, dst):
        calls.append((src, dst))
        if len(calls) == 2:  # the new run moving into place
            raise OSError(28, "No space left on device")
        return real_replace(src, dst)

    monkeypatch.setattr(rundir.os, "replace", flaky_replace)
    with pytest.raises(OSError), staged_run_dir(out, force=True) as stage:
        (stage / "truth.csv").write_text("new")
    assert (out / "truth.csv").read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["run"]
