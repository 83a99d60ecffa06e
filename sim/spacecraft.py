"""Spacecraft mass properties and wheel configurations (paper Sections 2 and 2.3).

``inertia_kgm2`` is the inertia *tensor* of the whole spacecraft with its wheels
locked (docs/conventions.md): off-diagonal entries are tensor elements, i.e. the
negatives of the products of inertia.  Wheel speeds are relative to the body.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

RPM = 2.0 * np.pi / 60.0  # rad/s per rpm

# Paper Section 2: diagonal of the GOES-Next inertia tensor, kg m^2.
GOES_NEXT_INERTIA_KGM2 = ((3364.376, 0.0, 0.0), (0.0, 954.936, 0.0), (0.0, 0.0, 3461.393))
GOES_NEXT_WHEEL_INERTIA_KGM2 = 0.1082    # Section 2.3
GOES_NEXT_CANT_DEG = 1.656               # Section 2.3
GOES_NEXT_WHEEL_SPEED_RPM = 5485.0       # Section 2.3
GOES_NEXT_YAW_WHEEL_INERTIA_KGM2 = 0.008626  # Section 2.3, backup reaction wheel


@dataclass(frozen=True)
class Wheel:
    """One wheel: spin inertia (kg m²), unit spin axis in body axes, speed (rad/s)."""

    spin_inertia_kgm2: float
    axis: tuple[float, float, float]
    speed_radps: float

    def __post_init__(self) -> None:
        a = np.asarray(self.axis, dtype=float)
        if a.shape != (3,) or not np.all(np.isfinite(a)):
            raise ValueError("wheel axis must be three finite numbers")
        if abs(np.linalg.norm(a) - 1.0) > 1e-9:
            raise ValueError(f"wheel axis must be a unit vector, |a| = {np.linalg.norm(a)}")
        if not (np.isfinite(self.spin_inertia_kgm2) and self.spin_inertia_kgm2 > 0):
            raise ValueError("wheel spin inertia must be positive")
        if not np.isfinite(self.speed_radps):
            raise ValueError("wheel speed must be finite")

    @property
    def momentum_Nms(self) -> np.ndarray:
        return self.spin_inertia_kgm2 * self.speed_radps * np.asarray(self.axis)


def check_inertia(j: np.ndarray, name: str = "inertia") -> np.ndarray:
    """Validate an inertia tensor; return it as a float array or raise ``ValueError``.

    A physical tensor is symmetric and positive definite, and its principal
    moments obey the triangle inequality (each ≤ the sum of the other two).
    """
    j = np.asarray(j, dtype=float)
    if j.shape != (3, 3):
        raise ValueError(f"{name} must be a 3x3 matrix, got shape {j.shape}")
    if not np.all(np.isfinite(j)):
        raise ValueError(f"{name} contains NaN or infinity")
    scale = np.max(np.abs(j))
    if not np.allclose(j, j.T, rtol=0.0, atol=1e-9 * scale):
        raise ValueError(f"{name} is not symmetric")
    eig = np.linalg.eigvalsh(j)
    if eig[0] <= 0.0:
        raise ValueError(f"{name} is not positive definite (smallest eigenvalue {eig[0]:.6g})")
    if eig[2] > eig[0] + eig[1] + 1e-9 * scale:
        raise ValueError(f"{name} violates the triangle inequality (principal moments {eig})")
    return j


@dataclass(frozen=True)
class Spacecraft:
    """Rigid body plus wheels.  ``inertia_kgm2`` is the locked-wheel tensor J.

    ``standby_wheel``, the index of a yaw reaction wheel (axis ±z) carried idle as the
    backup of the others' yaw control: no command until a wheel switch
    (``sim.control.wheel_allocation``); the others alone must span the y–z plane."""

    inertia_kgm2: tuple[tuple[float, float, float], ...] = GOES_NEXT_INERTIA_KGM2
    wheels: tuple[Wheel, ...] = field(default_factory=lambda: goes_next_wheels())
    standby_wheel: int | None = None

    def __post_init__(self) -> None:
        check_inertia(np.asarray(self.inertia_kgm2))
        if len(self.wheels) < 1:
            raise ValueError("a momentum-biased spacecraft needs at least one wheel")
        flying = [i for i in range(self.n_wheels) if i != self.standby_wheel]
        if np.linalg.matrix_rank(self.wheel_axes[flying, 1:]) < 2:
            raise ValueError("wheel axes must span the body y-z plane (pitch and yaw momentum)")
        if self.standby_wheel is not None:
            if not 0 <= self.standby_wheel < self.n_wheels:
                raise ValueError(f"standby wheel {self.standby_wheel} is not one of the "
                                 f"{self.n_wheels} wheels")
            if abs(abs(self.wheel_axes[self.standby_wheel, 2]) - 1.0) > 1e-9:
                raise ValueError("the standby wheel must be a yaw wheel, its axis along ±z")

    @property
    def J(self) -> np.ndarray:
        return np.asarray(self.inertia_kgm2, dtype=float)

    @property
    def wheel_axes(self) -> np.ndarray:
        """Spin axes as rows, shape (n_wheels, 3)."""
        return np.array([w.axis for w in self.wheels], dtype=float)

    @property
    def wheel_inertias(self) -> np.ndarray:
        return np.array([w.spin_inertia_kgm2 for w in self.wheels], dtype=float)

    @property
    def wheel_speeds(self) -> np.ndarray:
        return np.array([w.speed_radps for w in self.wheels], dtype=float)

    @property
    def n_wheels(self) -> int:
        return len(self.wheels)

    def wheel_momentum(self, speeds_radps: np.ndarray | None = None) -> np.ndarray:
        """Σ I_w Ω_i a_i in body axes (N m s); ``speeds`` may carry leading dims."""
        speeds = self.wheel_speeds if speeds_radps is None else np.asarray(speeds_radps)
        return (speeds * self.wheel_inertias) @ self.wheel_axes

    def pitch_bias_Nms(self, speeds_radps: np.ndarray | None = None) -> np.ndarray:
        """H: the body-y wheel momentum (Eq. 1; negative for GOES-Next)."""
        return self.wheel_momentum(speeds_radps)[..., 1]

    def yaw_momentum_Nms(self, speeds_radps: np.ndarray | None = None) -> np.ndarray:
        """h: the body-z wheel momentum (Eq. 2)."""
        return self.wheel_momentum(speeds_radps)[..., 2]

    def momentum_factors(self, axis: int) -> np.ndarray:
        """k_i = I_w,i a_i[axis]: the wheels' momentum along body ``axis`` is Σ k_i Ω_i
        (axis 2: h of Eq. 2, from the tachometers; axis 1: H of Eq. 1)."""
        return self.wheel_inertias * self.wheel_axes[:, axis]

    def speeds_with_yaw_momentum(self, speeds_radps: np.ndarray, h_Nms: np.ndarray,
                                 h_new_Nms: np.ndarray) -> np.ndarray:
        """Wheel speeds (N, n) carrying yaw momentum ``h_new`` instead of ``h``: the
        smallest (minimum-norm) change of the speeds, k (h_new − h)/|k|²."""
        k = self.momentum_factors(2)
        return speeds_radps + np.outer(h_new_Nms - h_Nms, k / (k @ k))


def canted_axes(cant_deg: float) -> tuple[tuple[float, float, float], ...]:
    """The two momentum-wheel axes of docs/conventions.md, canted ±cant from −y."""
    if not (np.isfinite(cant_deg) and 0.0 <= cant_deg < 90.0):
        raise ValueError("wheel cant must be in [0, 90) deg")
    c, s = np.cos(np.deg2rad(cant_deg)), np.sin(np.deg2rad(cant_deg))
    return (0.0, -c, s), (0.0, -c, -s)


def goes_next_wheels(spin_inertia_kgm2: float = GOES_NEXT_WHEEL_INERTIA_KGM2,
                     cant_deg: float = GOES_NEXT_CANT_DEG,
                     speed_rpm: float = GOES_NEXT_WHEEL_SPEED_RPM) -> tuple[Wheel, Wheel]:
    """Two canted momentum wheels at equal speed: H ≈ −124.2 N m s, h = 0."""
    a1, a2 = canted_axes(cant_deg)
    return (Wheel(spin_inertia_kgm2, a1, speed_rpm * RPM),
            Wheel(spin_inertia_kgm2, a2, speed_rpm * RPM))


def goes_next(inertia_kgm2=GOES_NEXT_INERTIA_KGM2, standby_yaw_wheel_inertia_kgm2=None,
              **wheel_kwargs) -> Spacecraft:
    """GOES-Next in its nominal two-momentum-wheel configuration; with
    ``standby_yaw_wheel_inertia_kgm2``, also carrying the backup yaw reaction wheel
    along +z, idle at 0 rpm (wheel 3, the ``standby_wheel``) until a wheel switch."""
    wheels = goes_next_wheels(**wheel_kwargs)
    if standby_yaw_wheel_inertia_kgm2 is None:
        return Spacecraft(inertia_kgm2=inertia_kgm2, wheels=wheels)
    rw = Wheel(standby_yaw_wheel_inertia_kgm2, (0.0, 0.0, 1.0), 0.0)
    return Spacecraft(inertia_kgm2=inertia_kgm2, wheels=(*wheels, rw), standby_wheel=2)


def goes_next_backup(inertia_kgm2=GOES_NEXT_INERTIA_KGM2,
                     spin_inertia_kgm2: float = GOES_NEXT_WHEEL_INERTIA_KGM2,
                     cant_deg: float = GOES_NEXT_CANT_DEG,
                     speed_rpm: float = GOES_NEXT_WHEEL_SPEED_RPM,
                     yaw_wheel_inertia_kgm2: float = GOES_NEXT_YAW_WHEEL_INERTIA_KGM2,
                     ) -> Spacecraft:
    """Backup configuration (Section 2.3): one canted momentum wheel plus a yaw
    reaction wheel along +z, whose speed cancels the momentum wheel's yaw
    component so that h = 0 and the pitch bias is halved."""
    a1, _ = canted_axes(cant_deg)
    mw = Wheel(spin_inertia_kgm2, a1, speed_rpm * RPM)
    rw_speed = -mw.momentum_Nms[2] / yaw_wheel_inertia_kgm2
    return Spacecraft(inertia_kgm2=inertia_kgm2,
                      wheels=(mw, Wheel(yaw_wheel_inertia_kgm2, (0.0, 0.0, 1.0), rw_speed)))
