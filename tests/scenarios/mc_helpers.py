"""Shared helpers of the Monte Carlo tests, and the Sun-gap prediction that the run
and Monte Carlo tests check the written Sun gaps against."""

from __future__ import annotations

import contextlib
import io
import json
import math
import re
import sys
from datetime import UTC, datetime, timedelta
from pathlib import Path

import numpy as np
from scipy import stats

from scenarios.cli import main
from scenarios.config.loader import load_scenario

DYNPROP = Path(sys.executable).with_name("dynprop")
DT = 0.512
STATES = ("roll_deg", "roll_rate_degps", "yaw_deg", "yaw_rate_degps", "h_Nms",
          "N_px_Nm", "N_pz_Nm", "N_cx_Nm", "N_cz_Nm")
YAW = STATES.index("yaw_deg")
FIGURES = ("mc_errors.png", "mc_nees.png", "mc_gap_yaw.png")
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
RAN = re.compile(r": (new|resumed) set, ran (\d+) of (\d+) cases")

# 19:00 local at 75° W the day after the equinox: the night Sun gap (~20:15–04:05
# local) falls ~1.3–9.1 h into the run, so 10 h hold one whole gap and its end.
# Epoch dispersions move whole days, so every case has its gap at the same hours.
GAP_SET = ("--duration-s", "36000", "--set", "epoch_utc=2026-03-21T00:00:00Z",
           "--set", "montecarlo.converged_after_h=1")
TWIN_SET = (*GAP_SET, "--set", "montecarlo.linear_twin=true")


def scenario_of(args):
    """The nominal scenario that CLI arguments ``args`` (--duration-s, --seed, --set) name."""
    overrides, it = [], iter(args)
    for a in it:
        if a == "--set":
            overrides.append(next(it))
        elif a in ("--duration-s", "--seed"):
            overrides.append(f"{a[2:].replace('-', '_')}={next(it)}")
    return load_scenario("goes_next_equinox", overrides)


def run_cli(*argv: str) -> tuple[int, str, str]:
    """``main(argv)`` in-process with stdout and stderr captured; argparse exits too."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            rc = main([str(a) for a in argv])
        except SystemExit as exc:
            rc = exc.code
    return rc, out.getvalue(), err.getvalue()


def montecarlo(out: Path, runs: int, *extra: str, workers: int = 2) -> tuple[int, str, str]:
    return run_cli("montecarlo", "goes_next_equinox", "--runs", runs, "--workers", workers,
                   "--out", out, *extra)


def ran(stdout: str) -> tuple[str, int, int]:
    """("ran" for a new set | "resumed", cases run now, cases in the set) from the
    summary line, which also says how many were already stored."""
    m = RAN.search(stdout)
    assert m, f"no 'new/resumed set, ran N of M cases' in {stdout!r}"
    n, total = int(m.group(2)), int(m.group(3))
    assert f"({total - n} already stored)" in stdout
    return ("ran" if m.group(1) == "new" else "resumed"), n, total


def assert_one_line(err: str) -> str:
    assert err.endswith("\n") and err.count("\n") == 1, f"stderr is not one line: {err!r}"
    assert "Traceback" not in err
    return err


def dispersions_override(d: dict) -> str:
    return f"montecarlo.dispersions={json.dumps(d)}"   # JSON is YAML


def case_files(cases: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(cases.iterdir())}


def snapshot(paths) -> dict[str, tuple[bytes, int]]:
    return {p.name: (p.read_bytes(), p.stat().st_mtime_ns) for p in paths}


def load_npz(path: Path) -> dict[str, np.ndarray]:
    with np.load(path) as data:
        return {k: data[k] for k in data.files}


def assert_same_arrays(a: dict, b: dict) -> None:
    assert set(a) == set(b)
    for k in a:
        assert a[k].dtype == b[k].dtype, k
        assert np.array_equal(a[k], b[k]), k


def chi2_var_interval(n: int, sigma, p: float = 0.999) -> tuple:
    """Where the sample variance (ddof=1) of n draws of N(·, σ²) lies with probability p."""
    lo, hi = stats.chi2.ppf([(1 - p) / 2, (1 + p) / 2], n - 1)
    s2 = np.square(sigma)
    return s2 * lo / (n - 1), s2 * hi / (n - 1)


def binomial_tol(p: float, n: int, k: float = 4.0) -> float:
    return k * math.sqrt(p * (1 - p) / n)




# --------------------------------------------------------------------------- Sun gaps


def sun_hour_angle_deg(epoch_utc: str, t_s, longitude_east_deg: float):
    """The true Sun's hour angle at the sub-satellite meridian (deg, (−180, 180], 0 at
    local noon, +90 at dusk) and its declination (deg), from first principles and
    nothing of dynprop: the equation of time E of Meeus, *Astronomical Algorithms*
    (2nd ed. 1998), Eq. 28.3 (Smart), with the solar coordinates of his Ch. 25 (low
    accuracy: E within a few seconds of time, δ within 0.01°).  Apparent solar time
    is UTC + λ/15° h + E.  GEO parallax (0.016°), nutation and UT1 − UTC (< 1 s)
    are left out: each moves an edge by seconds."""
    epoch = datetime.fromisoformat(epoch_utc.replace("Z", "+00:00")).astimezone(UTC)
    t_s = np.asarray(t_s, dtype=float)
    days = (epoch - datetime(2000, 1, 1, 12, tzinfo=UTC)) / timedelta(days=1) + t_s / 86400
    T = days / 36525.0                                          # Julian centuries of TT≈UTC
    L0 = np.radians(280.46646 + 36000.76983 * T + 0.0003032 * T**2)   # mean longitude
    M = np.radians(357.52911 + 35999.05029 * T - 0.0001537 * T**2)    # mean anomaly
    e = 0.016708634 - 0.000042037 * T - 0.0000001267 * T**2           # eccentricity
    eps = np.radians(23.0 + 26 / 60 + (21.448 - 46.8150 * T) / 3600)  # mean obliquity
    y = np.tan(eps / 2) ** 2
    eot = (y * np.sin(2 * L0) - 2 * e * np.sin(M) + 4 * e * y * np.sin(M) * np.cos(2 * L0)
           - 0.5 * y**2 * np.sin(4 * L0) - 1.25 * e**2 * np.sin(2 * M))   # rad
    centre = np.radians((1.914602 - 0.004817 * T) * np.sin(M)
                        + (0.019993 - 0.000101 * T) * np.sin(2 * M) + 0.000289 * np.sin(3 * M))
    declination = np.degrees(np.arcsin(np.sin(eps) * np.sin(L0 + centre)))
    midnight = epoch.replace(hour=0, minute=0, second=0, microsecond=0)
    utc_h = (epoch - midnight) / timedelta(hours=1) + t_s / 3600
    solar_h = utc_h + longitude_east_deg / 15 + np.degrees(eot) / 15
    return (15 * (solar_h - 12) + 180) % 360 - 180, declination


def predicted_sun_gaps_h(scenario, epoch_utc: str | None = None) -> list[tuple[float, float]]:
    """Start and end (h into the run) of the yaw outages of at least
    ``estimator.sun_gap_min_h`` that the Sun-sensor geometry alone predicts, for a
    spacecraft on its nominal (zero) attitude.

    With the body on the orbit frame the Sun at hour angle H and declination δ is
    (−cos δ sin H, ·, −cos δ cos H) in body x, z: a head with boresight at hour angle
    θ_b sees it at in-plane angle α = H − θ_b and out-of-plane angle
    β = atan(tan δ / cos α); yaw needs α and β within the head's field of view, and
    the Sun at least ``min_sun_separation_deg`` from the yaw axis (cos of that angle:
    cos δ |cos H|).  Eclipses fall inside the night gap at GEO.  The attitude
    (hundredths of a degree) moves the edges by seconds: 0.01° is 2.4 s of hour angle.
    """
    sun = scenario.sensors.sun
    dt = scenario.sample_interval_s
    # A 1 s grid, offset by half a second so no point lands on an edge.
    t = np.arange(0.5, scenario.duration_s, 1.0)
    H, dec = sun_hour_angle_deg(epoch_utc or scenario.epoch_utc, t,
                                scenario.orbit.longitude_deg)
    seen = np.zeros(t.size, dtype=bool)
    for head in (sun.dss, sun.cass1, sun.cass2):
        alpha = (H - head.boresight_hour_angle_deg + 180) % 360 - 180
        beta = np.degrees(np.arctan(np.tan(np.radians(dec)) / np.cos(np.radians(alpha))))
        seen |= ((np.abs(alpha) <= head.fov_in_plane_deg) & (np.abs(alpha) < 90)
                 & (np.abs(beta) <= head.fov_out_of_plane_deg))
    from_yaw_axis = np.degrees(np.arccos(np.cos(np.radians(dec)) * np.abs(np.cos(np.radians(H)))))
    seen &= from_yaw_axis >= sun.min_sun_separation_deg
    edges = np.flatnonzero(np.diff(np.r_[1, seen.astype(int), 1]))
    # A missing sample is one whose time has no yaw: grid times ± 0.5 s.
    gaps = [(max(t[a] - 0.5, 0.0), min(t[b - 1] + 0.5, scenario.duration_s))
            for a, b in zip(edges[::2], edges[1::2], strict=True)]
    return [(a / 3600, b / 3600) for a, b in gaps
            if b - a >= scenario.estimator.sun_gap_min_h * 3600 - dt]
