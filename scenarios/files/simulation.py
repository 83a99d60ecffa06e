"""The files of `dynprop simulate`: scenario.yaml (resolved), truth.csv and
telemetry.csv, from a simulation's whole arrays (``run.simulate``)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from ..config.management import telemeters_torquers, torquer_columns
from ..config.schema import Scenario, resolved_yaml
from .columns import (
    UtcTags,
    telemetry_columns,
    telemetry_lattices,
    truth_columns,
)
from .csvio import write_csv


def simulated_telemetry(sim) -> dict[str, np.ndarray]:
    """telemetry.csv's columns of a ``run.simulate.Simulation``: the sensors', and the
    torquers' commanded dipoles when the scenario telemeters them
    (``config.management.telemeters_torquers``)."""
    tel = telemetry_columns(sim.telemetry, sim.suite)
    if telemeters_torquers(sim.scenario):
        tel.update(torquer_columns(sim.truth.torquer_dipole_Am2))
    return tel


def write_simulation(stage: Path, sim, show_progress: bool | None = None,
                     truth_writer=None, scenario: Scenario | None = None
                     ) -> dict[str, np.ndarray]:
    """scenario.yaml (resolved), truth.csv and telemetry.csv of ``sim`` (a
    ``run.simulate.Simulation``) into ``stage``; returns the telemetry columns
    exactly as written (shortest round-trip text: a re-read gives the same doubles,
    so `dynprop estimate` on the file reproduces a run's filter).  With
    ``truth_writer`` (a callable taking path and columns) truth.csv is handed off.
    ``scenario`` is what scenario.yaml records, if not the one simulated (a Monte
    Carlo case records its nominal scenario)."""
    (stage / "scenario.yaml").write_text(resolved_yaml(scenario or sim.scenario))
    truth = truth_columns(sim.truth, sim.telemetry.sun_visible)
    tel = simulated_telemetry(sim)
    lattices = telemetry_lattices(sim.suite, sim.telemetry.wheel_speeds_radps.shape[1])
    # The epoch line and time_utc column say when t_s is (the simulated scenario's epoch).
    tags = UtcTags.of(sim.scenario.epoch_utc, sim.scenario.sample_interval_s)
    if truth_writer is not None:
        truth_writer(stage / "truth.csv", truth)
        write_csv(stage / "telemetry.csv", tel, exact=True, lattices=lattices, tags=tags)
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
                  lattices=lattices, tags=tags)
    finally:
        if bar is not None:
            bar.close()
    return tel
