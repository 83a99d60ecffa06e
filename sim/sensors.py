"""Attitude sensors at the telemetry rate (paper Section 2.1 and 2.3).

Each sensor draws from its own ``numpy.random.Generator``, so changing one
sensor's settings never changes another's noise.  Every sensor draws its full
(N, k) noise array whether or not it sees anything, which keeps each stream's
use independent of the trajectory.  With ``noise_enabled=False`` nothing is drawn
and only quantisation remains.

Sun-sensor geometry.  A head's boresight lies in the body x–z plane at the Sun
hour angle ``boresight_hour_angle_deg`` θ_b, measured from local noon: with the
body on the orbit frame, the Sun is at ŝ = (−sin θ, 0, −cos θ), overhead (−z) at
noon, along −x at dusk, at nadir (+z) at midnight.  The head measures two angles
of the Sun, α in that plane (towards increasing θ) and β out of it (along +y):
α = atan2(ŝ·u, ŝ·b), β = atan2(ŝ·ŷ, ŝ·b), with u = (−cos θ_b, 0, sin θ_b).

Biases.  Every sensor can carry a constant bias, an error the ground does not
know (the ground yaw does not correct for it), so that Monte Carlo runs can
disperse it.  The convention is the same for all of them, in the sensor's own
unit: measured = quantise(true + bias + noise).  A bias is added only when it is
non-zero, so a zero bias leaves every output bit-for-bit as without one.  It
shifts the reading only: what a Sun head sees (its field of view, and a CASS's
noise growth off the boresight) follows the true Sun direction.

Outliers (not in the paper; off by default).  Every sensor can replace a fraction
``outlier_rate`` of its readings by true + bias + noise + s · ``outlier_size`` · σ,
s = ±1 at random and σ that reading's noise 1σ (a CASS's grows off the boresight),
before quantisation.  Each channel (roll, pitch; a head's α, β; each wheel) is an
outlier or not on its own, with probability ``outlier_rate``.  The draws come from a
stream of their own per sensor (``outlier_stream(name)``): one uniform u per channel
and sample, drawn for every sample whether the head sees the Sun or not (so the
stream never depends on the trajectory, nor on how the samples are split into
windows); the reading is an outlier when u < rate, with s = +1 when u < rate/2
(given u < rate, u/rate is uniform: s is a fair sign, independent of which samples
are outliers).  A sensor's generator carries its outlier generator
(``NoiseStream.outliers``), and ``draw_ahead``'s draws carry the outlier draws, so
the sensors reach them by the same argument as their noise.  With ``outlier_rate`` 0
nothing is drawn and nothing added, and with the noise switched off there are no
outliers either (every random draw is off).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .spacecraft import RPM

DEG = np.pi / 180.0


def quantize(x: np.ndarray, quantum: float) -> np.ndarray:
    """Round to the nearest multiple of ``quantum`` (mid-tread quantiser)."""
    return np.round(np.asarray(x) / quantum) * quantum


def _check_finite(what: str, spec, names: tuple[str, ...]) -> None:
    # A NaN bias is truthy and would silently turn every reading into NaN.
    for name in names:
        if not np.isfinite(getattr(spec, name)):
            raise ValueError(f"{what}: {name} must be finite")


OUTLIER_SIZE = 20.0   # default outlier size, in units of the reading's noise σ


def _check_outliers(what: str, spec) -> None:
    if not 0.0 <= spec.outlier_rate <= 1.0:
        raise ValueError(f"{what}: outlier_rate must be in [0, 1]")
    if not (np.isfinite(spec.outlier_size) and spec.outlier_size >= 0):
        raise ValueError(f"{what}: outlier_size must be finite and >= 0")


class NoiseStream(np.random.Generator):
    """A sensor's noise generator (drawing exactly as ``numpy.random.default_rng(noise)``
    would) that carries the generator of its outliers, ``outliers``, seeded by a
    ``SeedSequence`` of its own: outliers never move the noise, nor the noise them."""

    def __init__(self, noise: np.random.SeedSequence, outliers: np.random.SeedSequence):
        super().__init__(np.random.PCG64(noise))
        self.outliers = np.random.default_rng(outliers)


@dataclass(frozen=True)
class EarthSensor:
    """Roll and pitch: 0.01° (1σ) noise and 0.01° quantisation (Section 2.1), plus
    constant biases and outliers (not in the paper; none by default)."""

    noise_deg: float = 0.01
    quantum_deg: float = 0.01
    roll_bias_deg: float = 0.0
    pitch_bias_deg: float = 0.0
    outlier_rate: float = 0.0          # fraction of readings, roll and pitch each
    outlier_size: float = OUTLIER_SIZE  # in units of noise_deg

    def __post_init__(self) -> None:
        _check_finite("earth sensor", self, ("roll_bias_deg", "pitch_bias_deg"))
        _check_outliers("earth sensor", self)


@dataclass(frozen=True)
class SunSensorHead:
    """One Sun-sensor head; ``kind`` is ``"dss"`` (digital) or ``"cass"`` (coarse analog).

    Noise on each angle is ``noise_deg`` for a DSS.  For a CASS it is
    ``noise_deg / cos(γ)``, γ the angle off the boresight: about 1° on the
    boresight, growing away from it (Section 2.1 gives no more than that).
    ``in_plane_bias_deg`` and ``out_of_plane_bias_deg`` are constant errors on α and β
    (0 by default).  Near zero attitude an α bias moves the ground yaw by
    tan δ cos θ_b / (cos α (sin²θ + tan²δ)) per unit (δ the Sun's declination): not at all
    for the DSS (θ_b = 90°, u is the yaw axis), whose yaw error is its β bias alone.
    ``outlier_rate`` and ``outlier_size`` (in units of the angle's σ) are the module's
    outliers, on α and β each.
    """

    name: str
    kind: str
    boresight_hour_angle_deg: float
    fov_in_plane_deg: float
    fov_out_of_plane_deg: float
    quantum_deg: float
    noise_deg: float
    in_plane_bias_deg: float = 0.0
    out_of_plane_bias_deg: float = 0.0
    outlier_rate: float = 0.0
    outlier_size: float = OUTLIER_SIZE

    def __post_init__(self) -> None:
        _check_finite(f"sun sensor {self.name}", self,
                      ("in_plane_bias_deg", "out_of_plane_bias_deg"))
        _check_outliers(f"sun sensor {self.name}", self)
        if self.kind not in ("dss", "cass"):
            raise ValueError(f"sun sensor {self.name}: kind must be 'dss' or 'cass'")
        for name in ("fov_in_plane_deg", "fov_out_of_plane_deg"):
            if not 0 < getattr(self, name) < 90:
                raise ValueError(f"sun sensor {self.name}: {name} must be in (0, 90)")
        if not (self.quantum_deg > 0 and self.noise_deg >= 0):
            raise ValueError(f"sun sensor {self.name}: quantum > 0 and noise >= 0 required")

    @property
    def axes(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Boresight b, in-plane axis u and out-of-plane axis ŷ, in body axes."""
        t = self.boresight_hour_angle_deg * DEG
        b = np.array([-np.sin(t), 0.0, -np.cos(t)])
        u = np.array([-np.cos(t), 0.0, np.sin(t)])
        return b, u, np.array([0.0, 1.0, 0.0])


def ground_yaw_sensitivity(head: SunSensorHead, hour_angle_rad, declination_rad
                           ) -> dict[str, np.ndarray]:
    """How much the ground yaw's error (ground − true, ``sim.telemetry.derive_yaw``)
    moves per unit of each constant error it does not know, when ``head`` gives the
    yaw, the attitude is zero and the Sun is at hour angle θ from local noon and
    declination δ (ŝ_R = (−sin θ cos δ, −sin δ, −cos θ cos δ)).  With T = tan δ,
    D = sin²θ + T² and α = θ − θ_b (first order in each error):

    * ``in_plane`` (the head's α bias):      T cos θ_b / (cos α · D)
    * ``out_of_plane`` (its β bias):         sin θ (cos²α + T²) / (cos α · D)
    * ``roll`` (the Earth sensor's roll bias, which the ground de-rotates by):
      sin θ cos θ / D
    * ``pitch`` (its pitch bias, likewise):  T cos θ / D

    The DSS (θ_b = 90°, θ = 90° + α) has ``out_of_plane`` exactly 1 and ``in_plane`` 0
    everywhere; its ``roll`` and ``pitch`` vanish on its boresight and change sign
    across it.  Near noon (sin θ → 0) at equinox (T → 0) every term but ``in_plane``
    grows without bound: the yaw is undetermined there (``MIN_SUN_SEPARATION_DEG``).
    Arrays broadcast over θ and δ.
    """
    theta, dec = np.asarray(hour_angle_rad, float), np.asarray(declination_rad, float)
    tb = head.boresight_hour_angle_deg * DEG
    t, alpha = np.tan(dec), theta - tb
    d = np.sin(theta) ** 2 + t ** 2
    return {"in_plane": t * np.cos(tb) / (np.cos(alpha) * d),
            "out_of_plane": np.sin(theta) * (np.cos(alpha) ** 2 + t ** 2) / (np.cos(alpha) * d),
            "roll": np.sin(theta) * np.cos(theta) / d,
            "pitch": t * np.cos(theta) / d}


def goes_next_sun_sensors() -> tuple[SunSensorHead, ...]:
    """Default heads: the DSS centred on dusk (it sees the Sun last before the
    gap, Section 2.1) and two CASS heads covering the morning and early
    afternoon.  Together they span hour angles −120°…+122°, leaving a 118° gap
    (7.9 h) centred just after local midnight, about one third of the day.

    DSS numbers are the paper's: 0.125° quantisation, 0.0042° noise.  They are not
    consistent (the noise is far below the quantum, so it cannot dither it; the
    effective error is the quantisation's 0.125/√12 = 0.036°), but they are the
    only numbers given; docs/paper-errata.md records this.
    """
    return (
        SunSensorHead("dss", "dss", 90.0, 32.0, 32.0, 0.125, 0.0042),
        SunSensorHead("cass1", "cass", -75.0, 45.0, 35.0, 0.039, 1.0),
        SunSensorHead("cass2", "cass", 15.0, 45.0, 35.0, 0.039, 1.0),
    )


@dataclass(frozen=True)
class Tachometer:
    """Wheel speed: 0.0163 rpm quantisation, 0.0978 rpm (3σ) noise (Section 2.3), plus
    a constant bias, the same on every wheel, and outliers, each wheel's on its own
    (not in the paper; none by default); ``outlier_size`` is in units of the 1σ noise,
    ``noise_3sigma_rpm`` / 3."""

    quantum_rpm: float = 0.0163
    noise_3sigma_rpm: float = 0.0978
    bias_rpm: float = 0.0
    outlier_rate: float = 0.0
    outlier_size: float = OUTLIER_SIZE

    def __post_init__(self) -> None:
        _check_finite("tachometer", self, ("bias_rpm",))
        _check_outliers("tachometer", self)


@dataclass(frozen=True)
class SensorSuite:
    earth: EarthSensor = field(default_factory=EarthSensor)
    sun_heads: tuple[SunSensorHead, ...] = field(default_factory=goes_next_sun_sensors)
    tachometer: Tachometer = field(default_factory=Tachometer)
    noise_enabled: bool = True

    def stream_names(self) -> tuple[str, ...]:
        """The random streams this suite uses, one per sensor (a sensor with outliers
        draws them from its stream's ``NoiseStream.outliers``)."""
        return ("earth", "tachometer", *(h.name for h in self.sun_heads))

    def outlier_sensors(self) -> tuple[str, ...]:
        """The sensors whose outliers are drawn: outlier_rate > 0 and the noise on."""
        if not self.noise_enabled:
            return ()
        specs = (("earth", self.earth), ("tachometer", self.tachometer),
                 *((h.name, h) for h in self.sun_heads))
        return tuple(name for name, spec in specs if spec.outlier_rate > 0)


@dataclass(frozen=True)
class SunReadings:
    """Per head: visibility and the two quantised angles (rad; NaN when not visible)."""

    visible: np.ndarray      # (N, n_heads) bool
    alpha_rad: np.ndarray    # (N, n_heads)
    beta_rad: np.ndarray     # (N, n_heads)


class DrawnUniforms:
    """A sensor's outlier uniforms drawn ahead of its readings (``random`` hands them
    back, as ``DrawnNormals`` does its normals)."""

    def __init__(self, values: np.ndarray):
        self.values = values

    def random(self, shape) -> np.ndarray:
        if self.values.shape != tuple(shape):
            raise ValueError(f"drawn {self.values.shape} uniforms, asked for {tuple(shape)}")
        return self.values


class DrawnNormals:
    """A sensor's standard normals drawn ahead of its readings: ``standard_normal``
    hands them back, so a sensor given this instead of its generator reads exactly
    what the generator would have given it at that point; ``outliers`` holds its
    outlier uniforms (``DrawnUniforms``) when it has outliers, as a ``NoiseStream``
    holds its outlier generator."""

    def __init__(self, values: np.ndarray, outliers: DrawnUniforms | None = None):
        self.values = values
        self.outliers = outliers

    def standard_normal(self, shape) -> np.ndarray:
        if self.values.shape != tuple(shape):
            raise ValueError(f"drawn {self.values.shape} normals, asked for {tuple(shape)}")
        return self.values

    def rows(self, lo: int, hi: int) -> DrawnNormals:
        u = self.outliers
        return DrawnNormals(self.values[lo:hi],
                            None if u is None else DrawnUniforms(u.values[lo:hi]))


def drawn_rows(drawn: dict, lo: int, hi: int) -> dict:
    """Samples lo … hi−1 of ``draw_ahead``'s draws, for sensing a piece of them."""
    return {name: d.rows(lo, hi) if isinstance(d, DrawnNormals) else d
            for name, d in drawn.items()}


def draw_ahead(suite: SensorSuite, rngs, n: int, n_wheels: int) -> dict:
    """What every sensor of ``suite`` draws for ``n`` samples, drawn now (for
    ``sim.telemetry.make_telemetry`` in place of ``rngs``): a thread can draw while
    the truth is simulated, and a second sensing of the same samples (the linear
    twin's) reads the same draws without drawing them again.  Each generator's
    draws are the ones the sensor would make, in the same order, and so are the
    outlier generators' (of the sensors with outliers only)."""
    if not suite.noise_enabled:
        return dict(rngs)
    shapes = {"earth": (n, 2), "tachometer": (n, n_wheels),
              **{h.name: (n, 2) for h in suite.sun_heads}}
    with_outliers = suite.outlier_sensors()
    return {name: DrawnNormals(rngs[name].standard_normal(shape),
                               DrawnUniforms(_outlier_source(rngs[name], name).random(shape))
                               if name in with_outliers else None)
            for name, shape in shapes.items()}


def _outlier_source(rng, name: str):
    """Sensor ``name``'s outlier draws: its ``NoiseStream``'s (or its drawn normals')
    ``outliers``; an error when its generator has none."""
    source = getattr(rng, "outliers", None)
    if source is None:
        raise ValueError(f"{name}: outliers need the sensor's outlier stream; give it a "
                         "NoiseStream (scenarios' build.streams) or draw_ahead's draws")
    return source


def _with_outliers(e: np.ndarray, spec, rng, name: str, sigma: float,
                   noise_enabled: bool) -> np.ndarray:
    """The noise ``e`` (the unit's, or σ-normalised with ``sigma`` 1) with the outliers
    added: e + s · size · σ where u < rate (module doc); ``e`` itself, nothing drawn,
    when the sensor has none.  Never written in place (``e`` may be drawn normals that
    a second sensing reads again)."""
    if not (noise_enabled and spec.outlier_rate > 0):
        return e
    u = _outlier_source(rng, name).random(e.shape)
    hit = u < spec.outlier_rate
    sign = np.where(u[hit] < 0.5 * spec.outlier_rate, 1.0, -1.0)
    out = e.copy()
    out[hit] += sign * (spec.outlier_size * sigma)
    return out


def _noise(rng, shape, sigma, enabled: bool) -> np.ndarray:
    if not enabled:
        return np.zeros(shape)
    z = rng.standard_normal(shape)
    return z if sigma == 1.0 else sigma * z   # 1·z is z, bit for bit: no copy


def _biased(x: np.ndarray, bias: float) -> np.ndarray:
    """x + bias; x itself when the bias is zero, so that the result stays bit-identical
    to a sensor without one (adding 0.0 would turn −0.0 into +0.0)."""
    return x + bias if bias else x


def earth_sensor(roll_rad, pitch_rad, spec: EarthSensor, rng, noise_enabled=True,
                 out: tuple[np.ndarray, np.ndarray] | None = None):
    """Quantised, noisy roll and pitch (rad): Q(true + bias + noise), in degrees, with
    the outliers of the module doc if ``spec`` has them (``rng`` carries their draws).
    With ``out`` (two arrays) they are written there."""
    n = len(roll_rad)
    e = _with_outliers(_noise(rng, (n, 2), spec.noise_deg, noise_enabled), spec, rng,
                       "earth", spec.noise_deg, noise_enabled)
    q = spec.quantum_deg
    roll = _biased(np.asarray(roll_rad) / DEG, spec.roll_bias_deg)
    pitch = _biased(np.asarray(pitch_rad) / DEG, spec.pitch_bias_deg)
    out = out or (None, None)
    return (np.multiply(quantize(roll + e[:, 0], q), DEG, out=out[0]),
            np.multiply(quantize(pitch + e[:, 1], q), DEG, out=out[1]))


def tachometers(speeds_radps, spec: Tachometer, rng, noise_enabled=True,
                out: np.ndarray | None = None) -> np.ndarray:
    """Quantised, noisy wheel speeds (rad/s), one column per wheel: Q(true + bias + noise),
    in rpm, with outliers as ``earth_sensor`` (written into ``out`` if given)."""
    speeds = np.asarray(speeds_radps)
    sigma = spec.noise_3sigma_rpm / 3.0
    e = _with_outliers(_noise(rng, speeds.shape, sigma, noise_enabled), spec, rng,
                       "tachometer", sigma, noise_enabled)
    return np.multiply(quantize(_biased(speeds / RPM, spec.bias_rpm) + e, spec.quantum_rpm),
                       RPM, out=out)


def sun_sensors(sun_body: np.ndarray, lit: np.ndarray, heads, rngs, noise_enabled=True,
                out: SunReadings | None = None) -> SunReadings:
    """Readings of every head from the true Sun direction in body axes (written into
    ``out``'s arrays if given).

    A head sees the Sun when the Sun is in front of it, within both field-of-view
    half angles, and not eclipsed (``lit``); both tests use the true angles.  Each
    reading is Q(true + bias + noise), in degrees, with outliers as ``earth_sensor``.
    """
    n = len(sun_body)
    if out is None:
        out = SunReadings(np.empty((n, len(heads)), dtype=bool),
                          np.empty((n, len(heads))), np.empty((n, len(heads))))
    visible, alpha, beta = out.visible, out.alpha_rad, out.beta_rad
    visible.fill(False)
    alpha.fill(np.nan)
    beta.fill(np.nan)
    for k, head in enumerate(heads):
        b, u, y = head.axes
        # Drawn for every sample, seen or not, so the stream never shifts.  Outliers
        # are added to the normalised noise, so they scale with σ as the noise does
        # (a CASS's grows off the boresight).
        e = _with_outliers(_noise(rngs[head.name], (n, 2), 1.0, noise_enabled), head,
                           rngs[head.name], head.name, 1.0, noise_enabled)
        sb = sun_body @ b
        front = np.flatnonzero((sb > 0) & lit)
        s = sun_body[front]
        a_true = np.arctan2(s @ u, sb[front])
        b_true = np.arctan2(s @ y, sb[front])
        inside = (np.abs(a_true) <= head.fov_in_plane_deg * DEG) \
            & (np.abs(b_true) <= head.fov_out_of_plane_deg * DEG)
        idx, a_true, b_true = front[inside], a_true[inside], b_true[inside]
        # CASS: σ grows as 1/cos(off-boresight); ŝ·b is that cosine for a unit ŝ.
        sigma = head.noise_deg if head.kind == "dss" else head.noise_deg / sb[idx]
        q = head.quantum_deg
        visible[idx, k] = True
        a_deg = _biased(a_true / DEG, head.in_plane_bias_deg)
        b_deg = _biased(b_true / DEG, head.out_of_plane_bias_deg)
        alpha[idx, k] = quantize(a_deg + sigma * e[idx, 0], q) * DEG
        beta[idx, k] = quantize(b_deg + sigma * e[idx, 1], q) * DEG
    return out
