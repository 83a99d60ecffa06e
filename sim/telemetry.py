"""Synthetic telemetry: sensor readings plus the ground system's yaw.

Yaw is not a sensor output.  As on the ground, it is solved from the quantised
Sun-sensor angles, the Earth sensor's roll and pitch, and the known Sun
direction: with C_BR = R2(θ) R1(φ) R3(ψ), the measured Sun vector ŝ_B satisfies
R1(φ)ᵀ R2(θ)ᵀ ŝ_B = R3(ψ) ŝ_R, so ψ is the angle between the x–y components of
ŝ_R and of the de-rotated measurement.  Yaw is missing when no head sees the
Sun, and when the Sun is within ``min_sun_separation_deg`` of the yaw axis,
where that angle is undetermined (near noon and midnight at equinox).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .sensors import (
    DEG,
    SensorSuite,
    SunReadings,
    draw_ahead,
    drawn_rows,
    earth_sensor,
    sun_sensors,
    tachometers,
)

MIN_SUN_SEPARATION_DEG = 10.0  # no ground yaw closer than this to the yaw axis


@dataclass(frozen=True)
class Telemetry:
    """What the ground receives (SI units; NaN marks a missing yaw)."""

    t_s: np.ndarray
    roll_rad: np.ndarray
    pitch_rad: np.ndarray
    yaw_rad: np.ndarray
    yaw_sigma_rad: np.ndarray   # a-priori 1σ of each yaw from sensor and geometry
    yaw_head: np.ndarray        # index of the Sun-sensor head used, −1 when none
    wheel_speeds_radps: np.ndarray
    sun: SunReadings

    @property
    def sun_visible(self) -> np.ndarray:
        return self.sun.visible.any(axis=1)


def _angle_sigma_rad(head, alpha, beta) -> np.ndarray:
    """1σ of one measured angle: noise (CASS: growing off boresight) and quantisation."""
    noise = np.full(alpha.shape, head.noise_deg)
    if head.kind == "cass":
        cos_off = 1.0 / np.sqrt(1.0 + np.tan(alpha) ** 2 + np.tan(beta) ** 2)
        noise = head.noise_deg / np.maximum(cos_off, 1e-3)
    return np.sqrt(noise**2 + head.quantum_deg**2 / 12.0) * DEG


def select_head(sun: SunReadings, heads) -> np.ndarray:
    """Per sample, the head the ground uses: a visible DSS if any, else the visible
    CASS whose measured Sun is closest to its boresight; −1 when none sees it."""
    n, k = sun.visible.shape
    rank = np.full((n, k), np.inf)
    for j, head in enumerate(heads):
        seen = np.flatnonzero(sun.visible[:, j])   # the others stay at infinity
        off = np.hypot(sun.alpha_rad[seen, j], sun.beta_rad[seen, j])
        # DSS heads outrank every CASS (offsets are < π/2 rad).
        rank[seen, j] = off + (0.0 if head.kind == "dss" else 10.0)
    best = np.argmin(rank, axis=1)
    return np.where(np.isfinite(rank[np.arange(n), best]), best, -1)


def derive_yaw(sun: SunReadings, heads, roll_rad, pitch_rad, sun_orbit_frame,
               min_sun_separation_deg: float = MIN_SUN_SEPARATION_DEG) -> tuple[np.ndarray, ...]:
    """Ground yaw (rad), its a-priori σ (rad) and the head used, per sample.

    Only samples that can have a yaw (a head sees the Sun, the Sun is far enough
    from the yaw axis) are computed; the rest stay NaN / −1.
    """
    n = len(roll_rad)
    s_r = np.asarray(sun_orbit_frame)
    sep_sin = np.hypot(s_r[:, 0], s_r[:, 1])  # sine of the Sun's angle from the yaw axis
    head_idx = select_head(sun, heads)
    head_idx[sep_sin < np.sin(min_sun_separation_deg * DEG)] = -1
    yaw = np.full(n, np.nan)
    sigma = np.full(n, np.nan)
    for j, head in enumerate(heads):
        use = np.flatnonzero(head_idx == j)
        if use.size == 0:
            continue
        b, u, y = head.axes
        alpha, beta = sun.alpha_rad[use, j], sun.beta_rad[use, j]
        v = b + np.tan(alpha)[:, None] * u + np.tan(beta)[:, None] * y
        s_meas = v / np.linalg.norm(v, axis=1, keepdims=True)
        # Undo pitch then roll (measured): w = R2(θ)ᵀ ŝ, then the x–y part of R1(φ)ᵀ w.
        cp, sp = np.cos(pitch_rad[use]), np.sin(pitch_rad[use])
        cr, sr = np.cos(roll_rad[use]), np.sin(roll_rad[use])
        wx = cp * s_meas[:, 0] + sp * s_meas[:, 2]
        wz = -sp * s_meas[:, 0] + cp * s_meas[:, 2]
        vy = cr * s_meas[:, 1] - sr * wz
        psi = np.arctan2(s_r[use, 1], s_r[use, 0]) - np.arctan2(vy, wx)
        yaw[use] = (psi + np.pi) % (2 * np.pi) - np.pi
        sigma[use] = _angle_sigma_rad(head, alpha, beta) / sep_sin[use]
    return yaw, sigma, head_idx


def make_telemetry(truth, suite: SensorSuite, rngs,
                   min_sun_separation_deg: float = MIN_SUN_SEPARATION_DEG) -> Telemetry:
    """Sense a ``sim.truth.TruthResult`` with ``suite``; ``rngs`` maps each of
    ``suite.stream_names()`` to its own generator."""
    on = suite.noise_enabled
    roll, pitch = earth_sensor(truth.roll_rad, truth.pitch_rad, suite.earth, rngs["earth"], on)
    speeds = tachometers(truth.wheel_speeds_radps, suite.tachometer, rngs["tachometer"], on)
    # Half the solar disc hidden counts as lost: the heads need the Sun's centroid.
    sun = sun_sensors(truth.sun_body, truth.shadow >= 0.5, suite.sun_heads, rngs, on)
    yaw, sigma, head = derive_yaw(sun, suite.sun_heads, roll, pitch, truth.sun_orbit_frame,
                                  min_sun_separation_deg)
    return Telemetry(truth.t_s, roll, pitch, yaw, sigma, head, speeds, sun)


class TelemetryRows:
    """A window's telemetry gathered piece by piece as it is sensed (``put``), into
    arrays of the whole window, so the joining is done while the truth still rolls
    out rather than all at once after it."""

    _FIELDS = ("t_s", "roll_rad", "pitch_rad", "yaw_rad", "yaw_sigma_rad", "yaw_head",
               "wheel_speeds_radps")

    def __init__(self, n: int):
        self.n = n
        self.only: Telemetry | None = None   # a single piece spanning the window
        self.arrays: dict[str, np.ndarray] | None = None

    def put(self, tel: Telemetry, lo: int, hi: int) -> None:
        if lo == 0 and hi == self.n:
            self.only = tel
            return
        parts = {**{f: getattr(tel, f) for f in self._FIELDS},
                 **{f"sun.{f}": getattr(tel.sun, f) for f in ("visible", "alpha_rad",
                                                             "beta_rad")}}
        if self.arrays is None:
            self.arrays = {k: np.empty((self.n, *v.shape[1:]), v.dtype)
                           for k, v in parts.items()}
        for k, v in parts.items():
            self.arrays[k][lo:hi] = v

    def telemetry(self) -> Telemetry:
        if self.only is not None:
            return self.only
        a = self.arrays
        sun = SunReadings(a["sun.visible"], a["sun.alpha_rad"], a["sun.beta_rad"])
        return Telemetry(*(a[f] for f in self._FIELDS), sun)


def sense_window(stream, a: int, b: int, suite: SensorSuite, rngs, pool,
                 min_sun_separation_deg: float = MIN_SUN_SEPARATION_DEG):
    """Samples a … b−1 of a ``sim.truth.TruthStream`` and their telemetry, on both
    cores: the noise drawn in ``pool`` (one thread) while the truth rolls out and is
    sensed a piece at a time behind the rollout (``TruthStream.window(sense=...)``).
    Returns the truth, the telemetry and the draws (``sensors.draw_ahead``), which a
    second sensing of the same samples can read again."""
    drawn = pool.submit(draw_ahead, suite, rngs, b - a, stream.spacecraft.n_wheels)
    gathered = TelemetryRows(b - a)

    def sense(rows, lo, hi) -> None:
        gathered.put(make_telemetry(rows, suite, drawn_rows(drawn.result(), lo, hi),
                                    min_sun_separation_deg), lo, hi)
    truth, _ = stream.window(a, b, sense=sense)
    return truth, gathered.telemetry(), drawn.result()
