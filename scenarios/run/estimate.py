"""Run directories of `dynprop run` and `dynprop estimate` (docs/outputs.md)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
from dynprop.estimator.kalman import rts_smoother
from dynprop.estimator.transition import discretize

from ..config import build
from ..config.schema import Scenario
from ..files.comparison import comparison_arrays
from ..files.csvio import BackgroundWriter, write_csv
from ..files.rundir import RunDirError
from ..files.summary import (
    estimate_columns,
    nees_series,
    summarize,
    write_summary,
)
from .simulate import simulate, write_simulation
from .whole import (
    TwoRuns,
    filter_telemetry,
    model_truth,
    run_scenario,
    telemetry_inputs,
    truth_torques,
)


def run_to_directory(s: Scenario, stage: Path, montecarlo_case: int | None = None) -> dict:
    """Everything of one `dynprop run` into ``stage``; returns the summary.

    A plain run streams in windows (``streamrun``).  With ``montecarlo_case`` K
    the spacecraft that flies is case K of the scenario's dispersions, with case
    K's noise streams; the filter stays nominal; every sample is kept.  Then
    scenario.yaml is the nominal scenario (rerun it with the same K), and
    case_scenario.yaml and montecarlo_case.json/.npz hold the case: the latter
    exactly what `dynprop montecarlo` stores for case K."""
    case = montecarlo_case
    if case is None:
        from .streamrun import stream_to_directory
        return stream_to_directory(s, stage)
    flying, dispersed = s, None
    if case is not None:
        from ..montecarlo.dispersions import draw_case
        dispersed, flying = draw_case(s, case)
    run = 0 if case is None else case
    sim = simulate(flying, run)
    writers = []

    def in_background(path, columns):
        writers.append(BackgroundWriter(path, columns))

    try:
        # truth.csv is written by a second process while the filters run; the filter
        # sees the telemetry exactly as written, so `dynprop estimate` reproduces it.
        written = write_simulation(stage, sim, truth_writer=in_background, scenario=s)
        runs = run_scenario(s, sim, written, run=run, truth_scenario=flying)
        from ..montecarlo.case import other_filters
        extra = other_filters(s, written)
        summary = _estimate_and_report(s, runs, written, stage, in_background, extra)
        if case is not None:
            summary.update(montecarlo_case=case, epoch_utc=flying.epoch_utc,
                           dispersed=dispersed)
            _write_case(s, runs, written, stage, case, dispersed, flying, extra)
        for w in writers:
            w.wait()
    except BaseException:
        for w in writers:
            w.cancel()
        raise
    write_summary(stage / "summary.json", summary)
    return summary


def _write_case(s: Scenario, runs, written, stage: Path, case: int, dispersed, flying,
                extra: dict) -> None:
    from ..config.loader import resolved_yaml
    from ..montecarlo.case import reduce_case
    from ..montecarlo.store import save_case
    (stage / "case_scenario.yaml").write_text(resolved_yaml(flying))
    if not s.montecarlo.linear_twin:
        runs = replace(runs, linear=None, twin_model=None)
    record, arrays = reduce_case(s, runs, np.isfinite(written["yaw_deg"]), case, dispersed,
                                 flying.epoch_utc, extra)
    save_case(stage / "montecarlo_case", {"record": record, "arrays": arrays})


def _estimate_and_report(s: Scenario, runs, written, stage: Path, in_background,
                         extra: dict) -> dict:
    from types import SimpleNamespace
    sim = runs.sim
    t = sim.truth.t_s
    present = np.isfinite(written["yaw_deg"])
    in_background(stage / "estimate.csv",
                  estimate_columns(t, runs.real.x, runs.real.sigma, runs.params.omega_n_radps))
    for name, r in extra.items():
        in_background(stage / f"estimate_{name}.csv",
                      estimate_columns(t, r.x, r.sigma, runs.params.omega_n_radps))
    nees_data = nees_series(runs)
    np.savez(stage / "comparison.npz",
             **comparison_arrays(SimpleNamespace(**vars(runs), extra=extra), t, present,
                                 nees_data, written))
    summary = summarize(s, runs, t, present, nees_data)
    summary["filters"] = ["paper", *extra]
    for name, r in extra.items():
        summary[name] = _filter_summary(s, name, r, runs.truth_model, t, present)
    from ..figures.run import plot_run_figures
    plot_run_figures(stage)
    return summary


def estimate_inputs(s: Scenario, path: Path, truth_path: Path | None = None):
    """The telemetry on the filter's grid and the truth at its samples (or None),
    every problem found reported before anything is written."""
    from ..files.telemetry_file import on_grid, read_telemetry
    from ..files.truth_file import read_truth

    grid = on_grid(read_telemetry(path, s), s.sample_interval_s, s.estimator.max_gap_s, path)
    truth = None if truth_path is None else read_truth(truth_path, s, grid.columns["t_s"])
    return grid, truth


def _other_filters(s: Scenario, columns: dict) -> dict:
    """The filters besides the paper's (``estimator.filters``) on the file's telemetry."""
    if "ekf" not in s.estimator.filters:
        return {}
    from .ekf import run_ekf
    from .whole import DEG
    if "pitch_deg" not in columns:
        raise RunDirError("estimator.filters: the EKF measures pitch, and the telemetry has "
                          "no pitch_deg column; remove ekf or add the Earth sensor's pitch")
    return {"ekf": run_ekf(s, *_ekf_measured(s, columns, DEG))}


def _ekf_measured(s: Scenario, columns: dict, deg: float):
    roll, yaw, speeds, sigma, head = telemetry_inputs(s, columns)
    return roll, columns["pitch_deg"] * deg, yaw, speeds, sigma, head


def _filter_summary(s: Scenario, name: str, result, truth_model, t_s, present) -> dict:
    """summary.json's section of a filter besides the paper's, for a run of one
    window (at the Sun gaps the paper's summary uses, ``outputs.sun_gaps``)."""
    from types import SimpleNamespace

    from ..files.decimate import output_rows
    from ..files.summary import NEES_STRIDE, sun_gaps
    from .filter_tally import FilterFigures
    gaps = sun_gaps(present, s.sample_interval_s, s.estimator.sun_gap_min_h)
    rec = {"start": 0, "t_s": t_s, "truth_model": truth_model, name: SimpleNamespace(
        x=result.x, sigma=result.sigma, innovations=result.innovations,
        innovation_var=result.innovation_var, backend=result.backend,
        P_nees=result.P_packed[output_rows(0, len(t_s), NEES_STRIDE)])}
    figs = FilterFigures(name)
    figs.add(rec, [(a, b) for a, b in gaps if b < len(t_s)], truth=truth_model is not None)
    return figs.summary()


def estimate_to_directory(s: Scenario, grid, truth, stage: Path, sources: dict) -> dict:
    """`dynprop estimate`: the filter and smoother on gridded telemetry
    (``estimate_inputs``), written as a run directory (scenario.yaml, estimate.csv,
    smoothed.csv, summary.json, comparison.npz, plots/) that `dynprop plot` redraws.
    With the truth, the errors, NEES and the summary's error figures are those `run`
    computes; there is no linear twin (it needs the simulation, not its files).
    ``sources`` (the input files' names) goes into summary.json."""
    from types import SimpleNamespace

    from ..config.loader import resolved_yaml

    params, noise = build.estimator_model(s)
    disc = discretize(params, noise, s.sample_interval_s)
    real, smoother_args = filter_telemetry(s, params, disc, *telemetry_inputs(s, grid.columns))
    smoothed = rts_smoother(real, disc, **smoother_args)
    truth_model = None
    if truth is not None:
        tt = truth_torques(truth, s.estimator.model_torques, params.omega0_radps)
        truth_model = model_truth(params, truth, tt)
    runs = TwoRuns(None if truth is None else SimpleNamespace(truth=truth), None, params,
                   truth_model, None, real, None, smoothed, build.yaw_factors(s))
    t = grid.columns["t_s"]
    extra = _other_filters(s, grid.columns)
    (stage / "scenario.yaml").write_text(resolved_yaml(s))
    write_csv(stage / "estimate.csv",
              estimate_columns(t, real.x, real.sigma, params.omega_n_radps))
    for name, r in extra.items():
        write_csv(stage / f"estimate_{name}.csv",
                  estimate_columns(t, r.x, r.sigma, params.omega_n_radps))
    write_csv(stage / "smoothed.csv",
              estimate_columns(t, smoothed.x, smoothed.sigma, params.omega_n_radps))
    present = np.isfinite(grid.columns["yaw_deg"])
    nees_data = nees_series(runs)
    np.savez(stage / "comparison.npz",
             **comparison_arrays(SimpleNamespace(**vars(runs), extra=extra), t, present,
                                 nees_data, grid.columns))
    summary = summarize(s, runs, t, present, nees_data)
    summary["filters"] = ["paper", *extra]
    for name, r in extra.items():
        summary[name] = _filter_summary(s, name, r, truth_model, t, present)
    # One key set for every summary: `run`'s output keys, for a file filtered row by row.
    summary.update(output_interval_s=s.sample_interval_s, telemetry_written=None, daily=None)
    summary["telemetry"] = {**sources, **grid.stats(s.sample_interval_s)}
    from ..figures.run import plot_run_figures
    plot_run_figures(stage)
    write_summary(stage / "summary.json", summary)
    return summary
