"""CCSDS AEM/APM (scenarios/files/aem.py): the round trip, segments at dropouts,
streaming at bounded memory, every bad input with its one-line message naming the
line, and the inertial quaternion checked against an independent Earth-nadir
direction.

No astropy or skyfield in the environment: the independent nadir comes from
formulas written out here from their publications, not from the code under test:
GMST in Meeus's degree form of IAU 1982 (*Astronomical Algorithms*, 2nd ed., Eq. 12.4;
the code uses Vallado's seconds form) and the IAU 1976 precession applied by Meeus's
rigorous spherical formulas (Eq. 21.4; the code builds a matrix), itself checked on
Meeus's Example 21.b.
"""

from __future__ import annotations

import tracemalloc
from datetime import UTC, datetime

import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

from scenarios.files import aem
from scenarios.files.aem import AemError, AemMeta
from sim.frames import GeoOrbit, quat_multiply
from sim.inertial import inertial_quaternions, orbit_frame_quaternions

EPOCH = datetime(2026, 3, 20, 12, tzinfo=UTC)
META = AemMeta("GOES-NEXT", "2026-000A")
PRINTED = 5e-13            # 12 decimals
READ = 3 * PRINTED         # after the reader's renormalisation (|Δ| ≤ 5e-13 + |Δnorm|)


def angles(t):
    """A smooth attitude (rad): what an estimate looks like at the output cadence."""
    return (3e-3 * np.sin(t / 5000.0), -2e-3 * np.cos(t / 7000.0), 5e-3 * np.sin(t / 9000.0))


def run(t):
    roll, pitch, yaw = angles(t)
    return inertial_quaternions(t, roll, pitch, yaw, GeoOrbit(), EPOCH)


def same_rotation(a, b):
    """Largest component difference, q and −q being one attitude."""
    return np.minimum(np.abs(a - b).max(axis=1), np.abs(a + b).max(axis=1)).max()


def grid():
    """Two days at 64 s with two dropouts (one of 10 rows, one of NaN rows)."""
    t = np.arange(0.0, 2 * 86400 + 1, 64.0)
    return t[(t < 20_000) | (t > 20_640)]


def written(tmp_path, name="a.aem", **kw):
    t = grid()
    q = run(t)
    q[1500:1504] = np.nan
    path = tmp_path / name
    aem.write_aem(path, t, q, kw.pop("meta", META), epoch=EPOCH, cadence_s=64.0,
                  creation_date="2026-07-01T00:00:00", **kw)
    return path, t, q


def test_round_trip_to_the_printed_precision_with_a_segment_per_stretch(tmp_path):
    path, t, q = written(tmp_path)
    segments = aem.read_aem(path)
    keep = np.isfinite(q[:, 0])
    assert [len(s.epochs) for s in segments] == [313, 1500 - 313, keep.sum() - 1500]
    epochs = np.concatenate([s.seconds_since(EPOCH) for s in segments])
    assert np.array_equal(epochs, t[keep])
    assert same_rotation(np.vstack([s.quaternions for s in segments]), q[keep]) < READ
    # The file's own digits, before any renormalisation: each within half a unit of the 12th.
    rows = [line.split() for line in path.read_text().splitlines()
            if line[:4] == "2026" and len(line.split()) == 5]
    printed = np.array([[float(x) for x in r[1:]] for r in rows])
    assert same_rotation(printed, q[keep]) <= PRINTED * 1.0001
    s = segments[1]
    assert s.frame == "EME2000" and s.body == "SC_BODY_1"
    assert s.meta["START_TIME"] == "2026-03-20T17:44:32.000000"
    assert s.meta["INTERPOLATION_DEGREE"] == "7" and s.header["CCSDS_AEM_VERS"] == "2.0"
    assert "ATTITUDE_DIR" not in s.meta and "QUATERNION_TYPE" not in s.meta  # fixed in 2.0
    text = path.read_text()
    assert text.count("META_START") == 3 and "COMMENT after a dropout of 704 s" in text
    assert "scalar last" in text and "Eq. 2.125" in text


def test_version_1_states_the_convention_and_reads_back(tmp_path):
    path, t, q = written(tmp_path, meta=AemMeta("GOES-NEXT", "2026-000A", version="1.0"))
    text = path.read_text()
    assert "ATTITUDE_DIR = A2B" in text and "QUATERNION_TYPE = LAST" in text
    keep = np.isfinite(q[:, 0])
    got = np.vstack([s.quaternions for s in aem.read_aem(path)])
    assert same_rotation(got, q[keep]) < READ


def test_streamed_blocks_write_the_same_bytes_at_bounded_memory(tmp_path, monkeypatch):
    path, t, q = written(tmp_path)
    blocks = ((t[k:k + 97], q[k:k + 97]) for k in range(0, len(t), 97))
    aem.write_aem_blocks(tmp_path / "b.aem", blocks, META, epoch=EPOCH, cadence_s=64.0,
                         creation_date="2026-07-01T00:00:00")
    assert (tmp_path / "b.aem").read_bytes() == path.read_bytes()
    # 40 000 rows (3.6 MB of text) in blocks of 1000, the spool held to 128 kB: memory
    # is a block and the spool, not the file.
    monkeypatch.setattr(aem, "SPOOL_BYTES", 1 << 17)
    n, size = 40_000, 1000
    q0 = run(np.arange(size) * 64.0)
    tracemalloc.start()
    aem.write_aem_blocks(tmp_path / "big.aem", ((np.arange(k, k + size) * 64.0, q0)
                                                for k in range(0, n, size)), META, epoch=EPOCH)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert (tmp_path / "big.aem").stat().st_size > 3.5e6
    assert peak < 1.5e6, f"peak {peak / 1e6:.2f} MB"


def test_interpolation_between_rows_follows_the_attitude(tmp_path):
    path, _, _ = written(tmp_path)
    segment = aem.read_aem(path)[2]
    t = np.random.default_rng(1).uniform(*segment.seconds_since(EPOCH)[[0, -1]], 200)
    got = segment.interpolate(np.datetime64("2026-03-20T12:00:00")
                              + np.round(t * 1e9).astype("timedelta64[ns]"))
    assert same_rotation(got, run(t)) < 1e-11


def test_interpolation_across_another_tools_sign_flip_is_the_slerp(tmp_path):
    """Another tool's AEM need not keep q's sign from row to row (q and −q are one
    attitude); many print QC ≥ 0, so q flips where the rotation angle crosses 180°.  The
    attitude here turns at a constant rate about a fixed axis (a nadir pointer seen
    from EME2000, once a sidereal day), which scipy's Slerp of the printed rows follows
    exactly; the reader's Lagrange must give it on every interval whose 8-row window
    holds the flip.  3e-12: the rows' printed 5e-13 through Lagrange's weights (Σ|w| < 2
    on these central intervals) and the slerp, renormalised; Lagrange's own truncation
    for 0.0047 rad a row is ~1e-24.  Taking the flipped rows as they are is off by ~1."""
    axis = np.array([0.2, -0.3, 1.0]) / np.linalg.norm([0.2, -0.3, 1.0])
    t = np.arange(0.0, 86400.0 + 1, 64.0)
    half = np.pi / 86164.1 * t
    path = tmp_path / "flips.aem"
    aem.write_aem(path, t, np.column_stack([np.sin(half)[:, None] * axis, np.cos(half)]),
                  META, epoch=EPOCH, cadence_s=64.0)
    lines = []
    for line in path.read_text().splitlines():
        f = line.split()
        if len(f) == 5 and line[:4] == "2026" and float(f[4]) < 0:
            line = f[0] + "".join(f" {-float(x):.12f}" for x in f[1:])
        lines.append(line)
    path.write_text("\n".join(lines) + "\n")
    rows = np.array([[float(x) for x in line.split()[1:]] for line in lines
                     if line[:4] == "2026" and len(line.split()) == 5])
    flips = np.flatnonzero(np.einsum("ij,ij->i", rows[1:], rows[:-1]) < 0)
    assert len(flips) == 1          # at 43082 s, between rows 673 and 674
    (segment,) = aem.read_aem(path)
    k = flips[0]
    at = (np.arange(k - 8, k + 9)[:, None] + [0.1, 0.5, 0.9]).ravel() * 64.0
    got = segment.interpolate(np.datetime64("2026-03-20T12:00:00")
                              + np.round(at * 1e9).astype("timedelta64[ns]"))
    expected = Slerp(t, Rotation.from_quat(rows))(at).as_quat()
    assert same_rotation(got, expected) < 3e-12


def edit(path, old, new, count=1):
    text = path.read_text()
    assert old in text
    path.write_text(text.replace(old, new, count))
    return path


def line_of(path, needle):
    return next(k for k, line in enumerate(path.read_text().splitlines(), 1) if needle in line)


def drop_rows(path, first, n):
    lines = path.read_text().splitlines(keepends=True)
    start = lines.index("DATA_START\n") + 1 + first
    path.write_text("".join(lines[:start] + lines[start + n:]))
    return path


def first_row(path):
    return next(line for line in path.read_text().splitlines() if line.startswith("2026-"))


def change_row(path, fields):
    row = first_row(path)
    return edit(path, row, fields(row.split()))


@pytest.mark.parametrize("case, change, message, needle", [
    ("unknown frame", lambda p: edit(p, "REF_FRAME_A = EME2000", "REF_FRAME_A = EME2001"),
     "REF_FRAME_A = EME2001 is not a frame dynprop reads", "EME2001"),
    ("reversed quaternion flag", lambda p: edit(
        p, "ATTITUDE_TYPE = QUATERNION", "ATTITUDE_TYPE = QUATERNION\nQUATERNION_TYPE = FIRST"),
     "QUATERNION_TYPE = FIRST in a 2.0 message", "QUATERNION_TYPE"),
    ("reversed direction flag", lambda p: edit(
        p, "TIME_SYSTEM = UTC", "ATTITUDE_DIR = B2A\nTIME_SYSTEM = UTC"),
     "ATTITUDE_DIR = B2A in a 2.0 message", "ATTITUDE_DIR"),
    ("unknown flag value", lambda p: edit(
        p, "TIME_SYSTEM = UTC", "ATTITUDE_DIR = SIDEWAYS\nTIME_SYSTEM = UTC"),
     "ATTITUDE_DIR = SIDEWAYS is neither A2B nor B2A", "ATTITUDE_DIR"),
    ("gap inside a segment", lambda p: drop_rows(p, 20, 10),
     "a gap of 704 s (2026-03-20T12:20:16.000000 to 2026-03-20T12:32:00.000000) inside the "
     "segment of line", "2026-03-20T12:32:00.000000 "),
    ("non-unit quaternion", lambda p: change_row(p, lambda f: " ".join(f[:4] + ["0.9"])),
     "quaternion norm 1.1", "2026-03-20T12:00:00.000000 "),
    ("epochs not increasing", lambda p: edit(
        p, "2026-03-20T12:01:04.000000", "2026-03-20T11:59:04.000000"),
     "is not after 2026-03-20T12:00:00.000000", "2026-03-20T11:59:04"),
    ("missing mandatory key", lambda p: edit(p, "OBJECT_ID = 2026-000A\n", ""),
     "the metadata have no OBJECT_ID", "OBJECT_NAME"),
    ("malformed row", lambda p: change_row(p, lambda f: " ".join(f[:4])),
     "expected an epoch and 4 numbers", "2026-03-20T12:00:00.000000 "),
    ("not a number", lambda p: change_row(p, lambda f: " ".join([f[0], "0.1x"] + f[2:])),
     "'0.1x' is not a number", "2026-03-20T12:00:00.000000 "),
    ("Euler angles", lambda p: edit(p, "ATTITUDE_TYPE = QUATERNION", "ATTITUDE_TYPE = EULER_ANGLE"),
     "dynprop reads quaternions only", "EULER_ANGLE"),
    ("time system", lambda p: edit(p, "TIME_SYSTEM = UTC", "TIME_SYSTEM = TAI"),
     "TIME_SYSTEM = TAI: dynprop reads UTC only", "TAI"),
    ("no DATA_STOP", lambda p: edit(p, "DATA_STOP\n", ""),
     "ends inside the data section", None),
])
def test_bad_input_is_one_line_naming_the_line(tmp_path, case, change, message, needle):
    path = tmp_path / "bad.aem"
    t = np.arange(0.0, 3600.0, 64.0)
    aem.write_aem(path, t, run(t), META, epoch=EPOCH, cadence_s=64.0)
    change(path)
    with pytest.raises(AemError) as err:
        aem.read_aem(path)
    text = str(err.value)
    assert message in text and "\n" not in text, (case, text)
    if needle is not None:
        assert text.startswith(f"{path}:{line_of(path, needle)}:"), (case, text)


def test_the_1_0_convention_flags_are_converted(tmp_path):
    t = np.arange(0.0, 3600.0, 64.0)
    q = run(t)
    path = tmp_path / "v1.aem"
    meta = AemMeta("GOES-NEXT", "2026-000A", version="1.0")
    aem.write_aem(path, t, q, meta, epoch=EPOCH)
    # Scalar first: every row rewritten QC Q1 Q2 Q3.
    lines = []
    for line in path.read_text().splitlines():
        f = line.split()
        lines.append(" ".join([f[0], f[4], *f[1:4]]) if len(f) == 5 and line[:2] == "20"
                     else line)
    first = tmp_path / "first.aem"
    first.write_text("\n".join(lines).replace("QUATERNION_TYPE = LAST", "QUATERNION_TYPE = FIRST"))
    # B2A with the data conjugated, and the frames swapped (A = body) with the data conjugated.
    conj = q * [-1, -1, -1, 1]
    for name, change in (("b2a", {"ATTITUDE_DIR = A2B": "ATTITUDE_DIR = B2A"}),
                         ("swapped", {"REF_FRAME_A = EME2000": "REF_FRAME_A = SC_BODY_1",
                                      "REF_FRAME_B = SC_BODY_1": "REF_FRAME_B = EME2000"})):
        aem.write_aem(tmp_path / f"{name}.aem", t, conj, meta, epoch=EPOCH)
        for old, new in change.items():
            edit(tmp_path / f"{name}.aem", old, new)
    for name in ("first", "b2a", "swapped"):
        (segment,) = aem.read_aem(tmp_path / f"{name}.aem")
        assert segment.frame == "EME2000" and segment.body == "SC_BODY_1"
        assert same_rotation(segment.quaternions, q) < READ, name


def test_apm_round_trip(tmp_path):
    q = run(np.array([100.0]))[0]
    aem.write_apm(tmp_path / "a.apm", "2026-03-20T12:01:40Z", q, META)
    text = (tmp_path / "a.apm").read_text()
    assert "CCSDS_APM_VERS = 2.0" in text and "QUAT_START" in text and f"QC = {q[3]:.12f}" in text
    got = aem.read_apm(tmp_path / "a.apm")
    assert got.epochs[0] == np.datetime64("2026-03-20T12:01:40")
    assert got.frame == "EME2000" and same_rotation(got.quaternions, q[None]) < READ
    edit(tmp_path / "a.apm", "REF_FRAME_A = EME2000", "REF_FRAME_A = TOD")
    with pytest.raises(AemError, match="REF_FRAME_A = TOD is not a frame"):
        aem.read_apm(tmp_path / "a.apm")


# --- the inertial quaternion against an independent nadir ---------------------------

def gmst_meeus_rad(jd):
    """IAU 1982 GMST in Meeus's form (Eq. 12.4), degrees."""
    t = (jd - 2451545.0) / 36525.0
    deg = 280.46061837 + 360.98564736629 * (jd - 2451545.0) + 0.000387933 * t * t \
        - t**3 / 38710000.0
    return np.deg2rad(deg % 360.0)


def precess_to_date(v, jd):
    """J2000 → mean equator and equinox of date, Meeus Eq. 21.4 with Lieske's angles."""
    t = (jd - 2451545.0) / 36525.0
    zeta, z, theta = (np.deg2rad(c / 3600.0) for c in (
        (2306.2181 + (0.30188 + 0.017998 * t) * t) * t,
        (2306.2181 + (1.09468 + 0.018203 * t) * t) * t,
        (2004.3109 - (0.42665 + 0.041833 * t) * t) * t))
    a0, d0 = np.arctan2(v[..., 1], v[..., 0]), np.arcsin(np.clip(v[..., 2], -1, 1))
    a = np.cos(d0) * np.sin(a0 + zeta)
    b = np.cos(theta) * np.cos(d0) * np.cos(a0 + zeta) - np.sin(theta) * np.sin(d0)
    c = np.sin(theta) * np.cos(d0) * np.cos(a0 + zeta) + np.cos(theta) * np.sin(d0)
    alpha, delta = np.arctan2(a, b) + z, np.arcsin(c)
    return np.stack([np.cos(delta) * np.cos(alpha), np.cos(delta) * np.sin(alpha),
                     np.sin(delta)], axis=-1)


def frame_bias():
    """B = R1(−η0) R2(ξ0) R3(dα0): GCRS (ICRS axes: GCRF, ICRF) to the mean equator and
    equinox of J2000 (EME2000), v_EME2000 = B v_GCRF, with the IAU 2000 offsets
    ξ0 = −16.617, η0 = −6.8192, dα0 = −14.6 mas (IERS Conventions 2003, Ch. 5; ERFA's
    eraBp00 builds it so).  R_i are frame rotations.  Its angle is 1.122e-7 rad; Orekit's
    GCRF → EME2000 is this to 7e-13 (orekit_checks)."""
    def r(axis, a):
        c, s = np.cos(a), np.sin(a)
        m = np.eye(3)
        i, j = [(1, 2), (2, 0), (0, 1)][axis]
        m[i, i] = m[j, j] = c
        m[i, j], m[j, i] = s, -s
        return m
    xi0, eta0, da0 = np.deg2rad(np.array([-16.617, -6.8192, -14.6]) / 3.6e6)
    return r(0, -eta0) @ r(1, xi0) @ r(2, da0)


def in_frame_bias_frame(q_eme2000, label):
    """C_{B←label} from C_{B←EME2000} (scalar last): GCRF and ICRF (the same axes, the
    ICRS's) are C_{B←EME2000} · B; J2000 is EME2000 itself (CCSDS; Orekit maps it so).
    Through scipy: its Rotation's matrix is Markley's A(q) transposed."""
    if label == "J2000":
        return np.array(q_eme2000, dtype=float)
    return (Rotation.from_matrix(frame_bias().T) * Rotation.from_quat(q_eme2000)).as_quat()


def test_meeus_precession_reproduces_example_21b():
    v = np.array([np.cos(np.deg2rad(49.227750)) * np.cos(np.deg2rad(41.054063)),
                  np.cos(np.deg2rad(49.227750)) * np.sin(np.deg2rad(41.054063)),
                  np.sin(np.deg2rad(49.227750))])
    out = precess_to_date(v, 2462088.69)
    assert np.rad2deg(np.arctan2(out[1], out[0])) == pytest.approx(41.547214, abs=2e-6)
    assert np.rad2deg(np.arcsin(out[2])) == pytest.approx(49.348483, abs=2e-6)


def body_axes(q):
    """Rows of A(q) (Markley Eq. 2.125): the body axes in the reference frame."""
    q1, q2, q3, q4 = q.T
    return np.stack([
        np.stack([q1*q1 - q2*q2 - q3*q3 + q4*q4, 2*(q1*q2 + q3*q4), 2*(q1*q3 - q2*q4)], -1),
        np.stack([2*(q1*q2 - q3*q4), -q1*q1 + q2*q2 - q3*q3 + q4*q4, 2*(q2*q3 + q1*q4)], -1),
        np.stack([2*(q1*q3 + q2*q4), 2*(q2*q3 - q1*q4), -q1*q1 - q2*q2 + q3*q3 + q4*q4], -1)],
        axis=1)


def angle(a, b):
    return np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.sum(a * b, axis=-1))


@pytest.mark.parametrize("attitude", ["zero", "moving"])
def test_inertial_quaternion_points_the_yaw_axis_at_the_independent_nadir(attitude):
    orbit = GeoOrbit(longitude_rad=np.deg2rad(-75.0))
    t = np.arange(0.0, 2 * 86400 + 1, 640.0)
    roll, pitch, yaw = angles(t) if attitude == "moving" else (0 * t, 0 * t, 0 * t)
    q = inertial_quaternions(t, roll, pitch, yaw, orbit, EPOCH)
    jd = 2451545.0 + ((EPOCH - datetime(2000, 1, 1, 12, tzinfo=UTC)).total_seconds() + t) / 86400
    alpha = gmst_meeus_rad(jd) + orbit.longitude_rad
    nadir = -np.stack([np.cos(alpha), np.sin(alpha), 0 * alpha], axis=-1)    # mean of date
    south = np.array([0.0, 0.0, -1.0])
    axes_j2000 = body_axes(q)
    axes = precess_to_date(axes_j2000, jd[:, None])                        # (N, 3 axes, 3)
    in_body = np.einsum("nij,nj->ni", axes, nadir)
    s_in_body = np.einsum("nij,j->ni", axes, south)
    # Conventions: the nadir in B is C_BR's third column, the orbit normal −z_N its second.
    sr, cr, sp, cp, sy, cy = np.sin(roll), np.cos(roll), np.sin(pitch), np.cos(pitch), \
        np.sin(yaw), np.cos(yaw)
    expected = np.stack([-sp * cr, sr, cp * cr], axis=-1)
    expected_s = np.stack([cp * sy + sp * sr * cy, cr * cy, sp * sy - cp * sr * cy], axis=-1)
    # ω0 differs from the GMST rate by 9.5e-13 rad/s: 1.6e-7 rad over the two days.
    assert angle(in_body, expected).max() < 1e-6
    assert angle(s_in_body, expected_s).max() < 1e-6
    if attitude == "zero":
        assert angle(axes[:, 2], nadir).max() < 1e-6
        # The precession since J2000 is what the export adds: ~0.3° on the nadir in 2026.
        assert 4e-3 < angle(axes_j2000[:, 2], nadir).min()


def test_orbit_frame_variant_is_q_br_and_composes_to_the_inertial(tmp_path):
    t = np.arange(0.0, 86400.0, 600.0)
    roll, pitch, yaw = angles(t)
    q_br = orbit_frame_quaternions(roll, pitch, yaw)
    a = body_axes(q_br)
    # 3e-16 measured (3 ulp); 1e-14 leaves another libm's sin/cos room, and a convention
    # error would be ~1e-3.
    assert np.allclose(a[:, :, 2], np.stack([-np.sin(pitch) * np.cos(roll), np.sin(roll),
                                          np.cos(pitch) * np.cos(roll)], -1), atol=1e-14)
    q_rj = inertial_quaternions(t, 0 * t, 0 * t, 0 * t, GeoOrbit(), EPOCH)
    assert same_rotation(quat_multiply(q_br, q_rj), run(t)) < 1e-14
    with pytest.raises(AemError, match="dynprop writes REF_FRAME_A = EME2000 or LVLH_ROTATING"):
        aem.write_aem(tmp_path / "x.aem", t, q_br, AemMeta("X", "Y", ref_frame_a="LVLH_SPINNING"))
    assert not (tmp_path / "x.aem").exists()
