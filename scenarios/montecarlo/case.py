"""One Monte Carlo case, run and reduced where it runs (a local process or a dask
worker), so that only a few hundred kB per case travel back.

The reduction keeps, on a common time grid (``montecarlo.grid_s``): the errors of
the filter on the nonlinear truth and on the linear twin, the filter's σ, and both
NEES; plus the per-case figures (errors and σ at every Sun-gap end, RMS, mean
NEES).  ``dynprop run --montecarlo-case K`` computes the same record from its full
run with the same function, so the two can be compared bit for bit.
"""

from __future__ import annotations

import time
import traceback

import numpy as np
from dynprop.estimator.augmented.filter import unpack as aug_unpack
from dynprop.estimator.kalman.consistency import nees
from dynprop.estimator.kalman.filter import unpack
from dynprop.estimator.linear.model import H_WHEEL, N_STATES, R, Y
from dynprop.estimator.pitch.filter import unpack as pitch_unpack

from ..config import build
from ..config.schema import Scenario
from ..files.columns import PITCH_FACTORS, display_factors
from ..files.simulation import simulated_telemetry
from ..run.ekf import other_filters
from ..run.filtering import BiasedResult, design_of, filter_section
from ..run.simulate import simulate
from ..run.whole import run_scenario
from ..samples import sun_gaps
from ..units import HOUR_S, RAD2DEG
from ..workers import blas_one_thread
from .dispersions import UnphysicalDraw, draw_case


def grid_stride(s: Scenario) -> int:
    """Samples between grid points: ``montecarlo.grid_s`` rounded to whole samples."""
    return max(1, int(round(s.montecarlo.grid_s / s.sample_interval_s)))


def case_rows(s: Scenario, n: int, yaw_present: np.ndarray):
    """Grid indices, Sun gaps (start, end) and the sorted union of the grid and the
    gap ends: the only samples of the filter history a case keeps."""
    grid = np.arange(0, n, grid_stride(s))
    gaps = sun_gaps(yaw_present, s.sample_interval_s, s.estimator.sun_gap_min_h)
    ends = [b for _, b in gaps if b < n]
    return grid, gaps, np.union1d(grid, np.asarray(ends, dtype=np.int64))


def _rms(a) -> float:
    return float(np.sqrt(np.mean(np.square(a))))


def reduce_case(s: Scenario, runs, yaw_present: np.ndarray, case: int,
                dispersed: dict, epoch_utc: str, extra: dict | None = None,
                truth_biases: dict | None = None) -> tuple[dict, dict[str, np.ndarray]]:
    """The case record (JSON) and its grid arrays (float32, display units: deg,
    deg/s, N m s, N m).  ``runs`` holds either the full histories or exactly the
    rows of ``case_rows``; so does each filter of ``extra`` (name → result: the
    filters besides the paper's, ``estimator.filters``).  With sensor-bias states
    (``run.filtering``), ``truth_biases`` (the flying scenario's, rad) gives the
    record's ``bias_states`` their truth and the augmented state's NEES."""
    n, dt = len(runs.truth_model), s.sample_interval_s
    grid, gaps, rows = case_rows(s, n, yaw_present)
    full = runs.rows is None
    if not full and not np.array_equal(runs.rows, rows):
        raise ValueError("the filter history was kept at other rows than case_rows")
    on_grid = np.searchsorted(rows, grid)
    converged = grid * dt >= s.montecarlo.converged_after_h * HOUR_S
    ends = [b for _, b in gaps if b < n]
    at_end = np.searchsorted(rows, ends)
    f = display_factors(runs.params.omega_n_radps)

    def against(result, truth_states):
        """Errors, σ and NEES of one filter history at ``rows``, against its truth."""
        x, P = (result.x[rows], result.P_packed[rows]) if full else (result.x, result.P_packed)
        sigma = result.sigma[rows] if full else result.sigma
        truth = truth_states[rows]
        err = x - truth
        nees_on_grid = nees(x, unpack(P), truth)[on_grid]
        mean = float(np.mean(nees_on_grid[converged])) if converged.any() else None
        return err, sigma, nees_on_grid, mean

    err, sigma, nees_real, nees_mean = against(runs.real, runs.truth_model)
    record = {
        "case": case, "status": "ok", "seed": s.seed, "spawn_key": [case],
        "dispersed": dispersed, "epoch_utc": epoch_utc, "backend": runs.real.backend,
        "sun_gaps_h": [[float(a * dt / 3600), float(b * dt / 3600)] for a, b in gaps],
        "gap_end_h": [float(b * dt / 3600) for b in ends],
        "yaw_error_at_gap_end_deg": [float(err[i, Y] * RAD2DEG) for i in at_end],
        "yaw_sigma_at_gap_end_deg": [float(sigma[i, Y] * RAD2DEG) for i in at_end],
        "roll_error_rms_deg": _rms(err[on_grid, R]) * RAD2DEG,
        "yaw_error_rms_deg": _rms(err[on_grid, Y]) * RAD2DEG,
        "h_error_rms_Nms": _rms(err[on_grid, H_WHEEL]),
        "yaw_error_max_abs_deg": float(np.max(np.abs(err[on_grid, Y]))) * RAD2DEG,
        "nees_mean": nees_mean,
    }
    if isinstance(runs.real, BiasedResult):
        record.update(_bias_record(s, runs.real, runs.truth_model, rows, full, on_grid,
                                   converged, truth_biases))
    arrays = {"t_s": (grid * dt).astype(np.float64),
              "err": (err[on_grid] * f).astype(np.float32),
              "sigma": (sigma[on_grid] * np.abs(f)).astype(np.float32),
              "nees": nees_real.astype(np.float32)}
    if runs.linear is not None:
        err_l, _, nees_lin, nees_mean_lin = against(runs.linear, runs.twin_model)
        record["yaw_error_linear_at_gap_end_deg"] = [float(err_l[i, Y] * RAD2DEG)
                                                     for i in at_end]
        record["yaw_error_rms_linear_deg"] = _rms(err_l[on_grid, Y]) * RAD2DEG
        record["nees_mean_linear"] = nees_mean_lin
        arrays["err_linear"] = (err_l[on_grid] * f).astype(np.float32)
        arrays["nees_linear"] = nees_lin.astype(np.float32)
    if runs.pitch is not None:
        record_p, arrays_p = _pitch_record(runs.pitch, runs.pitch_truth, grid, converged)
        record.update(record_p)
        arrays.update(arrays_p)
    for name, result in (extra or {}).items():
        err_e, sigma_e, nees_e, mean_e = against(result, runs.truth_model)
        record[f"yaw_error_{name}_at_gap_end_deg"] = [float(err_e[i, Y] * RAD2DEG)
                                                      for i in at_end]
        record[f"yaw_sigma_{name}_at_gap_end_deg"] = [float(sigma_e[i, Y] * RAD2DEG)
                                                      for i in at_end]
        record[f"yaw_error_rms_{name}_deg"] = _rms(err_e[on_grid, Y]) * RAD2DEG
        record[f"nees_mean_{name}"] = mean_e
        arrays[f"err_{name}"] = (err_e[on_grid] * f).astype(np.float32)
        arrays[f"sigma_{name}"] = (sigma_e[on_grid] * np.abs(f)).astype(np.float32)
        arrays[f"nees_{name}"] = nees_e.astype(np.float32)
    return record, arrays


def _pitch_record(p, truth, grid, converged) -> tuple[dict, dict[str, np.ndarray]]:
    """The pitch filter's part of a case (``run.pitch``; its history holds every
    sample): pitch error RMS and 3-state NEES on the grid, kept apart from the
    9-state figures."""
    err = p.x[grid] - truth[grid]
    values = nees(p.x[grid], pitch_unpack(p.P_packed[grid]), truth[grid])
    record = {"pitch_error_rms_deg": _rms(err[:, 0]) * RAD2DEG,
              "nees_mean_pitch": float(np.mean(values[converged])) if converged.any()
              else None}
    return record, {"err_pitch": (err * PITCH_FACTORS).astype(np.float32),
                    "sigma_pitch": (p.sigma[grid] * PITCH_FACTORS).astype(np.float32),
                    "nees_pitch": values.astype(np.float32)}


def _bias_record(s: Scenario, real, truth_model, rows, full: bool, on_grid, converged,
                 truth_biases: dict | None) -> dict:
    """A case's bias states at its last kept sample against the truth's, and the NEES
    of the augmented state (the paper's nine and the biases) on the converged grid.
    ``rows``: the samples kept (``case_rows``); the history holds every sample when
    ``full``, else those alone; the truth always every sample."""
    a = real.augmented
    x, P = (a.x[rows], a.P_packed[rows]) if full else (a.x, a.P_packed)
    keep = rows
    names = a.names
    final = {f"bias_{n}_deg": float(x[-1, N_STATES + j]) * RAD2DEG
             for j, n in enumerate(names)}
    sig = np.sqrt(np.diagonal(aug_unpack(P[-1:]), axis1=1, axis2=2))[0]
    final |= {f"sigma_bias_{n}_deg": float(sig[N_STATES + j]) * RAD2DEG
              for j, n in enumerate(names)}
    section = filter_section(s, design_of(s), final, None, truth_biases)
    record = {"bias_states": section["bias_states"], "nees_mean_augmented": None,
              "nees_dof_augmented": N_STATES + len(names)}
    if truth_biases is not None:
        b = np.array([truth_biases[n] for n in names])
        truth = np.column_stack([truth_model[keep], np.tile(b, (len(keep), 1))])
        values = nees(x[on_grid], aug_unpack(P[on_grid]), truth[on_grid])
        if converged.any():
            record["nees_mean_augmented"] = float(np.mean(values[converged]))
    return record


def full_arrays(runs) -> dict[str, np.ndarray]:
    """A kept case's whole trajectories (float32, display units)."""
    f = display_factors(runs.params.omega_n_radps)
    out = {"t_s": runs.sim.truth.t_s, "err": (runs.real.x - runs.truth_model) * f,
           "sigma": runs.real.sigma * np.abs(f), "truth": runs.truth_model * f}
    if runs.linear is not None:
        out["err_linear"] = (runs.linear.x - runs.twin_model) * f
    return {k: (v if k == "t_s" else np.asarray(v, dtype=np.float32)) for k, v in out.items()}


@blas_one_thread()   # a worker per core: OpenBLAS's spinning threads only took cores
def run_case(s: Scenario, case: int, keep_full: bool = False) -> dict:
    """Draw, simulate, filter and reduce case ``case`` of the nominal scenario ``s``.

    Never raises for a failing case: the outcome then has status "failed" and the
    error, so one bad case cannot stop a set."""
    start = time.perf_counter()
    try:
        dispersed, flying = draw_case(s, case)
        sim = simulate(flying, run=case)
        # The filter sees the telemetry exactly as `dynprop run` writes it.
        cols = simulated_telemetry(sim)
        present = np.isfinite(cols["yaw_deg"])
        _, _, rows = case_rows(s, len(present), present)
        runs = run_scenario(s, sim, cols, run=case, smooth=False, truth_scenario=flying,
                            rows=None if keep_full else rows, twin=s.montecarlo.linear_twin)
        extra = other_filters(s, cols, None if keep_full else rows)
        record, arrays = reduce_case(s, runs, present, case, dispersed, flying.epoch_utc,
                                     extra, build.truth_biases_rad(flying))
        full = full_arrays(runs) if keep_full else None
        return {"record": record, "arrays": arrays, "full": full,
                "wall_s": time.perf_counter() - start}
    except Exception as exc:  # recorded, not raised: see the docstring
        return failed(case, exc, time.perf_counter() - start)


def failed(case: int, exc: BaseException, wall_s: float = 0.0) -> dict:
    """A failed case's outcome: the error, where it came from and, for a draw that is
    not physical, the values drawn."""
    message = str(exc).splitlines()[0] if str(exc) else ""
    record = {"case": case, "status": "failed", "error": f"{type(exc).__name__}: {message}",
              "traceback": traceback.format_exception(exc)[-3:]}
    if isinstance(exc, UnphysicalDraw):
        record["dispersed"] = exc.values
    return {"record": record, "arrays": None, "full": None, "wall_s": wall_s}
