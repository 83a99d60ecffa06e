"""The typed records that pass between rooms: a window of a streamed run, from the
producer's truth and telemetry to what the filters leave of it.

``dynprop run`` streams (``run.stream.windows``): the producer process hands the consumer a
``TruthWindow`` as soon as a window's truth and telemetry exist and a ``TwinWindow``
once the linear twin and its filter are through it; the consumer's stages filter
and smooth the truth window and join the two into a ``Window``, which the tallies
(``run.tally``) and the writers (``files.decimate``, estimate.csv) read.  Every
array is in SI and in the filter's model coordinates unless its name says
otherwise; sample indices are global (from the run's first sample).
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import NamedTuple

import numpy as np
from dynprop.estimator.linear.model import ModelParams


class Measured(NamedTuple):
    """Telemetry in SI as the filter reads it (``bridge.inputs.telemetry_inputs``):
    Earth-sensor roll, ground yaw (NaN where none), wheel speeds (N, n), the yaw's
    a-priori 1σ (or None), the Sun head it came from (NaN where none, or None) and the
    maneuver flag (1 while a thruster fires, 0 otherwise, NaN where a file's flag was
    screened; None without one: a run without events, a file without the column)."""

    roll_rad: np.ndarray
    yaw_rad: np.ndarray
    speeds_radps: np.ndarray
    yaw_sigma_rad: np.ndarray | None
    sun_head: np.ndarray | None
    maneuver: np.ndarray | None = None
    known_Nm: np.ndarray | None = None   # (N, 2) roll, yaw torques known (estimator.known_torques)

    @property
    def readings(self) -> tuple:
        """The five the filters take by position (roll, yaw, speeds, yaw σ, Sun head):
        the maneuver flag goes by name."""
        return tuple(self[:5])

    def cut(self, rows: slice) -> Measured:
        """The same telemetry on ``rows`` only (None stays None)."""
        return Measured(*(None if v is None else v[rows] for v in self))


class Padding(NamedTuple):
    """Samples beside a telemetry file's window that its inputs are derived over:
    their times, telemetry and Earth-sensor pitch (None without one)."""

    t_s: np.ndarray
    measured: Measured
    pitch_rad: np.ndarray | None


@dataclass(frozen=True)
class FilterHistory:
    """What the summary, the figures and the files need of a filter's run over a
    window, once its covariance history is no longer needed: the estimate, 1σ,
    innovations and their variances (model coordinates), the backend that ran it,
    and for a filter beside the paper's the packed covariance on the NEES samples."""

    x: np.ndarray
    sigma: np.ndarray | None
    innovations: np.ndarray
    innovation_var: np.ndarray
    backend: str
    P_nees: np.ndarray | None = None
    # With sensor-bias states or a gate (``run.filtering``): estimate.csv's bias columns
    # at every sample, and the gate's rejections (N, 3).
    bias_columns: dict | None = None
    rejected: np.ndarray | None = None


@dataclass(frozen=True)
class TruthWindow:
    """A window's truth and telemetry, as the producer hands it on: samples
    [start, stop) at times ``t_s``, the telemetry the filter reads (``measured``;
    the Earth sensor's pitch, which the pitch filter and the EKF read), telemetry.csv's
    columns at the output rows, the truth in the model's states and in the pitch
    filter's (θ, θ̇, N_y), the shadow factor and the true 3-1-2 angles (yaw, roll,
    pitch) at the output rows.

    A window of a telemetry file (``run.stream.file_windows``) has no truth (None) and
    no shadow (None), and brings its own padding: ``lead`` and ``trail``, the samples
    before and after it that its inputs are derived over, reaching back and on to a
    sample with every wheel read, so a dropout across the window's edge is bridged as
    in the whole file; off the scenario's grid ``steps`` holds the interval after
    each sample.  With a truth file, its states (``truth_rows`` where it has rows)."""

    index: int
    start: int
    stop: int
    t_s: np.ndarray
    measured: Measured
    pitch_rad: np.ndarray | None
    tel_rows: dict[str, np.ndarray]
    truth_model: np.ndarray | None
    pitch_truth: np.ndarray | None
    shadow: np.ndarray | None
    euler_rows: np.ndarray | None
    steps: np.ndarray | None = field(default=None, kw_only=True)
    lead: Padding | None = field(default=None, kw_only=True)
    trail: Padding | None = field(default=None, kw_only=True)
    # A truth file with rows at only some samples: those (local indices), where the
    # truth arrays are finite (NaN elsewhere); None when every sample has one.
    truth_rows: np.ndarray | None = field(default=None, kw_only=True)


@dataclass(frozen=True)
class TwinWindow:
    """The linear twin over a window: its states (model coordinates), its filter's
    history and that filter's NEES on the window's NEES samples."""

    index: int
    twin_model: np.ndarray
    linear: FilterHistory
    nees_linear: np.ndarray


@dataclass(frozen=True)
class Window(TruthWindow):
    """A window once everything is through it: the truth window, the paper's filter
    on the real telemetry (``real``, with its NEES on the NEES samples), its RTS
    smoothed estimate (None when not smoothed), the filters beside the paper's by
    name (``estimator.filters``), the pitch filter (``run.pitch.PitchHistory``), and
    the linear twin with its filter."""

    params: ModelParams                   # the paper filter's model
    real: FilterHistory
    nees_real: np.ndarray | None
    smoothed_x: np.ndarray | None
    filters: dict[str, FilterHistory]
    pitch: object
    twin_model: np.ndarray | None
    linear: FilterHistory | None
    nees_linear: np.ndarray | None
    smoothed_sigma: np.ndarray | None = field(default=None, kw_only=True)
    pitch_rows: object = field(default=None, kw_only=True)   # at a sparse truth's rows

    @classmethod
    def join(cls, truth: TruthWindow, twin: TwinWindow | None, **estimates) -> Window:
        """The truth window with its estimates and its twin (None: a telemetry
        file's window, which has none)."""
        own = {f.name: getattr(truth, f.name) for f in fields(TruthWindow)}
        return cls(**own, twin_model=None if twin is None else twin.twin_model,
                   linear=None if twin is None else twin.linear,
                   nees_linear=None if twin is None else twin.nees_linear, **estimates)
