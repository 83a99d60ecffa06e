"""Turn a validated scenario into the simulator's and the estimator's parameter
objects, its truth stream and its seeded random streams: the one place where a
scenario's keys become ``sim`` and ``estimator`` objects."""

from __future__ import annotations

from datetime import datetime

import numpy as np
from dynprop.estimator.linear.model import ModelParams, ProcessNoise
from dynprop.sim import (
    control,
    disturbance,
    environment,
    ephemeris,
    geomag,
    sensors,
    spacecraft,
)
from dynprop.sim.events import Schedule
from dynprop.sim.frames import GeoOrbit
from dynprop.sim.truth import InitialState, TruthStream

from ..units import DEG
from . import events
from .schema import Scenario
from .sections import SunHead

# Every random stream of a run, in a fixed order: stream i of run k is seeded by
# SeedSequence(seed, spawn_key=(k, i)), exactly what SeedSequence(seed).spawn()
# would give, but independent of which sensors a scenario configures, so that
# changing one sensor never moves another's noise.
STREAMS = ("ripple", "earth", "tachometer", "dss", "cass1", "cass2")
# Monte Carlo case k draws its dispersed values from SeedSequence(seed, spawn_key=
# (k, DISPERSION_STREAM, crc32(key))): case k's own child, one stream per key, so
# adding a dispersion never moves another key's draw.
DISPERSION_STREAM = len(STREAMS)
# The disturbance torque of run k draws from SeedSequence(seed, spawn_key=(k,
# DISTURBANCE_STREAM)), made only for a scenario that flies one: a stream of its own
# past DISPERSION_STREAM rather than one more of STREAMS, which would move
# DISPERSION_STREAM and with it every Monte Carlo case's dispersed values.
DISTURBANCE_STREAM = DISPERSION_STREAM + 1
# Sensor j of OUTLIER_SENSORS draws its outliers from SeedSequence(seed, spawn_key=(run,
# OUTLIER_STREAM, j)), past DISTURBANCE_STREAM for the same reason; they are drawn only
# by a sensor with outliers (sim.sensors' module doc), so none of the streams above moves.
OUTLIER_STREAM = DISTURBANCE_STREAM + 1
OUTLIER_SENSORS = ("earth", "tachometer", "dss", "cass1", "cass2")


def streams(seed: int, run: int = 0) -> dict[str, np.random.Generator]:
    """Run ``run``'s generators by name (STREAMS); each sensor's is a
    ``sensors.NoiseStream``, which draws as the plain generator would and carries the
    generator of its outliers (``OUTLIER_STREAM``), made but drawn from only when the
    sensor has outliers."""
    def make(i: int, name: str) -> np.random.Generator:
        noise = np.random.SeedSequence(seed, spawn_key=(run, i))
        if name not in OUTLIER_SENSORS:
            return np.random.default_rng(noise)
        return sensors.NoiseStream(noise, np.random.SeedSequence(
            seed, spawn_key=(run, OUTLIER_STREAM, OUTLIER_SENSORS.index(name))))
    return {name: make(i, name) for i, name in enumerate(STREAMS)}


def disturbance_generator(s: Scenario, run: int = 0) -> np.random.Generator | None:
    """Run ``run``'s disturbance generator (``DISTURBANCE_STREAM``), or None when the
    scenario flies no disturbance (nothing is drawn then)."""
    if not build_disturbance(s).enabled:
        return None
    return np.random.default_rng(np.random.SeedSequence(
        s.seed, spawn_key=(run, DISTURBANCE_STREAM)))


def epoch(s: Scenario) -> datetime:
    return ephemeris.parse_epoch(s.epoch_utc)


def orbit(s: Scenario) -> GeoOrbit:
    return GeoOrbit(longitude_rad=s.orbit.longitude_deg * DEG, radius_m=s.orbit.radius_m)


def field_orbit_frame(s: Scenario) -> np.ndarray:
    """The geomagnetic field at the station in the orbit frame (T), the model the
    truth's torquers fly in (``sim.step.pack_params``)."""
    o, mag = orbit(s), build_environment(s).magnetic
    return geomag.geo_field_orbit_frame(o.longitude_rad, o.radius_m,
                                        moment_Am2=mag.earth_dipole_Am2,
                                        pole_lat_deg=mag.pole_lat_deg,
                                        pole_lon_deg=mag.pole_lon_deg)


def build_spacecraft(s: Scenario) -> spacecraft.Spacecraft:
    sc, w = s.spacecraft, s.spacecraft.wheels
    if sc.configuration == "backup":
        return spacecraft.goes_next_backup(sc.inertia_kgm2, w.spin_inertia_kgm2, w.cant_deg,
                                           w.speed_rpm, sc.yaw_wheel.spin_inertia_kgm2)
    standby = sc.yaw_wheel.spin_inertia_kgm2 if sc.yaw_wheel.standby else None
    return spacecraft.goes_next(sc.inertia_kgm2, standby, spin_inertia_kgm2=w.spin_inertia_kgm2,
                                cant_deg=w.cant_deg, speed_rpm=w.speed_rpm)


def build_environment(s: Scenario) -> environment.Environment:
    e = s.environment
    return environment.Environment(
        environment.GravityGradient(e.gravity_gradient.enabled),
        environment.SolarTorque(e.solar.enabled, e.solar.untrimmed_torque_Nm,
                                e.solar.tab_effectiveness_Nm_per_deg, e.solar.trim_tab_deg,
                                e.solar.lever_axis, e.solar.array_offset_deg,
                                e.solar.offset_effectiveness_Nm_per_deg,
                                e.solar.untrimmed_offset_torque_Nm),
        environment.MagneticTorque(e.magnetic.enabled, e.magnetic.residual_dipole_Am2,
                                   e.magnetic.profile_amplitude_Am2,
                                   e.magnetic.profile_period_s,
                                   e.magnetic.profile_phase_deg * DEG),
        # The noise switch turns off every random draw, the ripple included.
        environment.WheelRipple(e.ripple.enabled and s.sensors.noise.enabled,
                                e.ripple.psd_Nm2_per_Hz),
        e.shadow_model)


def build_disturbance(s: Scenario) -> disturbance.Disturbance:
    d = s.environment.disturbance
    # The noise switch turns off every random draw, the disturbance included.
    kind = d.kind if s.sensors.noise.enabled else "none"
    return disturbance.Disturbance(kind, d.q_Nm2s, d.sigma_Nm, d.correlation_time_s)


def build_control(s: Scenario) -> control.Control:
    mag = s.momentum_management.magnetic
    return control.Control(**s.control.model_dump(), momentum_direction_gain_per_s=(
        mag.gain_per_s if mag.enabled else 0.0))


def build_initial(s: Scenario) -> InitialState:
    i = s.initial_state
    return InitialState(i.yaw_deg * DEG, i.roll_deg * DEG, i.pitch_deg * DEG,
                        tuple(np.asarray(i.rate_wrt_orbit_degps) * DEG))


def _head(name: str, h: SunHead) -> sensors.SunSensorHead:
    return sensors.SunSensorHead(name, h.kind, h.boresight_hour_angle_deg, h.fov_in_plane_deg,
                                 h.fov_out_of_plane_deg, h.quantum_deg, h.noise_deg,
                                 h.in_plane_bias_deg, h.out_of_plane_bias_deg,
                                 h.outlier_rate, h.outlier_size)


def build_sensors(s: Scenario) -> sensors.SensorSuite:
    c = s.sensors
    return sensors.SensorSuite(
        sensors.EarthSensor(c.earth.noise_deg, c.earth.quantum_deg, c.earth.roll_bias_deg,
                            c.earth.pitch_bias_deg, c.earth.outlier_rate, c.earth.outlier_size),
        (_head("dss", c.sun.dss), _head("cass1", c.sun.cass1), _head("cass2", c.sun.cass2)),
        sensors.Tachometer(c.tachometer.quantum_rpm, c.tachometer.noise_3sigma_rpm,
                           c.tachometer.bias_rpm, c.tachometer.outlier_rate,
                           c.tachometer.outlier_size),
        c.noise.enabled)


def estimator_model(s: Scenario) -> tuple[ModelParams, ProcessNoise]:
    """The paper's linear model for this scenario: the diagonal inertias (the
    model neglects products of inertia, Section 3), the signed pitch momentum of
    the configured wheels (Eq. 1), the orbit rate, and the estimator's process noise."""
    sc = build_spacecraft(s)
    J = sc.J
    params = ModelParams(J[0, 0], J[1, 1], J[2, 2], float(sc.pitch_bias_Nms()),
                         orbit(s).rate_radps)
    q = s.estimator.process_noise
    return params, ProcessNoise(q.q_x, q.q_z, q.q_w, q.q_px, q.q_pz, q.q_cx, q.q_cz)


def estimator_sensor_specs(s: Scenario):
    """The sensor numbers the covariance analysis uses (Section 6), from the scenario;
    the yaw variance is the DSS's, the sensor that sees the Sun last before the gap."""
    from dynprop.estimator.linear.noise import SensorSpecs
    c, w = s.sensors, s.spacecraft.wheels
    return SensorSpecs(dt_s=s.sample_interval_s, tach_quantum_rpm=c.tachometer.quantum_rpm,
                       tach_noise_3sigma_rpm=c.tachometer.noise_3sigma_rpm,
                       roll_noise_deg=c.earth.noise_deg, roll_quantum_deg=c.earth.quantum_deg,
                       yaw_noise_deg=c.sun.dss.noise_deg, yaw_quantum_deg=c.sun.dss.quantum_deg,
                       wheel_inertia_kgm2=w.spin_inertia_kgm2, cant_deg=w.cant_deg,
                       h_factor_sq_sum=float(np.sum(yaw_factors(s) ** 2)))


def yaw_factors(s: Scenario) -> np.ndarray:
    """k_i with h = Σ k_i Ω_i: each wheel's spin inertia times its axis's z component."""
    return build_spacecraft(s).momentum_factors(2)


def truth_stream(s: Scenario, rng: np.random.Generator, duration_s: float | None = None,
                 dt_s: float | None = None, model=None,
                 disturbance_rng: np.random.Generator | None = None) -> TruthStream:
    """The truth of ``s`` as a stream of windows (``sim.truth.TruthStream``), its wheel
    ripple drawn from ``rng`` and its disturbance, if it flies one, from
    ``disturbance_rng`` (``disturbance_generator(s, run)``: required then), flying its
    events (``build_schedule``); ``duration_s`` and ``dt_s`` default to the scenario's."""
    mm = s.momentum_management
    solar = mm.solar.law() if mm.solar.enabled else None
    return TruthStream(build_spacecraft(s), orbit(s), build_environment(s), build_control(s),
                       build_initial(s), epoch(s),
                       s.duration_s if duration_s is None else duration_s,
                       s.sample_interval_s if dt_s is None else dt_s, rng=rng, model=model,
                       disturbance=build_disturbance(s), disturbance_rng=disturbance_rng,
                       managed=s.momentum_management.on(), solar_management=solar,
                       schedule=build_schedule(s))


def build_schedule(s: Scenario) -> Schedule:
    """The scenario's ``events``, every occurrence of each (``sim.events.Schedule``;
    empty without any)."""
    return events.schedule(s)


def bias_model(s: Scenario):
    """The filter's sensor-bias states (``estimator.bias_states``, those not 'off', in
    the schema's order) as an ``estimator.augmented.BiasModel``: prior 1σ in rad and
    random-walk density q = (walk_deg_per_sqrt_h · π/180)² / 3600 rad²/s (a 1σ growth of
    walk degrees over an hour); None when every bias is off (the paper's filter)."""
    from dynprop.estimator.augmented.filter import BiasModel
    states = s.estimator.bias_states
    on = [(name, getattr(states, name)) for name in states.on()]
    if not on:
        return None
    return BiasModel(tuple(name for name, _ in on), tuple(b.sigma_deg * DEG for _, b in on),
                     tuple((b.walk_deg_per_sqrt_h * DEG) ** 2 / 3600.0 for _, b in on))


def truth_biases_rad(s: Scenario) -> dict[str, float]:
    """The constant sensor errors the truth flies (``sensors.*bias*``), as the filter's
    bias states (rad): what the filter's roll (r + b) and each head's ground yaw
    (y + b_head) would see.

    * ``earth_roll``: the Earth sensor's roll bias.
    * ``dss_yaw``: the DSS's β (out-of-plane) bias, with the same sign (ground −
      true), exactly, wherever the Sun is in its field of view; its α bias does not
      move the yaw.  The Earth sensor's roll and pitch biases, by which the ground
      de-rotates, add nothing on its boresight and change sign across it
      (``sim.sensors.ground_yaw_sensitivity``), about cot θ per unit at equinox.
    * ``cass1_yaw``, ``cass2_yaw``: geometry-dependent; given on the head's boresight
      at the epoch's solar declination δ, the small-angle value
      Σ ∂ψ/∂(bias) · bias over the head's α and β biases and the Earth sensor's roll
      and pitch biases.  At equinox on the boresight that is β/sin θ_b and
      roll · cot θ_b (cass1: −1.035 β − 0.268 roll; cass2: 3.86 β + 3.73 roll), and it
      changes across the field of view and with the season.
    """
    suite = build_sensors(s)
    unit, _ = ephemeris.sun_position_eci(ephemeris.julian_date(epoch(s)))
    dec = float(np.arcsin(np.clip(unit[2], -1.0, 1.0)))
    e = suite.earth
    out = {"earth_roll": e.roll_bias_deg * DEG}
    for head in suite.sun_heads:
        k = sensors.ground_yaw_sensitivity(head, head.boresight_hour_angle_deg * DEG, dec)
        out[f"{head.name}_yaw"] = DEG * float(
            k["in_plane"] * head.in_plane_bias_deg + k["out_of_plane"] * head.out_of_plane_bias_deg
            + k["roll"] * e.roll_bias_deg + k["pitch"] * e.pitch_bias_deg)
    return out
