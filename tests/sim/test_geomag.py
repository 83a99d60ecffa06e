"""Tests for sim.geomag against closed-form dipole results and IGRF-14 Gauss coefficients.

Round-off tolerances: unit-vector components to 1e-13 (a few ulps of O(1) values; measured
≤ 9e-18), field vectors to 1e-12 relative (a handful of products and one division by
|r|³, no cancellation; measured ≤ 1.2e-15), exact-zero components to an atol scaled to the
field they are a fraction of.
"""

import numpy as np
import pytest

from sim.geomag import (
    DIPOLE_MOMENT_AM2,
    POLE_LAT_DEG,
    POLE_LON_DEG,
    dipole_field_ecef,
    dipole_moment_ecef,
    geo_field_orbit_frame,
    geo_orbit_frame_axes,
)

R_GEO = 42_164_170.0
A_REF = 6_371_200.0  # IGRF reference radius [m]
# IGRF-14, epoch 2025.0, degree 1 (IAGA V-MOD, igrf14coeffs.txt) [T].
G10, G11, H11 = -29350.0e-9, -1410.3e-9, 4545.5e-9


def _north_axis(lat_deg=POLE_LAT_DEG, lon_deg=POLE_LON_DEG):
    lat, lon = np.deg2rad(lat_deg), np.deg2rad(lon_deg)
    return np.array([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)])


def _equatorial_unit(axis):
    e = np.cross(axis, [0.0, 0.0, 1.0])
    return e / np.linalg.norm(e)


def _b_equator(radius, moment=DIPOLE_MOMENT_AM2):
    return 1e-7 * moment / radius**3  # mu0 m / (4 pi r^3)


def test_default_dipole_matches_igrf14_and_published_pole():
    b0 = np.sqrt(G10**2 + G11**2 + H11**2)
    assert b0 == pytest.approx(29.73e-6, rel=1e-3)  # ~29.7 uT equatorial surface field
    assert DIPOLE_MOMENT_AM2 == pytest.approx(4 * np.pi * A_REF**3 * b0 / (4e-7 * np.pi))
    assert DIPOLE_MOMENT_AM2 == pytest.approx(7.69e22, rel=1e-3)
    # IGRF-14 2025 north geomagnetic (dipole) pole as usually quoted: 80.8 N, 72.7-72.8 W.
    assert POLE_LAT_DEG == pytest.approx(80.8, abs=0.05)
    assert POLE_LON_DEG == pytest.approx(-72.8, abs=0.1)


def test_moment_points_to_geomagnetic_south_pole():
    m = dipole_moment_ecef()
    np.testing.assert_allclose(m, -DIPOLE_MOMENT_AM2 * _north_axis(), rtol=1e-13)
    assert m[2] < 0.0


def test_magnetic_equator_magnitude_and_direction():
    axis = _north_axis()
    r = R_GEO * _equatorial_unit(axis)
    b = dipole_field_ecef(r)
    assert np.linalg.norm(b) == pytest.approx(_b_equator(R_GEO), rel=1e-12)
    # On the magnetic equator the field is horizontal and points to the north magnetic pole
    # (b·r̂ is zero in exact arithmetic: a cancellation of O(|b|) terms, a few eps).
    assert abs(np.dot(b, r)) / (np.linalg.norm(b) * R_GEO) < 1e-12
    np.testing.assert_allclose(b / np.linalg.norm(b), axis, atol=1e-12)


def test_pole_field_is_twice_equatorial_and_downward():
    axis = _north_axis()
    b_north = dipole_field_ecef(R_GEO * axis)
    b_south = dipole_field_ecef(-R_GEO * axis)
    np.testing.assert_allclose(b_north, -2.0 * _b_equator(R_GEO) * axis, rtol=1e-12)
    np.testing.assert_allclose(b_south, b_north, rtol=1e-12)  # also along -r_hat there


def test_axial_dipole_equator_points_north_with_explicit_parameters():
    b = dipole_field_ecef([R_GEO, 0.0, 0.0], moment_Am2=7.72e22, pole_lat_deg=90.0)
    # x and y are cos(90°) = 6.1e-17 of the field (measured 6e-24 T): atol 1e-13 of it.
    b_eq = _b_equator(R_GEO, 7.72e22)
    np.testing.assert_allclose(b, [0.0, 0.0, b_eq], rtol=1e-12, atol=1e-13 * b_eq)


def test_magnitude_matches_dipole_latitude_law():
    # |B| = (mu0 m / 4 pi r^3) sqrt(1 + 3 sin^2(magnetic latitude)), any direction.
    rng = np.random.default_rng(1)
    u = rng.normal(size=(200, 3))
    u /= np.linalg.norm(u, axis=-1, keepdims=True)
    radius = rng.uniform(A_REF, 8 * A_REF, size=200)
    b = dipole_field_ecef(u * radius[:, None])
    sin_lat = u @ _north_axis()
    expected = _b_equator(radius) * np.sqrt(1.0 + 3.0 * sin_lat**2)
    np.testing.assert_allclose(np.linalg.norm(b, axis=-1), expected, rtol=1e-12)


def _central_gradient(f, r, h):
    """d f_i / d x_j by central differences, shape (..., i, j) (or (..., j) for scalar f)."""
    cols = []
    for j in range(3):
        step = np.zeros(3)
        step[j] = h
        cols.append((f(r + step) - f(r - step)) / (2.0 * h))
    return np.stack(cols, axis=-1)


def test_matches_igrf14_degree1_potential():
    # V = a^3 (g10 z + g11 x + h11 y) / r^3 is the IGRF n = 1 potential (P10 = cos theta,
    # P11 = sin theta with Schmidt normalization); B = -grad V.
    def potential(r):
        rn = np.linalg.norm(r, axis=-1)
        return A_REF**3 * (G10 * r[..., 2] + G11 * r[..., 0] + H11 * r[..., 1]) / rn**3

    rng = np.random.default_rng(2)
    u = rng.normal(size=(50, 3))
    r = u / np.linalg.norm(u, axis=-1, keepdims=True) * rng.uniform(A_REF, R_GEO, 50)[:, None]
    b_ref = -_central_gradient(potential, r, h=1.0)
    b = dipole_field_ecef(r)
    err = np.linalg.norm(b - b_ref, axis=-1) / np.linalg.norm(b_ref, axis=-1)
    assert np.max(err) < 1e-6


def test_divergence_and_curl_free():
    rng = np.random.default_rng(3)
    u = rng.normal(size=(50, 3))
    r = u / np.linalg.norm(u, axis=-1, keepdims=True) * rng.uniform(A_REF, R_GEO, 50)[:, None]
    h = 1.0e-4 * np.linalg.norm(r, axis=-1).min()
    jac = _central_gradient(dipole_field_ecef, r, h)  # jac[..., i, j] = dB_i / dx_j
    scale = np.linalg.norm(dipole_field_ecef(r), axis=-1) / np.linalg.norm(r, axis=-1)
    div = np.trace(jac, axis1=-2, axis2=-1)
    curl = jac - np.swapaxes(jac, -1, -2)
    assert np.max(np.abs(div) / scale) < 1e-6
    assert np.max(np.max(np.abs(curl), axis=(-2, -1)) / scale) < 1e-6


def test_vectorized_shapes():
    r = np.full((4, 5, 3), R_GEO / np.sqrt(3.0))
    assert dipole_field_ecef(r).shape == (4, 5, 3)
    assert geo_field_orbit_frame(np.linspace(-np.pi, np.pi, 7)).shape == (7, 3)
    assert geo_field_orbit_frame(0.3).shape == (3,)


def test_orbit_frame_axes():
    lon = np.deg2rad(np.array([-137.2, -75.2, 0.0, 90.0]))
    axes = geo_orbit_frame_axes(lon)
    for k, lam in enumerate(lon):
        x_r, y_r, z_r = axes[k]
        np.testing.assert_allclose(axes[k] @ axes[k].T, np.eye(3), atol=1e-13)
        assert np.linalg.det(axes[k]) == pytest.approx(1.0)
        np.testing.assert_allclose(z_r, -np.array([np.cos(lam), np.sin(lam), 0.0]), atol=1e-13)
        np.testing.assert_allclose(y_r, [0.0, 0.0, -1.0], atol=1e-13)
        # x_R is local east, the direction of motion of a prograde equatorial orbit.
        np.testing.assert_allclose(x_r, [-np.sin(lam), np.cos(lam), 0.0], atol=1e-13)


def test_geo_axial_dipole_orbit_frame():
    b = geo_field_orbit_frame(np.deg2rad(-75.2), pole_lat_deg=90.0)
    np.testing.assert_allclose(b, [0.0, -_b_equator(R_GEO), 0.0], atol=1e-12 * 1e-7)
    assert 100e-9 < _b_equator(R_GEO) < 110e-9


@pytest.mark.parametrize("lon_deg", [-137.2, -75.2, 0.0, 60.0, 105.0])
def test_geo_tilted_dipole_orbit_frame(lon_deg):
    b = geo_field_orbit_frame(np.deg2rad(lon_deg))
    mag = np.linalg.norm(b)
    # At GEO the IGRF dipole gives ~100-110 nT; the tilt (9.2 deg) keeps y dominant.
    assert 100e-9 < mag < 110e-9
    assert b[1] < 0.0 and abs(b[1]) > 0.9 * mag
    # Independent dipole relations with sin(magnetic latitude) = cos(pole lat) cos(lon - pole
    # lon) on the equator: |B| = B_eq sqrt(1 + 3 sin^2), upward B_r = -2 B_eq sin (so the
    # nadir component is +2 B_eq sin).
    sin_lat = np.cos(np.deg2rad(POLE_LAT_DEG)) * np.cos(np.deg2rad(lon_deg - POLE_LON_DEG))
    b_eq = _b_equator(R_GEO)
    assert mag == pytest.approx(b_eq * np.sqrt(1 + 3 * sin_lat**2), rel=1e-12)
    assert b[2] == pytest.approx(2.0 * b_eq * sin_lat, abs=1e-12 * b_eq)
    # East component = B_eq (dipole axis . east) = B_eq cos(pole lat) sin(pole lon - lon).
    east = np.cos(np.deg2rad(POLE_LAT_DEG)) * np.sin(np.deg2rad(POLE_LON_DEG - lon_deg))
    assert b[0] == pytest.approx(b_eq * east, abs=1e-12 * b_eq)
