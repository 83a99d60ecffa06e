"""Column definitions of truth.csv, telemetry.csv and estimate.csv (docs/outputs.md).

Degrees and rpm appear only here, at the I/O boundary, with the unit in each
column name.  Missing values are NaN and are written as empty fields.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from dynprop.sim.ephemeris import parse_epoch

from ..units import RAD2DEG, RADPS2RPM

# Estimate columns: state name with its unit, and the factor from model units
# (ṙ/ω_n and ẏ/ω_n are written as rates in deg/s).
STATE_COLUMNS = ("roll_deg", "roll_rate_degps", "yaw_deg", "yaw_rate_degps", "h_Nms",
                 "N_px_Nm", "N_pz_Nm", "N_cx_Nm", "N_cz_Nm")


def display_factors(omega_n: float) -> np.ndarray:
    """Model units (Eq. 10) to estimate.csv's units, per state."""
    return np.array([RAD2DEG, RAD2DEG * omega_n, RAD2DEG, RAD2DEG * omega_n, 1, 1, 1, 1, 1])


def estimate_columns(t_s, x, sigma, omega_n: float) -> dict[str, np.ndarray]:
    """estimate.csv's columns: time, the 9 states and their 1σ."""
    f = display_factors(omega_n)
    cols = {"t_s": t_s}
    for k, name in enumerate(STATE_COLUMNS):
        cols[name] = x[:, k] * f[k]
    for k, name in enumerate(STATE_COLUMNS):
        cols[f"sigma_{name}"] = sigma[:, k] * abs(f[k])
    return cols


# The pitch filter's states (Eq. 3b, ``estimator.pitch``): θ, θ̇, N_y, from rad,
# rad/s and N m.
PITCH_COLUMNS = ("pitch_deg", "pitch_rate_degps", "N_y_Nm")
PITCH_FACTORS = np.array([RAD2DEG, RAD2DEG, 1.0])


def pitch_columns(x, sigma) -> dict[str, np.ndarray]:
    """estimate.csv's pitch columns: the pitch filter's 3 states and their 1σ."""
    cols = {name: x[:, k] * PITCH_FACTORS[k] for k, name in enumerate(PITCH_COLUMNS)}
    return cols | {f"sigma_{name}": sigma[:, k] * PITCH_FACTORS[k]
                   for k, name in enumerate(PITCH_COLUMNS)}


def truth_columns(result, sun_visible: np.ndarray, rows: np.ndarray | None = None
                  ) -> dict[str, np.ndarray]:
    """``w{x,y,z}_radps`` is ω_BN in body axes (what a gyro reads).  ``sun_visible`` is
    1 when any Sun-sensor head has the Sun in its field of view (geometry and
    eclipse, not noise); ``shadow`` is the visible fraction of the solar disc.
    Torques are ``<source>_{x,y,z}_Nm``, body axes, at each sample.  With ``rows``,
    those samples only: the same values, the torques formed there alone
    (``sim.history.Torques.rows``)."""
    cols = _state_columns(result, sun_visible)
    if rows is None:
        torques = result.torques
    else:
        cols = {k: v[rows] for k, v in cols.items()}
        torques = result.torques.rows(rows) if hasattr(result.torques, "rows") \
            else {k: v[rows] for k, v in result.torques.items()}
    for name, torque in torques.items():
        for k, axis in enumerate("xyz"):
            cols[f"{name}_{axis}_Nm"] = torque[:, k]
    return cols


def _state_columns(result, sun_visible: np.ndarray) -> dict[str, np.ndarray]:
    cols = {
        "t_s": result.t_s,
        "yaw_deg": result.yaw_rad * RAD2DEG,
        "roll_deg": result.roll_rad * RAD2DEG,
        "pitch_deg": result.pitch_rad * RAD2DEG,
        "wx_radps": result.w_bn_radps[:, 0],
        "wy_radps": result.w_bn_radps[:, 1],
        "wz_radps": result.w_bn_radps[:, 2],
    }
    for i in range(result.wheel_speeds_radps.shape[1]):
        cols[f"wheel{i + 1}_rpm"] = result.wheel_speeds_radps[:, i] * RADPS2RPM
    cols["h_Nms"] = result.h_Nms
    cols["H_Nms"] = result.H_Nms
    cols["sun_visible"] = np.asarray(sun_visible, dtype=float)
    cols["eclipse"] = result.eclipse.astype(float)
    cols["shadow"] = result.shadow
    return cols


def decimals_of(quantum: float, most: int = 12) -> int | None:
    """Decimal places of a quantum written in decimal (0.0163 → 4, 0.125 → 3), or
    None if it has no short decimal form (then readings are left as they are)."""
    for d in range(most + 1):
        if round(quantum, d) == quantum:
            return d
    return None


def as_decimal_reading(values: np.ndarray, quantum: float) -> np.ndarray:
    """Quantised readings as the nearest double to their decimal value.

    The sensor model gives k·q in rad or rad/s; converted back to deg or rpm the
    product is a few ulps off the decimal a ground system prints (5485.096699999999
    for 336 519 × 0.0163 rpm).  Re-rounding to the quantum's decimal places moves
    each reading by those ulps only (never by a count: |error| ≪ q/2) and makes the
    file's shortest round-trip text the reading itself, 5485.0967."""
    d = decimals_of(quantum)
    if d is None:
        return values
    with np.errstate(invalid="ignore"):
        return np.round(np.round(values / quantum) * quantum, d)


def telemetry_lattices(suite, n_wheels: int) -> dict[str, float]:
    """The reading quantum of each quantised column of ``telemetry_columns``: the one
    place that says which, for the columns themselves (``as_decimal_reading``) and
    for ``csvio``'s faster exact text."""
    earth_q, tach_q = suite.earth.quantum_deg, suite.tachometer.quantum_rpm
    out = {"roll_deg": earth_q, "pitch_deg": earth_q, "sun_head": 1.0, "maneuver": 1.0,
           **{f"wheel{i + 1}_rpm": tach_q for i in range(n_wheels)}}
    for head in suite.sun_heads:
        out[f"{head.name}_alpha_deg"] = out[f"{head.name}_beta_deg"] = head.quantum_deg
    return out


def telemetry_columns(tel, suite) -> dict[str, np.ndarray]:
    """What a ground system receives, plus its own yaw solution.

    ``yaw_deg`` is the ground yaw (empty when no Sun sensor sees the Sun or the Sun
    is too near the yaw axis); ``yaw_sigma_deg`` its a-priori 1σ from the sensor and
    the geometry; ``sun_head`` the index of the head it came from (0 = first head);
    ``<head>_{alpha,beta}_deg`` the raw quantised Sun-sensor angles (empty when that
    head does not see the Sun); ``maneuver``, only in a run with events, 1 while a
    thruster fires and 0 otherwise.  Quantised readings are their decimal values
    (``as_decimal_reading``); the run's filter reads these very columns.
    """
    quantum = telemetry_lattices(suite, tel.wheel_speeds_radps.shape[1])
    cols = {
        "t_s": tel.t_s,
        "roll_deg": as_decimal_reading(tel.roll_rad * RAD2DEG, quantum["roll_deg"]),
        "pitch_deg": as_decimal_reading(tel.pitch_rad * RAD2DEG, quantum["pitch_deg"]),
        "yaw_deg": tel.yaw_rad * RAD2DEG,
    }
    for i in range(tel.wheel_speeds_radps.shape[1]):
        name = f"wheel{i + 1}_rpm"
        cols[name] = as_decimal_reading(tel.wheel_speeds_radps[:, i] * RADPS2RPM,
                                        quantum[name])
    cols["yaw_sigma_deg"] = tel.yaw_sigma_rad * RAD2DEG
    cols["sun_head"] = np.where(tel.yaw_head >= 0, tel.yaw_head, np.nan)
    for k, head in enumerate(suite.sun_heads):
        for angle, values in (("alpha", tel.sun.alpha_rad), ("beta", tel.sun.beta_rad)):
            name = f"{head.name}_{angle}_deg"
            cols[name] = as_decimal_reading(values[:, k] * RAD2DEG, quantum[name])
    if tel.maneuver is not None:
        cols["maneuver"] = tel.maneuver
    return cols


def epoch_ns(epoch_utc: str) -> np.datetime64:
    """An ISO 8601 epoch with a zone (``sim.ephemeris.parse_epoch``) as UTC
    datetime64[ns]."""
    return np.datetime64(parse_epoch(epoch_utc).replace(tzinfo=None), "ns")


def utc_text(instants: np.ndarray) -> np.ndarray:
    """datetime64[ns] instants as ISO 8601 UTC text ending in Z, to the finest unit
    any of them needs (s, ms, µs or ns): ``2026-03-20T12:00:00Z``."""
    ns = np.asarray(instants, dtype="datetime64[ns]")
    whole = ns.astype(np.int64)
    unit = next((u for u, d in (("s", 10**9), ("ms", 10**6), ("us", 10**3))
                 if not np.any(whole % d)), "ns")
    return np.datetime_as_string(ns, unit=unit, timezone="UTC")


@dataclass(frozen=True)
class UtcTags:
    """telemetry.csv's ``# epoch_utc:`` first line and its ``time_utc`` column: each
    row's t_s after the epoch as ISO 8601 UTC, in milliseconds when the step is a
    whole number of them (0.512 s: ``2026-03-20T12:00:00.512Z``), else microseconds.
    One unit per file, so a file written a window at a time has the bytes of one
    written whole.  ``t_s`` stays the exact time; these tags say what it is."""

    epoch_utc: str
    unit: str = "ms"

    @classmethod
    def of(cls, epoch_utc: str, step_s: float) -> UtcTags:
        ms = step_s * 1e3
        return cls(epoch_utc, "ms" if abs(ms - round(ms)) < 1e-9 * max(ms, 1.0) else "us")

    def comment(self) -> str:
        """The first line: the epoch t_s counts from, in UTC."""
        return f"# epoch_utc: {utc_text(epoch_ns(self.epoch_utc))}\n"

    def text(self, t_s: np.ndarray) -> np.ndarray:
        """The tags of ``t_s`` (s after the epoch), rounded to the unit (the text
        itself would cut a 1.5359999999999998 s off to 1.535)."""
        per_s = {"ms": 1e3, "us": 1e6}[self.unit]
        offset = np.rint(np.asarray(t_s, dtype=float) * per_s).astype(np.int64)
        return np.datetime_as_string(epoch_ns(self.epoch_utc)
                                     + offset.astype(f"timedelta64[{self.unit}]"),
                                     unit=self.unit, timezone="UTC")
