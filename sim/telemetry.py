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

import dataclasses
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
    # With scheduled events (``sim.events``): 1 inside a thruster firing, else 0, as a
    # ground system flags a maneuver; None without events.
    maneuver: np.ndarray | None = None

    @property
    def sun_visible(self) -> np.ndarray:
        return self.sun.visible.any(axis=1)


def _angle_sigma_rad(head, tan_alpha, tan_beta) -> np.ndarray:
    """1σ of one measured angle: noise (CASS: growing off boresight) and quantisation,
    from the tangents of the measured angles."""
    noise = np.full(tan_alpha.shape, head.noise_deg)
    if head.kind == "cass":
        cos_off = 1.0 / np.sqrt(1.0 + tan_alpha ** 2 + tan_beta ** 2)
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
               min_sun_separation_deg: float = MIN_SUN_SEPARATION_DEG,
               out: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
               ) -> tuple[np.ndarray, ...]:
    """Ground yaw (rad), its a-priori σ (rad) and the head used, per sample (written
    into ``out``'s three arrays if given).

    Only samples that can have a yaw (a head sees the Sun, the Sun is far enough
    from the yaw axis) are computed; the rest stay NaN / −1.
    """
    n = len(roll_rad)
    s_r = np.asarray(sun_orbit_frame)
    sep_sin = np.hypot(s_r[:, 0], s_r[:, 1])  # sine of the Sun's angle from the yaw axis
    yaw, sigma, head_idx = out if out is not None else (np.empty(n), np.empty(n),
                                                        np.empty(n, dtype=np.intp))
    head_idx[:] = select_head(sun, heads)
    head_idx[sep_sin < np.sin(min_sun_separation_deg * DEG)] = -1
    yaw.fill(np.nan)
    sigma.fill(np.nan)
    for j, head in enumerate(heads):
        use = np.flatnonzero(head_idx == j)
        if use.size == 0:
            continue
        b, u, y = head.axes
        ta, tb = np.tan(sun.alpha_rad[use, j]), np.tan(sun.beta_rad[use, j])
        # ŝ = v/|v| with v = b + tan α u + tan β y, a component at a time (contiguous
        # arrays; the same operations, in the same order, as on (n, 3) rows).
        v = [b[k] + ta * u[k] + tb * y[k] for k in range(3)]
        norm = np.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
        s0, s1, s2 = (c / norm for c in v)
        # Undo pitch then roll (measured): w = R2(θ)ᵀ ŝ, then the x–y part of R1(φ)ᵀ w.
        cp, sp = np.cos(pitch_rad[use]), np.sin(pitch_rad[use])
        cr, sr = np.cos(roll_rad[use]), np.sin(roll_rad[use])
        wx = cp * s0 + sp * s2
        wz = -sp * s0 + cp * s2
        vy = cr * s1 - sr * wz
        psi = np.arctan2(s_r[use, 1], s_r[use, 0]) - np.arctan2(vy, wx)
        yaw[use] = (psi + np.pi) % (2 * np.pi) - np.pi
        sigma[use] = _angle_sigma_rad(head, ta, tb) / sep_sin[use]
    return yaw, sigma, head_idx


def make_telemetry(truth, suite: SensorSuite, rngs,
                   min_sun_separation_deg: float = MIN_SUN_SEPARATION_DEG,
                   out: Telemetry | None = None) -> Telemetry:
    """Sense a ``sim.truth.TruthResult`` with ``suite``; ``rngs`` maps each of
    ``suite.stream_names()`` to its own generator.  With ``out`` (``TelemetryRows``'
    views of a piece) every reading is written there, and ``out`` returned."""
    on = suite.noise_enabled
    if out is not None:
        out.t_s[:] = truth.t_s
    roll, pitch = earth_sensor(truth.roll_rad, truth.pitch_rad, suite.earth, rngs["earth"], on,
                               None if out is None else (out.roll_rad, out.pitch_rad))
    speeds = tachometers(truth.wheel_speeds_radps, suite.tachometer, rngs["tachometer"], on,
                         None if out is None else out.wheel_speeds_radps)
    # Half the solar disc hidden counts as lost: the heads need the Sun's centroid.
    sun = sun_sensors(truth.sun_body, truth.shadow >= 0.5, suite.sun_heads, rngs, on,
                      None if out is None else out.sun)
    yaw, sigma, head = derive_yaw(
        sun, suite.sun_heads, roll, pitch, truth.sun_orbit_frame, min_sun_separation_deg,
        None if out is None else (out.yaw_rad, out.yaw_sigma_rad, out.yaw_head))
    return out if out is not None else Telemetry(truth.t_s, roll, pitch, yaw, sigma, head,
                                                 speeds, sun)


class TelemetryRows:
    """A window's telemetry, sensed piece by piece straight into arrays of the whole
    window (``rows`` hands ``make_telemetry`` a piece's views): nothing is joined
    after the rollout, and no piece is copied."""

    def __init__(self, n: int, n_heads: int, n_wheels: int):
        self.window = Telemetry(
            np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n),
            np.empty(n, dtype=np.intp), np.empty((n, n_wheels)),
            SunReadings(np.empty((n, n_heads), dtype=bool), np.empty((n, n_heads)),
                        np.empty((n, n_heads))))

    def rows(self, lo: int, hi: int) -> Telemetry:
        """Views of samples lo … hi−1 of the window's arrays."""
        w, cut = self.window, slice(lo, hi)
        return Telemetry(w.t_s[cut], w.roll_rad[cut], w.pitch_rad[cut], w.yaw_rad[cut],
                         w.yaw_sigma_rad[cut], w.yaw_head[cut], w.wheel_speeds_radps[cut],
                         SunReadings(w.sun.visible[cut], w.sun.alpha_rad[cut],
                                     w.sun.beta_rad[cut]))

    def telemetry(self) -> Telemetry:
        return self.window


def with_events(tel: Telemetry, schedule) -> Telemetry:
    """``tel`` as a run with the ``schedule`` (``sim.events``) receives it: each sensor
    empty (NaN) inside its outages (earth: roll and pitch; sun: the ground yaw, its σ
    and head, and every head's angles, while the truth's Sun visibility stays;
    tachometer: every wheel), and the maneuver flag attached.  The readings are blanked
    in place (the window's own arrays) after they are drawn, so the noise streams, and
    the linear twin's draws with them, are those of the run without outages.  Without
    events, ``tel`` itself."""
    if not schedule:
        return tel
    t = tel.t_s
    out = schedule.outage("earth", t)
    tel.roll_rad[out] = np.nan
    tel.pitch_rad[out] = np.nan
    out = schedule.outage("sun", t)
    for a in (tel.yaw_rad, tel.yaw_sigma_rad, tel.sun.alpha_rad, tel.sun.beta_rad):
        a[out] = np.nan
    tel.yaw_head[out] = -1
    tel.wheel_speeds_radps[schedule.outage("tachometer", t)] = np.nan
    return dataclasses.replace(tel, maneuver=schedule.maneuver(t).astype(float))


def sense_window(stream, a: int, b: int, suite: SensorSuite, rngs, pool,
                 min_sun_separation_deg: float = MIN_SUN_SEPARATION_DEG):
    """Samples a … b−1 of a ``sim.truth.TruthStream`` and their telemetry, on both
    cores: the noise drawn in ``pool`` (one thread) while the truth rolls out and is
    sensed a piece at a time behind the rollout (``TruthStream.window(sense=...)``).
    Returns the truth, the telemetry (with the stream's events, ``with_events``) and
    the draws (``sensors.draw_ahead``), which a second sensing of the same samples can
    read again."""
    n_wheels = stream.spacecraft.n_wheels
    drawn = pool.submit(draw_ahead, suite, rngs, b - a, n_wheels)
    gathered = TelemetryRows(b - a, len(suite.sun_heads), n_wheels)

    def sense(rows, lo, hi) -> None:
        make_telemetry(rows, suite, drawn_rows(drawn.result(), lo, hi),
                       min_sun_separation_deg, gathered.rows(lo, hi))
    truth, _ = stream.window(a, b, sense=sense)
    return truth, with_events(gathered.telemetry(), stream.schedule), drawn.result()
