"""Time, Earth rotation, Sun position and Earth-shadow models.

Pure numpy functions, vectorized over leading (time) dimensions. SI units throughout:
radians, metres, seconds; Julian dates are in days.

Accuracy is that of the low-precision almanac formulas (about 0.01 deg for the Sun direction),
which is ample for attitude sensing and solar-torque/eclipse modelling; nutation, polar motion
and the UT1-UTC / TT-UTC differences are deliberately ignored (each is below that level or
shifts eclipse edges by at most about a second).
"""

from __future__ import annotations

from datetime import UTC, datetime, timedelta

import numpy as np

AU_M = 149_597_870_700.0
"""Astronomical unit [m] (IAU 2012 Resolution B2)."""
R_EARTH_M = 6_378_137.0
"""Earth equatorial radius [m] (WGS-84), used as the occulting sphere."""
R_SUN_M = 695_700_000.0
"""Nominal solar radius [m] (IAU 2015 Resolution B3)."""
JD_J2000 = 2_451_545.0
"""Julian date of the J2000.0 epoch, 2000-01-01T12:00 [days]."""

_J2000_UTC = datetime(2000, 1, 1, 12, 0, 0, tzinfo=UTC)
_TWO_PI = 2.0 * np.pi


def parse_epoch(text: str) -> datetime:
    """Parse an ISO 8601 timestamp with an explicit zone into a timezone-aware UTC datetime.

    Accepts e.g. ``"2026-03-20T12:00:00Z"`` or ``"2026-03-20T14:00:00+02:00"`` (converted to
    UTC). A timestamp without a zone designator is rejected rather than guessed, because
    silently taking local time would shift the Sun by up to a day's worth of rotation.

    Raises:
        ValueError: if ``text`` is not a string, is not ISO 8601, or has no UTC offset.
    """
    if not isinstance(text, str):
        raise ValueError(f"epoch must be an ISO 8601 string, got {type(text).__name__}")
    try:
        parsed = datetime.fromisoformat(text.strip())
    except ValueError as exc:
        raise ValueError(
            f"invalid epoch {text!r}: expected ISO 8601 such as '2026-03-20T12:00:00Z'"
        ) from exc
    if parsed.tzinfo is None or parsed.utcoffset() is None:
        raise ValueError(
            f"epoch {text!r} has no timezone; append 'Z' (UTC) or an offset like '+00:00'"
        )
    return parsed.astimezone(UTC)


def julian_date(epoch_utc: datetime) -> float:
    """Julian date [days] of a timezone-aware datetime (UTC scale, no leap-second smearing).

    Computed as an exact timedelta from J2000.0 so the only rounding is the final float
    conversion (resolution about 40 microseconds at current dates).

    Raises:
        ValueError: if ``epoch_utc`` is naive (its zone would otherwise be guessed).
    """
    if epoch_utc.tzinfo is None or epoch_utc.utcoffset() is None:
        raise ValueError("julian_date needs a timezone-aware datetime (e.g. tzinfo=UTC)")
    return JD_J2000 + (epoch_utc - _J2000_UTC) / timedelta(days=1)


def gmst_rad(jd_ut1):
    """Greenwich mean sidereal time [rad] in [0, 2*pi), IAU 1982 model.

    GMST[s] = 67310.54841 + (876600 h + 8640184.812866) T + 0.093104 T^2 - 6.2e-6 T^3,
    T = (JD_UT1 - 2451545.0) / 36525 (Vallado, "Fundamentals of Astrodynamics and
    Applications", eq. 3-47). UTC may be passed for UT1 (|UT1-UTC| < 0.9 s, i.e. < 0.004 deg).

    Args:
        jd_ut1: Julian date(s) on the UT1 scale [days], any shape.
    """
    days = np.asarray(jd_ut1, dtype=float) - JD_J2000
    t_cent = days / 36525.0
    # The 876600 h * T term equals 86400 s * days, a whole number of turns per day, so only
    # the fractional day is kept: this avoids losing ~1e-7 s of precision to a 3e9 s term.
    seconds = (
        67310.54841
        + 86400.0 * np.mod(days, 1.0)
        + t_cent * (8640184.812866 + t_cent * (0.093104 - 6.2e-6 * t_cent))
    )
    return np.mod(seconds * (_TWO_PI / 86400.0), _TWO_PI)


def sun_position_eci(jd):
    """Sun direction and distance in the mean-equator-of-date inertial frame.

    Source: Astronomical Almanac, section C, low-precision formulas for the Sun, accuracy
    about 0.01 deg 1950-2050. With n = JD - 2451545.0:

    - mean longitude L = 280.460 deg + 0.9856474 deg n (includes aberration),
    - mean anomaly g = 357.528 deg + 0.9856003 deg n,
    - ecliptic longitude lambda = L + 1.915 deg sin g + 0.020 deg sin 2g, latitude 0,
    - obliquity eps = 23.439 deg - 0.0000004 deg n,
    - distance R = 1.00014 - 0.01671 cos g - 0.00014 cos 2g [AU].

    The frame has x toward the (mean) equinox of date and z toward the north celestial pole.
    The almanac argument is TT; passing UTC shifts the Sun by < 0.001 deg.

    Args:
        jd: Julian date(s) [days], any shape.

    Returns:
        (unit_vector, distance_m): arrays of shape ``jd.shape + (3,)`` and ``jd.shape`` [m].
    """
    n = np.asarray(jd, dtype=float) - JD_J2000
    mean_lon = np.deg2rad(280.460 + 0.9856474 * n)
    g = np.deg2rad(357.528 + 0.9856003 * n)
    ecl_lon = mean_lon + np.deg2rad(1.915 * np.sin(g) + 0.020 * np.sin(2.0 * g))
    eps = np.deg2rad(23.439 - 4.0e-7 * n)
    sin_lon = np.sin(ecl_lon)
    unit = np.stack([np.cos(ecl_lon), np.cos(eps) * sin_lon, np.sin(eps) * sin_lon], axis=-1)
    dist_au = 1.00014 - 0.01671 * np.cos(g) - 0.00014 * np.cos(2.0 * g)
    return unit, dist_au * AU_M


def _cylindrical(r_sat, sun_unit):
    along = np.sum(r_sat * sun_unit, axis=-1)
    perp = np.linalg.norm(r_sat - along[..., None] * sun_unit, axis=-1)
    return np.where((along < 0.0) & (perp < R_EARTH_M), 0.0, 1.0)


def _conical(r_sat, sun_unit, sun_dist):
    sat_to_sun = sun_unit * sun_dist[..., None] - r_sat
    d_sun = np.linalg.norm(sat_to_sun, axis=-1)
    d_earth = np.linalg.norm(r_sat, axis=-1)
    # Apparent angular radii of the Sun (a) and Earth (b) and their centre separation (c),
    # as in Montenbruck & Gill (2000) sec. 3.4.2; atan2 keeps c accurate near 0 and pi.
    a = np.arcsin(np.clip(R_SUN_M / d_sun, 0.0, 1.0))
    b = np.arcsin(np.clip(R_EARTH_M / d_earth, 0.0, 1.0))
    to_earth = -r_sat
    c = np.arctan2(
        np.linalg.norm(np.cross(to_earth, sat_to_sun), axis=-1),
        np.sum(to_earth * sat_to_sun, axis=-1),
    )

    # Area of overlap of two discs, same section. The separation is clamped to the partial range
    # so that points handled by the other branches below still evaluate without warnings.
    cp = np.maximum(np.clip(c, np.abs(a - b), a + b), 1e-12)
    x = (cp * cp + a * a - b * b) / (2.0 * cp)
    y = np.sqrt(np.maximum(a * a - x * x, 0.0))
    overlap = (
        a * a * np.arccos(np.clip(x / a, -1.0, 1.0))
        + b * b * np.arccos(np.clip((cp - x) / b, -1.0, 1.0))
        - cp * y
    )
    partial = 1.0 - overlap / (np.pi * a * a)

    return np.select(
        [c >= a + b, c <= b - a, c <= a - b],
        # no occultation, total (umbra), annular (Earth disc inside the Sun's: only far away)
        [1.0, 0.0, 1.0 - (b * b) / (a * a)],
        default=np.clip(partial, 0.0, 1.0),
    )


def shadow_factor(r_sat_m, sun_unit, sun_dist_m, model="conical"):
    """Fraction of the solar disc visible from a satellite, Earth as the occulting body.

    1 means full Sun, 0 means umbra (or cylindrical shadow). Inputs broadcast over leading
    dimensions and must share one inertial frame centred on the Earth.

    Models (Montenbruck & Gill, "Satellite Orbits", 2000, section 3.4.2):

    - ``"cylindrical"``: 0 if the satellite is behind the Earth (r . s < 0) and closer than
      R_earth = 6378137 m to the Sun-Earth axis, else 1.
    - ``"conical"``: umbra/penumbra from the overlap area of the apparent discs of the Sun
      (radius 695700 km) and the Earth, giving a continuous factor in [0, 1].

    Args:
        r_sat_m: satellite position [m], shape (..., 3).
        sun_unit: unit vector from the Earth's centre to the Sun, shape (..., 3).
        sun_dist_m: Earth-Sun distance [m], shape (...).
        model: ``"conical"`` (default) or ``"cylindrical"``.

    Returns:
        Visible fraction, shape of the broadcast leading dimensions.

    Raises:
        ValueError: for an unknown model.
    """
    r_sat = np.asarray(r_sat_m, dtype=float)
    s_hat = np.asarray(sun_unit, dtype=float)
    dist = np.asarray(sun_dist_m, dtype=float)
    if model == "cylindrical":
        return _cylindrical(r_sat, s_hat)
    if model == "conical":
        lead = np.broadcast_shapes(r_sat.shape[:-1], s_hat.shape[:-1], dist.shape)
        r_sat = np.broadcast_to(r_sat, lead + (3,))
        s_hat = np.broadcast_to(s_hat, lead + (3,))
        dist = np.broadcast_to(dist, lead)
        # Only points behind the Earth and within the penumbra cone's reach can be
        # shadowed; evaluating the disc-overlap formula there alone keeps day-long
        # 0.512 s grids cheap.  The margin is twice the penumbra's widening.
        along = np.sum(r_sat * s_hat, axis=-1)
        perp = np.linalg.norm(r_sat - along[..., None] * s_hat, axis=-1)
        reach = R_EARTH_M + 2.0 * np.linalg.norm(r_sat, axis=-1) * R_SUN_M / dist
        near = (along < 0.0) & (perp < reach)
        out = np.ones(lead)
        out[near] = _conical(r_sat[near], s_hat[near], dist[near])
        return out
    raise ValueError(f"unknown shadow model {model!r}; expected 'conical' or 'cylindrical'")


_ARCSEC = np.pi / 648000.0


def precession_matrix(jd):
    """C_{MOD←EME2000} at Julian date(s) ``jd``: the IAU 1976 precession (Lieske 1977;
    SOFA ``iauPmat76``), P = R3(−z) R2(θ) R3(−ζ), ~0.37° in 2026.  UTC stands in for TT
    in the argument (< 1e-9 rad).  dynprop's N is the mean equator and equinox of date
    (the GMST above), so P carries it to EME2000 (docs/conventions.md, "Frames")."""
    from .frames import rot2, rot3
    t = (np.asarray(jd, dtype=float) - JD_J2000) / 36525.0
    zeta = (2306.2181 + (0.30188 + 0.017998 * t) * t) * t * _ARCSEC
    z = (2306.2181 + (1.09468 + 0.018203 * t) * t) * t * _ARCSEC
    theta = (2004.3109 + (-0.42665 - 0.041833 * t) * t) * t * _ARCSEC
    return rot3(-z) @ rot2(theta) @ rot3(-zeta)
