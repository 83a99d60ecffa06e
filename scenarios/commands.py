"""The work behind the commands that write a run directory, shared by the command
line (``cli``) and the Python API (``dynprop.api``), so the two cannot drift apart.

This is the top room: it alone wires the run engine (``run``) to the analyses
that plug into it (the trim loop of ``trim``, a Monte Carlo case of
``montecarlo``), which ``run`` itself never imports.
"""

from __future__ import annotations

from pathlib import Path

from .config.schema import Scenario
from .files.simulation import write_simulation
from .run.simulate import Simulation, simulate
from .run.stream.directory import stream_to_directory


def simulate_to_directory(s: Scenario, stage: Path) -> Simulation:
    """`dynprop simulate`: truth and telemetry of ``s`` into ``stage``."""
    sim = simulate(s)
    write_simulation(stage, sim)
    return sim


def run_to_directory(s: Scenario, stage: Path, montecarlo_case: int | None = None) -> dict:
    """Everything of one `dynprop run` into ``stage``; returns the summary.

    A plain run streams in windows (``run.stream.directory``), steered by the trim loop when
    the scenario closes it (``trim.every_days``).  With ``montecarlo_case`` K the
    spacecraft that flies is case K of the scenario's dispersions, every sample kept
    (``montecarlo.case_dir``)."""
    if montecarlo_case is not None:
        from .montecarlo.case_dir import case_to_directory
        return case_to_directory(s, stage, montecarlo_case)
    steering = None
    if s.trim.every_days is not None:
        from .trim.loop import TrimSteering
        steering = TrimSteering(s)
    return stream_to_directory(s, stage, steering=steering)


WINDOW_SAMPLES_ENV = "DYNPROP_WINDOW_SAMPLES"   # a test hook: small windows in a subprocess


def estimate_into(s: Scenario, telemetry: Path, truth: Path | None, stage: Path,
                  window_samples: int | None = None) -> dict:
    """`dynprop estimate` into ``stage``; returns the summary.  Without a truth file the
    telemetry streams through the run's engine (``run.stream.file_run``), read by
    range from a scratch copy in the stage (``files.telemetry_source``), so a file of
    any length fits in memory; every problem with the file is reported before the
    engine starts; a truth.csv streams alongside (``file_windows.FileTruth``).  With
    an attitude history (CCSDS AEM) the record is held whole (``run.estimate``)."""
    import os
    sources = {"file": str(Path(telemetry).resolve()),
               "truth_file": None if truth is None else str(Path(truth).resolve())}
    from .files.truth_aem import is_aem
    if truth is not None and is_aem(truth):
        # An attitude history (attitude alone): held whole (``run.estimate``).
        from .run.estimate import estimate_inputs, estimate_to_directory
        grid, truth_rows = estimate_inputs(s, telemetry, truth)
        return estimate_to_directory(s, grid, truth_rows, stage, sources)
    from .files.telemetry_source import open_source
    from .run.stream.file_run import estimate_stream
    if window_samples is None and os.environ.get(WINDOW_SAMPLES_ENV):
        window_samples = int(os.environ[WINDOW_SAMPLES_ENV])
    source = open_source(telemetry, s, Path(stage))
    try:
        return estimate_stream(s, source, stage, sources, window_samples, truth_path=truth)
    finally:
        source.close()
