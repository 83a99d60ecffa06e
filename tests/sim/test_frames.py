"""Tests for sim.frames against independent references written here in plain numpy.

References (docs/conventions.md conventions):

* Frame (passive) rotations ``R1, R2, R3`` written out element by element below.
* Attitude ``C_BR = R2(pitch) R1(roll) R3(yaw)`` (3-1-2: yaw, roll, pitch).
* Scalar-last quaternions, Markley & Crassidis (2014) Eq. 2.125:
  ``A(q) = (q4² − |qv|²) I + 2 qv qvᵀ − 2 q4 [qv×]``.
* Rodrigues for a frame rotation by θ about unit e:
  ``C = cos θ I + (1 − cos θ) e eᵀ − sin θ [e×]``.
* scipy's ``Rotation`` (active convention) is used as a second, unrelated reference:
  a frame rotation is the transpose of the active one.
"""

import numpy as np
import pytest
from hypothesis import assume, example, given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from sim.frames import (
    GEO_RADIUS_M,
    MU_EARTH_M3PS2,
    GeoOrbit,
    dcm_from_euler312,
    dcm_from_quat,
    euler312_from_dcm,
    euler312_from_quat,
    orbit_frame_dcm,
    quat_from_dcm,
    quat_from_euler312,
    quat_multiply,
    rot1,
    rot2,
    rot3,
    skew,
)

EPS = np.finfo(float).eps
HALF_PI = 0.5 * np.pi
SIDEREAL_DAY_S = 86164.0905
PROP = settings(max_examples=200, deadline=None, database=None)

# Round-off allowances (issue 12), for quantities of size ≤ 1 (direction cosines, quaternion
# and unit-vector components).  Each is a few libm calls (≤ 1 ulp on glibc; other libms and
# numpy's SIMD loops allow a few ulps) combined in a handful of products and sums, so the
# arithmetic promises ≲ 20 eps ≈ 4e-15; measured here ≤ 7 eps (1.6e-15, a determinant) over
# the hypothesis draws, with the default OpenBLAS kernel and with OPENBLAS_CORETYPE=Sandybridge.
# A convention error (sign, order, transpose, scalar-first) is O(angle) ≥ 1e-3.
ROUND_OFF = 1e-13  # ≈ 450 eps
# Round trips through two or three conversions (atan2, sqrt, Shepperd's branch choice), also
# near their singular points (gimbal lock, 180°), compared on the rebuilt O(1) matrix or
# quaternion: measured ≤ 1e-15 (4.5 eps); 1e-12 leaves three orders of magnitude.
ROUND_TRIP = 1e-12


def angle_tol(roll):
    """Allowance for the individual 3-1-2 angles of a round trip: their condition number is
    1/cos(roll) (yaw and pitch axes align at gimbal lock), measured up to 3.8e-13 rad at
    roll = 90° − 1e-3 rad via the quaternion; 256 eps / cos(roll) leaves > 100×."""
    return 256 * EPS / abs(np.cos(roll))


# --------------------------------------------------------------------------------------
# Independent references
# --------------------------------------------------------------------------------------


def r1_ref(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, s], [0.0, -s, c]])


def r2_ref(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]])


def r3_ref(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])


def skew_ref(v):
    x, y, z = v
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def c312_ref(yaw, roll, pitch):
    """Hand-written 3-1-2 product R2(pitch) R1(roll) R3(yaw)."""
    return r2_ref(pitch) @ r1_ref(roll) @ r3_ref(yaw)


def attitude_matrix_ref(q):
    """Markley & Crassidis Eq. 2.125, scalar-last, in matrix form."""
    q = np.asarray(q, dtype=float)
    qv, q4 = q[:3], q[3]
    return (q4**2 - qv @ qv) * np.eye(3) + 2.0 * np.outer(qv, qv) - 2.0 * q4 * skew_ref(qv)


def rodrigues_ref(e, theta):
    """Frame rotation by theta about the unit axis e."""
    e = np.asarray(e, dtype=float)
    return (np.cos(theta) * np.eye(3) + (1.0 - np.cos(theta)) * np.outer(e, e)
            - np.sin(theta) * skew_ref(e))


def quat_axis_angle(e, theta):
    e = np.asarray(e, dtype=float)
    return np.concatenate([e * np.sin(0.5 * theta), [np.cos(0.5 * theta)]])


def wrap(a):
    """Wrap an angle difference into [−π, π)."""
    return (np.asarray(a) + np.pi) % (2.0 * np.pi) - np.pi


def assert_rotation_matrix(c, tol=ROUND_OFF):
    np.testing.assert_allclose(c @ c.T, np.eye(3), rtol=0, atol=tol)
    assert np.linalg.det(c) == pytest.approx(1.0, abs=tol)


# --------------------------------------------------------------------------------------
# Hypothesis strategies
# --------------------------------------------------------------------------------------

angles = st.floats(-np.pi, np.pi, allow_nan=False, allow_infinity=False)
# Roll at least 1e-3 rad from gimbal lock: individual angles are then well conditioned.
safe_rolls = st.floats(-(HALF_PI - 1e-3), HALF_PI - 1e-3, allow_nan=False)
lock_offsets = st.floats(0.0, 1e-3, allow_nan=False)
signs = st.sampled_from([1.0, -1.0])


@st.composite
def unit_vectors(draw):
    v = np.array(draw(st.lists(st.floats(-1.0, 1.0, allow_nan=False), min_size=3, max_size=3)))
    n = np.linalg.norm(v)
    if n < 1e-3:
        v, n = np.array([0.0, 0.0, 1.0]), 1.0
    return v / n


@st.composite
def unit_quaternions(draw):
    q = np.array(draw(st.lists(st.floats(-1.0, 1.0, allow_nan=False), min_size=4, max_size=4)))
    n = np.linalg.norm(q)
    if n < 1e-3:
        q, n = np.array([0.0, 0.0, 0.0, 1.0]), 1.0
    return q / n


# --------------------------------------------------------------------------------------
# Elementary rotations and skew
# --------------------------------------------------------------------------------------

SAMPLE_ANGLES = [0.0, 0.3, -1.1, HALF_PI, np.pi, 2.5, -3.0, 7.0]


@pytest.mark.parametrize("angle", SAMPLE_ANGLES)
@pytest.mark.parametrize(("fn", "ref"), [(rot1, r1_ref), (rot2, r2_ref), (rot3, r3_ref)])
def test_elementary_rotations_match_hand_written(fn, ref, angle):
    m = fn(angle)
    np.testing.assert_allclose(m, ref(angle), rtol=0, atol=ROUND_OFF)
    assert_rotation_matrix(m)


def test_elementary_rotation_explicit_values():
    # R3(90°) maps the inertial x axis to body −y (frame rotation), as written in the design.
    # The zeros are cos(π/2) = 6.1e-17 in floating point, hence an atol, not equality.
    np.testing.assert_allclose(rot3(HALF_PI), [[0, 1, 0], [-1, 0, 0], [0, 0, 1]], atol=ROUND_OFF)
    np.testing.assert_allclose(rot1(HALF_PI), [[1, 0, 0], [0, 0, 1], [0, -1, 0]], atol=ROUND_OFF)
    np.testing.assert_allclose(rot2(HALF_PI), [[0, 0, -1], [0, 1, 0], [1, 0, 0]], atol=ROUND_OFF)


@pytest.mark.parametrize(("fn", "ref"), [(rot1, r1_ref), (rot2, r2_ref), (rot3, r3_ref)])
def test_elementary_rotations_broadcast(fn, ref):
    a = np.array([[0.1, -0.2, 0.3], [1.0, 2.0, -3.0]])
    m = fn(a)
    assert m.shape == (2, 3, 3, 3)
    for idx in np.ndindex(a.shape):
        np.testing.assert_allclose(m[idx], ref(a[idx]), rtol=0, atol=ROUND_OFF)


@PROP
@given(unit_vectors(), unit_vectors())
def test_skew_is_cross_product(a, b):
    """[a×] b = a × b to round-off.  Identity is the requirement for the matrix itself:
    both it and the reference only place and negate components, which is exact."""
    np.testing.assert_allclose(skew(a) @ b, np.cross(a, b), rtol=0, atol=ROUND_OFF)
    # Exact: both only place and negate the components (no arithmetic that can round).
    np.testing.assert_array_equal(skew(a), skew_ref(a))


# --------------------------------------------------------------------------------------
# 3-1-2 Euler angles
# --------------------------------------------------------------------------------------


@PROP
@given(angles, st.floats(-HALF_PI, HALF_PI), angles)
def test_dcm_from_euler312_matches_explicit_product(yaw, roll, pitch):
    c = dcm_from_euler312(yaw, roll, pitch)
    np.testing.assert_allclose(c, c312_ref(yaw, roll, pitch), rtol=0, atol=ROUND_OFF)
    assert_rotation_matrix(c)
    # Second, unrelated reference: scipy's intrinsic z-x-y (active) sequence, transposed.
    scipy_ref = Rotation.from_euler("ZXY", [yaw, roll, pitch]).as_matrix().T
    np.testing.assert_allclose(c, scipy_ref, rtol=0, atol=ROUND_OFF)


def test_dcm_from_euler312_broadcasts():
    rng = np.random.default_rng(312)
    y, r, p = rng.uniform(-1, 1, (3, 4, 5))
    c = dcm_from_euler312(y, r, p)
    assert c.shape == (4, 5, 3, 3)
    for idx in np.ndindex(4, 5):
        np.testing.assert_allclose(c[idx], c312_ref(y[idx], r[idx], p[idx]), atol=ROUND_OFF)


@pytest.mark.parametrize("scale", [1e-2, 1e-3, 1e-4, 1e-6])
def test_small_angle_dcm_is_identity_minus_skew(scale):
    """C_BR ≈ I − [ε×] with ε = (roll, pitch, yaw), error O(|ε|²)."""
    rng = np.random.default_rng(7)
    for _ in range(50):
        roll, pitch, yaw = scale * rng.uniform(-1.0, 1.0, 3)
        eps_vec = np.array([roll, pitch, yaw])
        c = dcm_from_euler312(yaw, roll, pitch)
        err = np.max(np.abs(c - (np.eye(3) - skew_ref(eps_vec))))
        # Second-order remainder: diagonal −ε²/2 terms and εi εj cross terms.
        assert err <= eps_vec @ eps_vec + 4 * EPS
        # ...and not first order: the linear model must beat |ε| by a factor ~|ε|.
        assert err <= 2.0 * np.max(np.abs(eps_vec)) ** 2 + 4 * EPS


def test_small_angle_error_is_second_order():
    e = np.array([0.7, -0.4, 0.5])
    errs = []
    for s in (1e-2, 1e-3):
        roll, pitch, yaw = s * e
        c = dcm_from_euler312(yaw, roll, pitch)
        errs.append(np.max(np.abs(c - (np.eye(3) - skew_ref(s * e)))))
    assert errs[1] / errs[0] == pytest.approx(1e-2, rel=0.05)


def test_euler312_extraction_formula_and_single_axis_cases():
    # Single-axis rotations come back on the right angle.
    for a in (0.2, -0.9, 1.4):
        np.testing.assert_allclose(euler312_from_dcm(r3_ref(a)), (a, 0, 0), atol=ROUND_OFF)
        np.testing.assert_allclose(euler312_from_dcm(r1_ref(a)), (0, a, 0), atol=ROUND_OFF)
        np.testing.assert_allclose(euler312_from_dcm(r2_ref(a)), (0, 0, a), atol=ROUND_OFF)
    # The pinned extraction formulas, evaluated by hand on a reference matrix.
    c = c312_ref(0.4, -0.3, 2.0)
    yaw, roll, pitch = euler312_from_dcm(c)
    # Roll −0.3 rad is far from lock: arcsin and atan2 agree to a few ulps.
    assert roll == pytest.approx(np.arcsin(c[1, 2]), abs=ROUND_OFF)
    assert yaw == pytest.approx(np.arctan2(-c[1, 0], c[1, 1]), abs=ROUND_OFF)
    assert pitch == pytest.approx(np.arctan2(-c[0, 2], c[2, 2]), abs=ROUND_OFF)


@PROP
@given(angles, safe_rolls, angles)
def test_euler_dcm_euler_round_trip(yaw, roll, pitch):
    y2, r2, p2 = euler312_from_dcm(c312_ref(yaw, roll, pitch))
    tol = angle_tol(roll)
    assert abs(wrap(y2 - yaw)) <= tol
    assert abs(r2 - roll) <= tol
    assert abs(wrap(p2 - pitch)) <= tol


@PROP
@given(angles, safe_rolls, angles)
def test_euler_quat_euler_round_trip(yaw, roll, pitch):
    q = quat_from_euler312(yaw, roll, pitch)
    assert np.linalg.norm(q) == pytest.approx(1.0, abs=ROUND_OFF)
    assert q[3] >= 0.0
    np.testing.assert_allclose(attitude_matrix_ref(q), c312_ref(yaw, roll, pitch),
                               atol=ROUND_OFF)
    y2, r2, p2 = euler312_from_quat(q)
    tol = angle_tol(roll)
    assert abs(wrap(y2 - yaw)) <= tol
    assert abs(r2 - roll) <= tol
    assert abs(wrap(p2 - pitch)) <= tol


@PROP
@given(angles, st.floats(-HALF_PI, HALF_PI), angles)
@example(0.3, HALF_PI - 1e-6, -1.2)
@example(0.3, -HALF_PI, 2.0)
def test_dcm_quat_dcm_round_trip(yaw, roll, pitch):
    """DCM→quat→DCM is well conditioned everywhere, gimbal lock included."""
    c = c312_ref(yaw, roll, pitch)
    np.testing.assert_allclose(dcm_from_quat(quat_from_dcm(c)), c, rtol=0, atol=ROUND_TRIP)


# ---- near gimbal lock (roll → ±90°): compare DCMs, not individual angles ----------

LOCK_GRID = [(y, p) for y in np.linspace(-3.1, 3.1, 9) for p in np.linspace(-3.1, 3.1, 9)]


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_dcm_euler_dcm_round_trip_exactly_at_lock(sign):
    for yaw, pitch in LOCK_GRID:
        c = c312_ref(yaw, sign * HALF_PI, pitch)
        back = dcm_from_euler312(*euler312_from_dcm(c))
        np.testing.assert_allclose(back, c, rtol=0, atol=ROUND_TRIP)


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_dcm_euler_dcm_round_trip_at_90deg_minus_1e6(sign):
    """roll = ±(90° − 1e-6 rad): an asin-based roll loses ~5e-11 here."""
    roll = sign * (HALF_PI - 1e-6)
    worst = 0.0
    for yaw, pitch in LOCK_GRID:
        c = c312_ref(yaw, roll, pitch)
        worst = max(worst, np.max(np.abs(dcm_from_euler312(*euler312_from_dcm(c)) - c)))
    assert worst <= ROUND_TRIP


@PROP
@given(angles, lock_offsets, signs, angles)
@example(0.5, 1e-8, 1.0, -2.0)  # sin(roll) rounds to 1.0: asin would lose 1e-8 rad
@example(0.5, 1e-6, -1.0, 1.0)
def test_dcm_euler_dcm_round_trip_near_lock(yaw, offset, sign, pitch):
    c = c312_ref(yaw, sign * (HALF_PI - offset), pitch)
    np.testing.assert_allclose(dcm_from_euler312(*euler312_from_dcm(c)), c, rtol=0,
                               atol=ROUND_TRIP)


@PROP
@given(angles, lock_offsets, signs, angles)
@example(0.3, 0.0, 1.0, 1.2)
@example(0.3, 1e-6, 1.0, 1.2)
def test_euler_quat_euler_round_trip_near_lock(yaw, offset, sign, pitch):
    """Via the quaternion the row-1 / column-2 entries are pure round-off at lock, so
    yaw and pitch must be extracted consistently, not independently."""
    c = c312_ref(yaw, sign * (HALF_PI - offset), pitch)
    q = quat_from_euler312(yaw, sign * (HALF_PI - offset), pitch)
    np.testing.assert_allclose(dcm_from_euler312(*euler312_from_quat(q)), c, rtol=0,
                               atol=ROUND_TRIP)


@pytest.mark.parametrize("sign", [1.0, -1.0])
@pytest.mark.parametrize(("yaw", "pitch"), [(0.3, 1.2), (-2.0, 2.9), (3.0, -0.4)])
def test_exact_lock_determines_only_yaw_pitch_combination(sign, yaw, pitch):
    """At roll = +90° C_BR depends only on ψ + θ, at −90° only on θ − ψ (from the product
    R2(θ) R1(±90°) R3(ψ)); the extracted pair must preserve that combination."""
    c = attitude_matrix_ref(quat_from_euler312(yaw, sign * HALF_PI, pitch))
    y2, r2, p2 = euler312_from_dcm(c)
    # At lock roll and ψ ± θ are well conditioned (measured ≤ 4 eps); the split is not.
    assert abs(r2 - sign * HALF_PI) <= ROUND_TRIP
    assert abs(wrap((p2 + sign * y2) - (pitch + sign * yaw))) <= ROUND_TRIP
    np.testing.assert_allclose(dcm_from_euler312(y2, r2, p2), c, rtol=0, atol=ROUND_TRIP)


# --------------------------------------------------------------------------------------
# Quaternions
# --------------------------------------------------------------------------------------


@PROP
@given(unit_quaternions())
def test_dcm_from_quat_matches_markley_and_scipy(q):
    a = dcm_from_quat(q)
    np.testing.assert_allclose(a, attitude_matrix_ref(q), rtol=0, atol=ROUND_OFF)
    np.testing.assert_allclose(a, Rotation.from_quat(q).as_matrix().T, rtol=0, atol=ROUND_OFF)
    assert_rotation_matrix(a)


@PROP
@given(unit_vectors(), st.floats(-2 * np.pi, 2 * np.pi, allow_nan=False))
def test_axis_angle_quaternion_matches_rodrigues(e, theta):
    q = quat_axis_angle(e, theta)
    np.testing.assert_allclose(dcm_from_quat(q), rodrigues_ref(e, theta), rtol=0,
                               atol=ROUND_OFF)


@PROP
@given(unit_quaternions())
def test_quat_from_dcm_recovers_quaternion(q):
    got = quat_from_dcm(attitude_matrix_ref(q))
    assert np.linalg.norm(got) == pytest.approx(1.0, abs=ROUND_OFF)
    assert got[3] >= 0.0
    # ±q describe the same attitude; the sign is fixed by q4 ≥ 0.
    assert abs(abs(got @ q) - 1.0) <= ROUND_TRIP
    np.testing.assert_allclose(attitude_matrix_ref(got), attitude_matrix_ref(q), atol=ROUND_TRIP)
    if abs(q[3]) > 1e-6:
        np.testing.assert_allclose(got, np.sign(q[3]) * q, rtol=0, atol=ROUND_TRIP)


def test_quat_from_dcm_identity_and_shapes():
    """The identity matrix gives exactly (0, 0, 0, 1) (exact arithmetic on small integers,
    so identity is the requirement there); batched shapes and signs."""
    # Exact: the identity takes the q4 branch, (0, 0, 0, 1 + 3) / 4, with no rounding.
    np.testing.assert_array_equal(quat_from_dcm(np.eye(3)), [0, 0, 0, 1])
    rng = np.random.default_rng(11)
    qs = rng.normal(size=(2, 7, 4))
    qs /= np.linalg.norm(qs, axis=-1, keepdims=True)
    got = quat_from_dcm(dcm_from_quat(qs))
    assert got.shape == (2, 7, 4)
    assert np.all(got[..., 3] >= 0)
    np.testing.assert_allclose(np.abs(np.sum(got * qs, axis=-1)), 1.0, atol=ROUND_TRIP)


GENERAL_AXIS = np.array([1.0, 2.0, -2.0]) / 3.0


@pytest.mark.parametrize(
    "axis", [(1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0), tuple(GENERAL_AXIS),
             (-1.0, 0.0, 0.0), (0.0, -0.6, 0.8)])
def test_quat_from_dcm_180_degree_rotations(axis):
    e = np.asarray(axis)
    c = rodrigues_ref(e, np.pi)
    q = quat_from_dcm(c)
    assert np.linalg.norm(q) == pytest.approx(1.0, abs=ROUND_OFF)
    assert q[3] >= 0.0
    # q4 = cos(90°) is zero to round-off (measured 2 eps; sin(π) = 1.2e-16 in the reference
    # itself); a sqrt(1 + trace) extraction would give ~1e-8 here.
    assert abs(q[3]) <= ROUND_OFF
    # Either sign of the axis is the same 180° rotation.
    assert abs(abs(q[:3] @ e) - 1.0) <= ROUND_TRIP
    np.testing.assert_allclose(attitude_matrix_ref(q), c, rtol=0, atol=ROUND_TRIP)


@PROP
@given(unit_vectors(), st.floats(0.0, 1e-6, allow_nan=False))
def test_quat_from_dcm_near_180_degrees(e, delta):
    theta = np.pi - delta
    c = rodrigues_ref(e, theta)
    q = quat_from_dcm(c)
    assert q[3] >= 0.0
    assert np.linalg.norm(q) == pytest.approx(1.0, abs=ROUND_OFF)
    np.testing.assert_allclose(attitude_matrix_ref(q), c, rtol=0, atol=ROUND_TRIP)
    assert abs(abs(q @ quat_axis_angle(e, theta)) - 1.0) <= ROUND_TRIP


@PROP
@given(unit_quaternions(), unit_quaternions())
def test_quat_multiply_composes_attitude_matrices(q, p):
    qp = quat_multiply(q, p)
    assert np.linalg.norm(qp) == pytest.approx(1.0, abs=ROUND_OFF)
    np.testing.assert_allclose(
        attitude_matrix_ref(qp), attitude_matrix_ref(q) @ attitude_matrix_ref(p), atol=ROUND_OFF)


def test_quat_multiply_identity_same_axis_and_312_sequence():
    rng = np.random.default_rng(5)
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    ident = np.array([0.0, 0.0, 0.0, 1.0])
    np.testing.assert_allclose(quat_multiply(q, ident), q, atol=ROUND_OFF)
    np.testing.assert_allclose(quat_multiply(ident, q), q, atol=ROUND_OFF)
    e = GENERAL_AXIS
    np.testing.assert_allclose(quat_multiply(quat_axis_angle(e, 0.4), quat_axis_angle(e, -1.1)),
                               quat_axis_angle(e, -0.7), atol=ROUND_OFF)
    # q(pitch) ⊗ q(roll) ⊗ q(yaw) gives the 3-1-2 attitude.
    yaw, roll, pitch = 0.7, -0.3, 2.1
    qx, qy, qz = (quat_axis_angle(ax, a) for ax, a in
                  (((1, 0, 0), roll), ((0, 1, 0), pitch), ((0, 0, 1), yaw)))
    q312 = quat_multiply(qy, quat_multiply(qx, qz))
    np.testing.assert_allclose(attitude_matrix_ref(q312), c312_ref(yaw, roll, pitch),
                               atol=ROUND_OFF)
    got = quat_from_euler312(yaw, roll, pitch)
    np.testing.assert_allclose(got, np.sign(q312[3]) * q312, atol=ROUND_OFF)


def test_quat_multiply_broadcasts():
    rng = np.random.default_rng(3)
    q = rng.normal(size=(6, 4))
    p = rng.normal(size=(6, 4))
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    p /= np.linalg.norm(p, axis=-1, keepdims=True)
    qp = quat_multiply(q, p)
    assert qp.shape == (6, 4)
    for i in range(6):
        np.testing.assert_allclose(attitude_matrix_ref(qp[i]),
                                   attitude_matrix_ref(q[i]) @ attitude_matrix_ref(p[i]),
                                   atol=ROUND_OFF)


# --------------------------------------------------------------------------------------
# Orbit reference frame
# --------------------------------------------------------------------------------------


@st.composite
def position_velocity(draw):
    r = draw(unit_vectors()) * draw(st.floats(7e6, 1e8))
    v = draw(unit_vectors()) * draw(st.floats(1e2, 1e4))
    # Keep r and v at least ~0.06 rad from parallel so the orbit normal is defined.
    assume(np.linalg.norm(np.cross(r, v)) > 0.06 * np.linalg.norm(r) * np.linalg.norm(v))
    return r, v


@PROP
@given(position_velocity())
def test_orbit_frame_dcm_axes(rv):
    r, v = rv
    c = orbit_frame_dcm(r, v)
    assert_rotation_matrix(c)
    h = np.cross(r, v)
    np.testing.assert_allclose(c[2], -r / np.linalg.norm(r), rtol=0, atol=ROUND_OFF)
    np.testing.assert_allclose(c[1], -h / np.linalg.norm(h), rtol=0, atol=ROUND_OFF)
    # x_R lies in the orbit plane, perpendicular to r, and points along-track (x·v > 0).
    # The dot products are zero in exact arithmetic; unit vectors: measured ≤ 1 eps.
    x = c[0]
    assert abs(x @ r) <= ROUND_OFF * np.linalg.norm(r)
    assert abs(x @ h) <= ROUND_OFF * np.linalg.norm(h)
    assert x @ v > 0.0


@pytest.mark.parametrize("alpha", [0.0, 0.4, 2.0, -2.9])
def test_orbit_frame_dcm_equatorial_prograde(alpha):
    ca, sa = np.cos(alpha), np.sin(alpha)
    r = GEO_RADIUS_M * np.array([ca, sa, 0.0])
    v = 3074.66 * np.array([-sa, ca, 0.0])
    c = orbit_frame_dcm(r, v)
    np.testing.assert_allclose(c[1], [0.0, 0.0, -1.0], rtol=0, atol=ROUND_OFF)
    np.testing.assert_allclose(c[2], [-ca, -sa, 0.0], rtol=0, atol=ROUND_OFF)
    np.testing.assert_allclose(c[0], [-sa, ca, 0.0], rtol=0, atol=ROUND_OFF)  # along velocity


def test_orbit_frame_dcm_broadcasts():
    rng = np.random.default_rng(9)
    r = rng.normal(size=(5, 3)) * 4e7
    v = rng.normal(size=(5, 3)) * 3e3
    c = orbit_frame_dcm(r, v)
    assert c.shape == (5, 3, 3)
    for i in range(5):
        # Not an identity requirement: numpy's row-wise norms and a vector's norm may round
        # differently (pairwise sum vs BLAS dot).
        np.testing.assert_allclose(c[i], orbit_frame_dcm(r[i], v[i]), rtol=0, atol=ROUND_OFF)
        assert_rotation_matrix(c[i])


# --------------------------------------------------------------------------------------
# GeoOrbit
# --------------------------------------------------------------------------------------

DAY_TIMES = np.linspace(0.0, 86400.0, 1441)


def test_geo_rate_matches_sidereal_rate():
    orbit = GeoOrbit()
    w0 = orbit.rate_radps
    # Kepler's third law; a cube, a quotient and a root: ≤ 3 eps however it is evaluated.
    assert w0 == pytest.approx(np.sqrt(3.986004418e14 / 42164170.0**3), rel=1e-14)
    assert w0 == pytest.approx(2.0 * np.pi / SIDEREAL_DAY_S, rel=1e-6)
    assert w0 == pytest.approx(7.2921e-5, rel=1e-4)
    assert orbit.radius_m == 42164170.0 and orbit.mu_m3ps2 == 3.986004418e14
    assert GEO_RADIUS_M == 42164170.0 and MU_EARTH_M3PS2 == 3.986004418e14


@pytest.mark.parametrize("gmst0", [0.0, 1.234, -2.5])
@pytest.mark.parametrize("lon_deg", [-75.0, -135.0, 0.0])
def test_geo_orbit_frame_matches_orbit_frame_dcm_over_a_day(gmst0, lon_deg):
    """The closed form equals the generic construction to round-off; its y_R row is the
    constant (0, 0, −1) exactly (a structural constant, so identity is the requirement)."""
    orbit = GeoOrbit(longitude_rad=np.deg2rad(lon_deg))
    closed = orbit.orbit_frame(DAY_TIMES, gmst0)
    generic = orbit_frame_dcm(*orbit.position_velocity(DAY_TIMES, gmst0))
    assert closed.shape == (DAY_TIMES.size, 3, 3)
    np.testing.assert_allclose(closed, generic, rtol=0, atol=ROUND_OFF)
    # Exact: the closed form writes y_R = (0, 0, −1) as constants.
    np.testing.assert_array_equal(closed[:, 1], np.tile([0.0, 0.0, -1.0], (DAY_TIMES.size, 1)))


@pytest.mark.parametrize("gmst0", [0.0, 1.234])
def test_geo_position_velocity(gmst0):
    """Radius, speed, orthogonality, phase and derivative of the GEO position.  The z
    components are structural zeros (written as 0.0), so they are compared exactly."""
    orbit = GeoOrbit()
    r, v = orbit.position_velocity(DAY_TIMES, gmst0)
    w0 = np.sqrt(MU_EARTH_M3PS2 / GEO_RADIUS_M**3)
    # R·|(cos, sin)|: a few eps (measured 1 ulp of R, 1.8e-16 relative).
    np.testing.assert_allclose(np.linalg.norm(r, axis=-1), GEO_RADIUS_M, rtol=ROUND_OFF)
    np.testing.assert_allclose(np.linalg.norm(v, axis=-1), GEO_RADIUS_M * w0, rtol=ROUND_OFF)
    assert np.all(r[:, 2] == 0.0) and np.all(v[:, 2] == 0.0)  # structural zeros
    np.testing.assert_allclose(np.sum(r * v, axis=-1) / (GEO_RADIUS_M**2 * w0), 0.0,
                               atol=ROUND_OFF)
    # Prograde: angular momentum along +z_N.
    h = np.cross(r, v)
    assert np.all(h[:, 2] > 0)
    # Right ascension at t = 0 is gmst0 + longitude; at t it has advanced by ω0 t.
    a = gmst0 + np.deg2rad(-75.0) + w0 * DAY_TIMES
    np.testing.assert_allclose(r / GEO_RADIUS_M, np.stack([np.cos(a), np.sin(a), 0 * a], -1),
                               rtol=0, atol=ROUND_OFF)
    # Velocity is the time derivative of position: for uniform circular motion the central
    # difference with step h is exactly v sin(ω0 h)/(ω0 h); the rest is round-off: the angle
    # (up to 7 rad) carries ulp(7) = 8.9e-16 rad, i.e. 3.7e-8 m of position, /h = 3.7e-10 m/s
    # at h = 100 s (measured 1.6e-10 m/s; 1e-7 m/s is 3e-11 of the 3075 m/s speed).
    h = 100.0
    rp, _ = orbit.position_velocity(DAY_TIMES + h, gmst0)
    rm, _ = orbit.position_velocity(DAY_TIMES - h, gmst0)
    np.testing.assert_allclose((rp - rm) / (2 * h), v * np.sin(w0 * h) / (w0 * h), rtol=0,
                               atol=1e-7)


def test_geo_scalar_time_shapes():
    orbit = GeoOrbit()
    r, v = orbit.position_velocity(100.0, 0.3)
    assert r.shape == (3,) and v.shape == (3,)
    assert orbit.orbit_frame(100.0, 0.3).shape == (3, 3)


@pytest.mark.parametrize("dt", [1.0, 60.0, 3600.0, 21600.0, 43082.0])
@pytest.mark.parametrize("t", [0.0, 12345.6, 80000.0])
def test_orbit_frame_rotates_at_minus_w0_about_y(t, dt):
    """For frame rotations, a frame turning at rate ω about its own y axis obeys
    C(t+dt) = R2(ω dt) C(t) (R2(a) ≈ I − a[e2×], i.e. Ċ = −[ω×] C).  The orbit frame
    turns at +ω0 about +z_N = −y_R, i.e. at ω = −ω0 about y_R."""
    orbit = GeoOrbit()
    w0 = np.sqrt(MU_EARTH_M3PS2 / GEO_RADIUS_M**3)
    c0 = orbit.orbit_frame(t, 0.7)
    c1 = orbit.orbit_frame(t + dt, 0.7)
    rel = c1 @ c0.T
    # Right ascensions of up to 9 rad carry ulp(9) = 1.8e-15 each (measured 1.8e-15); the
    # opposite sign is off by 2 ω0 dt ≥ 1.5e-4.
    np.testing.assert_allclose(rel, r2_ref(-w0 * dt), rtol=0, atol=1e-12)
    # The opposite sign is distinguishable at this tolerance.
    assert np.max(np.abs(rel - r2_ref(+w0 * dt))) > 1e-6


def test_orbit_frame_angular_velocity_from_poisson_equation():
    """Ċ_RN = −[ω_R×] C_RN, by central differences: ω_R = (0, −ω0, 0), i.e. +ω0 ẑ_N.

    For a uniform rotation the central difference is exactly sin(ω0 h)/(ω0 h) times the
    derivative (a truncation of 6.5e-14 rad/s at h = 1 s, taken out below), so what is
    left is round-off: C's O(1) entries carry ~1e-15 from the angle, ~5e-16 rad/s in Ċ
    (measured ≤ 1e-16); ROUND_OFF = 1e-13 rad/s is 1.4e-9 of ω0."""
    orbit = GeoOrbit()
    w0 = orbit.rate_radps
    h = 1.0
    rate = w0 * np.sin(w0 * h) / (w0 * h)  # what the central difference sees
    for t in (0.0, 5000.0, 70000.0):
        c = orbit.orbit_frame(t, 0.2)
        cdot = (orbit.orbit_frame(t + h, 0.2) - orbit.orbit_frame(t - h, 0.2)) / (2 * h)
        w_skew = -cdot @ c.T
        np.testing.assert_allclose(w_skew, -w_skew.T, rtol=0, atol=ROUND_OFF)
        w_r = np.array([w_skew[2, 1], w_skew[0, 2], w_skew[1, 0]])
        np.testing.assert_allclose(w_r, [0.0, -rate, 0.0], rtol=0, atol=ROUND_OFF)
        np.testing.assert_allclose(c.T @ w_r, [0.0, 0.0, rate], rtol=0, atol=ROUND_OFF)
        # Axis kinematics in N: d(z_R)/dt = ω_N × z_R with ω_N = −ω0 y_R.
        np.testing.assert_allclose(cdot[2], np.cross(-rate * c[1], c[2]), rtol=0,
                                   atol=ROUND_OFF)


@pytest.mark.parametrize(
    "kwargs", [{"longitude_rad": np.nan}, {"longitude_rad": np.inf}, {"radius_m": 6.0e6},
               {"radius_m": np.nan}, {"radius_m": -4.2e7}])
def test_geo_orbit_rejects_bad_parameters(kwargs):
    with pytest.raises(ValueError):
        GeoOrbit(**kwargs)


def test_rotate_312_is_the_dcm_applied():
    """The twin's Sun in body axes, rotated an axis at a time, equals C_BR v from the
    stacked matrices to round-off (a few ulps of |v|), at any angles."""
    from sim.frames import dcm_from_euler312, rotate_312
    rng = np.random.default_rng(4)
    yaw, roll, pitch = rng.uniform(-np.pi, np.pi, (3, 5000))
    v = rng.normal(size=(5000, 3))
    ref = np.einsum("nij,nj->ni", dcm_from_euler312(yaw, roll, pitch), v)
    got = rotate_312(yaw, roll, pitch, v)
    np.testing.assert_allclose(got, ref, rtol=0,
                               atol=16 * np.finfo(float).eps * np.abs(v).sum(axis=1).max())
