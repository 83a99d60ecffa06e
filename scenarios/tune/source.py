"""The telemetry `dynprop tune` fits: a run directory's (its telemetry.csv, or the
file a `dynprop estimate` directory names) or a telemetry file with ``--scenario``,
on the filter's grid or off it (jittered tags, another cadence, gaps: each sample at
its own time, as `dynprop estimate` reads it), turned into exactly what
`dynprop estimate`'s filter reads (``bridge.inputs``); and why it may be too little
to tune on."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from dynprop.estimator.kalman.filter import Measurements
from dynprop.estimator.linear.model import ModelParams, ProcessNoise

from ..bridge.inputs import initial_prior, prepared_inputs, telemetry_inputs
from ..config import build
from ..config.estimation import QUARTER_ORBIT_S
from ..config.loader import load_scenario
from ..config.schema import Scenario
from ..files.rundir import RunDirError
from ..files.telemetry_file import run_telemetry
from ..units import DAY_S

ORBIT_S = 86164.0905
PAPER_GAP_S = 8 * 3600.0   # Section 5: "one-third of an orbit, or 8 hours"


class TuneError(ValueError):
    """Telemetry or options `dynprop tune` cannot work with: one line per problem, exit 2."""


@dataclass(frozen=True)
class TuneSource:
    """The telemetry as the filter reads it, with its scenario: on the scenario's grid
    (``regular``, a row per step, NaN where missing) or each sample at its own time
    ``t_s``, stepping over its own interval (``estimator.linear.steps``)."""

    scenario: Scenario
    telemetry: Path
    run_dir: Path | None
    t_s: np.ndarray
    meas: Measurements
    u: np.ndarray
    bridge_noise: np.ndarray | None   # a dropout's measured q_w per step (``prepare``)
    x0: np.ndarray
    P0: np.ndarray
    params: ModelParams
    noise: ProcessNoise
    stats: dict
    regular: bool = True

    @property
    def span_s(self) -> float:
        return float(self.t_s[-1] - self.t_s[0])

    @property
    def cadence_s(self) -> float:
        """The step between samples: the scenario's on its grid, else the median."""
        if self.regular:
            return self.scenario.sample_interval_s
        return float(np.median(np.diff(self.t_s)))

    def measured_gap_s(self) -> float | None:
        """The mean length of the Sun gaps the telemetry shows (yaw outages of at
        least ``estimator.sun_gap_min_h``, both ends inside it), or None."""
        from ..samples import sun_gaps, sun_gaps_at
        present, min_h = np.isfinite(self.meas.yaw_rad), self.scenario.estimator.sun_gap_min_h
        if self.regular:
            dt = self.scenario.sample_interval_s
            gaps = sun_gaps(present, dt, min_h)
            lengths = [(b - a) * dt for a, b in gaps if 0 < a and b < len(self.t_s)]
        else:   # the same length measured in time: last yaw before to first after, less a step
            t, step = self.t_s, self.cadence_s
            lengths = [t[b] - t[a - 1] - step for a, b in sun_gaps_at(present, t, min_h)
                       if 0 < a and b < len(t)]
        return float(np.mean(lengths)) if lengths else None

    def gap_s(self) -> float:
        """``measured_gap_s``, or the paper's 8 h for telemetry without a whole gap."""
        measured = self.measured_gap_s()
        return PAPER_GAP_S if measured is None else measured


def _run_telemetry(run_dir: Path) -> Path:
    found = run_telemetry(run_dir)
    if found is not None:
        return found
    raise TuneError(f"{run_dir}: no telemetry.csv to tune on (a run longer than 2 days "
                    "writes it only with output.telemetry: true: rerun with --set "
                    "output.telemetry=true)")


def read_source(source: Path, scenario: str | Path | None = None,
                overrides: list[str] = ()) -> TuneSource:
    """The telemetry of a run directory, or a telemetry file with its scenario."""
    from ..run.estimate import estimate_inputs
    source = Path(source)
    if source.is_dir():
        if not (source / "scenario.yaml").is_file():
            raise TuneError(f"{source}: not a run directory (no scenario.yaml)")
        run_dir, path = source, _run_telemetry(source)
        s = load_scenario(scenario or source / "scenario.yaml", list(overrides))
    else:
        if scenario is None:
            raise TuneError(f"{source}: a telemetry file needs --scenario (the spacecraft "
                            "and sensors it came from)")
        if not source.is_file():
            raise RunDirError(f"{source}: no such telemetry file or run directory")
        run_dir, path = None, source
        s = load_scenario(scenario, list(overrides))
    grid, _ = estimate_inputs(s, path)
    cols = grid.columns
    params, noise = build.estimator_model(s)
    # Off the grid, as `dynprop estimate`'s filter: N_w* and a dropout's noise per step.
    inputs = prepared_inputs(s, params, *telemetry_inputs(s, cols),
                             t_s=None if grid.regular else cols["t_s"])
    x0, P0 = initial_prior(s, params)
    return TuneSource(s, path, run_dir, cols["t_s"], inputs.measurements, inputs.u,
                      inputs.wheel_noise, x0, P0, params, noise,
                      grid.stats(s.sample_interval_s), grid.regular)


def source_problems(src: TuneSource, tuned: tuple[str, ...]) -> list[str]:
    """Why this telemetry is too little for these parameters (one line each)."""
    problems = []
    name = src.telemetry
    span_h = src.span_s / 3600
    if not np.isfinite(src.meas.yaw_rad).any():
        problems.append(f"{name}: no Sun-sensor yaw at all: without yaw the constant yaw "
                        "torque and yaw itself are unobservable (Section 4), and the "
                        "likelihood cannot tell the yaw noise from them")
    if src.span_s < QUARTER_ORBIT_S:
        problems.append(f"{name}: spans {span_h:.2f} h, shorter than a quarter orbit "
                        f"({QUARTER_ORBIT_S / 3600:.2f} h), the filter's memory for yaw "
                        "(Eq. 45): too short to tune on")
    walks = [k for k in tuned if k in ("q_px", "q_pz", "q_cx", "q_cz")]
    if walks and QUARTER_ORBIT_S <= src.span_s < ORBIT_S:
        problems.append(f"{name}: spans {span_h:.2f} h; the torque random walks "
                        f"({', '.join(walks)}) need at least one orbit "
                        f"({ORBIT_S / 3600:.2f} h) of telemetry to tell a wandering torque "
                        "from the orbit-rate one: leave them out (--params q_x,q_z,q_w)")
    return problems


__all__ = ["DAY_S", "TuneError", "TuneSource", "read_source", "source_problems"]
