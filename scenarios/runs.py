"""Run directories of `dynprop run` and `dynprop estimate` (DESIGN.md section 6)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from estimator.kalman import rts_smoother
from estimator.transition import discretize

from . import build
from .comparison import comparison_arrays
from .csvio import BackgroundWriter, read_csv, write_csv
from .loader import cap_lines, closest
from .outputs import (
    estimate_columns,
    nees_series,
    summarize,
    write_summary,
)
from .pipeline import (
    REQUIRED_TELEMETRY,
    filter_telemetry,
    run_scenario,
    telemetry_inputs,
)
from .rundir import RunDirError
from .runner import simulate, write_simulation
from .schema import Scenario


def run_to_directory(s: Scenario, stage: Path, montecarlo_case: int | None = None) -> dict:
    """Everything of one `dynprop run` into ``stage``; returns the summary.

    With ``montecarlo_case`` K the spacecraft that flies is case K of the scenario's
    dispersions, with case K's noise streams; the filter stays nominal.  Then
    scenario.yaml is the nominal scenario (rerun it with the same K), and
    case_scenario.yaml and montecarlo_case.json/.npz hold the case: the latter
    exactly what `dynprop montecarlo` stores for case K."""
    case = montecarlo_case
    flying, dispersed = s, None
    if case is not None:
        from .montecarlo.dispersions import draw_case
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
        summary = _estimate_and_report(s, runs, written, stage, in_background)
        if case is not None:
            summary.update(montecarlo_case=case, epoch_utc=flying.epoch_utc,
                           dispersed=dispersed)
            _write_case(s, runs, written, stage, case, dispersed, flying)
        for w in writers:
            w.wait()
    except BaseException:
        for w in writers:
            w.cancel()
        raise
    write_summary(stage / "summary.json", summary)
    return summary


def _write_case(s: Scenario, runs, written, stage: Path, case: int, dispersed, flying) -> None:
    from .loader import resolved_yaml
    from .montecarlo.case import reduce_case
    from .montecarlo.store import save_case
    (stage / "case_scenario.yaml").write_text(resolved_yaml(flying))
    if not s.montecarlo.linear_twin:
        runs = replace(runs, linear=None, twin_model=None)
    record, arrays = reduce_case(s, runs, np.isfinite(written["yaw_deg"]), case, dispersed,
                                 flying.epoch_utc)
    save_case(stage / "montecarlo_case", {"record": record, "arrays": arrays})


def _estimate_and_report(s: Scenario, runs, written, stage: Path, in_background) -> dict:
    sim = runs.sim
    t = sim.truth.t_s
    present = np.isfinite(written["yaw_deg"])
    in_background(stage / "estimate.csv",
                  estimate_columns(t, runs.real.x, runs.real.sigma, runs.params.omega_n_radps))
    nees_data = nees_series(runs)
    np.savez(stage / "comparison.npz", **comparison_arrays(runs, t, present, nees_data))
    summary = summarize(s, runs, t, present, nees_data)
    from .plotting import plot_run_figures
    plot_run_figures(stage, written)
    return summary


OPTIONAL_TELEMETRY = ("yaw_sigma_deg", "sun_head")


def read_telemetry(path: Path, s: Scenario) -> dict[str, np.ndarray]:
    """A telemetry CSV with at least the contract columns.  Every problem found is
    reported, one line each naming the column; a missing column names the file's
    column it was most likely misspelt as."""
    path = Path(path)
    if not path.is_file():
        raise RunDirError(f"{path}: no such telemetry file")
    try:
        cols = read_csv(path)
    except (ValueError, UnicodeDecodeError) as exc:
        raise RunDirError(f"{path}: not a numeric CSV ({str(exc).splitlines()[0]})") from None
    n_wheels = len(build.yaw_factors(s))
    required = (*REQUIRED_TELEMETRY,
                *(f"wheel{i + 1}_rpm" for i in range(2, n_wheels)))
    unused = [c for c in cols if c not in required and c not in OPTIONAL_TELEMETRY]
    problems = []
    for name in required:
        if name in cols:
            continue
        # A file column that looks like the missing one is most likely it, misspelt:
        # name the file's column and suggest the valid name, as for a scenario key.
        typo = closest(name, unused)
        problems.append(f"{path}: unknown column {typo}; did you mean '{name}'?" if typo
                        else f"{path}: missing column {name}")
    t = cols.get("t_s")
    if t is not None and len(t) < 2:
        problems.append(f"{path}: needs at least two samples")
    for name in ("t_s", "roll_deg", *(f"wheel{i + 1}_rpm" for i in range(n_wheels))):
        bad = ~np.isfinite(cols[name]) if name in cols else np.zeros(0, bool)
        if bad.any():
            problems.append(f"{path}: column {name} has a missing or non-numeric value in "
                            f"row {int(np.argmax(bad)) + 2}")
    present = np.isfinite(cols["yaw_deg"]) if "yaw_deg" in cols else None
    if "yaw_sigma_deg" in cols and present is not None:
        sig = cols["yaw_sigma_deg"][present]
        if not np.all(np.isfinite(sig) & (sig > 0)):
            problems.append(f"{path}: yaw_sigma_deg must be positive wherever yaw_deg is "
                            "present")
    if "sun_head" in cols:
        head = cols["sun_head"][np.isfinite(cols["sun_head"])]
        if not np.all(np.isin(head, (0.0, 1.0, 2.0))):
            problems.append(f"{path}: sun_head must be 0 (dss), 1 (cass1) or 2 (cass2)")
    if t is not None and len(t) >= 2 and np.all(np.isfinite(t)):
        steps = np.diff(t)
        off = ~np.isclose(steps, s.sample_interval_s, rtol=1e-6, atol=1e-6)
        if off.any():
            k = int(np.argmax(off))
            problems.append(f"{path}: t_s must advance by the scenario's sample_interval_s "
                            f"({s.sample_interval_s} s); row {k + 3} steps {steps[k]:g} s")
    if problems:
        raise RunDirError("\n".join(cap_lines(problems)))
    return cols


def estimate_to_directory(s: Scenario, cols: dict[str, np.ndarray], stage: Path) -> None:
    params, noise = build.estimator_model(s)
    disc = discretize(params, noise, s.sample_interval_s)
    real, u = filter_telemetry(s, params, disc, *telemetry_inputs(s, cols))
    write_csv(stage / "estimate.csv",
              estimate_columns(cols["t_s"], real.x, real.sigma, params.omega_n_radps))
    smoothed = rts_smoother(real, disc, u=u)
    write_csv(stage / "smoothed.csv",
              estimate_columns(cols["t_s"], smoothed.x, smoothed.sigma, params.omega_n_radps))
