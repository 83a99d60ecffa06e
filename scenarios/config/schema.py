"""The scenario schema: every key, its unit, its default (docs/scenario-reference.md).

Defaults are GOES-Next's from the paper, so a scenario file only lists what it
changes.  Models are strict: unknown keys, wrong types, NaN and infinity are
errors, and each error carries its key path.  ``docs/scenario-reference.md`` is
generated from these definitions (``python -m dynprop.scenarios.reference``).
"""

from __future__ import annotations

import difflib
from typing import Annotated, Literal

import numpy as np
from dynprop.sim import control as sim_control
from dynprop.sim import environment as sim_env
from dynprop.sim import ephemeris, sensors, spacecraft
from dynprop.sim.frames import GeoOrbit
from dynprop.sim.telemetry import MIN_SUN_SEPARATION_DEG
from pydantic import BaseModel, ConfigDict, Field, Strict, field_validator, model_validator

from .montecarlo import MonteCarlo, check_dispersion

# The simulator's dataclasses hold the GOES-Next defaults; the schema reads them
# from there so that the two can never disagree.
_SOLAR = sim_env.SolarTorque()
_MAG = sim_env.MagneticTorque()
_RIPPLE = sim_env.WheelRipple()
_CTRL = sim_control.Control()
_EARTH = sensors.EarthSensor()
_TACH = sensors.Tachometer()

# Elements stay strict (an int is a float; a string or bool is not), while the
# containers accept YAML lists.
_Float = Annotated[float, Strict()]
Vec3 = Annotated[tuple[_Float, _Float, _Float], Strict(False)]
Matrix3 = Annotated[tuple[Vec3, Vec3, Vec3], Strict(False)]
# A year and a day: `dynprop run` streams a run a window at a time, so its memory
# does not grow with the duration.  The commands that hold whole arrays (simulate,
# montecarlo, linearization, run --montecarlo-case) check their own 30-day limit.
MAX_DURATION_S = 366 * 86400.0
# The sampled control loop loses its damping for steps above about 2.2 s and diverges
# by 2.5 s (one day from a 0.5 deg yaw offset: the attitude-rate transient still decays
# at 2.4 s and grows 40-fold at 2.5 s).  The step is capped at two 0.512 s samples, a
# factor of two inside that.
MAX_SAMPLE_INTERVAL_S = 1.024


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
    enabled: bool = Field(True, description="solar array/sail imbalance torque, zero in "
                          "eclipse")
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


class Environment(_Section):
    gravity_gradient: GravityGradient = Field(default_factory=GravityGradient)
    solar: Solar = Field(default_factory=Solar)
    magnetic: Magnetic = Field(default_factory=Magnetic)
    ripple: Ripple = Field(default_factory=Ripple)
    shadow_model: Literal["conical", "cylindrical", "none"] = Field(
        "conical", description="Earth shadow model; 'none' removes eclipses")


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
                          "and wheel ripple); quantisation stays")


class EarthSensor(_Section):
    noise_deg: float = Field(_EARTH.noise_deg, ge=0, description="roll and pitch noise, 1σ (deg)")
    quantum_deg: float = Field(_EARTH.quantum_deg, gt=0,
                               description="roll and pitch quantisation (deg)")
    roll_bias_deg: float = Field(_EARTH.roll_bias_deg, description="constant roll error: "
                                 "measured = quantised(true + bias + noise) (deg)")
    pitch_bias_deg: float = Field(_EARTH.pitch_bias_deg,
                                  description="constant pitch error, likewise (deg)")


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


# GOES-Next heads, from sim.sensors: the DSS on dusk, two CASS.
HEAD_DEFAULTS = {
    h.name: dict(kind=h.kind, boresight_hour_angle_deg=h.boresight_hour_angle_deg,
                 fov_in_plane_deg=h.fov_in_plane_deg, fov_out_of_plane_deg=h.fov_out_of_plane_deg,
                 quantum_deg=h.quantum_deg, noise_deg=h.noise_deg,
                 in_plane_bias_deg=h.in_plane_bias_deg,
                 out_of_plane_bias_deg=h.out_of_plane_bias_deg)
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


class Sensors(_Section):
    noise: Noise = Field(default_factory=Noise)
    earth: EarthSensor = Field(default_factory=EarthSensor)
    sun: SunSensors = Field(default_factory=SunSensors)
    tachometer: Tachometer = Field(default_factory=Tachometer)


class ProcessNoise(_Section):
    """Spectral densities of Eqs. 34–35 (paper units)."""

    q_x: float = Field(5.4e-7, ge=0, description="roll torque, Eq. 45 ((N m)² s)")
    q_z: float = Field(5.4e-7, ge=0, description="yaw torque, Eq. 45 ((N m)² s)")
    q_w: float = Field(5.0e-10, ge=0, description="wheel ripple on h, 2 sin²c · G/2; the "
                       "paper prints 1.3e-10 (errata 6) ((N m)² s)")
    q_px: float = Field(3e-18, ge=0, description="periodic roll torque random walk; not in "
                        "the paper: ~5e-7 N m per day ((N m)²/s)")
    q_pz: float = Field(3e-18, ge=0, description="periodic yaw torque random walk ((N m)²/s)")
    q_cx: float = Field(3e-18, ge=0, description="constant roll torque random walk ((N m)²/s)")
    q_cz: float = Field(3e-18, ge=0, description="constant yaw torque random walk ((N m)²/s)")


class InitialSigma(_Section):
    """The filter's initial 1σ per state (its initial estimate is zero)."""

    roll_deg: float = Field(0.05, gt=0, description="roll (deg)")
    roll_rate_degps: float = Field(1e-3, gt=0, description="roll rate (deg/s)")
    yaw_deg: float = Field(0.5, gt=0, description="yaw (deg)")
    yaw_rate_degps: float = Field(1e-3, gt=0, description="yaw rate (deg/s)")
    h_Nms: float = Field(0.05, gt=0, description="yaw wheel momentum (N m s)")
    N_px_Nm: float = Field(5e-6, gt=0, description="periodic roll torque (N m)")
    N_pz_Nm: float = Field(5e-6, gt=0, description="periodic yaw torque (N m)")
    N_cx_Nm: float = Field(5e-6, gt=0, description="constant roll torque (N m)")
    N_cz_Nm: float = Field(5e-6, gt=0, description="constant yaw torque (N m)")


class ModelTorques(_Section):
    """The modelled environment torques N_x*, N_z* of Eq. 9 (may differ from the truth)."""

    roll_Nm: float = Field(0.0, description="N_x*, constant (N m)")
    yaw_Nm: float = Field(0.0, description="N_z*, constant (N m)")


class Estimator(_Section):
    filters: list[Literal["paper", "ekf"]] = Field(
        ["paper"], min_length=1, description="which filters `dynprop run` runs on the same "
        "telemetry: the paper's linear filter (always, first) and optionally the extended "
        "Kalman filter on the full nonlinear model (docs/validation.md §8)")
    process_noise: ProcessNoise = Field(default_factory=ProcessNoise)
    initial_sigma: InitialSigma = Field(default_factory=InitialSigma)
    model_torques: ModelTorques = Field(default_factory=ModelTorques)
    wheel_torque_window_s: float = Field(20.0, gt=0, le=600, description="Savitzky–Golay "
                                         "window for N_w* = ḣ from the tachometers (s)")
    sun_gap_min_h: float = Field(4.0, gt=0, description="a yaw outage at least this long "
                                 "counts as a Sun gap in the summary (h)")
    dss_error_correlation_s: float = Field(
        600.0, gt=0, description="how long the DSS yaw error stays correlated: its "
        "quantisation share of the yaw variance counts once per this time; measured "
        "autocorrelation 0.5 at 8.5 min, because the out-of-plane angle that sets yaw "
        "moves slowly (s)")
    max_gap_s: float = Field(
        3600.0, gt=0, description="Longest telemetry dropout `dynprop estimate` propagates "
        "across (samples missing from its grid of sample_interval_s steps: no update, the "
        "covariance grows); a longer one is rejected with the row where it starts.")


QUARTER_ORBIT_S = 21541.0   # the correlation time of Eq. 45


class Trim(_Section):
    """How `dynprop trim` estimates the solar imbalance κ (docs/trim.md).  Its batch
    filter is the paper's, with the known magnetic torques as modelled torques and
    a process noise for what is left once the tab is near trim: Eq. 45's recipe
    (mean-square torque error × a quarter-orbit correlation time) with this
    torque error, and no random walk of the torque states (κ does not change)."""

    torque_error_Nm: float = Field(
        2e-7, gt=0, description="unmodelled roll and yaw torque left after the known "
        "ones (gravity gradient as the attitude moves, residual-dipole changes); Eq. 45 "
        "takes 5e-6 for an untrimmed spacecraft, an upper limit meant for yaw (N m)")
    correlation_time_s: float = Field(QUARTER_ORBIT_S, gt=0, description="its correlation "
                                      "time; Eq. 45's quarter orbit (s)")
    every_days: int | None = Field(
        None, ge=1, description="`dynprop run` only: close the loop, estimating κ from "
        "each such span of the run's own telemetry and moving the tab as `dynprop trim` "
        "recommends from the next sample on (trim_loop.csv); null flies the tab fixed (days)")

    @property
    def q_Nm2s(self) -> float:
        """White roll and yaw torque density q = δN² τ ((N m)² s), as Eq. 45."""
        return self.torque_error_Nm ** 2 * self.correlation_time_s


DEFAULT_OUTPUT_INTERVAL_S = 64.0   # 125 samples of 0.512 s
TELEMETRY_AUTO_MAX_S = 2 * 86400.0


class Output(_Section):
    """What `dynprop run` writes, as Basilisk recorders' sampling time, 42's DTOUT or
    S2E's log period set it.  The rows of truth.csv, estimate.csv and comparison.npz
    are the samples every ``interval_s`` (each the value at that sample, not an
    average); every figure in summary.json and daily.csv is accumulated at the full
    sample rate, and the figures draw a min/max envelope per output interval, so
    the decimation hides no peak.  Full-rate telemetry is ~14 MB per simulated day
    as CSV (5 GB a year), which is why ``auto`` writes it only for short runs."""

    interval_s: float | None = Field(
        None, gt=0, description="spacing of the rows of truth.csv, estimate.csv and "
        "comparison.npz: a whole multiple of sample_interval_s; null (the default) takes "
        f"the multiple nearest {DEFAULT_OUTPUT_INTERVAL_S:g} s "
        f"({DEFAULT_OUTPUT_INTERVAL_S:g} s at 0.512 s); sample_interval_s writes every "
        "sample (s)")
    telemetry: Literal["auto", True, False] = Field(
        "auto", description="telemetry.csv at every sample: true, false, or auto = "
        f"written when duration_s is at most {TELEMETRY_AUTO_MAX_S:g} s (two days); "
        "`dynprop estimate` needs it")


def output_stride(s: Scenario) -> int:
    """Samples between output rows (``output.interval_s`` / ``sample_interval_s``)."""
    dt = s.sample_interval_s
    if s.output.interval_s is None:
        return max(1, round(DEFAULT_OUTPUT_INTERVAL_S / dt))
    return max(1, round(s.output.interval_s / dt))


def output_writes_telemetry(s: Scenario) -> bool:
    """Whether `dynprop run` writes telemetry.csv (``output.telemetry``, auto resolved)."""
    t = s.output.telemetry
    return t if isinstance(t, bool) else s.duration_s <= TELEMETRY_AUTO_MAX_S + 1e-9


class Scenario(_Section):
    name: str = Field(min_length=1, description="short identifier of the scenario")
    description: str = Field("", description="one line shown by `dynprop scenarios`")
    dynprop_version: None = Field(None, description="written into resolved scenarios; "
                                  "ignored on input")
    seed: int = Field(20260320, ge=0, description="root of every random stream")
    epoch_utc: str = Field("2026-03-20T12:00:00Z", description="ISO 8601 UTC start time in "
                           "1950–2049, where the solar ephemeris holds 0.01°; sets the Sun and "
                           "so the season")
    duration_s: float = Field(172800.0, gt=0, le=MAX_DURATION_S,
                              description="length of the run, at least one "
                              f"sample_interval_s and at most {MAX_DURATION_S / 86400:g} "
                              "days (s)")
    sample_interval_s: float = Field(
        0.512, gt=0, le=MAX_SAMPLE_INTERVAL_S, description="telemetry, control and "
        f"integration step, at most {MAX_SAMPLE_INTERVAL_S:g} s: the sampled control loop "
        "loses its damping above about 2.2 s and diverges by 2.5 s, and the cap keeps a "
        "factor of two inside that (s)")
    spacecraft: Spacecraft = Field(default_factory=Spacecraft)
    orbit: Orbit = Field(default_factory=Orbit)
    initial_state: InitialState = Field(default_factory=InitialState)
    environment: Environment = Field(default_factory=Environment)
    control: Control = Field(default_factory=Control)
    sensors: Sensors = Field(default_factory=Sensors)
    estimator: Estimator = Field(default_factory=Estimator)
    montecarlo: MonteCarlo = Field(default_factory=MonteCarlo)
    output: Output = Field(default_factory=Output)
    trim: Trim = Field(default_factory=Trim)

    @field_validator("dynprop_version", mode="before")
    @classmethod
    def _ignore_version(cls, v):
        return None

    def __str__(self) -> str:
        """The resolved YAML: every key with its value, as scenario.yaml holds it."""
        from .loader import resolved_yaml
        return resolved_yaml(self)

    @field_validator("epoch_utc")
    @classmethod
    def _epoch(cls, v: str) -> str:
        epoch = ephemeris.parse_epoch(v)
        if not 1950 <= epoch.year < 2050:
            raise ValueError("must be in 1950–2049, where the solar ephemeris holds 0.01°")
        return v

    @model_validator(mode="after")
    def _whole_scenario_checks(self):
        # Checks across keys; every problem is reported, one line each (the loader
        # splits them), each naming its own key path.
        problems = []
        if self.duration_s < self.sample_interval_s:
            # A run needs a step to propagate over; a shorter one writes one-row files.
            problems.append(f"duration_s: {self.duration_s:g} s is shorter than one "
                            f"sample_interval_s ({self.sample_interval_s:g} s)")
        interval = self.output.interval_s
        if interval is not None:
            ratio = interval / self.sample_interval_s
            k = round(ratio)
            if k < 1 or abs(ratio - k) > 1e-9 * ratio:
                near = sorted({max(1, int(np.floor(ratio))), max(1, int(np.ceil(ratio)))})
                problems.append(f"output.interval_s: {interval:g} s is not a whole multiple of "
                                f"sample_interval_s ({self.sample_interval_s:g} s); nearest: "
                                + " or ".join(f"{m * self.sample_interval_s:g}" for m in near))
        f = self.estimator.filters
        if f[0] != "paper" or len(set(f)) != len(f):
            problems.append(f"estimator.filters: {f} must start with paper (every comparison is "
                            "against the paper's filter) and name each filter once")
        every = self.trim.every_days
        if every is not None and every * 86400.0 >= self.duration_s:
            problems.append(f"trim.every_days: {every} days is not shorter than the run "
                            f"({self.duration_s / 86400.0:g} days): the tab would never move")
        for key, d in self.montecarlo.dispersions.items():
            try:
                check_dispersion(key, leaf_value(self, key), d)
            except ValueError as exc:
                problems.append(str(exc))
        if problems:
            raise ValueError("\n".join(problems))
        return self


def leaf_value(scenario: BaseModel, key: str):
    """The value at a dotted key path; ValueError naming it if it is not a leaf key."""
    node = scenario
    for part in key.split("."):
        if not isinstance(node, BaseModel) or part not in type(node).model_fields:
            match = difflib.get_close_matches(key, leaf_paths(type(scenario)), n=1)
            hint = f"; did you mean '{match[0]}'?" if match else ""
            raise ValueError(f"montecarlo.dispersions.{key}: no such scenario key{hint}")
        node = getattr(node, part)
    if isinstance(node, BaseModel):
        raise ValueError(f"montecarlo.dispersions.{key}: is a section, not a value")
    return node


def leaf_paths(model: type[BaseModel], prefix: str = "") -> list[str]:
    """Every dotted key path of ``model`` that holds a value (not a section)."""
    paths = []
    for name, field in model.model_fields.items():
        sub = field.annotation
        if isinstance(sub, type) and issubclass(sub, BaseModel):
            paths += leaf_paths(sub, f"{prefix}{name}.")
        else:
            paths.append(f"{prefix}{name}")
    return paths
