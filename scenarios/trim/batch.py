"""`dynprop trim`: the solar trim-tab setting from the estimated torque, the
paper's second requirement (abstract, Section 2.2); ``--verify`` flies it.

The batch [from, to] of a run's telemetry goes through the paper's filter once
more, tuned for a spacecraft near trim (``config.estimation.Trim``) and with the known
magnetic torques as modelled torques (Eq. 9).  Its torque states at the batch
end give κ̂ ± σ by generalised least squares against the solar torque of a unit
κ over the same batch (``estimator.analysis.trim``).  What that assumes known is
``ASSUMED_KNOWN``, written into every report.  docs/trim.md has the method and
its validation.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from dynprop.eom.gyrostat import (
    gravity_gradient_torque,
    magnetic_torque,
    solar_torque,
    unloading_dipole,
)
from dynprop.estimator.analysis.trim import (
    KappaFit,
    Recommendation,
    equivalent_states,
    fit_kappa,
    recommend,
)
from dynprop.estimator.kalman.filter import FilterResult, kalman_filter, unpack
from dynprop.estimator.kalman.preprocess import yaw_momentum
from dynprop.estimator.linear import model as em
from dynprop.estimator.linear.noise import torque_noise_density
from dynprop.estimator.linear.steps import StepTable
from dynprop.estimator.linear.transition import discretize
from dynprop.sim import geomag
from dynprop.sim.frames import nadir_body

from ..bridge.inputs import filter_inputs, initial_prior, telemetry_inputs
from ..config import build
from ..config.estimation import QUARTER_ORBIT_S
from ..config.schema import Scenario
from ..run.windowed import (
    DAYS,
    ArraySource,
    Windows,
    cut_inputs,
    pad_samples,
    padded_range,
    used_names,
    wheel_names,
    window_bounds,
)
from ..units import DAY_S, DEG

ASSUMED_KNOWN = (
    "the Sun's direction and distance (the ephemeris), the Earth's shadow and the "
    "array-to-sail lever axis: the solar torque's direction, its phase over the orbit "
    "and its switch-off in eclipse",
    "the geomagnetic field model at the station longitude, the torquers' unloading law "
    "(gain, saturation) and any commanded dipole profile: the torquer torque is "
    "rebuilt from the telemetered wheel momentum h, Earth pointing assumed (a degree "
    "of attitude error changes it by under 2%), and enters the filter as a modelled "
    "torque",
    "the nominal inertia and the measured roll and pitch: the gravity-gradient torque, "
    "which the paper's model leaves out (Eq. 6) but which moves by 7e-7 N m per degree "
    "of roll, also enters as a modelled torque",
    "the tab law κ = untrimmed − effectiveness · tab: only the effectiveness is needed",
)
ESTIMATED = ("κ", "a constant roll and a constant yaw torque (residual dipole, gravity-"
             "gradient imperfections: constant in the body of an Earth-pointing GEO "
             "satellite)")
SHAPE_EVERY = 8   # the unit-κ solar torque is smooth: every 8th sample (4 s) is plenty


class TrimError(ValueError):
    """A batch that cannot give κ: reported one line per problem, exit status 2."""


@dataclass(frozen=True)
class Batch:
    """Samples k0 … k1−1 of the run's grid (times k·dt from the scenario's epoch)."""

    k0: int
    k1: int
    dt_s: float

    @property
    def from_s(self) -> float:
        return round(self.k0 * self.dt_s, 9)

    @property
    def to_s(self) -> float:
        return round((self.k1 - 1) * self.dt_s, 9)


def choose_batch(t_s: np.ndarray, dt_s: float, from_s: float | None, to_s: float | None,
                 regular: bool = True) -> Batch:
    """The batch on the telemetry's grid (default: all of it); TrimError if it is
    outside the telemetry or empty (``batch_problems`` judges whether it is enough).
    Telemetry off the grid (``regular`` False) is bounded by the grid times inside its
    first and last sample."""
    if regular:
        k_all = np.rint(np.asarray(t_s) / dt_s).astype(np.int64)
        lo, hi = int(k_all[0]), int(k_all[-1])
    else:
        lo, hi = int(np.ceil(t_s[0] / dt_s - 1e-9)), int(np.floor(t_s[-1] / dt_s + 1e-9))
    problems = []
    k0 = lo if from_s is None else int(np.ceil(from_s / dt_s - 1e-9))
    k1 = hi if to_s is None else int(np.floor(to_s / dt_s + 1e-9))
    if not lo <= k0 <= hi:
        problems.append(f"--from-s: {from_s:g} s is outside the telemetry "
                        f"({lo * dt_s:g} … {hi * dt_s:g} s)")
    if not lo <= k1 <= hi:
        problems.append(f"--to-s: {to_s:g} s is outside the telemetry "
                        f"({lo * dt_s:g} … {hi * dt_s:g} s)")
    if not problems and k1 <= k0:
        problems.append(f"--from-s/--to-s: the batch {from_s:g} … {to_s:g} s is empty")
    if problems:
        raise TrimError("\n".join(problems))
    return Batch(k0, k1 + 1, dt_s)


def batch_problems(batch: Batch, sunlit_fraction: float) -> list[str]:
    """Why a batch cannot give κ (one line each), or nothing."""
    problems = []
    length = (batch.k1 - 1 - batch.k0) * batch.dt_s
    if length < QUARTER_ORBIT_S - batch.dt_s:   # to the sample
        problems.append(f"--from-s/--to-s: the batch is {length / 3600:.2f} h, shorter than a "
                        f"quarter orbit ({QUARTER_ORBIT_S / 3600:.2f} h): too short to tell "
                        "the orbit-rate solar torque from a constant one")
    if sunlit_fraction == 0:
        problems.append(f"--from-s/--to-s: the batch {batch.from_s:g} … {batch.to_s:g} s has "
                        "no sunlit time: the solar torque is zero throughout and κ cannot be "
                        "estimated")
    return problems


def solar_unit_torque(s: Scenario, batch: Batch, every: int = SHAPE_EVERY
                      ) -> tuple[np.ndarray, np.ndarray, float]:
    """The roll and yaw solar torque of κ = 1 N m over the batch, d̂ × ŝ · (1 AU/r)² ·
    shadow in an Earth-pointing body (as the truth computes it), every ``every``-th
    sample: times, torques (M, 2), and the sunlit share of the batch.  It does not
    depend on ``environment.solar.enabled``, which is the truth's business."""
    # No draws: ``sun`` rolls nothing out, so any generators will do.
    stream = build.truth_stream(s, np.random.default_rng(0), (batch.k1 - 1) * batch.dt_s,
                                batch.dt_s, disturbance_rng=np.random.default_rng(0))
    lever = np.asarray(stream.environment.solar.lever_axis, dtype=float)
    day = int(round(DAY_S / batch.dt_s))
    t, torque, sunlit = [], [], 0
    for a in range(batch.k0, batch.k1, day):
        b = min(a + day, batch.k1)
        ts, sun_r, scale = stream.sun(a, b)
        sunlit += int(np.count_nonzero(scale > 0))
        keep = (np.arange(a, b) - batch.k0) % every == 0
        t.append(ts[keep])
        # Earth pointing: the body axes are the orbit frame's.
        torque.append(solar_torque(sun_r[keep], scale[keep, None], lever)[:, [0, 2]])
    return np.concatenate(t), np.concatenate(torque), sunlit / (batch.k1 - batch.k0)


def _filled(t_s: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``v`` with missing samples (a dropout) interpolated from their neighbours."""
    ok = np.isfinite(v)
    return v if ok.all() else np.interp(t_s, t_s[ok], v[ok])


def gravity_gradient(s: Scenario, roll_rad: np.ndarray, pitch_rad: np.ndarray) -> np.ndarray:
    """(N, 3) gravity-gradient torque of the nominal inertia at the measured roll and
    pitch (the nadir does not depend on yaw), the truth's law (``eom.gyrostat``).
    The paper's model leaves it out (Eq. 6); at the trim level it matters:
    3ω0²(I_z − I_y) is 7e-7 N m per degree of roll."""
    J = build.build_spacecraft(s).J
    w0 = build.orbit(s).rate_radps
    return gravity_gradient_torque(nadir_body(roll_rad, pitch_rad), J, 3.0 * w0**2)


def known_torques(s: Scenario, t_s: np.ndarray, speeds_radps: np.ndarray,
                  roll_rad: np.ndarray | None = None, pitch_rad: np.ndarray | None = None
                  ) -> np.ndarray:
    """(N, 2) roll and yaw torques known from the telemetry and the scenario
    (``ASSUMED_KNOWN``): the torquers (the truth's unloading law, ``eom.gyrostat``, on
    the telemetered h, crossed with the field model, Earth pointing), the commanded
    dipole profile, and the gravity gradient at the measured roll and pitch."""
    t_s = np.asarray(t_s, dtype=float)
    orbit, env, ctrl = build.orbit(s), build.build_environment(s), build.build_control(s)
    mag = env.magnetic
    field = geomag.geo_field_orbit_frame(orbit.longitude_rad, orbit.radius_m,
                                         moment_Am2=mag.earth_dipole_Am2,
                                         pole_lat_deg=mag.pole_lat_deg,
                                         pole_lon_deg=mag.pole_lon_deg)
    h = _filled(t_s, yaw_momentum(speeds_radps, build.yaw_factors(s)))
    m = np.zeros((len(h), 3))
    if ctrl.enabled and ctrl.magnetic_unloading:
        m = unloading_dipole(field, h, ctrl.unloading_gain_per_s, ctrl.torquer_max_Am2,
                             floor=0.0)
    if mag.enabled:
        m = m + mag.profile(t_s)
    torque = magnetic_torque(m, field)
    if env.gravity_gradient.enabled and roll_rad is not None:
        pitch = np.zeros_like(t_s) if pitch_rad is None else _filled(t_s, pitch_rad)
        torque += gravity_gradient(s, _filled(t_s, roll_rad), pitch)
    return torque[:, [0, 2]]


def trim_q_Nm2s(s: Scenario) -> float:
    """The batch filter's white roll and yaw torque density q = δN² τ ((N m)² s),
    Eq. 45 with ``trim.torque_error_Nm`` and ``trim.correlation_time_s``."""
    return torque_noise_density(s.trim.torque_error_Nm, s.trim.correlation_time_s)


def trim_noise(s: Scenario, noise: em.ProcessNoise) -> em.ProcessNoise:
    """The batch filter's process noise: Eq. 45's white torque density from
    ``trim.torque_error_Nm`` and no random walk of the torque states."""
    q = trim_q_Nm2s(s)
    return dataclasses.replace(noise, q_x=q, q_z=q, q_px=0.0, q_pz=0.0, q_cx=0.0, q_cz=0.0)


@dataclass(frozen=True)
class TrimResult:
    batch: Batch
    fit: KappaFit
    rec: Recommendation
    sunlit_fraction: float
    rows_t_s: np.ndarray         # the filter history kept (every ``stride`` samples)
    torque_xz: np.ndarray        # its roll and yaw torque estimates (N m)
    shape_t_s: np.ndarray
    shape_xz: np.ndarray         # the unit-κ solar torque there
    v: np.ndarray                # its torque states at the batch end


def estimate_kappa(s: Scenario, cols: dict[str, np.ndarray], batch: Batch,
                   stride: int = 125, regular: bool = True) -> TrimResult:
    """κ̂ ± σ and the recommendation from the telemetry columns ``cols`` (telemetry.csv's
    names) over ``batch``: on the scenario's grid, or (``regular`` False) each sample at
    its own time, the filter stepping over each interval (``estimator.linear.steps``)
    as `dynprop estimate`'s does; ``stride`` is then in the scenario's steps.  The
    columns are filtered whole (``kappa_from_source`` reads a file window by window)."""
    return kappa_from_source(s, ArraySource(cols, regular), batch, stride,
                             Windows(whole_s=np.inf))


def kappa_from_source(s: Scenario, source, batch: Batch, stride: int = 125,
                      windows: Windows = DAYS) -> TrimResult:
    """``estimate_kappa`` of a ``files.telemetry_source.TelemetrySource`` (or an
    ``ArraySource``), read and filtered window by window (``run.windowed``): the
    filter carries its prior across each boundary and keeps its history only at the
    figure's rows, so memory is a window's whatever the batch's length.  A batch of
    up to two days is one window: the whole computation, bit for bit."""
    t_shape, shape, sunlit = solar_unit_torque(s, batch)
    problems = batch_problems(batch, sunlit)
    if problems:
        raise TrimError("\n".join(problems))
    t_all = np.asarray(source.columns(0, source.n, ["t_s"])["t_s"], dtype=float)
    if source.regular:
        k = np.rint(t_all / batch.dt_s).astype(np.int64)
        sel = (k >= batch.k0) & (k < batch.k1)
    else:
        sel = (t_all >= batch.from_s - 1e-9) & (t_all <= batch.to_s + 1e-9)
    idx = np.flatnonzero(sel)
    i0, i1 = int(idx[0]), int(idx[-1]) + 1      # times increase: one stretch of samples
    t = t_all[i0:i1]
    n = len(t)
    if not source.regular:   # the figure's rows as often in time as on the grid
        stride = max(1, round(stride * batch.dt_s / float(np.median(np.diff(t)))))
    rows = np.unique(np.r_[np.arange(0, n, stride), n - 1])
    x, theta, P_theta = _filter_rows(s, source, t_all, i0, i1, batch.dt_s, rows, windows)
    torque_states = slice(em.NPX, em.NCZ + 1)
    params, _ = build.estimator_model(s)
    v = equivalent_states(t_shape, shape, t[-1], params.omega0_radps)
    fit = fit_kappa(theta[torque_states], P_theta[torque_states, torque_states], v)
    solar = s.environment.solar
    rec = recommend(fit, solar.trim_tab_deg, solar.tab_effectiveness_Nm_per_deg)
    torque_xz = np.column_stack([x[:, em.NPX] + x[:, em.NCX], x[:, em.NPZ] + x[:, em.NCZ]])
    return TrimResult(batch, fit, rec, sunlit, t[rows], torque_xz, t_shape, shape, v)


def _filter_rows(s: Scenario, source, t_all: np.ndarray, i0: int, i1: int, dt_s: float,
                 rows: np.ndarray, windows: Windows
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The batch filter over samples [i0, i1) of ``source``: its states at ``rows``
    (of the batch) and its state and covariance at the batch end.  Each window's
    inputs, known torques included, are formed from its padded samples inside the
    batch (``run.windowed``), so with one window they are the batch's own."""
    params, noise = build.estimator_model(s)
    q = trim_noise(s, noise)
    regular = source.regular
    disc = discretize(params, q, dt_s) if regular else None
    pitch_name = ["pitch_deg"] if "pitch_deg" in source.names else []
    names = used_names(source, s, tuple(pitch_name))
    # The columns ``known_torques`` bridges with a straight line (``_filled``).
    needed = wheel_names(s) + ["roll_deg"] + pitch_name
    step = dt_s if regular else float(np.median(np.diff(t_all[i0:i1])))
    pad = pad_samples(s, step)
    # Off the grid each window's N_w* is resampled onto the batch's own points.
    record = None if regular else (step, float(t_all[i0]))
    prior = initial_prior(s, params)
    xs = []
    for a, b in window_bounds(t_all, i0, i1, windows):
        c, d = padded_range(source, a, b, i0, i1, pad, needed)
        cols = source.columns(c, d, names)
        tw = np.asarray(cols["t_s"], dtype=float)
        tel = telemetry_inputs(s, cols)
        pitch = cols["pitch_deg"] * DEG if pitch_name else None
        known = known_torques(s, tw, tel.speeds_radps, tel.roll_rad, pitch)
        sl = slice(a - c, b - c)
        meas, u, extra = cut_inputs(*filter_inputs(s, params, *tel.readings, known_Nm=known,
                                                   t_s=None if regular else tw,
                                                   record=record), sl)
        wdisc = disc if regular else StepTable.from_times(params, q, tw).cut(sl)
        local = rows[(rows >= a - i0) & (rows < b - i0)] - (a - i0)
        result: FilterResult = kalman_filter(meas, wdisc, *prior, u=u, extra=extra,
                                             rows=local)
        prior = (result.x_next, result.P_next)
        xs.append(result.x)
    # The batch's last sample is always a row: the last window's last kept one.
    return np.concatenate(xs), result.x[-1], unpack(result.P_packed[-1])


def true_kappa_Nm(s: Scenario) -> float:
    """The κ the scenario's truth flies (zero with the solar torque switched off)."""
    solar = build.build_environment(s).solar
    return solar.coefficient_Nm if s.environment.solar.enabled else 0.0
