"""The fit of `dynprop tune`: which noise parameters, their bounds, the maximum of
the likelihood (``estimator.tuning.maximum``), what each estimate is worth, the noise the
filter is given, and the filter's innovations before and after."""

from __future__ import annotations

import time
from collections.abc import Mapping
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np
from dynprop.estimator.analysis.covariance import approx_yaw_variance
from dynprop.estimator.analysis.covariance_report import covariance_report
from dynprop.estimator.linear.model import ProcessNoise
from dynprop.estimator.linear.transition import discretize
from dynprop.estimator.tuning.intervals import interval_noise
from dynprop.estimator.tuning.likelihood import NOISE_KEYS, Likelihood, noise_model
from dynprop.estimator.tuning.maximum import (
    DETERMINED_SIGMA,
    WEAK_SIGMA,
    Fit,
    maximize,
    nearest_allowed,
    profile,
)
from dynprop.estimator.tuning.samples import distinct_intervals

from ..bridge.covariance import dss_yaw_weighting
from ..config import build
from ..units import RAD2DEG
from .innovations import Diagnostics, innovation_diagnostics
from .source import TuneError, TuneSource

ROLL = "roll_variance"       # the optional factor on the Earth sensor's roll variance
# Bounds, each far beyond what matters: at the lower ones the noise changes σ_yaw by
# under 1e-5° (Eq. 55) or a torque state by 3e-11 N m a day; at the upper ones the
# filter would follow every sample.
DEFAULT_BOUNDS = {"q_x": (1e-14, 1e-4), "q_z": (1e-14, 1e-4), "q_w": (1e-14, 1e-4),
                  "q_px": (1e-26, 1e-12), "q_pz": (1e-26, 1e-12), "q_cx": (1e-26, 1e-12),
                  "q_cz": (1e-26, 1e-12), ROLL: (1e-2, 1e2)}


@dataclass(frozen=True)
class TuneOptions:
    """What `dynprop tune` estimates: ``params`` (process-noise keys), q_x and q_z as
    one (``tie_xz``), a factor on the roll variance (``roll_variance``), and bounds
    by name (``ROLL`` for the factor) over ``DEFAULT_BOUNDS``."""

    params: tuple[str, ...] = NOISE_KEYS
    tie_xz: bool = False
    roll_variance: bool = False
    bounds: Mapping[str, tuple[float, float]] = field(default_factory=dict)

    def names(self) -> list[str]:
        return list(self.params) + ([ROLL] if self.roll_variance else [])

    def groups(self) -> dict[str, dict[str, float]]:
        out: dict[str, dict[str, float]] = {}
        for k in self.params:
            if self.tie_xz and k in ("q_x", "q_z"):
                out["q_x=q_z"] = {"q_x": 1.0, "q_z": 1.0}
            else:
                out[k] = {k: 1.0}
        return out

    def bound(self, name: str) -> tuple[float, float]:
        key = "q_x" if name == "q_x=q_z" else name
        return tuple(self.bounds.get(key, DEFAULT_BOUNDS[key]))


def option_problems(o: TuneOptions) -> list[str]:
    problems = []
    unknown = [k for k in o.params if k not in NOISE_KEYS]
    if unknown:
        problems.append(f"--params: unknown {', '.join(unknown)}; the process-noise keys are "
                        + ", ".join(NOISE_KEYS))
    if not o.params and not o.roll_variance:
        problems.append("--params: nothing to tune")
    if len(set(o.params)) != len(o.params):
        problems.append("--params: a key appears twice")
    if o.tie_xz and not {"q_x", "q_z"} <= set(o.params):
        problems.append("--tie-xz: needs both q_x and q_z in --params")
    for k, (lo, hi) in o.bounds.items():
        if k not in o.names():
            problems.append(f"--bounds {k}: not a tuned parameter ({', '.join(o.names())})")
        elif not (np.isfinite(lo) and np.isfinite(hi) and lo > 0 and hi > 0):
            problems.append(f"--bounds {k}={lo:g}:{hi:g}: bounds must be positive and finite "
                            "(the fit is in log space)")
        elif lo >= hi:
            problems.append(f"--bounds {k}={lo:g}:{hi:g}: the lower bound must be below the "
                            "upper")
    return problems


@dataclass(frozen=True)
class TuneResult:
    source: TuneSource
    options: TuneOptions
    names: list[str]
    fit: Fit
    entries: dict                  # per tuned name: value, σ, status, upper limit, applied
    applied: ProcessNoise
    roll_factor: float
    before: Diagnostics
    after: Diagnostics
    profiles: dict                 # name -> (θ, ln L − max)
    seconds: float
    passes: dict


def _sigma_yaw(src: TuneSource, noise: ProcessNoise, roll_factor: float) -> dict:
    sensors = build.estimator_sensor_specs(src.scenario)
    if roll_factor != 1.0:
        from dataclasses import replace
        sensors = replace(sensors, roll_noise_deg=sensors.roll_noise_deg
                          * np.sqrt(roll_factor), roll_quantum_deg=sensors.roll_quantum_deg
                          * np.sqrt(roll_factor))
    # The yaw weighed as the run's filter weighs it, as `dynprop covariance` does.
    rep = covariance_report(src.params, noise, sensors, gap_s=src.gap_s(),
                            **dss_yaw_weighting(src.scenario))
    q = 0.5 * (noise.q_x + noise.q_z)
    return {"eq55": float(np.sqrt(approx_yaw_variance(q, src.params.H_Nms,
                                                      src.params.omega0_radps)) * RAD2DEG),
            "gap_end": rep["methods"]["gap_end"]["sigma_yaw_deg"],
            "gap_max": rep["methods"]["gap_max"]["sigma_yaw_deg"]}


def diagnostics(lik: Likelihood, theta, src: TuneSource, noise: ProcessNoise,
                roll_factor: float) -> Diagnostics:
    """The filter's innovations at θ (``innovations``) and its σ_yaw at that noise."""
    return innovation_diagnostics(lik, theta, src, _sigma_yaw(src, noise, roll_factor))


def _status(fit: Fit, j: int) -> str:
    s, bound = float(fit.sigma_log[j]), int(fit.at_bound[j])
    if bound:
        return "at lower bound" if bound < 0 else "at upper bound"
    if s <= DETERMINED_SIGMA:
        return "determined"
    return "weakly determined" if s <= WEAK_SIGMA else "not determined"


ESTIMATED = ("determined", "weakly determined")


def _entries(fit: Fit, names: list[str], start: np.ndarray, limits: dict
             ) -> tuple[dict, np.ndarray]:
    """What each estimate is worth and the value the filter is given: the estimate
    where the telemetry informs it (σ of ln θ ≤ 3, within a factor of 20); else the
    scenario's value if the telemetry allows it (95%), or the allowed value nearest
    it, a one-sided limit (``limits``: index → ``estimator.tune.nearest_allowed``)."""
    sigma_ln = fit.sigma_log
    out, applied = {}, start.copy()
    for j, name in enumerate(names):
        value, s, status = float(fit.theta[j]), float(sigma_ln[j]), _status(fit, j)
        limit = side = None
        if status in ESTIMATED:
            applied[j] = value
        else:
            applied[j], allowed, _ = limits[j]
            if not allowed:
                limit, side = float(applied[j]), ("upper" if start[j] > value else "lower")
        finite = np.isfinite(s)
        estimated = status in ESTIMATED or fit.at_bound[j] != 0
        out[name] = {"value": value if estimated else None,
                     "sigma": value * s if finite and estimated else None,
                     "sigma_ln": s if finite else None, "status": status,
                     "limit_95": limit, "limit_side": side,
                     "scenario_allowed": None if estimated else limit is None,
                     "start": float(start[j]), "applied": float(applied[j]),
                     "bounds": [float(fit.lower[j]), float(fit.upper[j])]}
    return out, applied


COARSE = 8   # every 8th sample (4.1 s): 42 per nutation period
MAX_PROFILES = 2
COARSE_TOL = 0.5   # the coarse maximum need only be near: the full likelihood finishes


def _likelihood(src: TuneSource, opts: TuneOptions, every: int) -> Likelihood:
    """The filter's likelihood of the telemetry, or of every ``every``-th sample with
    the filter stepping ``every`` samples at a time (``src.samples``).  Off the grid
    each step spans its own interval, its Φ, Γ and unit Q_d evaluated once per
    distinct interval (``tuning.intervals``)."""
    dt = src.cadence_s * every
    model = noise_model(src.params, dt, opts.groups(), src.noise, opts.roll_variance)
    samples = src.samples(every)
    disc = (discretize(src.params, src.noise, dt) if src.regular else
            interval_noise(src.params, distinct_intervals(samples, src.block), opts.groups(),
                           src.noise))
    return Likelihood.of_samples(samples, disc, src.x0, src.P0, model, block=src.block)


def tune(src: TuneSource, opts: TuneOptions) -> TuneResult:
    """Everything `dynprop tune` computes (``TuneError`` for what it cannot)."""
    problems = option_problems(opts) + source_problems_for(src, opts)
    if problems:
        raise TuneError("\n".join(problems))
    t0 = time.perf_counter()
    groups = opts.groups()
    lik = _likelihood(src, opts, 1)
    model = lik.model
    names = list(groups) + ([ROLL] if opts.roll_variance else [])
    start = model.theta_of(src.noise)
    bounds = np.array([opts.bound(n) for n in names], dtype=float)
    pool = ThreadPoolExecutor(2)
    # The scenario's noise's innovations do not wait for the fit: on the other core.
    before = pool.submit(diagnostics, lik, start, src, src.noise, 1.0)
    # Coarse to fine: the climb from the scenario's noise, often orders of magnitude
    # off, on every COARSE-th sample (a filter stepping COARSE times as far, a pass
    # COARSE times cheaper), then the maximum of the full telemetry's likelihood from
    # there, which is near: the same model, a fraction of its data.
    try:
        coarse = maximize(_likelihood(src, opts, COARSE), start, bounds[:, 0],
                          bounds[:, 1], tol=COARSE_TOL)
        fit = maximize(lik, coarse.theta, bounds[:, 0], bounds[:, 1])
    except BaseException:
        pool.shutdown(cancel_futures=True)
        raise
    # What follows the maximum is passes independent of one another (each parameter's
    # limit, each profile): two at a time, on both cores (the compiled loop lets go of
    # the GIL), each the same pass as alone.
    unknown = [j for j in range(len(names)) if _status(fit, j) not in ESTIMATED]
    determined = [j for j in range(len(names)) if _status(fit, j) == "determined"]
    # The likelihood at ±2σ along the determined parameters, the least certain first
    # (where the quadratic of the information is likeliest to fail), at most two.
    shown = sorted(determined, key=lambda j: -fit.sigma_log[j])[:MAX_PROFILES]
    with pool:
        limits = {j: pool.submit(nearest_allowed, lik, fit, j, float(start[j]))
                  for j in unknown}
        profiles = {names[j]: pool.submit(profile, lik, fit, j, (-2.0, 2.0)) for j in shown}
        limits = {j: f.result() for j, f in limits.items()}
        entries, applied = _entries(fit, names, start, limits)
        roll_factor = float(applied[-1]) if opts.roll_variance else 1.0
        tuned = model.process_noise(applied)
        after = pool.submit(diagnostics, lik, applied, src, tuned, roll_factor)
        before, after = before.result(), after.result()
        profiles = {k: f.result() for k, f in profiles.items()}
    limit_passes = sum(k for _, _, k in limits.values())
    passes = {"coarse": {"every": COARSE, **coarse.passes}, "score": fit.passes["score"],
              "directions": fit.passes["directions"],
              "likelihood": fit.passes["likelihood"] + limit_passes + 2 * len(profiles) + 2}
    return TuneResult(src, opts, names, fit, entries, tuned, roll_factor, before, after,
                      profiles, time.perf_counter() - t0, passes)


def source_problems_for(src: TuneSource, opts: TuneOptions) -> list[str]:
    from .source import source_problems
    return source_problems(src, tuple(opts.params))
