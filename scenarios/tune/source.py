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
from dynprop.estimator.tuning.intervals import intervals
from dynprop.estimator.tuning.likelihood import PASS_BLOCK
from dynprop.estimator.tuning.samples import ArraySamples

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
LAG_SPAN = 1 << 19         # samples per autocorrelation piece: a 3-day file is one


class TuneError(ValueError):
    """Telemetry or options `dynprop tune` cannot work with: one line per problem, exit 2."""


@dataclass(frozen=True)
class TuneSource:
    """The telemetry as the filter reads it, with its scenario: on the scenario's grid
    (``regular``, a row per step, NaN where missing) or each sample at its own time
    ``t_s``, stepping over its own interval (``estimator.linear.steps``).  Held whole:
    the reference `dynprop tune`'s streamed source (``streamed.StreamedSource``, the
    same interface) is held to, and the arrays the tests' own filter runs read."""

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
    block: int = PASS_BLOCK           # samples per block of a likelihood pass
    span: int = LAG_SPAN              # samples per piece of the autocorrelation

    @property
    def n(self) -> int:
        return len(self.t_s)

    @property
    def t_first(self) -> float:
        return float(self.t_s[0])

    @property
    def t_last(self) -> float:
        return float(self.t_s[-1])

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
        """``sun_gap_s`` of this telemetry's yaw."""
        return sun_gap_s(self.scenario, np.isfinite(self.meas.yaw_rad),
                         None if self.regular else self.t_s, self.cadence_s)

    def gap_s(self) -> float:
        """``measured_gap_s``, or the paper's 8 h for telemetry without a whole gap."""
        measured = self.measured_gap_s()
        return PAPER_GAP_S if measured is None else measured

    def updates(self) -> dict:
        """The present updates of each measurement kind."""
        return {k: int(np.isfinite(v).sum()) for k, v in
                (("roll", self.meas.roll_rad), ("yaw", self.meas.yaw_rad),
                 ("h", self.meas.h_Nms))}

    def roll_variance(self) -> float:
        """The Earth sensor's roll variance the filter is given (the median per sample)."""
        return float(np.median(np.broadcast_to(self.meas.var_roll, self.t_s.shape)))

    def samples(self, every: int = 1) -> ArraySamples:
        """The likelihood's samples: every one, or every ``every``-th with the filter
        stepping ``every`` samples at a time, the inputs ū held over a step the mean
        of its samples' (Eq. 31), a bridged dropout's noise density its mean; off the
        grid each step spans its own interval (to the ``every``-th sample after)."""
        meas, u, e = self.meas, self.u, self.bridge_noise
        if every > 1:
            n = len(meas.roll_rad)
            pad = (-n) % every

            def mean(a):
                a = np.concatenate([a, np.repeat(a[-1:], pad, axis=0)])
                return a.reshape(-1, every, *a.shape[1:]).mean(axis=1)
            meas = type(meas)(*(np.asarray(v)[::every] if np.ndim(v) else v for v in
                                (meas.roll_rad, meas.yaw_rad, meas.h_Nms, meas.var_roll,
                                 meas.var_yaw, meas.var_h)))
            u, e = mean(u), None if e is None else mean(e)
        return ArraySamples(meas, u, e, None if self.regular else
                            intervals(self.t_s[::every]))

    def times(self, start: int, stop: int) -> np.ndarray:
        return self.t_s[start:stop]


def sun_gap_s(s: Scenario, yaw_present: np.ndarray, t_s: np.ndarray | None,
              cadence_s: float) -> float | None:
    """The mean length of the Sun gaps the telemetry shows (yaw outages of at least
    ``estimator.sun_gap_min_h``, both ends inside it), or None: on the grid (``t_s``
    None) in steps, else in time, last yaw before to first after, less a step."""
    from ..samples import sun_gaps, sun_gaps_at
    min_h = s.estimator.sun_gap_min_h
    if t_s is None:
        dt = s.sample_interval_s
        n = len(yaw_present)
        lengths = [(b - a) * dt for a, b in sun_gaps(yaw_present, dt, min_h) if 0 < a and b < n]
    else:
        lengths = [t_s[b] - t_s[a - 1] - cadence_s for a, b in
                   sun_gaps_at(yaw_present, t_s, min_h) if 0 < a and b < len(t_s)]
    return float(np.mean(lengths)) if lengths else None


def _run_telemetry(run_dir: Path) -> Path:
    found = run_telemetry(run_dir)
    if found is not None:
        return found
    raise TuneError(f"{run_dir}: no telemetry.csv to tune on (a run longer than 2 days "
                    "writes it only with output.telemetry: true: rerun with --set "
                    "output.telemetry=true)")


def locate(source: Path, scenario: str | Path | None = None, overrides: list[str] = ()
           ) -> tuple[Path | None, Path, Scenario]:
    """The run directory (or None), the telemetry file and the scenario of ``source``,
    a run directory or a telemetry file with its scenario."""
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
    return run_dir, path, s


def read_source(source: Path, scenario: str | Path | None = None,
                overrides: list[str] = ()) -> TuneSource:
    """The telemetry of a run directory, or a telemetry file with its scenario, whole."""
    from ..run.estimate import estimate_inputs
    run_dir, path, s = locate(source, scenario, overrides)
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
    if not src.updates()["yaw"]:
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
