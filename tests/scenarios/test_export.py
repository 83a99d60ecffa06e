"""`dynprop export` (scenarios/export) and ``read_truth_aem`` (scenarios/files/truth_aem.py):
a run's attitude out as a CCSDS AEM/APM and another tool's AEM back in.

The references are the run's own CSVs read with numpy, matrices written out here
(R1, R2, R3 and Markley's A(q), Eq. 2.125) and test_aem's Earth-nadir direction from
Meeus's formulas, never the code under test.  The files print 12 decimals (|Δq| ≤
5e-13), truth.csv and estimate.csv 10 significant digits.
"""

from __future__ import annotations

import contextlib
import io
import os
import shutil
import tracemalloc
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import pytest
from scipy.interpolate import BarycentricInterpolator
from scipy.spatial.transform import Rotation

from scenarios.cli import main
from scenarios.config.loader import load_scenario
from scenarios.export import source as export_source
from scenarios.files import aem
from scenarios.files.aem import AemError, AemMeta
from scenarios.files.rundir import RunDirError
from scenarios.files.truth_aem import read_truth_aem
from sim.frames import GeoOrbit
from sim.inertial import inertial_quaternions

from .test_aem import (
    angle,
    angles,
    body_axes,
    frame_bias,
    gmst_meeus_rad,
    in_frame_bias_frame,
    precess_to_date,
)
from .test_cli_run import run_cli

EPOCH = datetime(2026, 3, 20, 12, tzinfo=UTC)
READ = 1.5e-12        # a printed component, after the reader's renormalisation
DURATION = 3 * 3600.0   # 169 rows at the default 64 s


def numbers(path: Path) -> dict[str, np.ndarray]:
    """A CSV of the run read with numpy alone (empty fields: NaN)."""
    names = path.read_text().splitlines()[0].split(",")
    data = np.genfromtxt(path, delimiter=",", skip_header=1, missing_values="",
                         filling_values=np.nan)
    return {n: data[:, k] for k, n in enumerate(names)}


@pytest.fixture(scope="module")
def run(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("export") / "run"
    rc, _, err = run_cli("run", "goes_next_equinox", "--duration-s", str(DURATION),
                         "--out", str(out))
    assert rc == 0, err
    return out


@pytest.fixture
def d(run, tmp_path) -> Path:
    """A copy of the run to write into."""
    return Path(shutil.copytree(run, tmp_path / "run"))


def export(*argv) -> tuple[int, str, str]:
    """`dynprop export ARGV` in this process: (status, stdout, stderr), argparse's
    exit on a bad choice included."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            rc = main(["export", *map(str, argv)])
        except SystemExit as exc:
            rc = exc.code
    return rc, out.getvalue(), err.getvalue()


def matrix(yaw, roll, pitch):
    """C_BR = R2(pitch) R1(roll) R3(yaw), written out (docs/conventions.md)."""
    def rot(axis, a):
        c, s = np.cos(a), np.sin(a)
        m = np.zeros(a.shape + (3, 3))
        i, j = [(1, 2), (2, 0), (0, 1)][axis]
        m[..., axis, axis] = 1
        m[..., i, i] = m[..., j, j] = c
        m[..., i, j], m[..., j, i] = s, -s
        return m
    return rot(1, pitch) @ rot(0, roll) @ rot(2, yaw)


def csv_angles(path: Path):
    c = numbers(path)
    return c["t_s"], *(np.deg2rad(c[k]) for k in ("yaw_deg", "roll_deg", "pitch_deg"))


def rows_of(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """(seconds after EPOCH, the printed quaternions) of an AEM's data lines, read here."""
    t, q = [], []
    for line in path.read_text().splitlines():
        f = line.split()
        if len(f) == 5 and line[:4] == "2026":
            t.append((np.datetime64(f[0]) - np.datetime64("2026-03-20T12:00:00"))
                     / np.timedelta64(1, "s"))
            q.append([float(x) for x in f[1:]])
    return np.array(t), np.array(q)


def same(a, b):
    return np.minimum(np.abs(a - b).max(axis=1), np.abs(a + b).max(axis=1)).max()


# --- the AEM -------------------------------------------------------------------------

@pytest.mark.parametrize("what", ["estimate", "truth"])
def test_the_aem_holds_every_row_in_eme2000_to_the_printed_precision(run, d, what):
    rc, out, err = export(d, "--format", "aem", "--what", what)
    assert rc == 0 and not err, err
    path = d / f"{what}.aem"
    assert out.startswith(f"wrote {path}: the {what}, EME2000 -> SC_BODY_1, 169 rows in 1 "
                          "segment")
    t, yaw, roll, pitch = csv_angles(run / f"{what}.csv")
    t_file, q_file = rows_of(path)
    assert np.array_equal(t_file, t)
    expected = inertial_quaternions(t, roll, pitch, yaw, GeoOrbit(), EPOCH)
    assert same(q_file, expected) <= 5e-13 * 1.0001
    (seg,) = aem.read_aem(path)
    assert same(seg.quaternions, expected) < READ
    assert (seg.frame, seg.body) == ("EME2000", "SC_BODY_1")
    assert {k: seg.meta[k] for k in ("OBJECT_NAME", "OBJECT_ID", "CENTER_NAME", "TIME_SYSTEM",
                                     "ATTITUDE_TYPE")} == {
        "OBJECT_NAME": "goes_next_equinox", "OBJECT_ID": "SIMULATED", "CENTER_NAME": "EARTH",
        "TIME_SYSTEM": "UTC", "ATTITUDE_TYPE": "QUATERNION"}
    assert seg.header["ORIGINATOR"] == "DYNPROP" and seg.header["CCSDS_AEM_VERS"] == "2.0"
    text = " ".join(line[8:] for line in path.read_text().splitlines()
                    if line.startswith("COMMENT "))
    for words in (f"export of the {what}: {what}.csv", f"of the run directory {d.name}",
                  "scalar last", "C(SC_BODY_1 <- EME2000) = C_BR(yaw, roll, pitch) C_RN(t) P(t)",
                  "CADENCE_S = 64"):
        assert words in text
    # The run by its folder's name: the user's local path stays out of an exchanged file.
    assert d.resolve().parent.name not in path.read_text()


def test_the_truth_export_points_the_yaw_axis_at_the_independent_nadir(run, d):
    """The body z axis of the file's quaternion against the Earth-nadir direction from
    Meeus's GMST and precession (test_aem): off by the angle the truth's roll and pitch
    tilt it, arccos(cos roll cos pitch)."""
    assert export(d, "--format", "aem", "--what", "truth")[0] == 0
    t, q = rows_of(d / "truth.aem")
    _, _, roll, pitch = csv_angles(run / "truth.csv")
    jd = 2451545.0 + ((EPOCH - datetime(2000, 1, 1, 12, tzinfo=UTC)).total_seconds() + t) / 86400
    alpha = gmst_meeus_rad(jd) + np.deg2rad(-75.0)
    nadir = -np.stack([np.cos(alpha), np.sin(alpha), 0 * alpha], axis=-1)   # mean of date
    z_body = precess_to_date(body_axes(q)[:, 2], jd)
    tilt = np.arccos(np.cos(roll) * np.cos(pitch))
    assert tilt.max() > 1e-5          # the truth moves: the check can see a swap
    assert np.abs(angle(z_body, nadir) - tilt).max() < 1e-6


def test_the_orbit_frame_variant_is_c_br(run, d):
    rc, out, err = export(d, "--format", "aem", "--frame", "orbit")
    assert rc == 0, err
    (seg,) = aem.read_aem(d / "estimate.aem")
    assert seg.frame == "LVLH_ROTATING"
    t, q = rows_of(d / "estimate.aem")
    _, yaw, roll, pitch = csv_angles(run / "estimate.csv")
    assert np.abs(body_axes(q) - matrix(yaw, roll, pitch)).max() < 3e-12
    assert "C(SC_BODY_1 <- LVLH_ROTATING) = C_BR = R2(pitch) R1(roll) R3(yaw)" in \
        (d / "estimate.aem").read_text().replace("\nCOMMENT ", " ")


def blank_and_cut(d: Path) -> None:
    """Rows 40–41 of estimate.csv with an empty yaw (the filter's dropout) and rows
    100–109 gone: three segments, 40, 58 and 59 rows."""
    lines = (d / "estimate.csv").read_text().splitlines()
    k = lines[0].split(",").index("yaw_deg")
    for r in (41, 42):
        f = lines[r].split(",")
        f[k] = ""
        lines[r] = ",".join(f)
    del lines[101:111]
    (d / "estimate.csv").write_text("\n".join(lines) + "\n")


def test_dropouts_start_new_segments(d):
    blank_and_cut(d)
    rc, out, _ = export(d, "--format", "aem")
    assert rc == 0 and "157 rows in 3 segments" in out
    segments = aem.read_aem(d / "estimate.aem")
    assert [len(s.epochs) for s in segments] == [40, 58, 59]
    assert [s.seconds_since(EPOCH)[0] for s in segments] == [0.0, 42 * 64.0, 110 * 64.0]
    assert "after a dropout of 192 s" in (d / "estimate.aem").read_text()


def test_blocks_stream_the_same_bytes_at_bounded_memory(run, d, tmp_path, monkeypatch):
    """Blocks of 7 rows give the bytes of one block; a 100 000-row file read in blocks
    of 1 000 holds about a block's arrays (1.5 MB traced here), not the file's (its
    angles alone are 3.2 MB, 87 MB through the export in one block)."""
    blank_and_cut(d)

    def body(path):
        return [line for line in path.read_text().splitlines()
                if not line.startswith("CREATION_DATE")]
    assert export(d, "--format", "aem", "--out", tmp_path / "one.aem")[0] == 0
    monkeypatch.setattr(export_source, "BLOCK_ROWS", 7)
    src = export_source.open_source(d, "estimate")
    assert [len(b.t_s) for b in src.blocks()] == [7] * 22 + [5]   # 159 rows
    assert export(d, "--format", "aem", "--out", tmp_path / "seven.aem")[0] == 0
    assert body(tmp_path / "seven.aem") == body(tmp_path / "one.aem")

    big = tmp_path / "big"
    big.mkdir()
    shutil.copy(run / "scenario.yaml", big)
    t = np.arange(100_000) * 64.0
    roll, pitch, yaw = (np.rad2deg(a) for a in angles(t))
    with open(big / "estimate.csv", "w") as f:
        f.write("t_s,roll_deg,yaw_deg,pitch_deg\n")
        np.savetxt(f, np.column_stack([t, roll, yaw, pitch]), fmt="%.10g", delimiter=",")
    monkeypatch.setattr(export_source, "BLOCK_ROWS", 1000)
    monkeypatch.setattr(aem, "SPOOL_BYTES", 1 << 17)
    tracemalloc.start()
    rc, out, err = export(big, "--format", "aem")
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert rc == 0 and "100000 rows in 1 segment" in out, err
    assert (big / "estimate.aem").stat().st_size > 9e6
    assert peak < 3e6, f"peak {peak / 1e6:.2f} MB"


def test_times_printed_to_10_digits_are_put_back_on_the_sample_grid(run, tmp_path):
    """A year into a run at every sample, %.10g keeps t_s to 10 ms: 30000000.51 is
    30000000.512, the AEM's epoch to the microsecond."""
    d = tmp_path / "late"
    d.mkdir()
    shutil.copy(run / "scenario.yaml", d)
    k = np.arange(58_593_750, 58_593_770)          # k · 0.512 s from 3e7 s
    with open(d / "truth.csv", "w") as f:
        f.write("t_s,yaw_deg,roll_deg,pitch_deg\n")
        np.savetxt(f, np.column_stack([k * 0.512, 0 * k, 0 * k, 0 * k]), fmt="%.10g",
                   delimiter=",")
    assert "30000000.51," in (d / "truth.csv").read_text()
    assert export(d, "--format", "aem", "--what", "truth")[0] == 0
    (seg,) = aem.read_aem(d / "truth.aem")
    assert np.array_equal(seg.epochs, np.datetime64("2026-03-20T12:00:00", "ns")
                          + (k * 512_000_000).astype("timedelta64[ns]"))


def test_a_monte_carlo_case_is_exported_with_the_scenario_it_flew(run, d):
    """A `run --montecarlo-case` directory: case_scenario.yaml's epoch (dispersed a day
    here) dates the rows and sets the Earth's angle, not the nominal scenario.yaml."""
    text = (run / "scenario.yaml").read_text()
    assert "epoch_utc: '2026-03-20T12:00:00Z'" in text
    (d / "case_scenario.yaml").write_text(text.replace("2026-03-20T12:00:00Z",
                                                       "2026-03-21T12:00:00Z"))
    assert export(d, "--format", "aem", "--what", "truth")[0] == 0
    (seg,) = aem.read_aem(d / "truth.aem")
    assert seg.epochs[0] == np.datetime64("2026-03-21T12:00:00")
    t, yaw, roll, pitch = csv_angles(run / "truth.csv")
    case_epoch = datetime(2026, 3, 21, 12, tzinfo=UTC)
    expected = inertial_quaternions(t, roll, pitch, yaw, GeoOrbit(), case_epoch)
    assert same(seg.quaternions, expected) < READ
    assert "case_scenario.yaml: goes_next_equinox" in (d / "truth.aem").read_text()


# --- the APM -------------------------------------------------------------------------

# 8 equispaced rows: Lagrange's weights sum to at most 6.93 (near a segment's end), so the
# rows' printed 5e-13 makes 3.5e-12; with the APM's own 5e-13, doubled by renormalising.
APM_READ = 1e-11


def lagrange_of_rows(path: Path, at_s: float) -> np.ndarray:
    """What the APM between rows is (docs/outputs.md), computed here: scipy's Lagrange
    (``BarycentricInterpolator``) of degree 7 on the components of the AEM's 8 printed
    rows nearest ``at_s`` (s after EPOCH) in the segment of the row before it
    (segments split where rows are over 1.5 cadences apart), normalised."""
    t, q = rows_of(path)
    cut = np.r_[0, np.flatnonzero(np.diff(t) > 1.5 * 64.0) + 1, len(t)]
    k = np.searchsorted(cut, np.searchsorted(t, at_s, "right") - 1, "right") - 1
    t, q = t[cut[k]:cut[k + 1]], q[cut[k]:cut[k + 1]]
    near = np.sort(np.argsort(np.abs(t - at_s))[:8])
    out = BarycentricInterpolator(t[near] - at_s, q[near])(0.0)
    return out / np.linalg.norm(out)


def test_the_apm_at_a_row_is_the_row_and_between_rows_the_aems_interpolation(run, d):
    """At a row the row's attitude; between rows the degree-7 Lagrange of the AEM's
    rows (``lagrange_of_rows``, to ``APM_READ``).  (scipy's Slerp of the two rows
    around is no sharper reference: the estimate's rows turn by up to 1.5e-3 rad more
    from one step to the next, and Lagrange and slerp part by up to 3e-4 rad.)"""
    t, yaw, roll, pitch = csv_angles(run / "estimate.csv")
    rc, out, err = export(d, "--format", "apm", "--at", "3200")   # row 50
    assert rc == 0 and "at 2026-03-20T12:53:20.000000 UTC" in out, err
    apm = aem.read_apm(d / "estimate.apm")
    assert apm.epochs[0] == np.datetime64("2026-03-20T12:53:20")
    expected = inertial_quaternions(t[50:51], roll[50:51], pitch[50:51], yaw[50:51],
                                    GeoOrbit(), EPOCH)
    assert same(apm.quaternions, expected) < READ
    # Between rows, as an AEM reader interpolates the AEM of the same run.
    assert export(d, "--format", "aem")[0] == 0
    for at, when, at_s in (("2026-03-20T13:00:00.250Z", "2026-03-20T13:00:00.250", 3600.25),
                           ("2026-03-20T14:00:30+01:00", "2026-03-20T13:00:30", 3630.0),
                           ("10.5", "2026-03-20T12:00:10.500", 10.5)):   # near the first row
        rc, out, err = export(d, "--format", "apm", "--at", at, "--out", d / "x.apm",
                              "--force")
        assert rc == 0, err
        apm = aem.read_apm(d / "x.apm")
        assert apm.epochs[0] == np.datetime64(when)
        assert same(apm.quaternions, lagrange_of_rows(d / "estimate.aem", at_s)[None]) \
            < APM_READ


def test_the_apm_is_not_interpolated_across_a_dropout(d):
    """Beside a dropout the APM interpolates the segment it is in (``lagrange_of_rows``
    on that segment's rows), as the AEM's reader does (inside the dropout there is no
    attitude: test_bad_input)."""
    blank_and_cut(d)
    assert export(d, "--format", "aem")[0] == 0
    for at in (39 * 64.0 - 20, 42 * 64.0 + 20, 99 * 64.0 - 1, 110 * 64.0 + 1):
        assert export(d, "--format", "apm", "--at", at)[0] == 0
        apm = aem.read_apm(d / "estimate.apm")
        assert same(apm.quaternions, lagrange_of_rows(d / "estimate.aem", at)[None]) \
            < APM_READ


# --- --truth ---------------------------------------------------------------------------

def test_the_truth_against_itself_is_zero_and_the_estimate_against_it_its_error(run, d):
    assert export(d, "--format", "aem", "--what", "truth", "--frame", "orbit")[0] == 0
    rc, out, err = export(d, "--format", "aem", "--what", "truth", "--truth",
                          d / "truth.aem", "--out", d / "again.aem")
    assert rc == 0, err
    assert "169 of 169 exported epochs inside its 1 segment" in out
    angle_rms = float(out.split("rotation angle: RMS ")[1].split()[0])
    assert angle_rms < 1e-9
    # The estimate against the truth: dynprop's own errors, from the CSVs.
    from dynprop import export as api_export
    r = api_export(d, truth=d / "truth.aem", out=d / "e.aem")
    t, *est = csv_angles(run / "estimate.csv")
    _, *tru = csv_angles(run / "truth.csv")
    c = r.comparison
    for k, axis in ((1, "roll"), (2, "pitch"), (0, "yaw")):
        e = np.rad2deg(est[k] - tru[k])
        assert c[f"{axis}_deg"]["rms"] == pytest.approx(np.sqrt(np.mean(e**2)), abs=1e-9)
        assert c[f"{axis}_deg"]["mean"] == pytest.approx(e.mean(), abs=1e-9)
        assert c[f"{axis}_deg"]["max_abs"] == pytest.approx(np.abs(e).max(), abs=1e-9)
    m = matrix(*est) @ np.swapaxes(matrix(*tru), -1, -2)
    rotation = np.rad2deg(np.arccos(np.clip((np.trace(m, axis1=1, axis2=2) - 1) / 2, -1, 1)))
    assert c["angle_rms_deg"] == pytest.approx(np.sqrt(np.mean(rotation**2)), rel=1e-6)
    assert c["angle_max_deg"] == pytest.approx(rotation.max(), rel=1e-6)
    assert c["angle_max_t_s"] == t[np.argmax(rotation)]
    assert c["yaw_deg"]["rms"] > 1e-3       # the estimate is not the truth
    # The same against the truth in EME2000: the frame is converted, the figures stay.
    assert export(d, "--format", "aem", "--what", "truth", "--out", d / "tj.aem")[0] == 0
    again = api_export(d, truth=d / "tj.aem", out=d / "e2.aem").comparison
    assert again["frame"] == "EME2000" and c["frame"] == "LVLH_ROTATING"
    for axis in ("roll", "pitch", "yaw"):
        assert again[f"{axis}_deg"]["rms"] == pytest.approx(c[f"{axis}_deg"]["rms"], abs=1e-9)
    # An APM is compared at its one time.
    r = api_export(d, format="apm", at=3200, truth=d / "truth.aem", out=d / "e.apm")
    assert r.comparison["compared"] == 1
    assert r.comparison["yaw_deg"]["mean"] == pytest.approx(np.rad2deg(est[0] - tru[0])[50],
                                                            abs=1e-9)


# --- read_truth_aem ---------------------------------------------------------------------

@pytest.mark.parametrize("frame", ["inertial", "orbit"])
def test_read_truth_aem_gives_truth_csvs_angles_at_its_rows(run, d, frame):
    assert export(d, "--format", "aem", "--what", "truth", "--frame", frame)[0] == 0
    s = load_scenario(run / "scenario.yaml")
    grid = np.arange(round(DURATION / 0.512)) * 0.512
    got = read_truth_aem(d / "truth.aem", s, grid)
    t, yaw, roll, pitch = csv_angles(run / "truth.csv")
    assert np.array_equal(got.rows, np.round(t / 0.512).astype(int))
    assert np.array_equal(got.t_s, t) and got.interpolated == 0 and got.file_rows == 169
    worst = np.abs(got.euler_rad - np.column_stack([yaw, roll, pitch])).max()
    assert np.rad2deg(worst) < 1e-9
    assert np.isnan(got.w_br_radps).all() and np.isnan(got.h_Nms).all() and got.torques == {}
    assert got.frame == {"inertial": "EME2000", "orbit": "LVLH_ROTATING"}[frame]


def test_read_truth_aem_interpolates_another_tools_epochs_inside_its_segments(tmp_path):
    """An AEM every 20 s off the 0.512 s grid, with a dropout: read at every grid sample
    inside a segment (none in the dropout), against the attitude it was written from."""
    s = load_scenario("goes_next_equinox")
    t = np.arange(0.05, 1200.0, 20.0)
    t = t[(t < 500) | (t > 620)]
    roll, pitch, yaw = angles(t)
    aem.write_aem(tmp_path / "other.aem", t, inertial_quaternions(t, roll, pitch, yaw,
                                                                  GeoOrbit(), EPOCH),
                  AemMeta("X", "Y"), epoch=EPOCH, cadence_s=20.0)
    grid = np.arange(0.0, 1200.0, 0.512)
    got = read_truth_aem(tmp_path / "other.aem", s, grid)
    inside = ((grid >= 0.05) & (grid <= 480.05)) | ((grid >= 620.05) & (grid <= 1180.05))
    assert np.array_equal(got.rows, np.flatnonzero(inside))
    assert got.interpolated == len(got.rows)
    r, p, y = angles(grid[inside])
    assert np.abs(got.euler_rad - np.column_stack([y, r, p])).max() < 2e-11
    # Off the grid (on_grid False): at the telemetry's own times.
    times = np.array([0.0, 100.3, 550.0, 1100.0, 1190.0])
    got = read_truth_aem(tmp_path / "other.aem", s, times, on_grid=False)
    assert list(got.rows) == [1, 3] and got.t_s.tolist() == [100.3, 1100.0]


@pytest.mark.parametrize("label", ["J2000", "ICRF", "GCRF"])
def test_read_truth_aem_takes_j2000_icrf_gcrf_as_eme2000_to_the_frame_bias(tmp_path, label):
    """One attitude written twice, C_{B←EME2000} and C_{B←label} (GCRF, ICRF: through the
    IERS frame bias B, test_aem.frame_bias, which Orekit's GCRF confirms; J2000 is
    EME2000), read back on the grid: the label's orbit-frame angles are the EME2000
    file's and those written, to the frame bias dynprop leaves out (aem.INERTIAL_FRAMES).
    The rotation between the two readings is B conjugated: its angle at most B's
    (1.1222e-7 rad; 0 for J2000) and the printing, ≤ 2e-12 a file (2|Δq|, |Δq| ≤ 1e-12); each
    3-1-2 angle within 1% more (their Jacobian at ≤ 5e-3 rad).  Read as the orbit frame
    instead, the file is off by radians."""
    s = load_scenario("goes_next_equinox")
    t = np.arange(0.0, 86400.0, 640.0)            # on the 0.512 s grid: rows, no interpolation
    roll, pitch, yaw = angles(t)
    q = inertial_quaternions(t, roll, pitch, yaw, GeoOrbit(), EPOCH)
    grid = np.arange(0.0, 86400.0, 0.512)
    got = {}
    for name, rows in (("EME2000", q), (label, in_frame_bias_frame(q, label))):
        path = tmp_path / f"{name}.aem"
        aem.write_aem(path, t, rows, AemMeta("X", "Y"), epoch=EPOCH, cadence_s=640.0)
        edit(path, "REF_FRAME_A = EME2000", f"REF_FRAME_A = {name}")
        got[name] = read_truth_aem(path, s, grid)
        assert got[name].frame == name and got[name].interpolated == 0
        assert np.array_equal(got[name].t_s, t)
    bias = 0.0 if label == "J2000" else Rotation.from_matrix(frame_bias()).magnitude()
    written = np.column_stack([yaw, roll, pitch])
    assert np.abs(got["EME2000"].euler_rad - written).max() < 1e-11
    for reference in (got["EME2000"].euler_rad, written):
        worst = np.abs(got[label].euler_rad - reference).max()
        assert worst <= 1.01 * bias + 1e-11, f"{worst:.3g} rad"
    c = [matrix(*got[k].euler_rad.T) for k in (label, "EME2000")]
    rotation = Rotation.from_matrix(c[0] @ np.swapaxes(c[1], -1, -2)).magnitude()
    assert rotation.max() < bias + 4e-12


def test_read_truth_aem_says_what_is_wrong_in_one_line(tmp_path, run, d):
    s = load_scenario(run / "scenario.yaml")
    assert export(d, "--format", "aem", "--what", "truth")[0] == 0
    text = (d / "truth.aem").read_text()
    (tmp_path / "bad.aem").write_text(text.replace("REF_FRAME_A = EME2000", "REF_FRAME_A = TOD"))
    with pytest.raises(AemError, match=r"bad.aem:\d+: REF_FRAME_A = TOD is not a frame"):
        read_truth_aem(tmp_path / "bad.aem", s, np.arange(100) * 0.512)
    with pytest.raises(RunDirError, match="covers a time of the filter's grid") as e:
        read_truth_aem(d / "truth.aem", s, 20_000 + np.arange(100) * 0.512)
    assert "\n" not in str(e.value)


# --- bad input ----------------------------------------------------------------------------

def edit(path: Path, old: str, new: str) -> None:
    text = path.read_text()
    assert old in text
    path.write_text(text.replace(old, new, 1))


def truth_aem_with(d: Path, old: str, new: str) -> Path:
    assert export(d, "--format", "aem", "--what", "truth", "--out", d / "t.aem")[0] == 0
    edit(d / "t.aem", old, new)
    return d / "t.aem"


def truth_aem_moved(d: Path) -> Path:
    """The truth's AEM five days later: it covers none of the run."""
    assert export(d, "--format", "aem", "--what", "truth", "--out", d / "t.aem")[0] == 0
    (d / "t.aem").write_text((d / "t.aem").read_text().replace("2026-03-20T", "2026-03-25T"))
    return d / "t.aem"


def drop_row(d: Path) -> Path:
    assert export(d, "--format", "aem", "--what", "truth", "--out", d / "t.aem")[0] == 0
    lines = (d / "t.aem").read_text().splitlines(keepends=True)
    k = next(i for i, line in enumerate(lines) if line.startswith("2026-03-20T12:10:40"))
    (d / "t.aem").write_text("".join(lines[:k] + lines[k + 1:]))
    return d / "t.aem"


def old_estimate(d: Path) -> None:
    lines = (d / "estimate.csv").read_text().splitlines()
    k = lines[0].split(",").index("pitch_deg")
    (d / "estimate.csv").write_text("\n".join(
        ",".join(f for j, f in enumerate(line.split(",")) if j != k) for line in lines) + "\n")


BAD = {
    "no directory": (lambda d: d / "nope", (), "nope: no such directory"),
    "not a run": (lambda d: (d / "scenario.yaml").unlink() or d, (),
                  "not a run directory (no scenario.yaml)"),
    "no estimate": (lambda d: (d / "estimate.csv").unlink() or d, (),
                    "no estimate.csv (a `dynprop simulate` directory holds the truth only"),
    "no truth": (lambda d: (d / "truth.csv").unlink() or d, ("--what", "truth"),
                 "no truth.csv (`dynprop estimate` writes none"),
    "old estimate": (lambda d: old_estimate(d) or d, (),
                     "no pitch_deg column: the directory was written before dynprop "
                     "estimated pitch; rerun"),
    "bad row": (lambda d: edit(d / "estimate.csv", "\n640,", "\n640x,") or d, (),
                "estimate.csv: not a CSV of numbers"),
    "bad frame": (lambda d: d, ("--frame", "gcrf"), "argument --frame: invalid choice"),
    "at without apm": (lambda d: d, ("--at", "60"), "--at: a time is for --format apm"),
    "apm without at": (lambda d: d, ("--format", "apm"), "--format apm: give the time"),
    "rows out of order": (lambda d: edit(d / "estimate.csv", "\n640,", "\n500,") or d, (),
                          "estimate.csv: t_s 500 does not follow 576: the rows must increase"),
    "at outside": (lambda d: d, ("--format", "apm", "--at", "20000"),
                   "--at 20000 s after epoch_utc: outside the run (its last row is at 10752 s)"),
    "at before": (lambda d: d, ("--format", "apm", "--at", "2026-03-20T11:59:59Z"),
                  "--at -1 s after epoch_utc: outside the run (its first row is at 0 s)"),
    "at no zone": (lambda d: d, ("--format", "apm", "--at", "2026-03-20T13:00:00"),
                   "has no timezone"),
    "at in a dropout": (lambda d: blank_and_cut(d) or d, ("--format", "apm", "--at", "6700"),
                        "in a dropout of estimate.csv (no rows from 6336 to 7040 s)"),
    "truth frame": (lambda d: truth_aem_with(d, "REF_FRAME_A = EME2000", "REF_FRAME_A = TOD")
                    and d, ("--truth", "{d}/t.aem"), "REF_FRAME_A = TOD is not a frame"),
    "truth reversed": (lambda d: truth_aem_with(d, "REF_FRAME_B = SC_BODY_1",
                                                "REF_FRAME_B = SC_BODY_1\nATTITUDE_DIR = B2A")
                       and d, ("--truth", "{d}/t.aem"), "ATTITUDE_DIR = B2A in a 2.0 message"),
    "truth gap": (lambda d: drop_row(d) and d, ("--truth", "{d}/t.aem"),
                  "a gap of 128 s (2026-03-20T12:09:36.000000 to 2026-03-20T12:11:44.000000)"),
    "truth elsewhere": (lambda d: truth_aem_moved(d) and d,
                        ("--truth", "{d}/t.aem"), "covers an exported epoch: nothing to compare"),
    "out exists": (lambda d: (d / "mine.aem").write_text("mine") and d, ("--out", "{d}/mine.aem"),
                   "mine.aem: exists (--force replaces it)"),
}


@pytest.mark.surface
@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_input_is_one_line_exit_2_and_nothing_written(d, case):
    """Each in one line naming the file or option; no traceback; DIR/estimate.aem as it
    was (a previous export kept byte for byte), no temporary file left."""
    prepare, extra, message = BAD[case]
    (d / "estimate.aem").write_text("a previous export")
    target = prepare(d)
    before = sorted(p.name for p in d.iterdir())
    extra = [str(x).format(d=d) for x in extra]
    fmt = [] if "--format" in extra else ["--format", "aem"]
    rc, out, err = export(target, *fmt, *extra)
    assert rc == 2 and not out
    assert err.count("\n") == 1 and err.startswith("dynprop: error: "), err
    assert message in err and "Traceback" not in err
    assert (d / "estimate.aem").read_text() == "a previous export"
    if d.is_dir():
        assert sorted(p.name for p in d.iterdir()) == before


@pytest.mark.surface
def test_a_second_export_replaces_its_own_file_and_force_an_out(d):
    (d / "estimate.aem").write_text("an old export")
    assert export(d, "--format", "aem")[0] == 0
    assert (d / "estimate.aem").read_text().startswith("CCSDS_AEM_VERS = 2.0")
    (d / "mine.aem").write_text("mine")
    rc, out, _ = export(d, "--format", "aem", "--out", d / "mine.aem", "--force",
                        "--object-id", "2016-071A")
    assert rc == 0 and "OBJECT_ID = 2016-071A" in (d / "mine.aem").read_text()
    umask = os.umask(0)
    os.umask(umask)
    assert (d / "mine.aem").stat().st_mode & 0o777 == 0o666 & ~umask   # not mkstemp's 0600


def test_a_bad_row_half_way_leaves_the_previous_export(d, monkeypatch):
    """Blocks of 7 rows: the first blocks are written (to the temporary file) before row
    120's bad number is read; the previous DIR/estimate.aem stays as it was."""
    assert export(d, "--format", "aem")[0] == 0
    previous = (d / "estimate.aem").read_bytes()
    before = sorted(p.name for p in d.iterdir())
    edit(d / "estimate.csv", "\n7680,", "\n7680x,")
    monkeypatch.setattr(export_source, "BLOCK_ROWS", 7)
    rc, out, err = export(d, "--format", "aem")
    assert rc == 2 and err.count("\n") == 1 and "estimate.csv: not a CSV of numbers" in err
    assert (d / "estimate.aem").read_bytes() == previous
    assert sorted(p.name for p in d.iterdir()) == before


def test_the_printed_comparison_names_its_figures(d):
    assert export(d, "--format", "aem", "--what", "truth")[0] == 0
    rc, out, err = export(d, "--format", "aem", "--truth", d / "truth.aem")
    assert rc == 0, err
    lines = io.StringIO(out).read().splitlines()
    assert lines[1].startswith(f"compared with {d / 'truth.aem'} (EME2000; 169 of 169")
    assert lines[2].startswith("  rotation angle: RMS ")
    assert [line.split(":")[0].strip() for line in lines[3:]] == ["roll", "pitch", "yaw"]


def test_the_default_exports_are_dynprops_own_files_and_other_aems_the_users(d):
    """`--force` replaces a run directory holding DIR/estimate.aem (dynprop's), not one
    holding another tool's AEM kept there for --truth."""
    from scenarios.files.rundir import foreign_files
    for name in ("estimate.aem", "truth.aem", "estimate.apm", "truth.apm",
                 ".estimate.aem.ab12cd_z"):
        (d / name).write_text("x")
    assert foreign_files(d) == []
    (d / "other_tool.aem").write_text("x")
    assert foreign_files(d) == ["other_tool.aem"]
