"""Tests for sim.spacecraft against the paper's wheel numbers (Section 2.3, Eqs. 1-2).

Paper values used as independent references (not read from the module):
wheel spin inertia I_w = 0.1082 kg m², cant c = 1.656°, nominal speed 5485 rpm,
pitch bias H = −124.2 N m s (Eq. 1), backup yaw reaction wheel inertia 0.008626 kg m².
"""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sim.spacecraft import (
    Spacecraft,
    Wheel,
    canted_axes,
    check_inertia,
    goes_next,
    goes_next_backup,
    goes_next_wheels,
)

IW = 0.1082                      # kg m^2
CANT = np.deg2rad(1.656)         # rad
RPM_TO_RADPS = 2.0 * np.pi / 60.0
OMEGA_NOM = 5485.0 * RPM_TO_RADPS
YAW_RW_IW = 0.008626             # kg m^2
H_PAPER = -124.2                 # N m s, Eq. 1 (quoted to 0.1 N m s)

A1 = np.array([0.0, -np.cos(CANT), np.sin(CANT)])
A2 = np.array([0.0, -np.cos(CANT), -np.sin(CANT)])

PROP = settings(max_examples=200, deadline=None, database=None)
# Round-off allowance for O(1) axis components and for the same conversion written in
# another order (5485 · 2π/60 vs 5485 · 2π / 60): a few ulps (≤ 4.4e-16 relative); measured
# 0 here.  1e-13 also covers libms and SIMD loops that round cos/sin differently.
ROUND_OFF = 1e-13


def pitch_bias_eq1(w1, w2):
    return -IW * (w1 + w2) * np.cos(CANT)


def yaw_momentum_eq2(w1, w2):
    return IW * (w1 - w2) * np.sin(CANT)


def rotation(e, theta):
    """Rodrigues rotation matrix about unit e (sign irrelevant for similarity transforms)."""
    e = np.asarray(e, dtype=float) / np.linalg.norm(e)
    k = np.array([[0.0, -e[2], e[1]], [e[2], 0.0, -e[0]], [-e[1], e[0], 0.0]])
    return np.cos(theta) * np.eye(3) + (1 - np.cos(theta)) * np.outer(e, e) - np.sin(theta) * k


# --------------------------------------------------------------------------------------
# Nominal GOES-Next configuration
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize("sc", [Spacecraft(), goes_next()], ids=["Spacecraft()", "goes_next()"])
def test_goes_next_defaults_reproduce_paper(sc):
    assert sc.n_wheels == 2
    np.testing.assert_allclose(sc.wheel_axes, [A1, A2], rtol=0, atol=ROUND_OFF)
    np.testing.assert_allclose(np.linalg.norm(sc.wheel_axes, axis=1), 1.0, rtol=0,
                               atol=ROUND_OFF)
    np.testing.assert_array_equal(sc.wheel_inertias, [IW, IW])  # stored, no arithmetic
    np.testing.assert_allclose(sc.wheel_speeds, [OMEGA_NOM, OMEGA_NOM], rtol=ROUND_OFF)

    h_pitch = sc.pitch_bias_Nms()
    assert h_pitch == pytest.approx(pitch_bias_eq1(OMEGA_NOM, OMEGA_NOM), rel=1e-12)
    assert h_pitch == pytest.approx(H_PAPER, abs=0.05)
    # h cancels two 1.8 N m s terms (ulp 2.2e-16): 1e-12 N m s is 4500 ulps.
    assert sc.yaw_momentum_Nms() == pytest.approx(0.0, abs=1e-12)
    hw = sc.wheel_momentum()
    assert hw.shape == (3,)
    assert hw[0] == 0.0  # structural: the axes' x components are exact zeros
    np.testing.assert_allclose(hw, [0.0, h_pitch, 0.0], rtol=0, atol=1e-12)


def test_default_inertia_is_a_valid_diagonal_tensor():
    """Identity is the requirement here: the tensor is stored and validated, never
    computed, so it comes back exactly."""
    j = Spacecraft().J
    assert j.shape == (3, 3)
    np.testing.assert_array_equal(j, np.diag(np.diag(j)))
    assert np.all(np.diag(j) > 0)
    np.testing.assert_array_equal(check_inertia(j), j)
    np.testing.assert_array_equal(goes_next().J, j)


def test_canted_axes_formula():
    for cant_deg in (0.0, 1.656, 10.0, 45.0):
        c = np.deg2rad(cant_deg)
        a1, a2 = canted_axes(cant_deg)
        np.testing.assert_allclose(a1, [0, -np.cos(c), np.sin(c)], rtol=0, atol=ROUND_OFF)
        np.testing.assert_allclose(a2, [0, -np.cos(c), -np.sin(c)], rtol=0, atol=ROUND_OFF)


@pytest.mark.parametrize("cant_deg", [90.0, -1.0, np.nan, np.inf])
def test_canted_axes_rejects_bad_cant(cant_deg):
    with pytest.raises(ValueError, match="cant"):
        canted_axes(cant_deg)


def test_wheel_momentum_and_goes_next_wheels_keyword_overrides():
    w = Wheel(0.2, (0.0, 0.6, -0.8), 300.0)
    np.testing.assert_allclose(w.momentum_Nms, [0.0, 36.0, -48.0], rtol=ROUND_OFF)
    wheels = goes_next_wheels(spin_inertia_kgm2=0.05, cant_deg=5.0, speed_rpm=4000.0)
    sc = Spacecraft(wheels=wheels)
    c = np.deg2rad(5.0)
    # The same few products in another order: a few ulps.
    assert sc.pitch_bias_Nms() == pytest.approx(-0.05 * 2 * 4000 * RPM_TO_RADPS * np.cos(c),
                                                rel=1e-12)


# --------------------------------------------------------------------------------------
# Eq. 2: yaw momentum from differential wheel speed
# --------------------------------------------------------------------------------------


def test_yaw_momentum_eq2_with_unequal_speeds():
    sc = Spacecraft()
    w1, w2 = 5485.0 * RPM_TO_RADPS, 5400.0 * RPM_TO_RADPS
    speeds = np.array([w1, w2])
    h_ref = yaw_momentum_eq2(w1, w2)
    assert h_ref == pytest.approx(0.02783, rel=1e-3)  # sanity on the hand calculation
    # Ω1 − Ω2 cancels 574 rad/s down to 8.9: a condition of 65, so ~65 ulps (1.4e-14)
    # at worst against 1e-12.
    assert sc.yaw_momentum_Nms(speeds) == pytest.approx(h_ref, rel=1e-12)
    assert sc.pitch_bias_Nms(speeds) == pytest.approx(pitch_bias_eq1(w1, w2), rel=1e-12)
    # Swapping the speeds reverses h.
    assert sc.yaw_momentum_Nms(speeds[::-1]) == pytest.approx(-h_ref, rel=1e-12)


@PROP
@given(st.floats(0.0, 7000.0), st.floats(0.0, 7000.0))
def test_eq1_eq2_over_speed_range(rpm1, rpm2):
    sc = Spacecraft()
    w1, w2 = rpm1 * RPM_TO_RADPS, rpm2 * RPM_TO_RADPS
    speeds = np.array([w1, w2])
    # Absolute, since h → 0 as the speeds meet: its terms reach 2.3 N m s (ulp 4.4e-16)
    # and H's 160 N m s (ulp 2.8e-14), so 1e-12 and 1e-11 are a few hundred ulps.
    assert sc.yaw_momentum_Nms(speeds) == pytest.approx(yaw_momentum_eq2(w1, w2), abs=1e-12)
    assert sc.pitch_bias_Nms(speeds) == pytest.approx(pitch_bias_eq1(w1, w2), abs=1e-11)


def test_momentum_accepts_leading_dimensions():
    sc = Spacecraft()
    rng = np.random.default_rng(2)
    speeds = rng.uniform(500.0, 600.0, size=(4, 5, 2))
    h = sc.yaw_momentum_Nms(speeds)
    big_h = sc.pitch_bias_Nms(speeds)
    assert h.shape == (4, 5) and big_h.shape == (4, 5)
    # h cancels two wheel terms of up to 1.9 N m s (ulp 2.2e-16) and the speeds drawn come
    # within 0.27 rad/s of each other (a factor of 2200): absolute, as in the property test
    # above (measured 1.9e-16 N m s, 7e-14 relative).
    np.testing.assert_allclose(h, yaw_momentum_eq2(speeds[..., 0], speeds[..., 1]), rtol=0,
                               atol=1e-12)
    np.testing.assert_allclose(big_h, pitch_bias_eq1(speeds[..., 0], speeds[..., 1]),
                               rtol=1e-12)
    assert sc.wheel_momentum(speeds).shape == (4, 5, 3)


# --------------------------------------------------------------------------------------
# Backup configuration: one momentum wheel + yaw reaction wheel
# --------------------------------------------------------------------------------------


def test_backup_configuration():
    sc = goes_next_backup()
    assert sc.n_wheels == 2
    mw, rw = sc.wheels
    np.testing.assert_allclose(mw.axis, A1, rtol=0, atol=ROUND_OFF)
    assert mw.spin_inertia_kgm2 == IW  # stored constants: no arithmetic, exact
    assert mw.speed_radps == pytest.approx(OMEGA_NOM, rel=ROUND_OFF)
    assert rw.spin_inertia_kgm2 == YAW_RW_IW
    np.testing.assert_array_equal(rw.axis, [0.0, 0.0, 1.0])
    # The reaction wheel cancels the momentum wheel's yaw component: I_rw Ω_rw = −I_w Ω sin c.
    assert rw.speed_radps == pytest.approx(-IW * OMEGA_NOM * np.sin(CANT) / YAW_RW_IW, rel=1e-12)

    assert sc.yaw_momentum_Nms() == pytest.approx(0.0, abs=1e-12)
    nominal = pitch_bias_eq1(OMEGA_NOM, OMEGA_NOM)
    assert sc.pitch_bias_Nms() == pytest.approx(0.5 * nominal, rel=1e-12)
    assert sc.pitch_bias_Nms() == pytest.approx(0.5 * H_PAPER, abs=0.03)
    assert sc.wheel_momentum()[0] == 0.0  # structural zero, as above


# --------------------------------------------------------------------------------------
# Inertia validation
# --------------------------------------------------------------------------------------

GOES_DIAG = np.diag([3364.376, 954.936, 3461.393])
# Tensor elements are minus the products of inertia; use ±30 kg m² products.
GOES_WITH_PRODUCTS = GOES_DIAG - np.array([[0.0, 30.0, -30.0],
                                           [30.0, 0.0, 30.0],
                                           [-30.0, 30.0, 0.0]])

NONSYMMETRIC = GOES_DIAG + np.array([[0, 30.0, 0], [0, 0, 0], [0, 0, 0]])
BAD_INERTIAS = [
    pytest.param(NONSYMMETRIC, "not symmetric", id="non-symmetric"),
    pytest.param(np.diag([1.0, 1.0, -1.0]), "not positive definite", id="negative-moment"),
    pytest.param(np.diag([1.0, 1.0, 0.0]), "not positive definite", id="zero-moment"),
    # Symmetric, positive diagonal, but indefinite: eigenvalues 3 and −1 in the x-y block.
    pytest.param(np.array([[1.0, 2.0, 0.0], [2.0, 1.0, 0.0], [0.0, 0.0, 1.0]]),
                 "not positive definite", id="indefinite"),
    pytest.param(np.diag([1.0, 1.0, 3.0]), "triangle inequality", id="triangle-diag"),
    pytest.param(np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, np.nan]]),
                 "NaN", id="nan"),
    pytest.param(np.diag([1.0, np.inf, 1.0]), "infinity", id="inf"),
    pytest.param(np.eye(2), "3x3", id="shape-2x2"),
    pytest.param(np.ones(3), "3x3", id="shape-vector"),
    pytest.param(np.eye(4)[:3], "3x3", id="shape-3x4"),
    pytest.param(np.eye(3)[None], "3x3", id="shape-1x3x3"),
]


@pytest.mark.parametrize(("j", "message"), BAD_INERTIAS)
def test_check_inertia_rejects(j, message):
    with pytest.raises(ValueError, match=message):
        check_inertia(j)


@pytest.mark.parametrize(("j", "message"), BAD_INERTIAS)
def test_spacecraft_rejects_bad_inertia(j, message):
    with pytest.raises(ValueError, match=message):
        Spacecraft(inertia_kgm2=j)


def test_check_inertia_message_uses_name():
    with pytest.raises(ValueError, match="J_sat is not symmetric"):
        check_inertia(NONSYMMETRIC, name="J_sat")


def test_goes_tensor_with_products_of_inertia_is_accepted():
    """Identity is the requirement here: validation must return the tensor unchanged."""
    out = check_inertia(GOES_WITH_PRODUCTS)
    np.testing.assert_array_equal(out, GOES_WITH_PRODUCTS)
    assert out.dtype == np.float64
    sc = Spacecraft(inertia_kgm2=GOES_WITH_PRODUCTS)
    np.testing.assert_array_equal(sc.J, GOES_WITH_PRODUCTS)
    sc2 = goes_next(inertia_kgm2=tuple(map(tuple, GOES_WITH_PRODUCTS)))
    np.testing.assert_array_equal(sc2.J, GOES_WITH_PRODUCTS)


def test_thin_plate_limit_is_accepted():
    # Triangle equality (a flat lamina) is physical.
    check_inertia(np.diag([1.0, 2.0, 3.0]))


def test_check_inertia_accepts_integer_input():
    out = check_inertia([[2, 0, 0], [0, 3, 0], [0, 0, 4]])
    assert out.dtype == np.float64


@st.composite
def rotations(draw):
    e = np.array(draw(st.lists(st.floats(-1.0, 1.0), min_size=3, max_size=3)))
    if np.linalg.norm(e) < 1e-3:
        e = np.array([0.0, 0.0, 1.0])
    return rotation(e, draw(st.floats(-np.pi, np.pi)))


@PROP
@given(rotations(), st.floats(0.1, 10.0), st.floats(0.1, 10.0), st.floats(0.0, 1.0))
def test_inertia_validity_is_rotation_invariant(r, a, b, frac):
    """Principal moments obeying the triangle inequality with a 5% margin are valid in any
    axes; c = 1.05 (a + b) is not."""
    margin = 0.05 * min(a, b)
    lo, hi = abs(a - b) + margin, a + b - margin
    good = r @ np.diag([a, b, lo + frac * (hi - lo)]) @ r.T
    good = 0.5 * (good + good.T)
    check_inertia(good)
    bad = r @ np.diag([a, b, 1.05 * (a + b)]) @ r.T
    bad = 0.5 * (bad + bad.T)
    with pytest.raises(ValueError, match="triangle inequality"):
        check_inertia(bad)


# --------------------------------------------------------------------------------------
# Wheel and wheel-set validation
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "axis", [(0.0, 1.0, 1.0), (0.0, 0.0, 0.0), (0.5, 0.0, 0.0), (0.0, 1.0 + 1e-6, 0.0),
             (0.0, -2.0, 0.0)])
def test_wheel_rejects_non_unit_axis(axis):
    with pytest.raises(ValueError, match="unit vector"):
        Wheel(IW, axis, OMEGA_NOM)


@pytest.mark.parametrize("axis", [(1.0, 0.0), (0.0, 0.0, 1.0, 0.0), (np.nan, 0.0, 1.0),
                                  (np.inf, 0.0, 0.0)])
def test_wheel_rejects_malformed_axis(axis):
    with pytest.raises(ValueError, match="axis"):
        Wheel(IW, axis, OMEGA_NOM)


@pytest.mark.parametrize("inertia", [0.0, -0.1082, np.nan, np.inf])
def test_wheel_rejects_non_positive_inertia(inertia):
    with pytest.raises(ValueError, match="inertia must be positive"):
        Wheel(inertia, tuple(A1), OMEGA_NOM)


@pytest.mark.parametrize("speed", [np.nan, np.inf, -np.inf])
def test_wheel_rejects_non_finite_speed(speed):
    with pytest.raises(ValueError, match="speed"):
        Wheel(IW, tuple(A1), speed)


def test_wheel_accepts_unit_axes_and_any_finite_speed():
    for axis in (tuple(A1), tuple(A2), (0.0, 0.0, 1.0), (1 / 3, 2 / 3, -2 / 3)):
        Wheel(IW, axis, 0.0)
        Wheel(IW, axis, -OMEGA_NOM)


def test_spacecraft_requires_wheels_spanning_pitch_and_yaw():
    with pytest.raises(ValueError, match="at least one wheel"):
        Spacecraft(wheels=())
    pitch_only = (Wheel(IW, (0.0, -1.0, 0.0), OMEGA_NOM), Wheel(IW, (0.0, -1.0, 0.0), OMEGA_NOM))
    with pytest.raises(ValueError, match="y-z plane"):
        Spacecraft(wheels=pitch_only)
    roll_yaw = (Wheel(IW, (1.0, 0.0, 0.0), OMEGA_NOM), Wheel(IW, (0.0, 0.0, 1.0), 0.0))
    with pytest.raises(ValueError, match="y-z plane"):
        Spacecraft(wheels=roll_yaw)
