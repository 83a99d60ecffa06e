"""Truth simulation: exogenous inputs, the chunked compiled rollout, and its result.

``simulate_truth`` is the public entry point.  It evaluates the slowly varying
inputs (Sun, shadow, field) on the whole output grid with vectorised numpy,
draws the wheel ripple from the caller's generator, and rolls the compiled RK4
step out in ``mapaccum`` chunks through ``Function.buffer()``: one Python call
per few thousand steps, none per step.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime
from functools import lru_cache

import numpy as np

from rollout.chunks import ChunkedRollout
from rollout.compiled import requested_backend

from . import ephemeris
from .control import Control
from .environment import Environment
from .frames import GeoOrbit, dcm_from_quat, quat_from_euler312
from .spacecraft import Spacecraft
from .step import build_step, input_layout, pack_params, split_aux

DEFAULT_CHUNK = 4096
TAIL_CHUNK = 256  # a short run's or a long run's last steps, without 4096-step padding


@dataclass(frozen=True)
class InitialState:
    """Initial attitude (3-1-2, rad) and rate of the body relative to the orbit
    frame, ω_BR in body axes (rad/s).  Wheel speeds default to the spacecraft's."""

    yaw_rad: float = 0.0
    roll_rad: float = 0.0
    pitch_rad: float = 0.0
    rate_wrt_orbit_radps: tuple[float, float, float] = (0.0, 0.0, 0.0)
    wheel_speeds_radps: tuple[float, ...] | None = None

    def state_vector(self, spacecraft: Spacecraft, orbit: GeoOrbit) -> np.ndarray:
        q = quat_from_euler312(self.yaw_rad, self.roll_rad, self.pitch_rad)
        c_br = dcm_from_quat(q)
        w_bn = np.asarray(self.rate_wrt_orbit_radps, float) \
            + c_br @ np.array([0.0, -orbit.rate_radps, 0.0])
        wheels = spacecraft.wheel_speeds if self.wheel_speeds_radps is None \
            else np.asarray(self.wheel_speeds_radps, float)
        if wheels.shape != (spacecraft.n_wheels,):
            raise ValueError(f"expected {spacecraft.n_wheels} wheel speeds, got {wheels.shape}")
        x0 = np.concatenate([q, w_bn, wheels])
        if not np.all(np.isfinite(x0)):
            raise ValueError("initial state contains NaN or infinity")
        return x0


@dataclass(frozen=True)
class TruthResult:
    """Truth histories on the output grid (SI units, body axes unless named).

    ``torques`` maps a source name to an (N, 3) body torque in N m:
    gravity_gradient, solar, magnetic (residual and prescribed dipoles),
    magnetic_control (the torquers), wheel_control (the reaction of the control's
    motor torques on the body), wheel_input (of ``wheel_torque``), wheel_ripple
    and external.  Torques are evaluated at each sample, the start of its step.
    """

    t_s: np.ndarray
    q_br: np.ndarray
    w_bn_radps: np.ndarray
    w_br_radps: np.ndarray
    wheel_speeds_radps: np.ndarray
    h_Nms: np.ndarray
    H_Nms: np.ndarray
    torques: dict[str, np.ndarray]
    wheel_command_Nm: np.ndarray
    torquer_dipole_Am2: np.ndarray
    sun_body: np.ndarray
    sun_orbit_frame: np.ndarray
    shadow: np.ndarray
    final_state: np.ndarray
    backend: str
    euler_rad: np.ndarray  # (N, 3): yaw, roll, pitch (3-1-2)

    @property
    def yaw_rad(self) -> np.ndarray:
        return self.euler_rad[:, 0]

    @property
    def roll_rad(self) -> np.ndarray:
        return self.euler_rad[:, 1]

    @property
    def pitch_rad(self) -> np.ndarray:
        return self.euler_rad[:, 2]

    @property
    def eclipse(self) -> np.ndarray:
        return self.shadow < 1.0


class TruthModel:
    """The compiled truth step for one wheel count, built once and reused."""

    def __init__(self, n_wheels: int, chunk: int = DEFAULT_CHUNK, backend: str | None = None):
        self.n_wheels = n_wheels
        self.chunk = chunk
        self.rollout_engine = ChunkedRollout(build_step(n_wheels), chunk, TAIL_CHUNK, backend)
        self.backend = self.rollout_engine.backend

    def rollout(self, x0: np.ndarray, inputs: dict[str, np.ndarray], p: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
        """Run one step per row of the per-step ``inputs`` (``step.input_layout``
        names, each (N, k)).  Returns states (N+1, n_x) including x0, and aux (N, n_aux).
        """
        arrays = [inputs[name] for name, _ in input_layout(self.n_wheels)]
        return self.rollout_engine.run(x0, arrays, p)


@lru_cache(maxsize=8)
def truth_model(n_wheels: int, chunk: int = DEFAULT_CHUNK, backend: str = "auto") -> TruthModel:
    return TruthModel(n_wheels, chunk, backend)


def step_inputs(t_s: np.ndarray, epoch: datetime, orbit: GeoOrbit, env: Environment,
                ripple: np.ndarray, extra_torque: np.ndarray | None = None,
                wheel_torque: np.ndarray | None = None
                ) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """Per-step inputs of ``step.input_layout`` on the output grid, and the shadow."""
    n, n_wheels = len(t_s), ripple.shape[1]
    jd0 = ephemeris.julian_date(epoch)
    alpha = orbit.right_ascension(t_s, ephemeris.gmst_rad(jd0))
    sun = _sun_on_grid(t_s, jd0)
    # Satellite-to-Sun direction in the orbit frame.  The geocentric Sun, at right
    # ascension λ and declination δ, is (ρ sin(λ−α), −sin δ, −ρ cos(λ−α)) in the frame
    # of GeoOrbit.orbit_frame (ρ = cos δ); the satellite sits at −R ẑ_R, so d ŝ − r
    # adds R to the z component (a parallax of up to R/AU = 0.016°).
    phase = sun["ra"] - alpha
    d, radius = sun["dist"], orbit.radius_m
    sun_r = np.empty((n, 3))
    sun_r[:, 0] = d * sun["cos_dec"] * np.sin(phase)
    sun_r[:, 1] = -d * sun["sin_dec"]
    sun_r[:, 2] = radius - d * sun["cos_dec"] * np.cos(phase)
    # |d ŝ + R ẑ|² = d² + 2 d R ŝ_z + R²
    sat_sun_dist = np.sqrt(d * (d - 2.0 * radius * sun["cos_dec"] * np.cos(phase)) + radius**2)
    sun_r /= sat_sun_dist[:, None]
    shadow = _shadow_on_grid(alpha, sun, radius, env.shadow_model)
    mag = env.magnetic
    if mag.enabled and np.any(mag.profile_amplitude_Am2):
        m_prof = mag.profile(t_s)
    else:
        m_prof = np.zeros((n, 3))
    inputs = {"sun_r": sun_r, "sun_scale": shadow * (ephemeris.AU_M / sat_sun_dist) ** 2,
              "m_prof": m_prof,
              "n_ext": _checked(extra_torque, (n, 3), "extra torque"),
              "u_wheel": _checked(wheel_torque, (n, n_wheels), "wheel torque"),
              "ripple": ripple}
    return inputs, shadow


def _checked(a: np.ndarray | None, shape: tuple[int, int], name: str) -> np.ndarray:
    if a is None:
        return np.zeros(shape)
    a = np.asarray(a, dtype=float)
    if a.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} contains NaN or infinity")
    return a


def _sun_inertial(sun: dict[str, np.ndarray], idx) -> np.ndarray:
    """Geocentric Sun unit vectors (inertial) at the given sample indices."""
    ra, cd = sun["ra"][idx], sun["cos_dec"][idx]
    return np.stack([cd * np.cos(ra), cd * np.sin(ra), sun["sin_dec"][idx]], axis=-1)


def _shadow_on_grid(alpha: np.ndarray, sun: dict[str, np.ndarray], radius: float, model: str,
                    every: int = 64) -> np.ndarray:
    """Shadow factor on the output grid, evaluated only where it can be below 1.

    A coarse pass (every ``every`` samples) flags the stretches that come within
    the penumbra's reach of the Earth's shadow axis, padded by the distance the
    satellite covers in one coarse interval; only those samples get the exact
    model.  Outside eclipse season nothing at all is evaluated finely.
    """
    n = len(alpha)
    out = np.ones(n)
    if model == "none":  # no eclipses: isolates their effect (the linearization report)
        return out

    def r_sat(i):
        return radius * np.stack([np.cos(alpha[i]), np.sin(alpha[i]), np.zeros(len(i))], -1)

    idx = np.arange(0, n, every)
    along = np.einsum("ij,ij->i", r_sat(idx), _sun_inertial(sun, idx))
    perp = np.sqrt(np.maximum(radius**2 - along**2, 0.0))
    step_len = radius * abs(alpha[min(every, n - 1)] - alpha[0])
    reach = ephemeris.R_EARTH_M + 2.0 * radius * ephemeris.R_SUN_M / sun["dist"][idx] + step_len
    near = (along < step_len) & (perp < reach)
    if not np.any(near):
        return out
    fine = np.zeros(n, dtype=bool)
    for k in np.flatnonzero(near):
        fine[max(idx[k] - every, 0):idx[k] + every + 1] = True
    fine = np.flatnonzero(fine)
    out[fine] = ephemeris.shadow_factor(r_sat(fine), _sun_inertial(sun, fine),
                                        sun["dist"][fine], model=model)
    return out


def _sun_on_grid(t_s: np.ndarray, jd0: float, every: int = 128) -> dict[str, np.ndarray]:
    """The Sun's right ascension, cos and sin of declination, and distance (m) on the
    output grid.

    The ephemeris is evaluated every ``every`` samples (about a minute) and these
    slowly varying quantities are interpolated linearly: the Sun moves about 1e-5 rad
    a minute, so the error (≈ angle²/8 ≈ 2e-11 rad) is far below the ephemeris's own
    0.01°, and the day-long evaluation costs almost nothing.
    """
    idx = np.arange(0, len(t_s) + every - 1, every)
    idx[-1] = min(idx[-1], len(t_s) - 1)
    idx = np.unique(idx)
    unit, dist = ephemeris.sun_position_eci(jd0 + t_s[idx] / 86400.0)
    nodes = {"ra": np.unwrap(np.arctan2(unit[:, 1], unit[:, 0])),
             "cos_dec": np.hypot(unit[:, 0], unit[:, 1]), "sin_dec": unit[:, 2], "dist": dist}
    return {k: np.interp(t_s, t_s[idx], v) for k, v in nodes.items()}


def simulate_truth(spacecraft: Spacecraft, orbit: GeoOrbit, environment: Environment,
                   control: Control, initial: InitialState, epoch: datetime,
                   duration_s: float, dt_s: float = 0.512,
                   rng: np.random.Generator | None = None,
                   extra_torque: np.ndarray | None = None,
                   wheel_torque: np.ndarray | None = None,
                   model: TruthModel | None = None) -> TruthResult:
    """Simulate the nonlinear truth on ``t = 0, dt, …`` up to ``duration_s``.

    ``rng`` supplies the wheel ripple; it is required when ripple is enabled so
    that every random draw traces back to the scenario seed.  ``extra_torque``
    (N, 3) adds a body torque and ``wheel_torque`` (N, n_wheels) adds motor torques
    to the control's, each held over its step.  ``final_state`` is the state one
    step after the last sample (the step that produced the last sample's outputs).
    """
    if not (np.isfinite(duration_s) and duration_s >= 0):
        raise ValueError("duration_s must be finite and non-negative")
    if not (np.isfinite(dt_s) and dt_s > 0):
        raise ValueError("dt_s must be positive")
    n = spacecraft.n_wheels
    n_samples = int(np.floor(duration_s / dt_s + 1e-9)) + 1
    # Sample times rounded to the nanosecond: exact decimals (4.608, not
    # 4.6080000000000005), so every file writes the same t_s to any precision.
    t_s = np.round(np.arange(n_samples) * dt_s, 9)
    sigma = environment.ripple.step_sigma_Nm(dt_s)
    if sigma > 0:
        if rng is None:
            raise ValueError("an rng is required when wheel ripple is enabled")
        ripple = sigma * rng.standard_normal((n_samples, n))
    else:
        ripple = np.zeros((n_samples, n))
    inputs, shadow = step_inputs(t_s, epoch, orbit, environment, ripple, extra_torque,
                                 wheel_torque)
    p = pack_params(spacecraft, orbit, environment, control, dt_s)
    model = model or truth_model(n, DEFAULT_CHUNK, requested_backend())
    # One step per output sample: the last step's end state is kept as final_state.
    states, aux = model.rollout(initial.state_vector(spacecraft, orbit), inputs, p)
    # NaN never turns finite again in the state update, so the last state tells;
    # only a failed run pays for finding where it went.
    if not np.all(np.isfinite(states[-1])):
        k = int(np.argmax(~np.isfinite(states).all(axis=1)))
        raise FloatingPointError(f"the truth became non-finite at t = {k * dt_s:.1f} s: the "
                                 "closed loop is unstable for these gains and this step")
    return _result(t_s, states, aux, inputs, shadow, spacecraft, model.backend)


def _result(t_s, states, aux, inputs, shadow, spacecraft, backend) -> TruthResult:
    n = spacecraft.n_wheels
    a = split_aux(aux, n)
    x = states[:-1]
    axes = spacecraft.wheel_axes
    torques = {
        "gravity_gradient": a["t_gg"],
        "solar": a["t_solar"],
        "magnetic": a["t_mag"],
        "magnetic_control": a["t_mtq"],
        "wheel_control": -a["u_cmd"] @ axes,
        "wheel_input": -inputs["u_wheel"] @ axes,
        "wheel_ripple": -inputs["ripple"] @ axes,
        "external": inputs["n_ext"],
    }
    return TruthResult(
        t_s=t_s, q_br=x[:, 0:4], w_bn_radps=x[:, 4:7], w_br_radps=a["w_br"],
        wheel_speeds_radps=x[:, 7:], h_Nms=a["h"], H_Nms=a["H"], torques=torques,
        wheel_command_Nm=a["u_cmd"], torquer_dipole_Am2=a["m_cmd"], sun_body=a["sun_b"],
        sun_orbit_frame=inputs["sun_r"], shadow=shadow, final_state=states[-1],
        backend=backend, euler_rad=a["euler"])
