"""Telemetry values the spacecraft cannot produce, screened before the filter
(docs/telemetry.md, "What dynprop does with bad values").

A ground system's file carries what no sensor read: an overflowed tachometer word
(1e308), a spike of ten times the wheel's speed, a 5° Earth-sensor glitch, a Sun angle
outside its head's field of view, the text ``nan``.  One such value ruins the
estimate: wheel speeds enter the filter twice, as the measured h and as the input
N_w* = ḣ, and the χ² gate sees only the first.  Each rule here asks what the scenario's
spacecraft can physically produce (limits: ``config.screen.TelemetryScreen``):

- non-finite: a cell written as ``nan`` or ``inf`` (an empty cell is a dropout, as
  always, and is not counted);
- range: a roll or pitch beyond the Earth sensor's range, a wheel beyond its speed limit,
  a yaw beyond ±180°;
- field of view: a head's α or β beyond its half field of view (and that head's yaw in
  the row with it);
- flag: a maneuver flag (``maneuver``, written by a run with events) neither 0 nor 1;
- jump: a roll, pitch or wheel reading further from the running median of its two
  neighbours on each side than the fastest motion (the attitude rate, the motor torque)
  over that span, the quantum and 25σ of the noise allow.  The median of five
  ignores one or two bad readings, and a real step (a new speed held) moves it.

A screened value becomes a dropout of that sensor only (NaN in its column), so neither
the measurement nor any input derived from it (ḣ, N_w*, the pitch Ḣ: the wheel bridge
interpolates across it) sees it.  Each is reported: summary.json counts them per column
with the first rows and the reason, and the warnings give one line per reason.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..config import build
from ..config.screen import HALF_WINDOW, JUMP_NOISE_SIGMAS, JUMP_QUANTA, WHEEL_SPEED_FACTOR
from ..units import RAD2DEG, RADPS2RPM

# How a reason reads in a warning, after "screened N value(s) ".
REASONS = {
    "non-finite": "written as nan or inf",
    "range": "outside the sensor's range or the wheel's speed limit",
    "field of view": "outside the Sun-sensor head's field of view (with that head's yaw)",
    "jump": "a jump from the neighbouring readings faster than the attitude or wheel can move",
    "flag": "a maneuver flag other than 0 or 1",
}
FIRST = 5          # rows listed per column in summary.json and the warning
ANGLE_UNITS = {"deg": 1.0, "rad": RAD2DEG, "urad": 1e-6 * RAD2DEG}   # to degrees
HEAD_NAMES = ("dss", "cass1", "cass2")   # telemetry.csv's sun_head codes 0, 1, 2


@dataclass(frozen=True)
class Limits:
    """The screen's limits for one scenario, in the file's canonical units (deg, rpm,
    s).  ``wheel_rate_rpmps`` is each wheel's fastest speed change, τ_max / I_w."""

    earth_range_deg: float
    attitude_rate_degps: float
    earth_allowance_deg: float
    wheel_speed_max_rpm: float
    wheel_rate_rpmps: tuple[float, ...]
    wheel_allowance_rpm: float
    fov_deg: dict[str, tuple[float, float]]     # head -> (in-, out-of-plane) limit

    def as_dict(self) -> dict:
        return {"earth_range_deg": self.earth_range_deg,
                "attitude_rate_max_degps": self.attitude_rate_degps,
                "earth_jump_allowance_deg": self.earth_allowance_deg,
                "wheel_speed_max_rpm": self.wheel_speed_max_rpm,
                "wheel_rate_max_rpmps": list(self.wheel_rate_rpmps),
                "wheel_jump_allowance_rpm": self.wheel_allowance_rpm}


@dataclass(frozen=True)
class Screened:
    """The values of one column screened for one reason: ``rows`` index the file's
    data rows (0 = the first row after the header)."""

    column: str
    reason: str
    rows: np.ndarray
    values: np.ndarray


@dataclass(frozen=True)
class ScreenReport:
    enabled: bool
    limits: Limits | None
    screened: tuple[Screened, ...]
    t_s: np.ndarray           # every file row's time, for the report
    names: dict[str, str]     # canonical column -> the file's name
    held: tuple = ()          # (column, row, row held from): a wheel's screened end

    @property
    def count(self) -> int:
        return int(sum(len(s.rows) for s in self.screened))

    def rows_any(self) -> np.ndarray:
        """The file rows with any screened value, in order."""
        if not self.screened:
            return np.zeros(0, dtype=np.int64)
        return np.unique(np.concatenate([s.rows for s in self.screened]))

    def summary(self) -> dict:
        """summary.json's ``telemetry.screened``: per file column, the count and, per
        reason, its count and first rows (numbered as the file's: the header is row 1),
        their times and values; and the limits screened against."""
        columns: dict[str, dict] = {}
        for s in self.screened:
            c = columns.setdefault(self.names.get(s.column, s.column),
                                   {"count": 0, "reasons": {}})
            c["count"] += len(s.rows)
            c["reasons"][s.reason] = {
                "count": int(len(s.rows)),
                "first_rows": [int(r) + 2 for r in s.rows[:FIRST]],
                "first_t_s": [float(self.t_s[r]) for r in s.rows[:FIRST]],
                "first_values": [_json_number(v) for v in s.values[:FIRST]]}
        return {"enabled": self.enabled, "values": self.count, "columns": columns,
                "held_at_ends": [{"column": self.names.get(c, c), "row": r + 2,
                                  "held_from_row": f + 2} for c, r, f in self.held],
                "limits": None if self.limits is None else self.limits.as_dict()}


def screen_warnings(screened: dict | None) -> list[dict]:
    """One warning per reason (summary.json's ``telemetry.screened``, ``ScreenReport.
    summary``), naming each column, its count and first rows."""
    if not screened or not screened.get("values"):
        return []
    out = []
    for reason, text in REASONS.items():
        hits = [(name, c["reasons"][reason]) for name, c in screened["columns"].items()
                if reason in c["reasons"]]
        if not hits:
            continue
        n = sum(h["count"] for _, h in hits)
        where = "; ".join(
            f"{name} ×{h['count']} (row{'s' * (h['count'] > 1)} "
            + ", ".join(map(str, h["first_rows"])) + (", …" if h["count"] > FIRST else "")
            + ")" for name, h in hits)
        out.append({"check": "telemetry_screen",
                    "message": f"screened {n} value{'s' * (n > 1)} {text}: {where}; each is "
                    "a dropout of its sensor (telemetry.screen)"})
    for h in screened.get("held_at_ends") or ():
        out.append({"check": "telemetry_screen",
                    "message": f"{h['column']}'s reading in row {h['row']}, the file's "
                    f"{'first' if h['row'] < h['held_from_row'] else 'last'}, was screened: "
                    f"row {h['held_from_row']}'s is held there, since the wheel-torque "
                    "bridge needs a reading at both ends"})
    return out


def screen_messages(screened: dict | None) -> list[str]:
    """``screen_warnings``' sentences alone, as tune.json, trim.json and batch.json
    list their warnings."""
    return [w["message"] for w in screen_warnings(screened)]


def _json_number(v: float):
    return float(v) if np.isfinite(v) else str(v)


def limits(s) -> Limits | None:
    """The scenario's screen limits (None when ``telemetry.screen.enabled`` is false)."""
    cfg = s.telemetry.screen
    if not cfg.enabled:
        return None
    sc = build.build_spacecraft(s)
    J = sc.J
    nutation = abs(float(sc.pitch_bias_Nms())) / np.sqrt(J[0, 0] * J[2, 2])
    rate = (cfg.attitude_rate_max_degps if cfg.attitude_rate_max_degps is not None
            else nutation * cfg.earth_range_deg)
    e, t = s.sensors.earth, s.sensors.tachometer
    speed_max = (cfg.wheel_speed_max_rpm if cfg.wheel_speed_max_rpm is not None
                 else WHEEL_SPEED_FACTOR * abs(s.spacecraft.wheels.speed_rpm))
    heads = s.sensors.sun
    fov = {name: _fov_limits(getattr(heads, name)) for name in HEAD_NAMES}
    return Limits(
        earth_range_deg=cfg.earth_range_deg, attitude_rate_degps=float(rate),
        earth_allowance_deg=JUMP_NOISE_SIGMAS * e.noise_deg + JUMP_QUANTA * e.quantum_deg,
        wheel_speed_max_rpm=float(speed_max),
        wheel_rate_rpmps=tuple(float(cfg.wheel_torque_max_Nm / w.spin_inertia_kgm2 * RADPS2RPM)
                               for w in sc.wheels),
        wheel_allowance_rpm=JUMP_NOISE_SIGMAS * t.noise_3sigma_rpm / 3
        + JUMP_QUANTA * t.quantum_rpm,
        fov_deg=fov)


def _fov_limits(h) -> tuple[float, float]:
    """A head's in- and out-of-plane limits: the half field of view, which the true
    angle keeps (the sensor reports only then), plus what its reading adds: 2 quanta
    and 25σ of its noise, a CASS's grown as 1/cos of the angle off the boresight."""
    def one(half_deg: float) -> float:
        grow = 1 / np.cos(np.radians(half_deg)) if h.kind == "cass" else 1.0
        return half_deg + JUMP_QUANTA * h.quantum_deg + JUMP_NOISE_SIGMAS * h.noise_deg * grow
    return one(h.fov_in_plane_deg), one(h.fov_out_of_plane_deg)


def jumps(t: np.ndarray, v: np.ndarray, rate: float, allowance: float) -> np.ndarray:
    """Where the present (finite) values of ``v`` lie further from the running median of
    ``2·HALF_WINDOW + 1`` present readings around them than ``rate`` times the window's
    span from them plus ``allowance``.  Near the ends the window is the first (last)
    full one, so a bad first or last reading is judged by the readings after (before)
    it, and a straight ramp is never a jump."""
    ok = np.flatnonzero(np.isfinite(v))
    out = np.zeros(len(v), dtype=bool)
    width = 2 * HALF_WINDOW + 1
    if len(ok) < width:
        return out
    x, tt = v[ok], t[ok]
    start = np.clip(np.arange(len(x)) - HALF_WINDOW, 0, len(x) - width)
    med = np.median(np.lib.stride_tricks.sliding_window_view(x, width), axis=1)[start]
    span = np.maximum(np.abs(tt - tt[start]), np.abs(tt[start + width - 1] - tt))
    out[ok] = np.abs(x - med) > rate * span + allowance
    return out


def screen(cols: dict[str, np.ndarray], written: dict[str, np.ndarray], s,
           names: dict[str, str] | None = None) -> tuple[dict[str, np.ndarray], ScreenReport]:
    """``cols`` (canonical telemetry columns, ``telemetry_file.read_telemetry``) with
    every screened value set to NaN, and the report.  ``written`` marks, per column,
    the cells whose text was a non-number such as ``nan`` (an empty cell is not
    marked: it is a dropout).  Columns are returned as they are, the very arrays, when
    nothing in them is screened, so clean telemetry reaches the filter bit for bit."""
    lim = limits(s)
    names = names or {}
    t = cols["t_s"]
    if lim is None:
        return cols, ScreenReport(False, None, (), t, names)
    out = dict(cols)
    found: list[Screened] = []

    def drop(name: str, mask: np.ndarray, reason: str) -> None:
        if mask.any():
            rows = np.flatnonzero(mask)
            found.append(Screened(name, reason, rows, out[name][rows].copy()))
            out[name] = np.where(mask, np.nan, out[name])

    measured = [c for c in out if c not in ("t_s", "sun_head")]
    for name in measured:
        bad = np.isinf(out[name])
        if name in written:
            bad |= written[name]
        drop(name, bad, "non-finite")
    for name in ("roll_deg", "pitch_deg"):
        if name in out:
            drop(name, np.abs(out[name]) > lim.earth_range_deg, "range")
    if "yaw_deg" in out:
        drop("yaw_deg", np.abs(out["yaw_deg"]) > 180.0, "range")
    if "yaw_sigma_deg" in out:
        drop("yaw_sigma_deg", out["yaw_sigma_deg"] <= 0, "range")
    wheels = [c for c in out if c.startswith("wheel") and c.endswith("_rpm")]
    for name in wheels:
        drop(name, np.abs(out[name]) > lim.wheel_speed_max_rpm, "range")
    if "maneuver" in out:
        drop("maneuver", bad_flags(out["maneuver"]), "flag")
    _screen_heads(out, lim, drop)
    # A yaw without its σ cannot be weighed: it goes with its σ, for the σ's reason.
    for bad in [x for x in found if x.column == "yaw_sigma_deg"]:
        if "yaw_deg" in out:
            mask = np.zeros(len(t), dtype=bool)
            mask[bad.rows] = True
            drop("yaw_deg", mask & np.isfinite(out["yaw_deg"]), bad.reason)
    for name in ("roll_deg", "pitch_deg"):
        if name in out:
            drop(name, jumps(t, out[name], lim.attitude_rate_degps, lim.earth_allowance_deg),
                 "jump")
    for k, name in enumerate(wheels):
        rate = lim.wheel_rate_rpmps[min(k, len(lim.wheel_rate_rpmps) - 1)]
        drop(name, jumps(t, out[name], rate, lim.wheel_allowance_rpm), "jump")
    if not found:
        return cols, ScreenReport(True, lim, (), t, names)
    held = _hold_wheel_ends(out, wheels, found)
    return out, ScreenReport(True, lim, tuple(found), t, names, held)


def bad_flags(v: np.ndarray) -> np.ndarray:
    """Maneuver flags that are neither 0 nor 1 (an empty one is a dropout, not bad)."""
    return np.isfinite(v) & (v != 0) & (v != 1)


def _hold_wheel_ends(out: dict, wheels: list[str], found: list[Screened]) -> tuple:
    """A wheel's first or last reading screened: the nearest good reading held there,
    since the wheel-torque bridge interpolates between readings and needs both ends
    (``estimator.kalman.preprocess``).  (column, row, row held from) for each."""
    held = []
    for name in wheels:
        rows = np.concatenate([x.rows for x in found if x.column == name] or [[]])
        v = out[name]
        ok = np.flatnonzero(np.isfinite(v))
        if not rows.size or not ok.size:
            continue
        for end, near in ((0, ok[0]), (len(v) - 1, ok[-1])):
            if end in rows:
                v[end] = v[near]
                held.append((name, int(end), int(near)))
    return tuple(held)


def _screen_heads(out: dict, lim: Limits, drop) -> None:
    """A head's α or β outside its field of view, and the yaw that head gave there."""
    head = out.get("sun_head")
    for code, name in enumerate(HEAD_NAMES):
        fov_in, fov_out = lim.fov_deg[name]
        bad = np.zeros(len(out["t_s"]), dtype=bool)
        for angle, fov in (("alpha", fov_in), ("beta", fov_out)):
            col = f"{name}_{angle}_deg"
            if col in out:
                mask = np.abs(out[col]) > fov
                bad |= mask
                drop(col, mask, "field of view")
        if not bad.any():
            continue
        # That head's yaw in those rows is computed from the angle; without sun_head
        # the yaw cannot be told apart, so any yaw in the row goes.
        gave = bad if head is None else bad & (head == code)
        for col in ("yaw_deg", "yaw_sigma_deg", "sun_head"):
            if col in out:
                if col == "yaw_deg":
                    drop(col, gave & np.isfinite(out[col]), "field of view")
                else:
                    out[col] = np.where(gave, np.nan, out[col])


def unit_problems(path, cols: dict[str, np.ndarray], s, names: dict[str, str]) -> list[str]:
    """A line per column whose values are a unit's factor away from what the scenario's
    spacecraft reads: wheel speeds 2π/60 (rad/s read as rpm) or 60/2π from each wheel's
    nominal speed; roll or pitch whose sample-to-sample scatter is 180/π or π/180 (or
    1e6 times that) from the Earth sensor's noise and quantum, a yaw likewise from the
    coarse Sun sensors' noise.  Within a factor of
    2 (wheels) or 3 (angles) of the factor, which no physical scatter reaches."""
    problems = []
    sc = build.build_spacecraft(s)
    for k, w in enumerate(sc.wheels):
        name = f"wheel{k + 1}_rpm"
        v = cols.get(name)
        nominal = abs(w.speed_radps) * RADPS2RPM
        if v is None or nominal == 0:
            continue
        v = np.abs(v[np.isfinite(v)])
        if not v.size:
            continue
        ratio = float(np.median(v)) / nominal
        given = s.telemetry.units.wheels
        as_written = float(np.median(v)) / (RADPS2RPM if given == "rad/s" else 1.0)
        for unit, factor in (("rad/s", 1 / RADPS2RPM), ("rpm", RADPS2RPM)):
            if unit != given and abs(np.log(ratio / factor)) < np.log(2):
                problems.append(
                    f"{path}: {names.get(name, name)} reads a median {as_written:.4g} "
                    f"{given}, {ratio:.4f} × the wheel's nominal {nominal:.5g} rpm: the "
                    f"file's wheel speeds look like {unit}, not {given} (--unit "
                    f"wheels={unit})")
    e, cass = s.sensors.earth, s.sensors.sun.cass1
    earth = (np.hypot(e.noise_deg, e.quantum_deg / np.sqrt(12)), "the Earth sensor's")
    head = cols.get("sun_head")
    for key, name in (("roll", "roll_deg"), ("pitch", "pitch_deg"), ("yaw", "yaw_deg")):
        v = cols.get(name)
        if v is None:
            continue
        d = np.diff(v)
        expected, whose = earth
        if key == "yaw":
            # The coarse heads' yaw is white at about their 1°; the digital head's is
            # quantised and slowly varying, its sample-to-sample scatter far below its
            # σ (0.006° against 0.036°), and would read as rad.  So the yaw is judged
            # on consecutive CASS readings, and not at all in a file without sun_head.
            if head is None:
                continue
            expected, whose = cass.noise_deg, "the coarse Sun sensors'"
            d = d[(head[:-1] >= 1) & (head[1:] == head[:-1])]
        d = d[np.isfinite(d)]
        if d.size < 10 or expected == 0:
            continue
        # The normal-scaled median absolute deviation (scipy.stats.median_abs_deviation
        # with scale="normal"; written out, since importing scipy.stats costs every
        # command that reads telemetry, `export` among them, 0.45 s of start-up).
        scatter = 1.4826 * float(np.median(np.abs(d - np.median(d)))) / np.sqrt(2)
        if scatter == 0:
            continue
        ratio = scatter / expected
        declared = getattr(s.telemetry.units, key)
        given = ANGLE_UNITS[declared]
        for unit, to_deg in ANGLE_UNITS.items():
            if unit != declared and abs(np.log(ratio / (given / to_deg))) < np.log(3):
                problems.append(
                    f"{path}: {names.get(name, name)} scatters {scatter:.3g}° from sample "
                    f"to sample read as {declared}, {ratio:.3g} × {whose} "
                    f"{expected:.3g}° of noise: the file's {key} looks like {unit}, not "
                    f"{declared} (--unit {key}={unit})")
    return problems


__all__ = ["Limits", "ScreenReport", "Screened", "bad_flags", "jumps", "limits", "screen",
           "screen_messages", "screen_warnings", "unit_problems"]
