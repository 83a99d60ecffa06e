"""summary.json: the figures of a `run` or `estimate`, every key documented in
docs/outputs.md, in one key order whichever way they were computed (from whole
arrays, ``run.statistics``, or window by window, ``run.tally``).  No wall-clock
time: the same scenario and seed must give the same bytes."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from dynprop.estimator.analysis.covariance import approx_yaw_variance
from dynprop.estimator.kalman.consistency import chi2_bounds
from dynprop.estimator.linear.model import N_STATES

from .. import __version__
from ..config import build
from ..config.schema import Scenario
from ..units import RAD2DEG
from .columns import STATE_COLUMNS, epoch_ns, utc_text


@dataclass(frozen=True)
class RunStatistics:
    """The figures of a run, accumulated at the full sample rate.  A figure that
    needs the truth (``estimate`` without ``--truth``) or the linear twin
    (``estimate``) is None, so every summary has the same keys.  Angles in degrees.

    ``gaps`` are the Sun gaps (first missing, first present again sample); the
    ``end_*`` lists hold the yaw error (real filter, twin's filter) and the real
    filter's σ at each gap end inside the run; ``per_state`` is the mean of
    (error/σ)² per state on the NEES samples; ``comparison`` the real-against-
    linearized figures per error; ``nees_inside`` the fraction of NEES samples within
    the 95% bounds; ``nis`` the mean NIS per measurement (roll, yaw, h);
    ``truth_max`` the truth's largest |roll| and |yaw| and when, (deg, s) per axis."""

    gaps: list[tuple[int, int]]
    end_sigma: list[float]
    nis: dict[str, float | None]
    yaw_rms: float | None = None
    per_state: np.ndarray | None = None
    yaw_rms_linear: float | None = None
    roll_rms: float | None = None
    h_rms: float | None = None
    yaw_rms_smoothed: float | None = None
    end_err: list[float] | None = None
    end_err_linear: list[float] | None = None
    ends_within: bool | None = None
    comparison: dict | None = None
    nees_mean: float | None = None
    nees_mean_linear: float | None = None
    nees_inside: float | None = None
    nees_inside_linear: float | None = None
    nis_linear: dict[str, float | None] | None = None
    nees_mean_settled: float | None = None
    truth_max: dict[str, tuple[float, float]] | None = None


def eq55_sigma_yaw_deg(s: Scenario, params) -> float:
    """The paper's steady-state yaw σ, √(q/(ω0 H²)) (Eq. 55), with q the mean of the
    scenario's roll and yaw torque noise, in degrees."""
    q = 0.5 * (s.estimator.process_noise.q_x + s.estimator.process_noise.q_z)
    return float(np.sqrt(approx_yaw_variance(q, params.H_Nms, params.omega0_radps))) * RAD2DEG


def _per_state(values) -> dict[str, float]:
    # Keyed by estimate.csv's column names, as montecarlo.json's per-state figures.
    return {name: float(v) for name, v in zip(STATE_COLUMNS, values, strict=True)}


def _gap_hours(gaps, dt: float, t_s) -> list[list[float]]:
    """Sun gaps in hours from the first sample: index × Δt on the grid, or from the
    samples' own times ``t_s`` (telemetry off the grid; an open gap ends a step
    after the last sample, as on the grid)."""
    if t_s is None:
        return [[a * dt / 3600, b * dt / 3600] for a, b in gaps]
    t = np.asarray(t_s, dtype=float) - t_s[0]
    step = float(np.median(np.diff(t)))
    return [[float(t[a]) / 3600, float(t[b] if b < len(t) else t[-1] + step) / 3600]
            for a, b in gaps]


def assemble_summary(s: Scenario, params, backend: str, truth: bool, twin: bool,
                     f: RunStatistics, t_s=None) -> dict:
    """summary.json's dict from the run's figures ``f``: one key order, one set of
    keys, whichever computed them.  ``t_s``: the samples' times, for telemetry off
    the grid (None on it)."""
    dt = s.sample_interval_s
    eq55 = eq55_sigma_yaw_deg(s, params)
    nees_b = chi2_bounds(N_STATES, 1)
    end_sigma = f.end_sigma
    # A scenario with events lists them, every occurrence; one without has no key.
    events = {"events": events_list(s)} if s.events else {}
    return {
        "scenario": s.name, "seed": s.seed, "epoch_utc": s.epoch_utc,
        "duration_s": s.duration_s, "dynprop_version": __version__,
        "backend": backend, "filters": ["paper"], "linear_twin": twin, "truth": truth,
        "yaw_error_rms_deg": f.yaw_rms,
        "nees_mean_per_state": None if f.per_state is None else _per_state(f.per_state),
        "yaw_error_rms_linear_deg": f.yaw_rms_linear,
        "roll_error_rms_deg": f.roll_rms,
        "h_error_rms_Nms": f.h_rms,
        "yaw_error_rms_smoothed_deg": f.yaw_rms_smoothed,
        "sun_gaps_h": _gap_hours(f.gaps, dt, t_s),
        "yaw_error_at_gap_end_deg": f.end_err,
        "yaw_error_linear_at_gap_end_deg": f.end_err_linear,
        "yaw_sigma_at_gap_end_deg": end_sigma,
        "yaw_within_3sigma_at_gap_ends": f.ends_within,
        "analytic_sigma_yaw_deg": eq55,
        "last_gap_end_sigma_over_eq55": (float(end_sigma[-1] / eq55) if end_sigma else None),
        "nonlinear_vs_linear": f.comparison,
        "nees_mean": f.nees_mean,
        "nees_mean_linear": f.nees_mean_linear,
        "nees_mean_after_1h": f.nees_mean_settled,
        "nees_dof": N_STATES, "nees_bounds_95_per_sample": nees_b,
        "nees_fraction_inside_95": f.nees_inside,
        "nees_fraction_inside_95_linear": f.nees_inside_linear,
        "nis_mean": f.nis,
        "nis_mean_linear": f.nis_linear,
        "nis_bounds_95_per_sample": chi2_bounds(1, 1),
        "truth_max_abs_deg": (None if f.truth_max is None else
                              {k: v[0] for k, v in f.truth_max.items()}),
        "truth_max_abs_at_h": (None if f.truth_max is None else
                               {k: v[1] / 3600.0 for k, v in f.truth_max.items()}),
        **events,
    }


# Each kind's own fields in summary.json's events, after kind, t_s, end_s, utc, label.
EVENT_FIELDS = {"thruster": ("duration_s", "torque_Nm"), "sensor_outage": ("duration_s", "sensor"),
                "trim_tab": ("angle_deg",), "array_offset": ("angle_deg",), "wheel_switch": ()}


def events_list(s: Scenario) -> list[dict]:
    """summary.json's ``events``: every occurrence of the scenario's events, periodic
    ones repeated, in time order (``sim.events.Schedule``), each with its start and
    end (s from the epoch), its start in UTC, its label (null without one) and its
    kind's own fields."""
    epoch = epoch_ns(s.epoch_utc)
    out = []
    for e in build.build_schedule(s).events:
        utc = utc_text(np.array([epoch + np.timedelta64(int(round(e.t_s * 1e9)), "ns")]))[0]
        d = {"kind": e.kind, "t_s": e.t_s, "end_s": e.end_s, "utc": str(utc),
             "label": e.label or None}
        for name in EVENT_FIELDS[e.kind]:
            value = getattr(e, name)
            d[name] = list(value) if isinstance(value, tuple) else value
        out.append(d)
    return out


def write_summary(path: Path, summary: dict) -> None:
    path.write_text(json.dumps(summary, indent=2, allow_nan=False) + "\n")

