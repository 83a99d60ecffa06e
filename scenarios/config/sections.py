"""The scenario's physical sections: the spacecraft, its orbit and initial state,
the environment, the control and the sensors (docs/scenario-reference.md).

Defaults are GOES-Next's from the paper, read from the simulator's own parameter
dataclasses so that the two can never disagree.  Models are strict: unknown keys,
wrong types, NaN and infinity are errors, and each error carries its key path.
"""

from __future__ import annotations

from typing import Annotated, Literal

import numpy as np
from dynprop.sim import control as sim_control
from dynprop.sim import disturbance as sim_disturbance
from dynprop.sim import environment as sim_env
from dynprop.sim import sensors, spacecraft
from dynprop.sim.ephemeris import parse_epoch
from dynprop.sim.frames import GeoOrbit
from dynprop.sim.telemetry import MIN_SUN_SEPARATION_DEG
from pydantic import BaseModel, ConfigDict, Field, Strict, field_validator, model_validator

from .screen import TelemetryScreen

# The simulator's dataclasses hold the GOES-Next defaults; the schema reads them
# from there so that the two can never disagree.
_SOLAR = sim_env.SolarTorque()
_MAG = sim_env.MagneticTorque()
_RIPPLE = sim_env.WheelRipple()
_DISTURBANCE = sim_disturbance.Disturbance()
_CTRL = sim_control.Control()
_EARTH = sensors.EarthSensor()
_TACH = sensors.Tachometer()

# Elements stay strict (an int is a float; a string or bool is not), while the
# containers accept YAML lists.
_Float = Annotated[float, Strict()]
Vec3 = Annotated[tuple[_Float, _Float, _Float], Strict(False)]
Matrix3 = Annotated[tuple[Vec3, Vec3, Vec3], Strict(False)]


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False, frozen=True)


class Wheels(_Section):
    """The two canted momentum wheels (paper Section 2.3)."""

    spin_inertia_kgm2: float = Field(spacecraft.GOES_NEXT_WHEEL_INERTIA_KGM2, gt=0,
                                     description="spin-axis inertia of each wheel (kg m²)")
    cant_deg: float = Field(spacecraft.GOES_NEXT_CANT_DEG, ge=0, lt=90,
                            description="cant of each wheel axis from −y in the y–z plane (deg)")
    speed_rpm: float = Field(spacecraft.GOES_NEXT_WHEEL_SPEED_RPM,
                             description="nominal speed of each wheel relative to the body; not "
                             "zero, since a momentum-biased spacecraft needs wheel momentum (rpm)")

    @field_validator("speed_rpm")
    @classmethod
    def _nonzero(cls, v: float) -> float:
        if v == 0:
            raise ValueError("must not be zero: a momentum-biased spacecraft needs wheel momentum")
        return v


class YawWheel(_Section):
    """The backup yaw reaction wheel along +z (Section 2.3)."""

    spin_inertia_kgm2: float = Field(spacecraft.GOES_NEXT_YAW_WHEEL_INERTIA_KGM2, gt=0,
                                     description="spin inertia; the wheel's speed cancels h "
                                     "(kg m²)")
    standby: bool = Field(False, description="the nominal configuration carries it too, "
                          "idle at 0 rpm (wheel 3, its tachometer in telemetry.csv's "
                          "wheel3_rpm and in the filter's h) until a wheel_switch event "
                          "gives it the yaw control")


class Spacecraft(_Section):
    configuration: Literal["nominal", "backup"] = Field(
        "nominal", description="'nominal': two momentum wheels; 'backup': one momentum wheel "
        "plus the yaw reaction wheel")
    inertia_kgm2: Matrix3 = Field(
        spacecraft.GOES_NEXT_INERTIA_KGM2,
        description="locked-wheel inertia tensor in body axes: symmetric, positive definite "
        "and within the triangle inequality; off-diagonals are tensor elements, that is minus "
        "the products of inertia (kg m²)")
    wheels: Wheels = Field(default_factory=Wheels)
    yaw_wheel: YawWheel = Field(default_factory=YawWheel)

    @field_validator("inertia_kgm2")
    @classmethod
    def _physical(cls, v):
        spacecraft.check_inertia(np.asarray(v), "inertia")
        return v


class Orbit(_Section):
    longitude_deg: float = Field(float(np.rad2deg(GeoOrbit().longitude_rad)), ge=-180, le=360,
                                 description="east longitude of the geostationary slot (deg)")
    radius_m: float = Field(GeoOrbit().radius_m, gt=6.6e6, description="orbit radius (m)")


class InitialState(_Section):
    yaw_deg: float = Field(0.0, ge=-180, le=180, description="3-1-2 yaw (deg)")
    roll_deg: float = Field(0.0, gt=-90, lt=90, description="3-1-2 roll (deg)")
    pitch_deg: float = Field(0.0, ge=-180, le=180, description="3-1-2 pitch (deg)")
    rate_wrt_orbit_degps: Vec3 = Field((0.0, 0.0, 0.0),
                                       description="ω_BR in body axes (deg/s)")


class GravityGradient(_Section):
    enabled: bool = Field(True, description="gravity-gradient torque, full inertia tensor")


class Solar(_Section):
    enabled: bool = Field(True, description="solar array/sail imbalance torque, zero in eclipse")
    untrimmed_torque_Nm: float = Field(_SOLAR.untrimmed_torque_Nm,
                                       description="imbalance κ with the tab at 0 (N m)")
    tab_effectiveness_Nm_per_deg: float = Field(_SOLAR.tab_effectiveness_Nm_per_deg,
                                                description="dκ/d(tab) (N m/deg)")
    trim_tab_deg: float = Field(_SOLAR.trim_tab_deg,
                                description="trim tab setting; the residual κ = "
                                "untrimmed − effectiveness · tab is 1e-6 N m by default (deg)")
    lever_axis: Vec3 = Field(_SOLAR.lever_axis,
                             description="array-to-sail centre-of-pressure direction, a unit "
                             "vector in body axes (-)")
    array_offset_deg: float = Field(_SOLAR.array_offset_deg,
                                    description="solar array offset from Sun-normal, the "
                                    "second actuator: torque κ_o ŝ⊥ with κ_o = untrimmed_offset "
                                    "− offset_effectiveness · offset (docs/conventions.md) (deg)")
    offset_effectiveness_Nm_per_deg: float = Field(
        _SOLAR.offset_effectiveness_Nm_per_deg, description="dκ_o/d(offset) (N m/deg)")
    untrimmed_offset_torque_Nm: float = Field(
        _SOLAR.untrimmed_offset_torque_Nm, description="imbalance κ_o along the in-plane Sun "
        "direction ŝ⊥ with the array Sun-normal; 0 in the paper's model (N m)")

    @field_validator("lever_axis")
    @classmethod
    def _unit(cls, v):
        if abs(np.linalg.norm(v) - 1) > 1e-9:
            raise ValueError("must be a unit vector")
        return v


class Magnetic(_Section):
    enabled: bool = Field(True, description="residual and prescribed dipole torques; the "
                          "torquers are control and keep working")
    residual_dipole_Am2: Vec3 = Field(_MAG.residual_dipole_Am2,
                                      description="body-fixed dipole (A m²)")
    profile_amplitude_Am2: Vec3 = Field(_MAG.profile_amplitude_Am2,
                                        description="prescribed control-dipole sine amplitude, "
                                        "per body axis (A m²)")
    profile_period_s: float = Field(_MAG.profile_period_s, gt=0, description="its period (s)")
    profile_phase_deg: float = Field(0.0, description="its phase (deg)")


class Ripple(_Section):
    enabled: bool = Field(True, description="wheel torque ripple, random and independent "
                         "per wheel")
    psd_Nm2_per_Hz: float = Field(_RIPPLE.psd_Nm2_per_Hz, ge=0,
                                  description="one-sided PSD G; step variance G/(2Δt) ((N m)²/Hz)")


class Disturbance(_Section):
    """A random body torque that the filter's model does not contain, independent on
    roll (x), pitch (y) and yaw (z) and held over each step (`sim/disturbance.py`).
    The levels default to the paper's Eq. 45 assumption, about 10% of the equinox
    torque amplitude correlated over a quarter orbit, and act only when `kind` selects
    them. `sensors.noise.enabled: false` turns the disturbance off with every other
    random draw."""

    kind: Literal["none", "white", "gauss_markov"] = Field(
        "none", description="'none'; 'white': white noise of density q_Nm2s; "
        "'gauss_markov': first-order Gauss–Markov of sigma_Nm and correlation_time_s")
    q_Nm2s: Vec3 = Field(_DISTURBANCE.q_Nm2s,
                         description="white: two-sided spectral density per axis, none "
                         "negative, E[w(t)w(t')] = q δ(t−t') (Eq. 35); each step holds a "
                         "draw of variance q/Δt ((N m)² s)")
    sigma_Nm: Vec3 = Field(_DISTURBANCE.sigma_Nm,
                           description="gauss_markov: stationary 1σ per axis, none "
                           "negative (N m)")
    correlation_time_s: float = Field(
        _DISTURBANCE.correlation_time_s, gt=0,
        description="gauss_markov: correlation time τ of the autocorrelation "
        "σ² exp(−|t|/τ); the default is a quarter orbit (s)")

    @field_validator("q_Nm2s", "sigma_Nm")
    @classmethod
    def _non_negative(cls, v):
        if any(x < 0 for x in v):
            raise ValueError("must not be negative")
        return v


class Environment(_Section):
    gravity_gradient: GravityGradient = Field(default_factory=GravityGradient)
    solar: Solar = Field(default_factory=Solar)
    magnetic: Magnetic = Field(default_factory=Magnetic)
    ripple: Ripple = Field(default_factory=Ripple)
    shadow_model: Literal["conical", "cylindrical", "none"] = Field(
        "conical", description="Earth shadow model; 'none' removes eclipses")
    disturbance: Disturbance = Field(default_factory=Disturbance)


class Control(_Section):
    enabled: bool = Field(True, description="all attitude control")
    pitch_loop: bool = Field(True, description="pitch PD loop on the common wheel torque")
    roll_yaw_loop: bool = Field(True, description="roll/yaw loop on the differential torque")
    pitch_bandwidth_radps: float = Field(_CTRL.pitch_bandwidth_radps, ge=0,
                                         description="pitch loop ω_p (rad/s)")
    pitch_damping: float = Field(_CTRL.pitch_damping, ge=0, description="pitch loop ζ (-)")
    roll_gain_per_s: float = Field(_CTRL.roll_gain_per_s,
                                   description="k_r in ḣ = H(k_r φ + k_ṙ φ̇) + k_h h (1/s)")
    roll_rate_gain: float = Field(_CTRL.roll_rate_gain, description="k_ṙ (-)")
    yaw_momentum_gain_per_s: float = Field(_CTRL.yaw_momentum_gain_per_s, description="k_h (1/s)")
    magnetic_unloading: bool = Field(True, description="torquers unload h with the dipole "
                                    "m = B×T/|B|²")
    unloading_gain_per_s: float = Field(_CTRL.unloading_gain_per_s, ge=0,
                                        description="k_m in T_z = −k_m h (1/s)")
    torquer_max_Am2: float = Field(_CTRL.torquer_max_Am2, ge=0,
                                   description="torquer saturation per axis (A m²)")


class Noise(_Section):
    enabled: bool = Field(True, description="false turns every random draw off (sensor noise "
                          "and outliers, wheel ripple and the disturbance torque); "
                          "quantisation stays")


OUTLIER_RATE_TEXT = (
    "fraction of readings that are outliers, each channel (roll, pitch; α, β; each wheel) "
    "drawn on its own at every sample from a stream of its own: an outlier reads true + "
    "bias + noise ± outlier_size · σ, before quantisation; 0 draws nothing (-)")
OUTLIER_SIZE_TEXT = "an outlier's offset from the noisy reading, with a random sign"


class EarthSensor(_Section):
    noise_deg: float = Field(_EARTH.noise_deg, ge=0, description="roll and pitch noise, 1σ (deg)")
    quantum_deg: float = Field(_EARTH.quantum_deg, gt=0,
                               description="roll and pitch quantisation (deg)")
    roll_bias_deg: float = Field(_EARTH.roll_bias_deg, description="constant roll error: "
                                 "measured = quantised(true + bias + noise) (deg)")
    pitch_bias_deg: float = Field(_EARTH.pitch_bias_deg,
                                  description="constant pitch error, likewise (deg)")
    outlier_rate: float = Field(_EARTH.outlier_rate, ge=0, le=1, description=OUTLIER_RATE_TEXT)
    outlier_size: float = Field(_EARTH.outlier_size, ge=0, description=OUTLIER_SIZE_TEXT
                                + "; σ is noise_deg (σ)")


class SunHead(_Section):
    """One Sun-sensor head.  Every key defaults to that head's own GOES-Next value
    (from ``sim.sensors``), so setting one key of a head keeps its others."""

    kind: Literal["dss", "cass"] = Field(description="'dss': digital; 'cass': coarse analog")
    boresight_hour_angle_deg: float = Field(
        description="Sun hour angle from local noon at which the Sun is on the boresight (deg)")
    fov_in_plane_deg: float = Field(gt=0, lt=90, description="half field of view in the "
                                    "body x–z plane (deg)")
    fov_out_of_plane_deg: float = Field(gt=0, lt=90, description="half field of view out of "
                                        "it (deg)")
    quantum_deg: float = Field(gt=0, description="angle quantisation (deg)")
    noise_deg: float = Field(ge=0, description="angle noise 1σ; CASS: on the boresight, "
                             "growing as 1/cos(off-boresight) (deg)")
    in_plane_bias_deg: float = Field(0.0, description="constant error of the in-plane angle "
                                     "α: measured = quantised(true + bias + noise); the "
                                     "ground yaw does not know it (deg)")
    out_of_plane_bias_deg: float = Field(0.0, description="constant error of the "
                                         "out-of-plane angle β, likewise (deg)")
    outlier_rate: float = Field(0.0, ge=0, le=1, description=OUTLIER_RATE_TEXT)
    outlier_size: float = Field(sensors.OUTLIER_SIZE, ge=0, description=OUTLIER_SIZE_TEXT
                                + "; σ is the angle's noise, a CASS's grown off the "
                                "boresight as noise_deg says (σ)")


# GOES-Next heads, from sim.sensors: the DSS on dusk, two CASS.
HEAD_DEFAULTS = {
    h.name: dict(kind=h.kind, boresight_hour_angle_deg=h.boresight_hour_angle_deg,
                 fov_in_plane_deg=h.fov_in_plane_deg, fov_out_of_plane_deg=h.fov_out_of_plane_deg,
                 quantum_deg=h.quantum_deg, noise_deg=h.noise_deg,
                 in_plane_bias_deg=h.in_plane_bias_deg,
                 out_of_plane_bias_deg=h.out_of_plane_bias_deg,
                 outlier_rate=h.outlier_rate, outlier_size=h.outlier_size)
    for h in sensors.goes_next_sun_sensors()
}


class SunSensors(_Section):
    dss: SunHead = Field(default_factory=lambda: SunHead(**HEAD_DEFAULTS["dss"]))
    cass1: SunHead = Field(default_factory=lambda: SunHead(**HEAD_DEFAULTS["cass1"]))
    cass2: SunHead = Field(default_factory=lambda: SunHead(**HEAD_DEFAULTS["cass2"]))
    min_sun_separation_deg: float = Field(MIN_SUN_SEPARATION_DEG, ge=0, lt=90,
                                          description="no ground yaw when "
                                          "the Sun is closer than this to the yaw axis (deg)")

    @model_validator(mode="before")
    @classmethod
    def _fill_heads(cls, data):
        # Each head's keys default to that head's own values, so `dss: {noise_deg: 0.01}`
        # changes only the noise (heads differ, so plain field defaults cannot do this).
        if isinstance(data, dict):
            data = dict(data)
            for name, defaults in HEAD_DEFAULTS.items():
                if isinstance(data.get(name), dict):
                    data[name] = {**defaults, **data[name]}
        return data


class Tachometer(_Section):
    quantum_rpm: float = Field(_TACH.quantum_rpm, gt=0, description="quantisation (rpm)")
    noise_3sigma_rpm: float = Field(_TACH.noise_3sigma_rpm, ge=0, description="noise, 3σ (rpm)")
    bias_rpm: float = Field(_TACH.bias_rpm, description="constant speed error, the same on "
                            "every wheel: measured = quantised(true + bias + noise) (rpm)")
    outlier_rate: float = Field(_TACH.outlier_rate, ge=0, le=1, description=OUTLIER_RATE_TEXT)
    outlier_size: float = Field(_TACH.outlier_size, ge=0, description=OUTLIER_SIZE_TEXT
                                + "; σ is noise_3sigma_rpm / 3 (σ)")


class Sensors(_Section):
    noise: Noise = Field(default_factory=Noise)
    earth: EarthSensor = Field(default_factory=EarthSensor)
    sun: SunSensors = Field(default_factory=SunSensors)
    tachometer: Tachometer = Field(default_factory=Tachometer)


# --------------------------------------------------------------------------- telemetry

AngleUnit = Literal["deg", "rad", "urad"]
SpeedUnit = Literal["rpm", "rad/s"]


def _column(name: str, what: str):
    return Field(name, min_length=1, description=f"the file's column of {what}")


class TelemetryColumns(_Section):
    """The file's column for each quantity, by its name in the file's header (CSV) or
    schema (Parquet); a key left out reads the column of dynprop's own telemetry.csv.
    The time is `t_s` or `time_utc`, whichever the file has (`t_s` when it has both);
    pitch, yaw_sigma, sun_head and maneuver are optional (docs/telemetry.md)."""

    t_s: str = _column("t_s", "time in seconds from the file's epoch (its `# epoch_utc:` "
                       "line or Parquet metadata, else telemetry.epoch_utc, else the "
                       "scenario's epoch_utc)")
    time_utc: str = _column("time_utc", "ISO 8601 UTC time tags (`2026-03-20T12:00:00.512Z`; "
                            "without a zone or with +00:00 also read as UTC; another offset "
                            "is an error), or a Parquet timestamp")
    roll: str = _column("roll_deg", "Earth-sensor roll")
    pitch: str = _column("pitch_deg", "Earth-sensor pitch (optional; the EKF's)")
    yaw: str = _column("yaw_deg", "ground yaw from the Sun sensors, empty where none")
    yaw_sigma: str = _column("yaw_sigma_deg", "each yaw's a-priori 1σ (optional)")
    sun_head: str = _column("sun_head", "the Sun-sensor head of each yaw: 0 (dss), 1 (cass1) "
                            "or 2 (cass2) (optional)")
    maneuver: str = _column("maneuver", "maneuver flags: 1 while a thruster fires, else 0; "
                            "another value is screened (optional)")
    wheel1: str = _column("wheel1_rpm", "wheel 1's tachometer speed")
    wheel2: str = _column("wheel2_rpm", "wheel 2's tachometer speed")


class TelemetryUnits(_Section):
    """The unit of each column as the file holds it, converted on reading to the
    degrees and rpm the rest of dynprop uses (the names' suffixes): `deg`, `rad` or
    `urad` (µrad) for angles, `rpm` or `rad/s` for wheel speeds."""

    roll: AngleUnit = Field("deg", description="unit of telemetry.columns.roll")
    pitch: AngleUnit = Field("deg", description="unit of telemetry.columns.pitch")
    yaw: AngleUnit = Field("deg", description="unit of telemetry.columns.yaw")
    yaw_sigma: AngleUnit = Field("deg", description="unit of telemetry.columns.yaw_sigma")
    wheels: SpeedUnit = Field("rpm", description="unit of every wheel's column")


class Telemetry(_Section):
    """How `dynprop estimate` (and `tune` and `trim`, which read the same way) reads a
    telemetry file that is not dynprop's own: its columns, their units and the epoch
    its time counts from (docs/telemetry.md).  Left out, the file is read as
    dynprop's own telemetry.csv."""

    columns: TelemetryColumns = Field(default_factory=TelemetryColumns)
    units: TelemetryUnits = Field(default_factory=TelemetryUnits)
    epoch_utc: str | None = Field(None, description="ISO 8601 epoch of a t_s column whose "
                                  "file does not carry one (`dynprop estimate --epoch-utc`); "
                                  "null: the scenario's epoch_utc")
    epoch_tolerance_s: float = Field(
        1.0, ge=0, description="how far the file's epoch (or its first time_utc tag) may be "
        "from the scenario's epoch_utc; further is an error, since the Sun and orbit geometry "
        "is computed from the scenario's: at the orbit rate (7.3e-5 rad/s) 1 s moves it by "
        "0.004°, a tenth of the paper's 0.040° yaw σ (s)")
    screen: TelemetryScreen = Field(default_factory=TelemetryScreen,
                                    description="which values are screened as physically "
                                    "impossible before the filter (docs/telemetry.md)")

    @field_validator("epoch_utc")
    @classmethod
    def _epoch(cls, v: str | None) -> str | None:
        if v is not None:
            parse_epoch(v)
        return v
