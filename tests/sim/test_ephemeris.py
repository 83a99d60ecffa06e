"""Tests for sim.ephemeris against published reference values (sources and tolerances inline)."""

from datetime import UTC, datetime, timedelta, timezone

import numpy as np
import pytest

from sim.ephemeris import (
    AU_M,
    R_EARTH_M,
    R_SUN_M,
    gmst_rad,
    julian_date,
    parse_epoch,
    shadow_factor,
    sun_position_eci,
)

GEO_RADIUS_M = 42_164_170.0
SIDEREAL_DAY_S = 86164.0905  # mean sidereal day (IERS / Astronomical Almanac)


def _ra_dec_deg(unit):
    ra = np.rad2deg(np.arctan2(unit[..., 1], unit[..., 0])) % 360.0
    dec = np.rad2deg(np.arcsin(unit[..., 2]))
    return ra, dec


def _angle_diff_deg(a, b):
    return (a - b + 180.0) % 360.0 - 180.0


# ---------------------------------------------------------------- epochs and Julian dates


def test_parse_epoch_zulu_and_offset():
    assert parse_epoch("2026-03-20T12:00:00Z") == datetime(2026, 3, 20, 12, tzinfo=UTC)
    shifted = parse_epoch("2026-03-20T14:00:00+02:00")
    assert shifted == datetime(2026, 3, 20, 12, tzinfo=UTC)
    assert shifted.utcoffset() == timedelta(0)


@pytest.mark.parametrize(
    "bad", ["", "yesterday", "2026-13-01T00:00:00Z", "2026-03-20T12:00:00", 20260320]
)
def test_parse_epoch_rejects_bad_input(bad):
    with pytest.raises(ValueError):
        parse_epoch(bad)


@pytest.mark.parametrize(
    ("epoch", "jd_expected"),
    [
        (datetime(2000, 1, 1, 12, tzinfo=UTC), 2451545.0),  # J2000.0 by definition
        (datetime(1970, 1, 1, tzinfo=UTC), 2440587.5),  # Unix epoch
        # Meeus, Astronomical Algorithms, example 7.a: 1957 Oct 4.81 -> JD 2436116.31
        (datetime(1957, 10, 4, 19, 26, 24, tzinfo=UTC), 2436116.31),
        # Vallado example 3-5: 1992 Aug 20 12:14 UT1 -> JD 2448855.009722
        (datetime(1992, 8, 20, 12, 14, tzinfo=UTC), 2448855.009722),
    ],
)
def test_julian_date_published(epoch, jd_expected):
    assert julian_date(epoch) == pytest.approx(jd_expected, abs=1e-6)


def test_julian_date_converts_offsets_and_rejects_naive():
    """J2000.0 is exact: the offset is applied to the datetime and the elapsed time from
    J2000 is an exact zero before the one float addition."""
    plus_two = timezone(timedelta(hours=2))
    assert julian_date(datetime(2000, 1, 1, 14, tzinfo=plus_two)) == 2451545.0
    with pytest.raises(ValueError):
        julian_date(datetime(2000, 1, 1, 12))


# ---------------------------------------------------------------- sidereal time


def test_gmst_vallado_example_3_5():
    # Vallado, Fundamentals of Astrodynamics and Applications, example 3-5:
    # 1992 Aug 20 12:14 UT1 -> GMST = 152.578787810 deg.
    jd = julian_date(datetime(1992, 8, 20, 12, 14, tzinfo=UTC))
    assert np.rad2deg(gmst_rad(jd)) == pytest.approx(152.578787810, abs=1e-6)


def test_gmst_at_j2000():
    # GMST at 2000 Jan 1 12h UT1 = 280.46061837 deg (IAU 1982; Meeus eq. 12.4).
    assert np.rad2deg(gmst_rad(2451545.0)) == pytest.approx(280.46061837, abs=1e-6)


def test_gmst_vectorized_wrapped_and_sidereal_rate():
    jd = 2451545.0 + np.linspace(-20000.0, 20000.0, 12).reshape(3, 4)
    theta = gmst_rad(jd)
    assert theta.shape == (3, 4)
    assert np.all((theta >= 0.0) & (theta < 2.0 * np.pi))
    # One mean sidereal day later GMST is back where it started (to < 0.001 s of time).
    later = gmst_rad(jd + SIDEREAL_DAY_S / 86400.0)
    wrapped = np.angle(np.exp(1j * (later - theta)))
    assert np.max(np.abs(wrapped)) < 2.0 * np.pi * 1e-3 / SIDEREAL_DAY_S


# ---------------------------------------------------------------- Sun position


def test_sun_meeus_example_25a():
    # Meeus, Astronomical Algorithms, example 25.a: 1992 Oct 13.0 TD (JD 2448908.5),
    # apparent RA 13h13m31.4s, Dec -7d47'06", R = 0.99766 AU. The almanac formulas claim
    # 0.01 deg; they omit nutation (here ~0.004 deg), hence the 0.01 deg tolerance.
    unit, dist = sun_position_eci(2448908.5)
    ra, dec = _ra_dec_deg(unit)
    assert _angle_diff_deg(ra, 15.0 * (13 + 13 / 60 + 31.4 / 3600)) == pytest.approx(0, abs=0.01)
    assert dec == pytest.approx(-(7 + 47 / 60 + 6 / 3600), abs=0.01)
    assert dist / AU_M == pytest.approx(0.99766, abs=1e-4)


def test_sun_march_equinox_2026():
    # March equinox 2026-03-20 14:46 UTC (USNO): apparent longitude 0, so RA = Dec = 0.
    unit, _ = sun_position_eci(julian_date(parse_epoch("2026-03-20T14:46:00Z")))
    ra, dec = _ra_dec_deg(unit)
    assert _angle_diff_deg(ra, 0.0) == pytest.approx(0.0, abs=0.01)
    assert dec == pytest.approx(0.0, abs=0.01)


def test_sun_june_solstice_2026():
    # June solstice 2026-06-21 08:24 UTC (USNO): RA = 90 deg, Dec = true obliquity of date,
    # 23.4359 deg (IAU 2006 mean obliquity for 2026.5) +/- 0.003 deg nutation.
    unit, _ = sun_position_eci(julian_date(parse_epoch("2026-06-21T08:24:00Z")))
    ra, dec = _ra_dec_deg(unit)
    assert ra == pytest.approx(90.0, abs=0.01)
    assert dec == pytest.approx(23.4359, abs=0.01)


def test_sun_distance_perihelion_and_aphelion_2026():
    # Earth's perihelion is in early January at 0.9833 AU (e.g. IMCCE: 0.983327 AU on
    # 2006-01-04); aphelion in early July at 1.0167 AU. Tolerance 1e-4 AU covers the lunar
    # perturbation that the almanac series omits.
    jd0 = julian_date(parse_epoch("2026-01-01T00:00:00Z"))
    jd = jd0 + np.arange(0.0, 365.0, 1.0 / 24.0)
    _, dist = sun_position_eci(jd)
    i_min, i_max = np.argmin(dist), np.argmax(dist)
    assert dist[i_min] / AU_M == pytest.approx(0.9833, abs=1e-4)
    assert 1.0 <= jd[i_min] - jd0 <= 4.0  # January 2-4
    assert dist[i_max] / AU_M == pytest.approx(1.0167, abs=1e-4)
    assert 183.0 <= jd[i_max] - jd0 <= 189.0  # July 3-7


def test_sun_vectorized_unit_vectors():
    jd = 2451545.0 + np.arange(20.0).reshape(4, 5) * 37.3
    unit, dist = sun_position_eci(jd)
    assert unit.shape == (4, 5, 3) and dist.shape == (4, 5)
    # A few ulps of 1 (measured 1.1e-16).
    np.testing.assert_allclose(np.linalg.norm(unit, axis=-1), 1.0, atol=1e-13)
    assert np.all((dist > 0.983 * AU_M) & (dist < 1.017 * AU_M))


# ---------------------------------------------------------------- Earth shadow

SUN_X = np.array([1.0, 0.0, 0.0])
SUN_DIST = AU_M


@pytest.mark.parametrize("model", ["cylindrical", "conical"])
def test_shadow_sunlit_and_behind_earth(model):
    """Full Sun and umbra are the models' exact branch values 1.0 and 0.0 (structural, so
    compared with ==)."""
    sunward = shadow_factor(7.0e6 * SUN_X, SUN_X, SUN_DIST, model=model)
    side = shadow_factor(np.array([0.0, GEO_RADIUS_M, 0.0]), SUN_X, SUN_DIST, model=model)
    behind = shadow_factor(-GEO_RADIUS_M * SUN_X, SUN_X, SUN_DIST, model=model)
    assert sunward == 1.0 and side == 1.0
    assert behind == 0.0


def test_shadow_unknown_model():
    with pytest.raises(ValueError, match="unknown shadow model"):
        shadow_factor(-GEO_RADIUS_M * SUN_X, SUN_X, SUN_DIST, model="dual-cone")


def _cone_radii(behind_m):
    """Umbra and penumbra radii [m] at a distance behind the Earth (similar-triangle cones)."""
    sin_u = (R_SUN_M - R_EARTH_M) / SUN_DIST
    sin_p = (R_SUN_M + R_EARTH_M) / SUN_DIST
    umbra = R_EARTH_M / np.sqrt(1 - sin_u**2) - behind_m * np.tan(np.arcsin(sin_u))
    penumbra = R_EARTH_M / np.sqrt(1 - sin_p**2) + behind_m * np.tan(np.arcsin(sin_p))
    return umbra, penumbra


def test_shadow_penumbra_geometry_monotone_and_models_agree_outside():
    """Outside the penumbra both models return their exact branch values 0.0 or 1.0, so
    equality there is structural; inside, the conical factor is strictly between."""
    # Sweep the distance from the shadow axis at GEO distance behind the Earth.
    behind = GEO_RADIUS_M
    perp = np.linspace(0.0, 2.0 * R_EARTH_M, 4001)
    r = np.stack([-behind * np.ones_like(perp), perp, np.zeros_like(perp)], axis=-1)
    conical = shadow_factor(r, SUN_X, SUN_DIST)
    cylindrical = shadow_factor(r, SUN_X, SUN_DIST, model="cylindrical")
    umbra_r, penumbra_r = _cone_radii(behind)
    margin = 1.0e3  # 1 km, far above float error, far below the ~400 km penumbra width

    assert np.all((conical >= 0.0) & (conical <= 1.0))
    assert np.all(np.diff(conical) >= 0.0)
    assert np.all(conical[perp < umbra_r - margin] == 0.0)
    assert np.all(conical[perp > penumbra_r + margin] == 1.0)
    inside = (perp > umbra_r + margin) & (perp < penumbra_r - margin)
    assert np.all((conical[inside] > 0.0) & (conical[inside] < 1.0))
    outside = ~((perp > umbra_r - margin) & (perp < penumbra_r + margin))
    np.testing.assert_array_equal(conical[outside], cylindrical[outside])
    # The cylinder edge lies inside the penumbra, where part of the Sun is hidden.
    assert umbra_r < R_EARTH_M < penumbra_r


def test_shadow_broadcasting():
    """Broadcast shapes; the values are the exact branch values 1.0 and 0.0."""
    r = np.array([[0.0, GEO_RADIUS_M, 0.0], [-GEO_RADIUS_M, 0.0, 0.0]])
    for model in ("conical", "cylindrical"):
        np.testing.assert_array_equal(shadow_factor(r, SUN_X, SUN_DIST, model=model), [1, 0])
    many_suns = np.broadcast_to(SUN_X, (2, 3))
    assert shadow_factor(r[0], many_suns, np.full(2, SUN_DIST)).shape == (2,)


def _geo_day(epoch_text, step_s=5.0):
    """Shadow factors over one day for a GEO satellite at 75.2 W, starting at the epoch."""
    t = np.arange(0.0, 86400.0, step_s)
    jd = julian_date(parse_epoch(epoch_text)) + t / 86400.0
    angle = gmst_rad(jd) + np.deg2rad(-75.2)
    r = GEO_RADIUS_M * np.stack([np.cos(angle), np.sin(angle), np.zeros_like(angle)], axis=-1)
    sun_unit, sun_dist = sun_position_eci(jd)
    return (
        shadow_factor(r, sun_unit, sun_dist),
        shadow_factor(r, sun_unit, sun_dist, model="cylindrical"),
        step_s / 60.0,
    )


def test_geo_eclipse_duration_at_equinox():
    # Published GEO eclipse at equinox: ~72 min including penumbra, ~69 min full shadow
    # (e.g. Wertz & Larson, SMAD; Agrawal, Design of Geosynchronous Spacecraft).
    conical, cylindrical, dt_min = _geo_day("2026-03-20T14:46:00Z")
    total = np.count_nonzero(conical < 1.0) * dt_min
    umbra = np.count_nonzero(conical == 0.0) * dt_min
    cyl = np.count_nonzero(cylindrical == 0.0) * dt_min
    assert 65.0 <= total <= 75.0
    assert 65.0 <= cyl <= 75.0
    assert umbra < cyl < total
    assert 1.5 <= (total - umbra) / 2.0 <= 3.0  # each penumbra crossing takes ~2 min


def test_no_geo_eclipse_at_june_solstice():
    conical, cylindrical, _ = _geo_day("2026-06-21T08:24:00Z")
    assert np.all(conical == 1.0)
    assert np.all(cylindrical == 1.0)
