"""`dynprop estimate`: the paper's filter and smoother (and the filters beside it)
on a telemetry file, written as a run directory (docs/outputs.md)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
from dynprop.estimator.kalman.consistency import nees
from dynprop.estimator.linear import model as em
from dynprop.estimator.linear.steps import StepTable
from dynprop.estimator.linear.transition import discretize
from dynprop.estimator.pitch.filter import unpack as pitch_unpack

from ..bridge.coordinates import model_truth, pitch_truth, truth_torques
from ..bridge.inputs import telemetry_inputs
from ..config import build
from ..config.schema import Scenario, output_stride, resolved_yaml
from ..files.checks import add_checks
from ..files.columns import estimate_columns, pitch_columns
from ..files.comparison import PitchRows, comparison_arrays
from ..files.csvio import write_csv
from ..files.rundir import RunDirError
from ..files.summary import assemble_summary, write_summary
from ..files.truth_aem import is_aem
from ..records import FilterHistory
from ..samples import nees_rows, output_rows, sun_gaps, sun_gaps_at
from ..units import DEG
from .ekf import other_filters
from .estimate_truth import comparison_at_rows, filter_row_summary, row_statistics
from .filter_tally import FilterTally
from .filtering import (
    bias_columns,
    design_of,
    filter_section,
    final_biases,
    paper_smoother,
    rejected_counts,
)
from .pitch import PitchHistory, PitchTally, history_at, pitch_summary, run_pitch
from .statistics import nees_series, whole_run_statistics
from .whole import TwoRuns, filter_telemetry


def estimate_inputs(s: Scenario, path: Path, truth_path: Path | None = None):
    """The telemetry on the filter's grid and the truth at its samples (or None),
    every problem found reported before anything is written."""
    from ..files.telemetry_file import on_grid, read_screened
    from ..files.truth_file import read_truth

    cols, report = read_screened(path, s)
    grid = on_grid(cols, s.sample_interval_s, s.estimator.max_gap_s, path, report)
    if truth_path is None:
        return grid, None
    if is_aem(truth_path):
        from ..files.aem import AemError
        from ..files.truth_aem import read_truth_aem
        try:
            return grid, read_truth_aem(truth_path, s, grid.columns["t_s"], grid.regular)
        except AemError as exc:
            raise RunDirError(str(exc)) from None
    return grid, read_truth(truth_path, s, grid.columns["t_s"], grid.regular)


def attitude_only(truth) -> bool:
    """Whether a truth holds the attitude alone (an AEM: no rates, momentum or
    torques), so only the roll, yaw and pitch errors can be formed."""
    return truth is not None and not np.isfinite(truth.h_Nms).any()


def _attitude_truth(truth) -> tuple[np.ndarray, np.ndarray]:
    """The model states and pitch states of an attitude-only truth: the angles, NaN
    for every state it does not hold (their errors and the NEES are then not tested)."""
    m = np.full((len(truth.t_s), em.N_STATES), np.nan)
    m[:, em.R], m[:, em.Y] = truth.roll_rad, truth.yaw_rad
    nan = np.full(len(truth.t_s), np.nan)
    return m, np.column_stack([truth.pitch_rad, nan, nan])


def filter_summary(s: Scenario, name: str, result, truth_model, t_s, present,
                   on_grid: bool = True) -> dict:
    """summary.json's section of a filter besides the paper's, for a run held whole
    (at the Sun gaps the paper's summary uses, ``samples.sun_gaps``)."""
    gaps = (sun_gaps(present, s.sample_interval_s, s.estimator.sun_gap_min_h) if on_grid
            else sun_gaps_at(present, t_s, s.estimator.sun_gap_min_h))
    history = FilterHistory(result.x, result.sigma, result.innovations, result.innovation_var,
                            result.backend, P_nees=result.P_packed[nees_rows(0, len(t_s))])
    tally = FilterTally(name)
    tally.add(history, 0, truth_model, [(a, b) for a, b in gaps if b < len(t_s)],
              t_s - t_s[0])
    return tally.summary()


def _truth_section(truth, t, ends) -> dict:
    """What summary.json's ``telemetry`` says of the truth the errors were computed
    against: how many rows, at what cadence, and where each gap end was judged."""
    if truth is None:
        return {"truth_rows": None, "compared_rows": None, "compared_cadence_s": None,
                "gap_end_compared_at_s": None}
    steps = np.diff(t[truth.rows])
    return {"truth_rows": truth.file_rows, "compared_rows": int(len(truth.rows)),
            "compared_cadence_s": float(np.median(steps)) if steps.size else None,
            "gap_end_compared_at_s": [None if r is None else float(t[r]) for _, r in ends]}


def estimate_to_directory(s: Scenario, grid, truth, stage: Path, sources: dict) -> dict:
    """`dynprop estimate`: the filter and smoother on gridded telemetry
    (``estimate_inputs``), written as a run directory (scenario.yaml, estimate.csv,
    smoothed.csv, summary.json, comparison.npz, plots/) that `dynprop plot` redraws.
    estimate.csv and smoothed.csv hold the rows at ``output.interval_s``, as `run`'s;
    every figure of the summary is computed at every sample.  With the truth, the
    errors, NEES and the summary's error figures are those `run` computes, at the
    samples the truth has a row for (``estimate_truth``; with a row at every sample,
    exactly `run`'s); there is no linear twin (it needs the simulation, not its
    files).  ``sources`` (the input files' names) goes into summary.json."""
    params, noise = build.estimator_model(s)
    t = grid.columns["t_s"]
    n = len(t)
    # Off the grid, each step propagates over its own interval (``estimator.linear.steps``).
    disc = (discretize(params, noise, s.sample_interval_s) if grid.regular
            else StepTable(params, noise, grid.steps))
    measured = telemetry_inputs(s, grid.columns)
    real, smoother_args = filter_telemetry(s, params, disc, *measured,
                                           t_s=None if grid.regular else t)
    smoothed = paper_smoother(design_of(s), real, disc, **smoother_args)
    sparse = truth is not None and not truth.every_sample(n)
    truth_model = p_truth = None
    if attitude_only(truth):
        truth_model, p_truth = _attitude_truth(truth)
    elif truth is not None:
        tt = truth_torques(truth, s.estimator.model_torques, params.omega0_radps)
        truth_model = model_truth(params, truth, tt)
        p_truth = pitch_truth(truth, tt)
    # The pitch filter (Eq. 3b) when the file has the Earth sensor's pitch.
    pitch = None
    if "pitch_deg" in grid.columns:
        pitch = run_pitch(s, grid.columns["pitch_deg"] * DEG,
                          measured.speeds_radps,
                          None if grid.regular else t)
    pitch_hist = (None if pitch is None else history_at(pitch, truth.rows, p_truth) if sparse
                  else PitchHistory.of(pitch, p_truth, nees_rows(0, n), keep_P=True))
    runs = TwoRuns(None, None, params, truth_model, None, real, None, smoothed,
                   build.yaw_factors(s),
                   true_euler_rad=None if truth is None else truth.euler_rad,
                   pitch=None if sparse else pitch_hist, pitch_truth=None if sparse else p_truth)
    extra = other_filters(s, grid.columns, on_grid=grid.regular)
    (stage / "scenario.yaml").write_text(resolved_yaml(s))
    # The files at the output cadence, as `run` writes them (``samples.output_rows``).
    # Off the grid, a row every output.interval_s of the file's own cadence.
    step_s = s.sample_interval_s if grid.regular else float(np.median(grid.steps[:-1]))
    stride = output_stride(s) if grid.regular else max(1, round(
        s.sample_interval_s * output_stride(s) / step_s))
    k = output_rows(0, n, stride)
    write_csv(stage / "estimate.csv",
              estimate_columns(t[k], real.x[k], real.sigma[k], params.omega_n_radps)
              | bias_columns(real, k)
              | ({} if pitch is None else pitch_columns(pitch.x[k], pitch.sigma[k])))
    for name, r in extra.items():
        write_csv(stage / f"estimate_{name}.csv",
                  estimate_columns(t[k], r.x[k], r.sigma[k], params.omega_n_radps))
    write_csv(stage / "smoothed.csv",
              estimate_columns(t[k], smoothed.x[k], smoothed.sigma[k], params.omega_n_radps))
    present = np.isfinite(grid.columns["yaw_deg"])
    if sparse:
        # The filter's own figures at every sample, the errors at the truth's rows.
        rows = truth.rows
        base = whole_run_statistics(s, dataclasses.replace(runs, truth_model=None), t,
                                    present, nees_series(dataclasses.replace(
                                        runs, truth_model=None)), grid.regular)
        stats, ends, n_real = row_statistics(base, real, smoothed, truth_model, rows, t)
        arrays = comparison_arrays(comparison_at_rows(runs, rows, extra, _sparse_pitch(
                                       pitch_hist, p_truth)), t[rows],
                                   present[rows], (np.arange(len(rows)), n_real, None),
                                   {c: v[rows] for c, v in grid.columns.items()})
    else:
        nees_data = nees_series(runs)
        stats = whole_run_statistics(s, runs, t, present, nees_data, grid.regular)
        arrays = comparison_arrays(runs.comparison_inputs(extra), t, present, nees_data,
                                   grid.columns)
        ends = [(b, b) for b in gap_ends(stats.gaps, n)]
    if grid.screen is not None and grid.screen.count:
        # The figures and the page mark the samples with a screened value.
        arrays["screened_t_s"] = grid.screen.t_s[grid.screen.rows_any()]
    np.savez(stage / "comparison.npz", **arrays)
    summary = assemble_summary(s, params, real.backend, truth is not None, False, stats,
                               None if grid.regular else t)
    summary["filters"] = ["paper", *extra]
    # The truth's biases are known only from a simulated run's scenario; a real file's
    # are what the filter is for.
    summary.update(filter_section(s, design_of(s), final_biases(real),
                                  rejected_counts(real, grid.columns.get("sun_head")),
                                  build.truth_biases_rad(s) if truth is not None else None))
    for name, r in extra.items():
        summary[name] = (filter_row_summary(name, r, truth_model, truth.rows, ends, t) if sparse
                         else filter_summary(s, name, r, truth_model, t, present,
                                           grid.regular))
    if sparse and pitch_hist is not None:
        # Its own figures at every sample, its errors where the truth has rows.
        tally = PitchTally(s)
        tally.add_own(PitchHistory.of(pitch, None, [], keep_P=True), t - t[0])
        tally.add_errors(pitch_hist, 0, t[truth.rows] - t[0], p_truth)
        summary["pitch"] = tally.summary()
    else:
        summary["pitch"] = pitch_summary(s, pitch_hist, t - t[0], p_truth)
    # One key set for every summary: `run`'s output keys, for a file filtered row by row.
    summary.update(output_interval_s=stride * step_s, telemetry_written=None,
                   daily=None)
    summary["telemetry"] = {**sources, **grid.stats(s.sample_interval_s),
                            **_truth_section(truth, t, ends)}
    if attitude_only(truth):
        # What needs the states an attitude history does not hold (rates, h, the
        # torque states: their errors, (e/σ)², NEES) is not tested, null.
        summary = _finite_or_none(summary)
        summary["telemetry"]["truth_holds"] = "attitude only"
    elif truth is not None:
        summary["telemetry"]["truth_holds"] = "every state"
    else:
        summary["telemetry"]["truth_holds"] = None
    # summary.json before the figures: they draw its verdicts and warnings.
    write_summary(stage / "summary.json", add_checks(summary))
    from ..figures.run import plot_run_figures
    plot_run_figures(stage)
    return summary


def _sparse_pitch(h: PitchHistory | None, truth) -> PitchRows | None:
    """The pitch filter at a sparse truth's common rows for comparison.npz, its NEES at
    every one of them (as the 9-state NEES is there)."""
    if h is None:
        return None
    values = None
    if truth is not None:
        values = nees(h.x, pitch_unpack(h.P_packed), truth)
    return PitchRows(h.x, h.sigma, h.innovations, h.innovation_var, truth, values)


def _finite_or_none(v):
    """``v`` with every NaN float (a figure of a state the truth lacks) as None."""
    if isinstance(v, dict):
        return {k: _finite_or_none(x) for k, x in v.items()}
    if isinstance(v, list | tuple):
        return type(v)(_finite_or_none(x) for x in v)
    if isinstance(v, float | np.floating) and not np.isfinite(v):
        return None
    return v


def gap_ends(gaps, n: int) -> list[int]:
    """The ends of the Sun gaps ``gaps`` that end inside the grid's ``n`` samples."""
    return [b for _, b in gaps if b < n]
