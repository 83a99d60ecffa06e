"""The body attitude against EME2000, from the attitude against the orbit frame R: what
an attitude ephemeris (CCSDS AEM) exchanges.

C_{B←EME2000} = C_BR(ψ, φ, θ) · C_RN(t) · P(t): the 3-1-2 angles (docs/conventions.md,
"Attitude"), the run's own orbit frame (``GeoOrbit.orbit_frame``, from GMST of date)
and the IAU 1976 precession from the mean equator and equinox of date to J2000
(``ephemeris.precession_matrix``).  Nutation (≤ 1e-4 rad) and UT1 − UTC (≤ 7e-5 rad)
are left out, as in ``ephemeris``: they move the model satellite against the real
slot and cancel when two exports (truth, estimate) are differenced.
"""

from __future__ import annotations

from datetime import UTC, datetime

import numpy as np

from . import ephemeris, frames


def _epoch(epoch) -> datetime:
    if isinstance(epoch, str):
        return ephemeris.parse_epoch(epoch)
    if isinstance(epoch, np.datetime64):
        epoch = epoch.astype("datetime64[us]").astype(datetime)
    return epoch if epoch.tzinfo else epoch.replace(tzinfo=UTC)


def inertial_quaternions(t_s, roll, pitch, yaw, orbit: frames.GeoOrbit, epoch) -> np.ndarray:
    """q_{B←EME2000} (N, 4, scalar-last) from the 3-1-2 angles (rad) at ``t_s`` (s) after
    ``epoch`` (UTC: a datetime, numpy datetime64 or ISO text)."""
    t = np.asarray(t_s, dtype=float)
    jd0 = ephemeris.julian_date(_epoch(epoch))
    c_bn = frames.dcm_from_euler312(yaw, roll, pitch) @ orbit.orbit_frame(
        t, ephemeris.gmst_rad(jd0))
    return frames.quat_from_dcm(c_bn @ ephemeris.precession_matrix(jd0 + t / 86400.0))


def orbit_frame_quaternions(roll, pitch, yaw) -> np.ndarray:
    """q_BR (N, 4): the attitude against the orbit frame R (CCSDS LVLH_ROTATING)."""
    return frames.quat_from_euler312(yaw, roll, pitch)
