"""`dynprop truth` and the run-directory contract (DESIGN.md section 6)."""

import csv

import numpy as np
import pytest

from scenarios.cli import main
from scenarios.rundir import RunDirError, staged_run_dir


def test_truth_writes_csv_and_plot(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["truth", "--duration-s", "600", "--out", str(out)]) == 0
    with open(out / "truth.csv") as fh:
        header = next(csv.reader(fh))
    for col in ("t_s", "yaw_deg", "roll_deg", "pitch_deg", "wx_radps", "wheel1_rpm",
                "wheel2_rpm", "h_Nms", "H_Nms", "eclipse", "solar_x_Nm",
                "gravity_gradient_z_Nm", "wheel_ripple_y_Nm"):
        assert col in header
    data = np.loadtxt(out / "truth.csv", delimiter=",", skiprows=1)
    assert data.shape == (int(600 / 0.512) + 1, len(header))
    # Units at the boundary: wheel speeds in rpm, H in N m s (paper: 5485 rpm, -124.2).
    assert abs(data[0, header.index("wheel1_rpm")] - 5485.0) < 1e-9
    assert abs(data[0, header.index("H_Nms")] + 124.2) < 0.05
    assert (out / "plots" / "truth.png").stat().st_size > 10_000
    assert "wrote" in capsys.readouterr().out


def test_same_seed_gives_identical_files(tmp_path):
    for name in ("a", "b"):
        assert main(["truth", "--duration-s", "120", "--seed", "5", "--out",
                     str(tmp_path / name)]) == 0
    a, b = (tmp_path / name / "truth.csv" for name in ("a", "b"))
    assert a.read_bytes() == b.read_bytes()


def test_existing_directory_is_refused_and_untouched(tmp_path, capsys):
    out = tmp_path / "run"
    out.mkdir()
    (out / "keep.txt").write_text("precious")
    assert main(["truth", "--duration-s", "10", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--out" in err[0] and "not empty" in err[0]
    assert (out / "keep.txt").read_text() == "precious"
    assert main(["truth", "--duration-s", "10", "--out", str(out), "--force"]) == 0
    assert not (out / "keep.txt").exists() and (out / "truth.csv").exists()


def test_bad_epoch_is_one_line_exit_2(tmp_path, capsys):
    assert main(["truth", "--epoch", "yesterday", "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("dynprop: error: --epoch")
    assert not (tmp_path / "x").exists()


def test_bad_duration_exits_2(tmp_path):
    with pytest.raises(SystemExit) as exc:
        main(["truth", "--duration-s", "nan", "--out", str(tmp_path / "x")])
    assert exc.value.code == 2


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


@pytest.mark.parametrize("argv, fragment", [
    (["--seed", "-1"], "--seed"),
    (["--seed", "1.5"], "--seed"),
    (["--duration-s", "1e15"], "--duration-s"),
    (["--duration-s", "-3"], "--duration-s"),
    (["--epoch", "2150-01-01T00:00:00Z"], "--epoch"),
    (["--epoch", "2026-13-01T00:00:00Z"], "--epoch"),
    (["--bogus", "1"], "unrecognized"),
])
def test_bad_arguments_are_one_line_exit_2(tmp_path, capsys, argv, fragment):
    out = tmp_path / "x"
    try:
        code = main(["truth", "--out", str(out), *argv])
    except SystemExit as exc:  # argparse's own errors
        code = exc.code
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1 and fragment in err[0], err
    assert not out.exists()


def test_out_under_a_file_is_refused_before_simulating(tmp_path, capsys):
    (tmp_path / "afile").write_text("x")
    assert main(["truth", "--out", str(tmp_path / "afile" / "sub")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not a directory" in err[0]


def test_run_json_records_seed_epoch_backend(tmp_path):
    import json
    out = tmp_path / "run"
    assert main(["truth", "--duration-s", "10", "--seed", "9", "--out", str(out)]) == 0
    info = json.loads((out / "run.json").read_text())
    assert info["seed"] == 9 and info["backend"] in ("compiled", "vm")
    assert info["epoch_utc"] == "2026-03-20T12:00:00Z" and info["dynprop_version"]


def test_swap_failure_restores_previous_run(tmp_path, monkeypatch):
    import os

    from scenarios import rundir
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
