"""Tilted-dipole geomagnetic field, and its value in a geostationary orbit reference frame.

Pure numpy functions, vectorized over leading dimensions; SI units (metres, radians unless a
name says ``_deg``, tesla, A m^2).

Source of the numbers: IGRF-14 (IAGA Working Group V-MOD, released Nov 2024), epoch 2025.0
degree-1 Gauss coefficients g10 = -29350.0 nT, g11 = -1410.3 nT, h11 = 4545.5 nT at reference
radius a = 6371.2 km. The n = 1 potential V = a^3 (g10 z + g11 x + h11 y) / r^3 is exactly a
centred dipole with

- B0 = sqrt(g10^2 + g11^2 + h11^2) = 29733 nT (equatorial surface field at r = a),
- |m| = 4 pi a^3 B0 / mu0 = 7.690e22 A m^2,
- north geomagnetic pole at (90 deg - acos(-g10/B0), atan2(-h11, -g11)) = (80.79 N, 72.76 W).

Those derived values are the defaults below, so moment and pole stay mutually consistent. The
often-quoted 7.72e22 A m^2 corresponds to IGRF epoch 2015 (0.4 % stronger).

What the dipole leaves out, measured against IGRF-14 to degree 13 at r = 42 164 km on the
equator (epochs 2025.0-2026.9; ppigrf 2.1's IGRF14.shc):

- the higher degrees (2-13) add 3.3 % of the field at 75 deg W (0.9 deg in direction) and up
  to 5.9 % (2.7 deg in direction) around the GEO belt, the largest near 19 deg W;
- the dipole itself weakens by 0.054 % per year (B0 = 29 733 nT at 2025.0, 29 653 nT at
  2030.0 from the secular variation), 0.3 % over the 2025-2030 model span;
- magnetospheric currents, which no internal-field model holds, add tens of nT at GEO
  against the dipole's 103-106 nT, varying with local time and activity.
"""

from __future__ import annotations

import numpy as np

from .frames import GEO_RADIUS_M

MU0_OVER_4PI = 1.0e-7
"""mu0 / (4 pi) [T m / A] (exact in the pre-2019 SI; the 2019 change is ~1e-10 relative)."""
IGRF_REF_RADIUS_M = 6_371_200.0
"""IGRF reference radius a [m]."""
IGRF14_2025_G10_T = -29350.0e-9
IGRF14_2025_G11_T = -1410.3e-9
IGRF14_2025_H11_T = 4545.5e-9

_B0_T = float(np.sqrt(IGRF14_2025_G10_T**2 + IGRF14_2025_G11_T**2 + IGRF14_2025_H11_T**2))
DIPOLE_MOMENT_AM2 = IGRF_REF_RADIUS_M**3 * _B0_T / MU0_OVER_4PI
"""Dipole moment magnitude [A m^2] from IGRF-14 2025.0, about 7.690e22."""
POLE_LAT_DEG = 90.0 - float(np.rad2deg(np.arccos(-IGRF14_2025_G10_T / _B0_T)))
"""North geomagnetic pole latitude [deg], about 80.79."""
POLE_LON_DEG = float(np.rad2deg(np.arctan2(-IGRF14_2025_H11_T, -IGRF14_2025_G11_T)))
"""North geomagnetic pole east longitude [deg], about -72.76."""


def dipole_moment_ecef(
    moment_Am2=DIPOLE_MOMENT_AM2, pole_lat_deg=POLE_LAT_DEG, pole_lon_deg=POLE_LON_DEG
):
    """Dipole moment vector m [A m^2] in the Earth-fixed frame.

    m points toward the geomagnetic SOUTH pole (antipode of the given north geomagnetic pole),
    which is what makes field lines leave the southern hemisphere and the equatorial field
    point north.
    """
    lat = np.deg2rad(pole_lat_deg)
    lon = np.deg2rad(pole_lon_deg)
    north_axis = np.array([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)])
    return -moment_Am2 * north_axis


def dipole_field_ecef(
    r_ecef_m, moment_Am2=DIPOLE_MOMENT_AM2, pole_lat_deg=POLE_LAT_DEG, pole_lon_deg=POLE_LON_DEG
):
    """Centred tilted-dipole magnetic field B [T] in the Earth-fixed frame.

    B = mu0/(4 pi) (3 (m . r_hat) r_hat - m) / |r|^3 with m from :func:`dipole_moment_ecef`.

    Args:
        r_ecef_m: position(s) in the Earth-fixed frame [m], shape (..., 3), nonzero.
        moment_Am2: dipole moment magnitude [A m^2] (default IGRF-14 2025.0, see module doc).
        pole_lat_deg, pole_lon_deg: north geomagnetic pole latitude / east longitude [deg].

    Returns:
        B [T], shape (..., 3).
    """
    r = np.asarray(r_ecef_m, dtype=float)
    m = dipole_moment_ecef(moment_Am2, pole_lat_deg, pole_lon_deg)
    r_norm = np.linalg.norm(r, axis=-1, keepdims=True)
    r_hat = r / r_norm
    m_dot_r = np.sum(r_hat * m, axis=-1, keepdims=True)
    return MU0_OVER_4PI * (3.0 * m_dot_r * r_hat - m) / r_norm**3


def geo_orbit_frame_axes(longitude_rad):
    """Orbit reference frame R axes, in ECEF, of a geostationary satellite at east longitude.

    z_R = nadir (-r_hat), y_R = negative orbit normal (-z_ECEF, the orbit being equatorial
    and prograde), x_R = y_R x z_R = local east (along the velocity).

    Returns:
        Array of shape (..., 3, 3) whose rows are x_R, y_R, z_R in ECEF, i.e. the rotation
        matrix taking ECEF components to R components.
    """
    lon = np.asarray(longitude_rad, dtype=float)
    zeros = np.zeros_like(lon)
    r_hat = np.stack([np.cos(lon), np.sin(lon), zeros], axis=-1)
    y_axis = np.broadcast_to(np.array([0.0, 0.0, -1.0]), r_hat.shape)
    z_axis = -r_hat
    x_axis = np.cross(y_axis, z_axis)
    return np.stack([x_axis, y_axis, z_axis], axis=-2)


def geo_field_orbit_frame(longitude_rad, radius_m=GEO_RADIUS_M, **dipole_kwargs):
    """Dipole field [T] in the orbit reference frame R of a geostationary satellite.

    The satellite is fixed in ECEF at (radius, 0 deg latitude, ``longitude_rad`` east), so
    the field in R is constant. With an axial dipole it is (0, -|B|, 0), |B| ~ 103 nT. With
    the 9.2 deg IGRF tilt the magnetic latitude reaches 9.2 deg near 73 W / 107 E, where the
    radial part gives a z_R component of up to 2 sin(9.2 deg) ~ 0.32 of the equatorial
    field (about 33 nT) and |B| rises to ~106 nT. Ninety degrees away in longitude the
    declination reaches 9.2 deg instead, giving an x_R (east) component of about 16 nT.

    Args:
        longitude_rad: east longitude(s) of the sub-satellite point [rad], any shape.
        radius_m: orbit radius [m], default geostationary 42164.17 km.
        **dipole_kwargs: passed to :func:`dipole_field_ecef` (moment_Am2, pole_*_deg).

    Returns:
        B in frame R [T], shape ``longitude_rad.shape + (3,)``.
    """
    axes = geo_orbit_frame_axes(longitude_rad)
    r_ecef = -radius_m * axes[..., 2, :]
    b_ecef = dipole_field_ecef(r_ecef, **dipole_kwargs)
    return np.einsum("...ij,...j->...i", axes, b_ecef)
