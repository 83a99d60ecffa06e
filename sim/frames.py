"""Attitude parameterisations and the orbit reference frame (docs/conventions.md).

Conventions, pinned by docs/conventions.md and relied on by the tests:

* Rotation matrices are *frame* rotations (passive): ``C_BR`` maps a vector's
  reference-frame components into body-frame components, ``v_B = C_BR @ v_R``.
* The attitude is the 3-1-2 sequence yaw ψ, roll φ, pitch θ (paper Section 2):
  ``C_BR = R2(θ) @ R1(φ) @ R3(ψ)``.
* Quaternions are scalar-last, ``q = [q1, q2, q3, q4]`` with ``q4 = cos(angle/2)``,
  and ``A(q)`` is the frame rotation of Markley & Crassidis, *Fundamentals of
  Spacecraft Attitude Determination and Control* (2014), Eq. 2.125:
  ``A(q) = (q4² − |q₁:₃|²) I + 2 q₁:₃ q₁:₃ᵀ − 2 q4 [q₁:₃×]``.

Every function here is pure numpy and broadcasts over leading dimensions.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from dynprop.eom import gyrostat

MU_EARTH_M3PS2 = 3.986004418e14
GEO_RADIUS_M = 42_164_170.0


def _rot(axis: int, angle) -> np.ndarray:
    a = np.asarray(angle, dtype=float)
    c, s = np.cos(a), np.sin(a)
    m = np.zeros(a.shape + (3, 3))
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    m[..., axis, axis] = 1.0
    m[..., i, i] = c
    m[..., j, j] = c
    m[..., i, j] = s
    m[..., j, i] = -s
    return m


def rot1(angle) -> np.ndarray:
    """Frame rotation about x: ``R1(a) = [[1,0,0],[0,c,s],[0,−s,c]]``."""
    return _rot(0, angle)


def rot2(angle) -> np.ndarray:
    """Frame rotation about y: ``R2(a) = [[c,0,−s],[0,1,0],[s,0,c]]``."""
    return _rot(1, angle)


def rot3(angle) -> np.ndarray:
    """Frame rotation about z: ``R3(a) = [[c,s,0],[−s,c,0],[0,0,1]]``."""
    return _rot(2, angle)


def dcm_from_euler312(yaw, roll, pitch) -> np.ndarray:
    """``C_BR = R2(pitch) R1(roll) R3(yaw)`` (docs/conventions.md)."""
    return rot2(pitch) @ rot1(roll) @ rot3(yaw)


def rotate_312(yaw, roll, pitch, v: np.ndarray) -> np.ndarray:
    """``C_BR v`` per row for (N,) angles and (N, 3) vectors, ``dcm_from_euler312``'s
    rotation applied one axis at a time (R3, then R1, then R2) in elementwise
    arithmetic: a fifth of the time of the stacked matrices, and no BLAS kernel
    choosing the rounding."""
    v = np.asarray(v, dtype=float)
    c, s = np.cos(yaw), np.sin(yaw)
    x, y = c * v[:, 0] + s * v[:, 1], c * v[:, 1] - s * v[:, 0]
    c, s = np.cos(roll), np.sin(roll)
    y, z = c * y + s * v[:, 2], c * v[:, 2] - s * y
    c, s = np.cos(pitch), np.sin(pitch)
    out = np.empty(v.shape)
    out[:, 0] = c * x - s * z
    out[:, 1] = y
    out[:, 2] = s * x + c * z
    return out


def nadir_body(roll, pitch) -> np.ndarray:
    """The nadir z_R in body axes, C_BR's third column, (N, 3): for C_BR = R2(θ) R1(φ)
    R3(ψ) it does not depend on yaw."""
    cr, sr = np.cos(roll), np.sin(roll)
    cp, sp = np.cos(pitch), np.sin(pitch)
    return np.column_stack([-sp * cr, sr, cp * cr])


def euler312_rates(euler_rad: np.ndarray, w_br: np.ndarray) -> np.ndarray:
    """(ψ̇, φ̇, θ̇) (N, 3) from the 3-1-2 angles (yaw, roll, pitch) and ω_BR in body
    axes, (N, 3) each (``eom.gyrostat.euler312_rates``)."""
    _, roll, pitch = euler_rad.T
    return np.column_stack(gyrostat.euler312_rates(roll, pitch, w_br[:, 0], w_br[:, 1],
                                                   w_br[:, 2]))


def rate_wrt_orbit(c_br: np.ndarray, w_bn: np.ndarray, omega0_radps: float) -> np.ndarray:
    """ω_BR = ω_BN − C_BR ω_RN (body axes, (N, 3)): the orbit frame turns at −ω0
    about y_R, so ω_BR = ω_BN + ω0 · C_BR's second column."""
    return w_bn + omega0_radps * c_br[:, :, 1]


def euler312_from_dcm(c: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return ``(yaw, roll, pitch)`` in rad from ``C_BR``.

    The angles are docs/conventions.md's: φ = asin(C[1,2]), ψ = atan2(−C[1,0], C[1,1]),
    θ = atan2(−C[0,2], C[2,2]).  They are *computed* more stably: ψ from row 1,
    then ``M = C R3(ψ)ᵀ = R2(θ) R1(φ)``, whose entries give φ = atan2(M[1,2], M[1,1])
    and θ = atan2(M[2,0], M[0,0]) without the asin's loss of precision near
    roll = ±90°.  θ absorbs any round-off in ψ, so DCM → angles → DCM is exact to
    round-off even at gimbal lock, where only ψ ± θ is defined: there ψ is whatever
    the round-off in row 1 gives (0 for an exact matrix) and θ takes up the rest.
    """
    c = np.asarray(c, dtype=float)
    yaw = np.arctan2(-c[..., 1, 0], c[..., 1, 1])
    m = c @ np.swapaxes(rot3(yaw), -1, -2)
    roll = np.arctan2(m[..., 1, 2], m[..., 1, 1])
    pitch = np.arctan2(m[..., 2, 0], m[..., 0, 0])
    return yaw, roll, pitch


def skew(v: np.ndarray) -> np.ndarray:
    """Cross-product matrix ``[v×]`` so that ``skew(a) @ b == cross(a, b)``."""
    v = np.asarray(v, dtype=float)
    m = np.zeros(v.shape[:-1] + (3, 3))
    m[..., 0, 1], m[..., 0, 2] = -v[..., 2], v[..., 1]
    m[..., 1, 0], m[..., 1, 2] = v[..., 2], -v[..., 0]
    m[..., 2, 0], m[..., 2, 1] = -v[..., 1], v[..., 0]
    return m


def dcm_from_quat(q: np.ndarray) -> np.ndarray:
    """Attitude matrix ``A(q)`` of a scalar-last unit quaternion (Markley Eq. 2.125)."""
    q = np.asarray(q, dtype=float)
    # Contiguous component arrays, written out element by element: several times
    # faster than the matrix form on day-long (N, 3, 3) histories.
    q1, q2, q3, q4 = np.ascontiguousarray(np.moveaxis(q, -1, 0))
    m = np.empty(q.shape[:-1] + (3, 3))
    m[..., 0, 0] = q1 * q1 - q2 * q2 - q3 * q3 + q4 * q4
    m[..., 1, 1] = -q1 * q1 + q2 * q2 - q3 * q3 + q4 * q4
    m[..., 2, 2] = -q1 * q1 - q2 * q2 + q3 * q3 + q4 * q4
    m[..., 0, 1] = 2 * (q1 * q2 + q3 * q4)
    m[..., 0, 2] = 2 * (q1 * q3 - q2 * q4)
    m[..., 1, 0] = 2 * (q1 * q2 - q3 * q4)
    m[..., 1, 2] = 2 * (q2 * q3 + q1 * q4)
    m[..., 2, 0] = 2 * (q1 * q3 + q2 * q4)
    m[..., 2, 1] = 2 * (q2 * q3 - q1 * q4)
    return m


def quat_from_dcm(c: np.ndarray) -> np.ndarray:
    """Scalar-last quaternion from a rotation matrix, sign fixed so that ``q4 ≥ 0``.

    Uses Shepperd's method (pick the largest of the four squared components) so
    the result stays accurate for every rotation, including 180° ones.
    """
    c = np.asarray(c, dtype=float)
    tr = np.trace(c, axis1=-2, axis2=-1)
    cand = np.stack([c[..., 0, 0], c[..., 1, 1], c[..., 2, 2], tr], axis=-1)
    k = np.argmax(cand, axis=-1)
    q = np.empty(c.shape[:-2] + (4,))
    # Each branch writes the quaternion scaled by 4*q_k; it is normalised below.
    b0 = k == 0
    b1 = k == 1
    b2 = k == 2
    b3 = k == 3
    q[b0] = np.stack([1 + 2 * c[b0, 0, 0] - tr[b0], c[b0, 0, 1] + c[b0, 1, 0],
                      c[b0, 0, 2] + c[b0, 2, 0], c[b0, 1, 2] - c[b0, 2, 1]], axis=-1)
    q[b1] = np.stack([c[b1, 1, 0] + c[b1, 0, 1], 1 + 2 * c[b1, 1, 1] - tr[b1],
                      c[b1, 1, 2] + c[b1, 2, 1], c[b1, 2, 0] - c[b1, 0, 2]], axis=-1)
    q[b2] = np.stack([c[b2, 2, 0] + c[b2, 0, 2], c[b2, 2, 1] + c[b2, 1, 2],
                      1 + 2 * c[b2, 2, 2] - tr[b2], c[b2, 0, 1] - c[b2, 1, 0]], axis=-1)
    q[b3] = np.stack([c[b3, 1, 2] - c[b3, 2, 1], c[b3, 2, 0] - c[b3, 0, 2],
                      c[b3, 0, 1] - c[b3, 1, 0], 1 + tr[b3]], axis=-1)
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    return np.where(q[..., 3:4] < 0, -q, q)


def quat_from_euler312(yaw, roll, pitch) -> np.ndarray:
    """Scalar-last quaternion of ``C_BR = R2(pitch) R1(roll) R3(yaw)``."""
    return quat_from_dcm(dcm_from_euler312(yaw, roll, pitch))


def euler312_from_quat(q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(yaw, roll, pitch)`` in rad from a scalar-last quaternion."""
    return euler312_from_dcm(dcm_from_quat(q))


def quat_multiply(q: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Composition with ``A(q ⊗ p) = A(q) A(p)`` (Markley Eq. 2.82b, scalar-last)."""
    q = np.asarray(q, dtype=float)
    p = np.asarray(p, dtype=float)
    qv, q4 = q[..., :3], q[..., 3:4]
    pv, p4 = p[..., :3], p[..., 3:4]
    vec = q4 * pv + p4 * qv - np.cross(qv, pv)
    return np.concatenate([vec, q4 * p4 - np.sum(qv * pv, axis=-1, keepdims=True)], axis=-1)


def orbit_frame_dcm(r: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``C_RN`` whose rows are the reference-frame axes in inertial components.

    z_R = −r̂ (nadir), y_R = −(r×v)/|r×v| (negative orbit normal),
    x_R = y_R × z_R (roughly along the velocity), docs/conventions.md.
    """
    r = np.asarray(r, dtype=float)
    v = np.asarray(v, dtype=float)
    z = -r / np.linalg.norm(r, axis=-1, keepdims=True)
    h = np.cross(r, v)
    y = -h / np.linalg.norm(h, axis=-1, keepdims=True)
    x = np.cross(y, z)
    return np.stack([x, y, z], axis=-2)


@dataclass(frozen=True)
class GeoOrbit:
    """Circular, equatorial, prograde geosynchronous orbit at a fixed east longitude.

    The satellite's inertial right ascension is ``gmst(epoch) + longitude + ω0 t``.
    Using ω0 = √(μ/R³) both for the orbit and for the Earth's spin keeps the
    sub-satellite longitude fixed; at the default radius the two rates differ by
    under 1e-6 relative, which is far below what the attitude problem can see.
    """

    longitude_rad: float = np.deg2rad(-75.0)
    radius_m: float = GEO_RADIUS_M
    mu_m3ps2: float = MU_EARTH_M3PS2

    def __post_init__(self) -> None:
        if not np.isfinite(self.longitude_rad):
            raise ValueError("orbit longitude must be finite")
        if not (np.isfinite(self.radius_m) and self.radius_m > 6.4e6):
            raise ValueError("orbit radius must be finite and above the Earth's surface")

    @property
    def rate_radps(self) -> float:
        """Orbit rate ω0 = √(μ/R³), ≈ 7.2921e-5 rad/s at GEO."""
        return float(np.sqrt(self.mu_m3ps2 / self.radius_m**3))

    def right_ascension(self, t_s, gmst0_rad: float) -> np.ndarray:
        return gmst0_rad + self.longitude_rad + self.rate_radps * np.asarray(t_s, dtype=float)

    def position_velocity(self, t_s, gmst0_rad: float) -> tuple[np.ndarray, np.ndarray]:
        """Inertial position (m) and velocity (m/s), shape ``t.shape + (3,)``."""
        a = self.right_ascension(t_s, gmst0_rad)
        c, s = np.cos(a), np.sin(a)
        zero = np.zeros_like(a)
        r = self.radius_m * np.stack([c, s, zero], axis=-1)
        v = self.radius_m * self.rate_radps * np.stack([-s, c, zero], axis=-1)
        return r, v

    def orbit_frame(self, t_s, gmst0_rad: float) -> np.ndarray:
        """``C_RN`` at the given times, in closed form for the equatorial orbit:
        x_R = (−sin α, cos α, 0), y_R = (0, 0, −1), z_R = (−cos α, −sin α, 0).
        Equal to ``orbit_frame_dcm(*position_velocity(...))`` (tested)."""
        a = self.right_ascension(t_s, gmst0_rad)
        c, s = np.cos(a), np.sin(a)
        m = np.zeros(a.shape + (3, 3))
        m[..., 0, 0], m[..., 0, 1] = -s, c
        m[..., 1, 2] = -1.0
        m[..., 2, 0], m[..., 2, 1] = -c, -s
        return m
