"""Truth and telemetry of one run as whole arrays: what `dynprop simulate`, a Monte
Carlo case and the whole-array run (``whole``) fly.  This is where ``sim`` meets
the scenario; ``files.simulation`` writes the result."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

from dynprop.sim.sensors import SensorSuite
from dynprop.sim.telemetry import Telemetry, sense_window
from dynprop.sim.truth import TruthResult

from ..config import build
from ..config.schema import Scenario


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
    ``build.streams(scenario.seed, run)`` (and the disturbance's, if it flies one,
    from ``build.disturbance_generator(scenario, run)``)."""
    rngs = build.streams(scenario.seed, run)
    suite = build.build_sensors(scenario)
    stream = build.truth_stream(scenario, rngs["ripple"], model=model,
                                disturbance_rng=build.disturbance_generator(scenario, run))
    with ThreadPoolExecutor(1) as pool:   # both cores (sense_window)
        truth, tel, _ = sense_window(stream, 0, stream.n_samples, suite, rngs, pool,
                                     scenario.sensors.sun.min_sun_separation_deg)
    return Simulation(scenario, truth, tel, suite)
