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
