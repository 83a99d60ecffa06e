"""Run a scenario: truth, then telemetry; write the run directory.

This is where ``sim`` meets the scenario; the estimator joins in a later issue.
"""

from __future__ import annotations

import sys
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from dynprop.sim.sensors import SensorSuite
from dynprop.sim.telemetry import Telemetry, sense_window
from dynprop.sim.truth import TruthResult, TruthStream

from ..config import build
from ..config.loader import resolved_yaml
from ..config.schema import Scenario
from ..files.columns import telemetry_columns, telemetry_lattices, truth_columns
from ..files.csvio import write_csv


@dataclass(frozen=True)
class Simulation:
    scenario: Scenario
    truth: TruthResult
    telemetry: Telemetry
    suite: SensorSuite

    @property
    def head_names(self) -> tuple[str, ...]:
        return tuple(h.name for h in self.suite.sun_heads)


def simulate(scenario: Scenario, run: int = 0, model=None) -> Simulation:
    """Truth and telemetry for one run; every random stream comes from
    ``build.streams(scenario.seed, run)``."""
    rngs = build.streams(scenario.seed, run)
    suite = build.build_sensors(scenario)
    stream = TruthStream(
        build.build_spacecraft(scenario), build.orbit(scenario), build.build_environment(scenario),
        build.build_control(scenario), build.build_initial(scenario), build.epoch(scenario),
        scenario.duration_s, scenario.sample_interval_s, rng=rngs["ripple"], model=model)
    with ThreadPoolExecutor(1) as pool:   # both cores (sense_window)
        truth, tel, _ = sense_window(stream, 0, stream.n_samples, suite, rngs, pool,
                                     scenario.sensors.sun.min_sun_separation_deg)
    return Simulation(scenario, truth, tel, suite)


def write_simulation(stage: Path, sim: Simulation, show_progress: bool | None = None,
                     truth_writer=None, scenario: Scenario | None = None
                     ) -> dict[str, np.ndarray]:
    """scenario.yaml (resolved), truth.csv and telemetry.csv into ``stage``; returns
    the telemetry columns exactly as written (shortest round-trip text: a re-read
    gives the same doubles, so `dynprop estimate` on the file reproduces a run's
    filter).  With
    ``truth_writer`` (a callable taking path and columns) truth.csv is handed off.
    ``scenario`` is what scenario.yaml records, if not the one simulated (a Monte
    Carlo case records its nominal scenario)."""
    (stage / "scenario.yaml").write_text(resolved_yaml(scenario or sim.scenario))
    truth = truth_columns(sim.truth, sim.telemetry.sun_visible)
    tel = telemetry_columns(sim.telemetry, sim.suite)
    lattices = telemetry_lattices(sim.suite, sim.telemetry.wheel_speeds_radps.shape[1])
    if truth_writer is not None:
        truth_writer(stage / "truth.csv", truth)
        write_csv(stage / "telemetry.csv", tel, exact=True, lattices=lattices)
        return tel
    rows = len(sim.truth.t_s)
    if show_progress is None:
        # A bar only on a terminal, and only when writing takes more than a moment.
        show_progress = sys.stderr.isatty() and rows > 50_000
    bar = None
    if show_progress:
        from tqdm import tqdm
        bar = tqdm(total=2 * rows, unit="row", unit_scale=True, desc="writing",
                   leave=False, file=sys.stderr)
    try:
        update = bar.update if bar is not None else None
        write_csv(stage / "truth.csv", truth, progress=update)
        write_csv(stage / "telemetry.csv", tel, progress=update, exact=True,
                  lattices=lattices)
    finally:
        if bar is not None:
            bar.close()
    return tel
