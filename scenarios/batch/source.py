"""The telemetry `dynprop batch` fits, and the truth it is judged against: a run
directory's telemetry.csv (or the file a `dynprop estimate` directory read) and
truth.csv, or a telemetry file with ``--scenario`` (and ``--truth``)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ..config.loader import load_scenario
from ..config.schema import Scenario
from ..files.rundir import RunDirError
from ..files.telemetry_file import GriddedTelemetry, run_telemetry


@dataclass(frozen=True)
class BatchSource:
    scenario: Scenario
    telemetry: Path
    truth_path: Path | None
    run_dir: Path | None
    grid: GriddedTelemetry
    truth: object | None      # files.truth_file.TruthFromFile


def read_source(source: Path, scenario: str | Path | None = None, overrides=(),
                truth: Path | None = None) -> BatchSource:
    """The telemetry on the filter's grid (or at its own times) and the truth at its
    samples; a run directory's truth.csv is used unless ``truth`` names another."""
    from ..run.estimate import estimate_inputs
    source = Path(source)
    if not source.exists():
        raise RunDirError(f"{source}: no such telemetry file or run directory")
    if source.is_dir():
        if not (source / "scenario.yaml").is_file():
            raise RunDirError(f"{source}: not a run directory (no scenario.yaml)")
        path = run_telemetry(source)
        if path is None:
            raise RunDirError(f"{source}: no telemetry.csv to fit (a run longer than 2 days "
                              "writes it only with output.telemetry: true: rerun with --set "
                              "output.telemetry=true)")
        s = load_scenario(scenario or source / "scenario.yaml", list(overrides))
        own_truth = source / "truth.csv"
        truth = truth if truth is not None else (own_truth if own_truth.is_file() else None)
        run_dir = source
    else:
        if scenario is None:
            raise RunDirError(f"{source}: a telemetry file needs --scenario (the spacecraft "
                              "and sensors it came from)")
        path, run_dir = source, None
        s = load_scenario(scenario, list(overrides))
    grid, truth_rows = estimate_inputs(s, path, truth)
    return BatchSource(s, path, truth, run_dir, grid, truth_rows)
