"""A run as whole arrays: truth → telemetry → the paper's filter and smoother, and
the linear twin (``bridge.twin``) with the same filter.

`dynprop estimate`, a Monte Carlo case and the linearization report hold a run's
arrays whole; `dynprop run` streams the same computation in windows (``stream``),
and for a run of one window every array is the one computed here, bit for bit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from dynprop.estimator.kalman.filter import FilterResult, SmootherResult
from dynprop.estimator.linear import model as em
from dynprop.estimator.linear.transition import discretize

from ..bridge.coordinates import model_truth, pitch_truth, truth_torques
from ..bridge.inputs import filter_inputs, initial_prior, known_torques, telemetry_inputs
from ..bridge.twin import linear_twin, measured
from ..config import build
from ..config.schema import Scenario
from ..files.comparison import ComparisonInputs, PitchRows
from ..samples import nees_rows
from ..units import DEG
from .filtering import design_of, paper_filter, paper_smoother
from .pitch import PitchHistory, run_pitch
from .simulate import Simulation, simulate


@dataclass(frozen=True)
class TwoRuns:
    """Everything a run directory is made of.  With ``rows`` the filter histories
    (``real``, ``linear``) hold only those samples; the truth arrays are always full."""

    sim: Simulation | None
    twin_telemetry: object | None
    params: em.ModelParams
    truth_model: np.ndarray | None  # nonlinear truth in the filter's model coordinates (N, 9)
    twin_model: np.ndarray | None   # linear twin's states, same coordinates (N, 9)
    real: FilterResult
    linear: FilterResult | None
    smoothed: SmootherResult | None
    yaw_factors: np.ndarray
    rows: np.ndarray | None = None
    true_euler_rad: np.ndarray | None = None   # (N, 3) yaw, roll, pitch, when known
    # The pitch filter (``run.pitch``; every sample) and the truth in its states.
    pitch: PitchHistory | None = None
    pitch_truth: np.ndarray | None = None

    def comparison_inputs(self, filters: dict) -> ComparisonInputs:
        """What comparison.npz is drawn from, every sample; ``filters`` are the
        filters beside the paper's, by name."""
        euler = self.true_euler_rad
        if euler is None and self.sim is not None:
            euler = self.sim.truth.euler_rad
        return ComparisonInputs(
            self.params.omega_n_radps, self.real, self.truth_model,
            None if self.smoothed is None else self.smoothed.x,
            None if self.linear is None else self.linear.x, self.twin_model, euler, filters,
            self.pitch_rows(slice(None)))

    def pitch_rows(self, rows) -> PitchRows | None:
        """The pitch filter at ``rows`` of every sample (its NEES, on the NEES samples,
        at those of ``rows``: ``comparison_arrays``'s ``nees_data`` indices)."""
        p = self.pitch
        if p is None:
            return None
        truth = None if self.pitch_truth is None else self.pitch_truth[rows]
        return PitchRows(p.x[rows], p.sigma[rows], p.innovations[rows],
                         p.innovation_var[rows], truth, p.nees)


def pitch_history(s: Scenario, pitch_rad, speeds, truth: np.ndarray | None, t_s=None
                  ) -> PitchHistory:
    """The pitch filter over a whole record and its NEES on the NEES samples against
    ``truth`` (its states at every sample, or None)."""
    r = run_pitch(s, pitch_rad, speeds, t_s)
    return PitchHistory.of(r, truth, nees_rows(0, len(r.x)), keep_P=True)


def filter_telemetry(s: Scenario, params, disc, roll, yaw, speeds, yaw_sigma=None,
                     sun_head=None, maneuver=None, known_Nm=None, rows=None, t_s=None
                     ) -> tuple[FilterResult, dict]:
    """Preprocess telemetry arrays and run the filter; returns the result (the
    history only at ``rows`` if given) and what the smoother needs besides it
    (``filtering.paper_smoother(design, result, disc, **that)``: the inputs u and any
    dropout noise, with the response to a ``maneuver`` flag).
    ``t_s``: the samples' own times when they are off the scenario's grid (``disc``
    then a ``StepTable``)."""
    meas, u, extra = filter_inputs(s, params, roll, yaw, speeds, yaw_sigma, sun_head,
                                   maneuver, known_Nm, t_s=t_s)
    x0, P0 = initial_prior(s, params)
    design = design_of(s)
    result = paper_filter(design, meas, disc, x0, P0, u, extra, sun_head, rows=rows)
    return result, {"u": u, "extra": extra}


def run_scenario(s: Scenario, sim: Simulation | None = None,
                 telemetry_columns: dict[str, np.ndarray] | None = None, run: int = 0,
                 smooth: bool = True, truth_scenario: Scenario | None = None,
                 rows=None, twin: bool = True) -> TwoRuns:
    """Both runs.  ``telemetry_columns`` (telemetry.csv read back) makes the real
    filter see exactly the file's values, so that ``dynprop estimate`` on that file
    reproduces the estimates bit for bit.  ``smooth=False`` skips the smoother
    (``smoothed`` is None) for analyses that need only the filters.

    ``truth_scenario`` (default ``s``) is the spacecraft that flies: a Monte Carlo
    case's dispersed scenario.  The filter is always designed from ``s``, the
    nominal one, as it would be in flight; the linear twin is the paper's model of
    the spacecraft that flies.  ``rows`` keeps only those samples of the filter
    histories (no smoother); ``twin=False`` skips the linear twin."""
    truth_scenario = truth_scenario or s
    if smooth and rows is not None:
        raise ValueError("the smoother needs the full filter history (rows=None)")
    sim = sim or simulate(truth_scenario, run)
    truth, tel, dt = sim.truth, sim.telemetry, s.sample_interval_s
    params, noise = build.estimator_model(s)
    disc = discretize(params, noise, dt)
    mt = s.estimator.model_torques
    if telemetry_columns is None:
        seen = measured(tel, known_torques(s, truth.torquer_dipole_Am2))
    else:
        seen = telemetry_inputs(s, telemetry_columns)
    tt = truth_torques(truth, mt, params.omega0_radps, seen.known_Nm)
    truth_model = model_truth(params, truth, tt)

    real, smoother_args = filter_telemetry(s, params, disc, *seen, rows=rows)
    twin_model = twin_tel = linear = None
    if twin:
        twin_model, twin_tel, twin_params = linear_twin(truth_scenario, truth, run, mt, tt)
        if twin_params != params:
            # The twin's rate states are ṙ/ω_n of its own spacecraft; the filter's use
            # the nominal ω_n.
            twin_model = twin_model.copy()
            twin_model[:, [1, 3]] *= twin_params.omega_n_radps / params.omega_n_radps
        linear, _ = filter_telemetry(s, params, disc, *measured(twin_tel, seen.known_Nm),
                                     rows=rows)
    smoothed = paper_smoother(design_of(s), real, disc, **smoother_args) if smooth else None
    pitch = tel.pitch_rad if telemetry_columns is None else telemetry_columns["pitch_deg"] * DEG
    p_truth = pitch_truth(truth, tt)
    return TwoRuns(sim, twin_tel, params, truth_model, twin_model, real, linear, smoothed,
                   build.yaw_factors(s), None if rows is None else np.asarray(rows),
                   pitch=pitch_history(s, pitch, seen.speeds_radps, p_truth),
                   pitch_truth=p_truth)
