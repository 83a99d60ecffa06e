"""The statistics of a run held as whole arrays (``whole.TwoRuns``: `dynprop
estimate`, a Monte Carlo case run alone), the same figures ``tally.RunTally``
accumulates window by window, computed by the same numpy operations."""

from __future__ import annotations

import numpy as np
from dynprop.estimator.kalman.consistency import chi2_bounds, fraction_inside, nees, nis
from dynprop.estimator.kalman.filter import unpack
from dynprop.estimator.linear.model import N_STATES, R, Y

from ..config.schema import Scenario
from ..files.summary import RunStatistics
from ..samples import NEES_STRIDE, sun_gaps, sun_gaps_at
from ..units import RAD2DEG

# The wheel control's and the filter's start-up transient (ekf_crossover skips the
# same hour): the NEES check judges the samples after it.
SETTLED_S = 3600.0


def nees_series(runs) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """Sample indices and NEES of the real and linear runs, unpacking only the
    covariances used; None for a run that has no truth (``estimate`` without
    ``--truth``) or no linear twin (``estimate``)."""
    idx = np.arange(0, len(runs.real.x), NEES_STRIDE)
    real = lin = None
    if runs.truth_model is not None:
        real = nees(runs.real.x[idx], unpack(runs.real.P_packed[idx]), runs.truth_model[idx])
    if runs.linear is not None:
        lin = nees(runs.linear.x[idx], unpack(runs.linear.P_packed[idx]), runs.twin_model[idx])
    return idx, real, lin


def _rms(a) -> float:
    return float(np.sqrt(np.nanmean(np.square(a))))


def mean_or_none(a) -> float | None:
    """Mean of the finite values, or None (JSON null) when there are none, e.g. the
    yaw NIS of a run that never sees the Sun."""
    a = np.asarray(a, dtype=float)
    a = a[np.isfinite(a)]
    return float(a.mean()) if a.size else None


def _nis_means(result) -> dict[str, float | None]:
    return {m: mean_or_none(nis(result.innovations[:, i], result.innovation_var[:, i]))
            for i, m in enumerate(("roll", "yaw", "h"))}


def _comparison(err, err_lin) -> dict:
    return {name: {"rms_real": _rms(err[:, k]) * f, "rms_linear": _rms(err_lin[:, k]) * f,
                   "rms_difference": _rms(err[:, k] - err_lin[:, k]) * f,
                   "max_abs_difference": float(np.max(np.abs(err[:, k] - err_lin[:, k])) * f)}
            for name, k, f in (("roll_deg", R, RAD2DEG), ("yaw_deg", Y, RAD2DEG),
                               ("h_Nms", 4, 1.0))}


def whole_run_statistics(s: Scenario, runs, t_s, yaw_present, nees_data,
                         on_grid: bool = True) -> RunStatistics:
    """summary.json's figures of ``runs`` (a ``whole.TwoRuns``); a figure that needs
    the truth or the linear twin is None without it.  ``on_grid`` False: samples at
    their own times (telemetry off the grid), Sun gaps measured in time."""
    truth, twin = runs.truth_model is not None, runs.linear is not None
    err = runs.real.x - runs.truth_model if truth else None
    err_lin = runs.linear.x - runs.twin_model if twin else None
    sig = runs.real.sigma
    gaps = (sun_gaps(yaw_present, s.sample_interval_s, s.estimator.sun_gap_min_h) if on_grid
            else sun_gaps_at(yaw_present, t_s, s.estimator.sun_gap_min_h))
    ends = [b for _, b in gaps if b < len(t_s)]
    idx, n_real, n_lin = nees_data
    nees_b = chi2_bounds(N_STATES, 1)

    def when(ok, value):
        return value() if ok else None

    return RunStatistics(
        gaps=gaps, end_sigma=[float(sig[b, Y] * RAD2DEG) for b in ends],
        nis=_nis_means(runs.real),
        yaw_rms=when(truth, lambda: _rms(err[:, Y]) * RAD2DEG),
        per_state=when(truth, lambda: np.mean(
            (err / np.maximum(sig, 1e-300))[::NEES_STRIDE] ** 2, axis=0)),
        yaw_rms_linear=when(twin, lambda: _rms(err_lin[:, Y]) * RAD2DEG),
        roll_rms=when(truth, lambda: _rms(err[:, R]) * RAD2DEG),
        h_rms=when(truth, lambda: _rms(err[:, 4])),
        yaw_rms_smoothed=when(
            truth and runs.smoothed is not None,
            lambda: _rms(runs.smoothed.x[:, Y] - runs.truth_model[:, Y]) * RAD2DEG),
        end_err=when(truth, lambda: [float(err[b, Y] * RAD2DEG) for b in ends]),
        end_err_linear=when(twin, lambda: [float(err_lin[b, Y] * RAD2DEG) for b in ends]),
        # No gap end, no verdict: None, never a vacuous True.
        ends_within=when(truth and bool(ends), lambda: bool(all(
            abs(err[b, Y]) <= 3 * sig[b, Y] for b in ends))),
        comparison=when(truth and twin, lambda: _comparison(err, err_lin)),
        nees_mean=when(truth, lambda: float(np.mean(n_real))),
        nees_mean_linear=when(twin, lambda: float(np.mean(n_lin))),
        nees_mean_settled=when(truth, lambda: mean_or_none(
            n_real[t_s[idx] >= t_s[0] + SETTLED_S])),
        nees_inside=when(truth, lambda: fraction_inside(n_real, nees_b)),
        nees_inside_linear=when(twin, lambda: fraction_inside(n_lin, nees_b)),
        nis_linear=when(twin, lambda: _nis_means(runs.linear)),
        truth_max=when(truth, lambda: truth_extremes(runs.truth_model, t_s)),
    )


def truth_extremes(truth_model, t_s) -> dict[str, tuple[float, float]]:
    """The truth's largest |roll| and |yaw| in degrees, and the time (s) of each:
    how far it went from the nominal attitude the paper linearizes about."""
    out = {}
    for name, k in (("roll", R), ("yaw", Y)):
        i = int(np.argmax(np.abs(truth_model[:, k])))
        out[name] = (float(abs(truth_model[i, k]) * RAD2DEG), float(t_s[i]))
    return out
