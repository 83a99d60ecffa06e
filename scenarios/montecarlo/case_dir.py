"""`dynprop run --montecarlo-case K`: case K of a scenario's dispersions flown alone
and written as a full run directory, every sample kept.

The spacecraft that flies is case K's, with case K's noise streams; the filter
stays nominal.  scenario.yaml is the nominal scenario (rerun it with the same K),
case_scenario.yaml the case's; montecarlo_case.json/.npz are exactly what `dynprop
montecarlo` stores for case K (``case.reduce_case`` on the full histories).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from ..config import build
from ..config.schema import Scenario, resolved_yaml
from ..files.checks import add_checks
from ..files.columns import estimate_columns, pitch_columns
from ..files.comparison import comparison_arrays
from ..files.csvio import BackgroundWriter
from ..files.simulation import write_simulation
from ..files.summary import assemble_summary, write_summary
from ..run.ekf import other_filters
from ..run.estimate import filter_summary
from ..run.filtering import (
    bias_columns,
    design_of,
    filter_section,
    final_biases,
    rejected_counts,
)
from ..run.pitch import pitch_summary
from ..run.simulate import simulate
from ..run.statistics import nees_series, whole_run_statistics
from ..run.whole import run_scenario
from .case import reduce_case
from .dispersions import draw_case
from .store import save_case


def case_to_directory(s: Scenario, stage: Path, case: int) -> dict:
    """Everything of case ``case`` into ``stage``; returns the summary."""
    dispersed, flying = draw_case(s, case)
    sim = simulate(flying, case)
    writers = []

    def in_background(path, columns):
        writers.append(BackgroundWriter(path, columns))

    try:
        # truth.csv is written by a second process while the filters run; the filter
        # sees the telemetry exactly as written, so `dynprop estimate` reproduces it.
        written = write_simulation(stage, sim, truth_writer=in_background, scenario=s)
        runs = run_scenario(s, sim, written, run=case, truth_scenario=flying)
        extra = other_filters(s, written)
        summary = _estimate_and_report(s, runs, written, stage, in_background, extra,
                                       build.truth_biases_rad(flying))
        # Every sample is kept and telemetry.csv written; no daily.csv (one run).
        summary.update(output_interval_s=s.sample_interval_s, telemetry_written=True,
                       daily=None, montecarlo_case=case, epoch_utc=flying.epoch_utc,
                       dispersed=dispersed)
        (stage / "case_scenario.yaml").write_text(resolved_yaml(flying))
        if not s.montecarlo.linear_twin:
            runs = replace(runs, linear=None, twin_model=None)
        record, arrays = reduce_case(s, runs, np.isfinite(written["yaw_deg"]), case,
                                     dispersed, flying.epoch_utc, extra,
                                     build.truth_biases_rad(flying))
        save_case(stage / "montecarlo_case", {"record": record, "arrays": arrays})
        for w in writers:
            w.wait()
    except BaseException:
        for w in writers:
            w.cancel()
        raise
    write_summary(stage / "summary.json", add_checks(summary))
    return summary


def _estimate_and_report(s: Scenario, runs, written, stage: Path, in_background,
                         extra: dict, truth_biases: dict | None = None) -> dict:
    t = runs.sim.truth.t_s
    present = np.isfinite(written["yaw_deg"])
    in_background(stage / "estimate.csv",
                  estimate_columns(t, runs.real.x, runs.real.sigma, runs.params.omega_n_radps)
                  | bias_columns(runs.real, slice(None))
                  | pitch_columns(runs.pitch.x, runs.pitch.sigma))
    for name, r in extra.items():
        in_background(stage / f"estimate_{name}.csv",
                      estimate_columns(t, r.x, r.sigma, runs.params.omega_n_radps))
    nees_data = nees_series(runs)
    np.savez(stage / "comparison.npz",
             **comparison_arrays(runs.comparison_inputs(extra), t, present, nees_data, written))
    summary = assemble_summary(s, runs.params, runs.real.backend, runs.truth_model is not None,
                               runs.linear is not None,
                               whole_run_statistics(s, runs, t, present, nees_data))
    summary["filters"] = ["paper", *extra]
    summary.update(filter_section(s, design_of(s), final_biases(runs.real),
                                  rejected_counts(runs.real, written.get("sun_head")),
                                  truth_biases))
    for name, r in extra.items():
        summary[name] = filter_summary(s, name, r, runs.truth_model, t, present)
    summary["pitch"] = pitch_summary(s, runs.pitch, t - t[0], runs.pitch_truth)
    # summary.json before the figures, which draw its verdicts and warnings; written
    # again, complete, when the case is done.
    write_summary(stage / "summary.json", add_checks(summary))
    from ..figures.run import plot_run_figures
    plot_run_figures(stage)
    return summary
