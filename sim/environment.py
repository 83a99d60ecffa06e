"""Environment-torque parameters (paper Section 2.2), each switchable on and off.

The torque *laws* are symbolic and live in ``eom.gyrostat``; this module holds
the frozen parameter sets and the numbers behind their defaults.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import geomag


def _finite_vector(v, name: str, n: int = 3) -> None:
    a = np.asarray(v, dtype=float)
    if a.shape != (n,) or not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be {n} finite numbers")


@dataclass(frozen=True)
class GravityGradient:
    """``3μ/R³ · n̂ × J n̂`` with the full inertia tensor (products included)."""

    enabled: bool = True


@dataclass(frozen=True)
class SolarTorque:
    """Solar-array / solar-sail imbalance with an adjustable trim tab (Section 2.2).

    The torque is ``κ · d̂ × ŝ · (1 AU / r)² · shadow``, with d̂ the array-to-sail
    centre-of-pressure direction (≈ the pitch axis) and ŝ the unit vector to the
    Sun.  It is fixed inertially, so its body roll and yaw components are
    sinusoids at the orbit rate, 90° apart, of amplitude |κ| cos(declination).

    The imbalance coefficient is ``κ = untrimmed − effectiveness · tab``:
    untrimmed = 5e-5 N m is the equinox amplitude of the paper's Fig. 2, and an
    effectiveness of 2.5e-6 N m/deg lets the tab reach any residual between
    1e-7 and 1e-5 N m (either sign) within ±25° of full trim at 20°.  The default
    tab of 19.6° leaves a 1e-6 N m residual.

    The array's offset angle is a second actuator (GOES I-M momentum management,
    US patent 5,996,942).  Turning the array by δ from Sun-normal tilts its
    radiation force out of the Sun line, towards d̂ × ŝ; with the array-to-sail
    lever along d̂ the torque is along d̂ × (d̂ × ŝ) = −ŝ⊥, where ŝ⊥ = ŝ − (d̂·ŝ) d̂
    is the Sun direction in the plane normal to d̂.  It is written
    ``κ_o · ŝ⊥ · (1 AU / r)² · shadow``, ``κ_o = untrimmed_offset − offset_effectiveness · δ``,
    perpendicular to the tab's torque in the same (orbit) plane, so the two
    actuators together reach any torque in that plane.  ``untrimmed_offset`` is the
    imbalance along ŝ⊥ with the array Sun-normal (0 by default: the paper's model
    has none); 5e-7 N m/deg is an assumed effectiveness, a fifth of the tab's,
    for a ±10° offset range.
    """

    enabled: bool = True
    untrimmed_torque_Nm: float = 5e-5
    tab_effectiveness_Nm_per_deg: float = 2.5e-6
    trim_tab_deg: float = 19.6
    lever_axis: tuple[float, float, float] = (0.0, 1.0, 0.0)
    array_offset_deg: float = 0.0
    offset_effectiveness_Nm_per_deg: float = 5e-7
    untrimmed_offset_torque_Nm: float = 0.0

    def __post_init__(self) -> None:
        _finite_vector(self.lever_axis, "solar lever axis")
        if abs(np.linalg.norm(self.lever_axis) - 1.0) > 1e-9:
            raise ValueError("solar lever axis must be a unit vector")
        for name in ("untrimmed_torque_Nm", "tab_effectiveness_Nm_per_deg", "trim_tab_deg",
                     "array_offset_deg", "offset_effectiveness_Nm_per_deg",
                     "untrimmed_offset_torque_Nm"):
            if not np.isfinite(getattr(self, name)):
                raise ValueError(f"solar {name} must be finite")

    @property
    def coefficient_Nm(self) -> float:
        """Signed residual imbalance κ at 1 AU (N m)."""
        return self.untrimmed_torque_Nm - self.tab_effectiveness_Nm_per_deg * self.trim_tab_deg

    @property
    def offset_coefficient_Nm(self) -> float:
        """Signed imbalance κ_o along ŝ⊥ at 1 AU (N m), the array offset's actuator."""
        return self.untrimmed_offset_torque_Nm \
            - self.offset_effectiveness_Nm_per_deg * self.array_offset_deg

    @classmethod
    def with_residual(cls, residual_Nm: float, **kwargs) -> SolarTorque:
        """The tab setting that leaves the requested signed residual κ."""
        base = cls(**kwargs)
        tab = (base.untrimmed_torque_Nm - residual_Nm) / base.tab_effectiveness_Nm_per_deg
        return cls(**{**kwargs, "trim_tab_deg": tab})


@dataclass(frozen=True)
class MagneticTorque:
    """Residual and control dipoles crossed with a tilted-dipole field (Section 2.2).

    The residual dipole defaults to 8 A m² along pitch, the body direction
    closest to the ≈105 nT GEO field.  The paper quotes both "about 8 A m²" and
    "at most 1e-7 N m"; those agree only for a dipole within ~7° of the local
    field.  Along pitch at 75°W the tilted field still gives 2.6e-7 N m
    (docs/paper-errata.md, entry 5).

    ``profile_*`` adds a prescribed, slowly varying control dipole
    ``A sin(2π t / period + phase)`` per body axis, on top of any closed-loop
    torquer command from ``sim.control``.
    """

    enabled: bool = True
    residual_dipole_Am2: tuple[float, float, float] = (0.0, 8.0, 0.0)
    profile_amplitude_Am2: tuple[float, float, float] = (0.0, 0.0, 0.0)
    profile_period_s: float = 86164.0905
    profile_phase_rad: float = 0.0
    pole_lat_deg: float = geomag.POLE_LAT_DEG
    pole_lon_deg: float = geomag.POLE_LON_DEG
    earth_dipole_Am2: float = geomag.DIPOLE_MOMENT_AM2

    def __post_init__(self) -> None:
        _finite_vector(self.residual_dipole_Am2, "residual dipole")
        _finite_vector(self.profile_amplitude_Am2, "control-dipole profile amplitude")
        if not (np.isfinite(self.profile_period_s) and self.profile_period_s > 0):
            raise ValueError("control-dipole profile period must be positive")

    def profile(self, t_s: np.ndarray) -> np.ndarray:
        """Prescribed control dipole (A m², body axes), shape ``t.shape + (3,)``."""
        t = np.asarray(t_s, dtype=float)
        s = np.sin(2.0 * np.pi * t / self.profile_period_s + self.profile_phase_rad)
        return s[..., None] * np.asarray(self.profile_amplitude_Am2)


@dataclass(frozen=True)
class WheelRipple:
    """Wheel torque ripple, white, per wheel (Section 2.3).

    ``psd_Nm2_per_Hz`` is read as a one-sided density G (the usual way wheel
    vendors quote ripple).  A white torque of intensity q, E[w(t)w(t')] = q δ(t−t'),
    has one-sided density G = 2q, so q = G/2.  Held constant over each step Δt, its
    discrete variance is q/Δt (the variance that gives the same momentum random
    walk, q·t), i.e. σ² = G / (2 Δt): 5.9e-7 (N m)² at 0.512 s.
    """

    enabled: bool = True
    psd_Nm2_per_Hz: float = 6e-7

    def __post_init__(self) -> None:
        if not (np.isfinite(self.psd_Nm2_per_Hz) and self.psd_Nm2_per_Hz >= 0):
            raise ValueError("ripple PSD must be finite and non-negative")

    def intensity_Nm2s(self) -> float:
        """White-noise intensity q = G/2, (N m)² s."""
        return 0.5 * self.psd_Nm2_per_Hz if self.enabled else 0.0

    def step_sigma_Nm(self, dt_s: float) -> float:
        return float(np.sqrt(self.intensity_Nm2s() / dt_s))


@dataclass(frozen=True)
class Environment:
    gravity_gradient: GravityGradient = field(default_factory=GravityGradient)
    solar: SolarTorque = field(default_factory=SolarTorque)
    magnetic: MagneticTorque = field(default_factory=MagneticTorque)
    ripple: WheelRipple = field(default_factory=WheelRipple)
    shadow_model: str = "conical"

    def __post_init__(self) -> None:
        if self.shadow_model not in ("conical", "cylindrical", "none"):
            raise ValueError("shadow_model must be 'conical', 'cylindrical' or 'none'")

    @classmethod
    def torque_free(cls) -> Environment:
        return cls(GravityGradient(False), SolarTorque(enabled=False),
                   MagneticTorque(enabled=False), WheelRipple(enabled=False))
