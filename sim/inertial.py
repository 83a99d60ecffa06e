"""The body attitude against EME2000, from the attitude against the orbit frame R: what
an attitude ephemeris (CCSDS AEM) exchanges.

C_{B←EME2000} = C_BR(ψ, φ, θ) · C_RN(t) · P(t): the 3-1-2 angles (docs/conventions.md,
"Attitude"), the run's own orbit frame (``GeoOrbit.orbit_frame``, from GMST of date)
and the IAU 1976 precession from the mean equator and equinox of date to J2000
(``ephemeris.precession_matrix``).  Nutation (≤ 1e-4 rad) and UT1 − UTC (≤ 7e-5 rad)
are left out, as in ``ephemeris``: they move the model satellite against the real
slot and cancel when two exports (truth, estimate) are differenced.

``orbit_frame_from_inertial`` is the way back, for an attitude read from another tool's
AEM: C_BR = C_{B←EME2000} · (C_RN(t) P(t))ᵀ.
"""

from __future__ import annotations

import numpy as np

from . import ephemeris, frames


def orbit_frame_from_eme2000(t_s, orbit: frames.GeoOrbit, epoch) -> np.ndarray:
    """C_{R←EME2000} = C_RN(t) · P(t) (N, 3, 3): the orbit frame R against EME2000 at
    ``t_s`` (s) after ``epoch`` (an aware datetime, ``ephemeris.julian_date``)."""
    t = np.asarray(t_s, dtype=float)
    jd0 = ephemeris.julian_date(epoch)
    return orbit.orbit_frame(t, ephemeris.gmst_rad(jd0)) @ ephemeris.precession_matrix(
        jd0 + t / 86400.0)


def inertial_quaternions(t_s, roll, pitch, yaw, orbit: frames.GeoOrbit, epoch) -> np.ndarray:
    """q_{B←EME2000} (N, 4, scalar-last) from the 3-1-2 angles (rad) at ``t_s`` (s) after
    ``epoch``: C_BR(ψ, φ, θ) · ``orbit_frame_from_eme2000``."""
    return frames.quat_from_dcm(frames.dcm_from_euler312(yaw, roll, pitch)
                                @ orbit_frame_from_eme2000(t_s, orbit, epoch))


def orbit_frame_quaternions(roll, pitch, yaw) -> np.ndarray:
    """q_BR (N, 4): the attitude against the orbit frame R (CCSDS LVLH_ROTATING)."""
    return frames.quat_from_euler312(yaw, roll, pitch)


def orbit_frame_from_inertial(t_s, q_bj, orbit: frames.GeoOrbit, epoch) -> np.ndarray:
    """q_BR (N, 4) from q_{B←EME2000} (N, 4, scalar-last) at ``t_s`` after ``epoch``: the
    inverse of ``inertial_quaternions``, C_BR = C_{B←EME2000} · (C_RN(t) P(t))ᵀ."""
    c_rj = orbit_frame_from_eme2000(t_s, orbit, epoch)
    return frames.quat_from_dcm(frames.dcm_from_quat(q_bj) @ np.swapaxes(c_rj, -1, -2))
