"""`dynprop estimate`: the paper's filter and smoother (and the filters beside it)
on a telemetry file, written as a run directory (docs/outputs.md)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from dynprop.estimator.kalman import rts_smoother
from dynprop.estimator.transition import discretize

from ..bridge.coordinates import model_truth, truth_torques
from ..bridge.inputs import telemetry_inputs
from ..config import build
from ..config.schema import Scenario, resolved_yaml
from ..files.columns import estimate_columns
from ..files.comparison import comparison_arrays
from ..files.csvio import write_csv
from ..files.summary import assemble_summary, write_summary
from ..records import FilterHistory
from ..samples import nees_rows, sun_gaps
from .ekf import other_filters
from .filter_tally import FilterTally
from .statistics import nees_series, whole_run_statistics
from .whole import TwoRuns, filter_telemetry


def estimate_inputs(s: Scenario, path: Path, truth_path: Path | None = None):
    """The telemetry on the filter's grid and the truth at its samples (or None),
    every problem found reported before anything is written."""
    from ..files.telemetry_file import on_grid, read_telemetry
    from ..files.truth_file import read_truth

    grid = on_grid(read_telemetry(path, s), s.sample_interval_s, s.estimator.max_gap_s, path)
    truth = None if truth_path is None else read_truth(truth_path, s, grid.columns["t_s"])
    return grid, truth


def filter_summary(s: Scenario, name: str, result, truth_model, t_s, present) -> dict:
    """summary.json's section of a filter besides the paper's, for a run held whole
    (at the Sun gaps the paper's summary uses, ``samples.sun_gaps``)."""
    gaps = sun_gaps(present, s.sample_interval_s, s.estimator.sun_gap_min_h)
    history = FilterHistory(result.x, result.sigma, result.innovations, result.innovation_var,
                            result.backend, P_nees=result.P_packed[nees_rows(0, len(t_s))])
    tally = FilterTally(name)
    tally.add(history, 0, truth_model, [(a, b) for a, b in gaps if b < len(t_s)])
    return tally.summary()


def estimate_to_directory(s: Scenario, grid, truth, stage: Path, sources: dict) -> dict:
    """`dynprop estimate`: the filter and smoother on gridded telemetry
    (``estimate_inputs``), written as a run directory (scenario.yaml, estimate.csv,
    smoothed.csv, summary.json, comparison.npz, plots/) that `dynprop plot` redraws.
    With the truth, the errors, NEES and the summary's error figures are those `run`
    computes; there is no linear twin (it needs the simulation, not its files).
    ``sources`` (the input files' names) goes into summary.json."""
    params, noise = build.estimator_model(s)
    disc = discretize(params, noise, s.sample_interval_s)
    real, smoother_args = filter_telemetry(s, params, disc, *telemetry_inputs(s, grid.columns))
    smoothed = rts_smoother(real, disc, **smoother_args)
    truth_model = None
    if truth is not None:
        tt = truth_torques(truth, s.estimator.model_torques, params.omega0_radps)
        truth_model = model_truth(params, truth, tt)
    runs = TwoRuns(None, None, params, truth_model, None, real, None, smoothed,
                   build.yaw_factors(s),
                   true_euler_rad=None if truth is None else truth.euler_rad)
    t = grid.columns["t_s"]
    extra = other_filters(s, grid.columns)
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
             **comparison_arrays(runs.comparison_inputs(extra), t, present, nees_data,
                                 grid.columns))
    summary = assemble_summary(s, params, real.backend, truth is not None, False,
                               whole_run_statistics(s, runs, t, present, nees_data))
    summary["filters"] = ["paper", *extra]
    for name, r in extra.items():
        summary[name] = filter_summary(s, name, r, truth_model, t, present)
    # One key set for every summary: `run`'s output keys, for a file filtered row by row.
    summary.update(output_interval_s=s.sample_interval_s, telemetry_written=None, daily=None)
    summary["telemetry"] = {**sources, **grid.stats(s.sample_interval_s)}
    from ..figures.run import plot_run_figures
    plot_run_figures(stage)
    write_summary(stage / "summary.json", summary)
    return summary
