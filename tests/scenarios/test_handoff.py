"""Records handed from the producer process through shared-memory files."""

from types import SimpleNamespace

import numpy as np
import pytest

from scenarios.files.rundir import clean_stale_handoffs
from scenarios.run.stream import handoff


@pytest.fixture
def shared():
    d = handoff.HandoffDir()
    if d.path is None:
        pytest.skip("no shared-memory file system here")
    yield d
    d.close()
    assert not d.path


def test_a_record_comes_back_equal_and_its_file_is_gone(shared):
    rng = np.random.default_rng(0)
    rec = {"index": 3, "x": rng.normal(size=(50_000, 9)), "flags": rng.random(50_000) > 0.5,
           "ns": SimpleNamespace(a=rng.normal(size=20_000), b=None),
           "strided": rng.normal(size=(1000, 6))[:, ::2], "tuple": (rng.normal(size=7), 1.5)}
    packed = handoff.pack(rec, shared.path)
    assert packed[1] is not None and sum(packed[2]) >= rec["x"].nbytes
    back = handoff.unpack(*packed)
    assert list(shared.path.iterdir()) == []          # unlinked as soon as mapped
    assert back["index"] == 3 and back["ns"].b is None and back["tuple"][1] == 1.5
    for got, want in ((back["x"], rec["x"]), (back["flags"], rec["flags"]),
                      (back["ns"].a, rec["ns"].a), (back["strided"], rec["strided"]),
                      (back["tuple"][0], rec["tuple"][0])):
        assert got.dtype == want.dtype and np.array_equal(got, want)
    back["x"][0, 0] = 1.0                              # the consumer may write in place


def test_small_records_and_no_directory_go_in_band(shared):
    small = {"a": np.arange(10.0)}
    for directory in (shared.path, None):
        data, name, sizes = handoff.pack(small, directory)
        assert name is None and sizes == ()
        assert np.array_equal(handoff.unpack(data, name, sizes)["a"], small["a"])


def test_closing_removes_what_was_never_unpacked(shared):
    handoff.pack({"x": np.zeros(100_000)}, shared.path)
    path = shared.path
    shared.close()
    assert not path.exists()


def test_a_killed_runs_directory_is_removed_by_the_next(tmp_path):
    import subprocess
    import sys
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    left = tmp_path / f"dynprop-{dead.pid}-abc123"
    left.mkdir()
    (left / "record").write_bytes(b"x" * 100)
    alive = tmp_path / "dynprop-1-abc123"          # pid 1 is always there
    alive.mkdir()
    other = tmp_path / "dynprop-cache"
    other.mkdir()
    assert clean_stale_handoffs(tmp_path) == [left]
    assert not left.exists() and alive.exists() and other.exists()


def test_no_room_in_shared_memory_sends_the_record_in_band(shared, monkeypatch):
    """A full /dev/shm (posix_fallocate: ENOSPC) must not kill the producer with a
    bus error on writing the mapping: the record goes through the pipe instead."""
    def full(fd, offset, length):
        raise OSError(28, "No space left on device")
    monkeypatch.setattr(handoff.os, "posix_fallocate", full)
    rec = {"x": np.arange(100_000.0)}
    data, name, sizes = handoff.pack(rec, shared.path)
    assert name is None and list(shared.path.iterdir()) == []
    assert np.array_equal(handoff.unpack(data, name, sizes)["x"], rec["x"])
