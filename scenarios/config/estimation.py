"""The scenario's estimation and output sections: the paper filter's tuning and
prior (``estimator``), `dynprop trim`'s batch filter (``trim``) and what `dynprop
run` writes (``output``); docs/scenario-reference.md."""

from __future__ import annotations

from typing import Literal

from pydantic import Field, ValidationInfo, field_validator

from ..units import DAY_S
from .sections import _Section


class ProcessNoise(_Section):
    """Spectral densities of Eqs. 34–35 (paper units)."""

    q_x: float = Field(5.4e-7, ge=0, description="roll torque, Eq. 45 ((N m)² s)")
    q_z: float = Field(5.4e-7, ge=0, description="yaw torque, Eq. 45 ((N m)² s)")
    q_w: float = Field(5.0e-10, ge=0, description="wheel ripple on h, 2 sin²c · G/2; the "
                       "paper prints 1.3e-10 (errata 6) ((N m)² s)")
    q_px: float = Field(3e-18, ge=0, description="periodic roll torque random walk; not in "
                        "the paper: ~5e-7 N m per day ((N m)²/s)")
    q_pz: float = Field(3e-18, ge=0, description="periodic yaw torque random walk ((N m)²/s)")
    q_cx: float = Field(3e-18, ge=0, description="constant roll torque random walk ((N m)²/s)")
    q_cz: float = Field(3e-18, ge=0, description="constant yaw torque random walk ((N m)²/s)")
    q_y: float = Field(5.4e-7, ge=0, description="pitch torque, white, for the pitch filter "
                       "(Eq. 3b); not in the paper: q_x's default, and its own key so that "
                       "tuning roll leaves pitch alone ((N m)² s)")
    q_cy: float = Field(3e-18, ge=0, description="pitch torque random walk, for the pitch "
                        "filter; q_cx's default ((N m)²/s)")


class InitialSigma(_Section):
    """The filter's initial 1σ per state (its initial estimate is zero)."""

    roll_deg: float = Field(0.05, gt=0, description="roll (deg)")
    roll_rate_degps: float = Field(1e-3, gt=0, description="roll rate (deg/s)")
    yaw_deg: float = Field(0.5, gt=0, description="yaw (deg)")
    yaw_rate_degps: float = Field(1e-3, gt=0, description="yaw rate (deg/s)")
    h_Nms: float = Field(0.05, gt=0, description="yaw wheel momentum (N m s)")
    N_px_Nm: float = Field(5e-6, gt=0, description="periodic roll torque (N m)")
    N_pz_Nm: float = Field(5e-6, gt=0, description="periodic yaw torque (N m)")
    N_cx_Nm: float = Field(5e-6, gt=0, description="constant roll torque (N m)")
    N_cz_Nm: float = Field(5e-6, gt=0, description="constant yaw torque (N m)")


class ModelTorques(_Section):
    """The modelled environment torques N_x*, N_z* of Eq. 9 (may differ from the truth)."""

    roll_Nm: float = Field(0.0, description="N_x*, constant (N m)")
    yaw_Nm: float = Field(0.0, description="N_z*, constant (N m)")


class BiasState(_Section):
    """One sensor-bias state appended to the paper's nine (not in the paper), so that a
    constant sensor error is estimated rather than taken for attitude: the filter
    measures roll as r + b_roll and a head's ground yaw as y + b_head.  The bias has
    no dynamics of its own (a constant, or a random walk).  Off, the filter is the
    paper's."""

    model: Literal["off", "constant", "random_walk"] = Field(
        "off", description="'off': no state; 'constant': a random constant, what a "
        "misalignment or an offset is; 'random_walk': one that drifts, e.g. with "
        "temperature, at walk_deg_per_sqrt_h")
    sigma_deg: float = Field(0.01, gt=0, description="the filter's prior 1σ of the bias, "
                             "its initial estimate being 0; the size of error the sensor "
                             "may carry (deg)")
    walk_deg_per_sqrt_h: float = Field(
        0.0, ge=0, validate_default=True, description="random-walk density as the 1σ "
        "growth over an hour, σ(t) = walk · √(t/1 h); 0 for 'constant', > 0 for "
        "'random_walk'; the filter's q = (walk · π/180)² / 3600 (rad²/s) (deg/√h)")

    @field_validator("model", mode="before")
    @classmethod
    def _yaml_off(cls, v):
        # YAML 1.1 reads an unquoted `off` as false: `model: off` means "off".
        return "off" if v is False else v

    @field_validator("walk_deg_per_sqrt_h")
    @classmethod
    def _walk_fits_model(cls, v: float, info: ValidationInfo) -> float:
        model = info.data.get("model")
        if model == "random_walk" and v == 0:
            raise ValueError("must be > 0 with model 'random_walk' (or use model 'constant')")
        if model == "constant" and v > 0:
            raise ValueError("must be 0 with model 'constant', which does not walk (or use "
                             "model 'random_walk')")
        return v


class CassBiasState(BiasState):
    """A CASS head's ground-yaw bias, yaw = y + b_head while that head gives the yaw: as
    the DSS's, with a wider prior (0.05°), since a coarse head's errors are larger.  A
    CASS angle bias moves the ground yaw by an amount that varies with the Sun's
    place in the head's field of view and with the season, so a constant (or slowly
    walking) state only approximates it."""

    sigma_deg: float = Field(0.05, gt=0, description="the filter's prior 1σ of the bias, "
                             "its initial estimate being 0 (deg)")


class BiasStates(_Section):
    """Sensor-bias states appended to the paper's nine states, in this order, each off
    by default: the Earth sensor's roll bias (roll = r + b_roll) and one ground-yaw
    bias per Sun-sensor head (yaw = y + b_head while that head gives the yaw).
    `dynprop observability --biases all` shows which of them the measurements can
    separate from the attitude (docs/validation.md)."""

    earth_roll: BiasState = Field(default_factory=BiasState)
    dss_yaw: BiasState = Field(default_factory=BiasState)
    cass1_yaw: CassBiasState = Field(default_factory=CassBiasState)
    cass2_yaw: CassBiasState = Field(default_factory=CassBiasState)

    def on(self) -> tuple[str, ...]:
        """The names of the states that are not 'off', in order."""
        return tuple(name for name in type(self).model_fields
                     if getattr(self, name).model != "off")


class ManeuverResponse(_Section):
    """What the filters do while the telemetry's ``maneuver`` flag is set (a thruster
    firing, which the filter's model does not know), used only when the telemetry
    has that column: ``inflate`` adds a white roll and yaw torque of intensity
    torque_Nm² · max_duration_s on every flagged step, so that the rate variance it
    adds over a flagged stretch no longer than max_duration_s covers the impulse
    (torque_Nm · duration)²; ``reset`` returns the attitude and rate states'
    covariance to the initial prior (``initial_sigma``) at the first sample after a
    flagged stretch, the estimate kept; ``ignore`` does nothing (docs/validation.md
    shows what follows).  The pitch filter does not respond (the Earth sensor
    measures pitch at every sample)."""

    response: Literal["inflate", "reset", "ignore"] = Field(
        "inflate", description="'inflate': more process noise while the flag is set; "
        "'reset': the attitude and rate covariance back to the prior after it; 'ignore': "
        "the flag is read and not used")
    torque_Nm: float = Field(0.01, gt=0, description="the largest roll or yaw thruster "
                             "torque expected (N m)")
    max_duration_s: float = Field(600.0, gt=0, description="the longest flagged stretch "
                                  "the inflated noise covers (s)")


class Estimator(_Section):
    filters: list[Literal["paper", "ekf"]] = Field(
        ["paper"], min_length=1, description="which filters `dynprop run` runs on the same "
        "telemetry: the paper's linear filter (always, first) and optionally the extended "
        "Kalman filter on the full nonlinear model (docs/validation.md §8)")
    process_noise: ProcessNoise = Field(default_factory=ProcessNoise)
    initial_sigma: InitialSigma = Field(default_factory=InitialSigma)
    model_torques: ModelTorques = Field(default_factory=ModelTorques)
    known_torques: list[Literal["magnetic_control"]] = Field(
        [], description="torques the ground knows per sample and the filter takes as "
        "modelled N_x*, N_z* (Eq. 9) beside model_torques: 'magnetic_control', the "
        "torquers' commanded dipoles (telemetry.csv's torquer_{x,y,z}_Am2) crossed with "
        "the field model at Earth pointing; `dynprop run` and `montecarlo` only")
    wheel_torque_window_s: float = Field(20.0, gt=0, le=600, description="Savitzky–Golay "
                                         "window for N_w* = ḣ from the tachometers (s)")
    sun_gap_min_h: float = Field(4.0, gt=0, description="a yaw outage at least this long "
                                 "counts as a Sun gap in the summary (h)")
    dss_error_correlation_s: float = Field(
        600.0, gt=0, description="how long the DSS yaw error stays correlated: its "
        "quantisation share of the yaw variance counts once per this time; measured "
        "autocorrelation 0.5 at 8.5 min, because the out-of-plane angle that sets yaw "
        "moves slowly (s)")
    max_gap_s: float = Field(
        3600.0, gt=0, description="Telemetry gap from which `dynprop estimate` warns (s): "
        "a gap of any length is propagated across (no update, the covariance grows with "
        "the process noise); one longer than this is listed in summary.json's telemetry "
        "and warnings.")
    bias_states: BiasStates = Field(default_factory=BiasStates)
    maneuver: ManeuverResponse = Field(default_factory=ManeuverResponse)
    outlier_gate_chi2: float | None = Field(
        None, gt=0, description="per-measurement innovation gate: a roll, yaw or h whose "
        "ν²/S exceeds it (χ² with 1 degree of freedom) is rejected, so that one outlier "
        "cannot pull the slow torque and bias states; 25 is 5σ, and below 9 (3σ) good "
        "measurements are rejected too often; null: no gating, the paper's filter (-)")


QUARTER_ORBIT_S = 21541.0   # the correlation time of Eq. 45


class Trim(_Section):
    """How `dynprop trim` estimates the solar imbalance κ (docs/trim.md).  Its batch
    filter is the paper's, with the known magnetic torques as modelled torques and
    a process noise for what is left once the tab is near trim: Eq. 45's recipe
    (mean-square torque error × a quarter-orbit correlation time) with this
    torque error, and no random walk of the torque states (κ does not change)."""

    torque_error_Nm: float = Field(
        2e-7, gt=0, description="unmodelled roll and yaw torque left after the known "
        "ones (gravity gradient as the attitude moves, residual-dipole changes); Eq. 45 "
        "takes 5e-6 for an untrimmed spacecraft, an upper limit meant for yaw (N m)")
    correlation_time_s: float = Field(QUARTER_ORBIT_S, gt=0, description="its correlation "
                                      "time; Eq. 45's quarter orbit (s)")
    every_days: int | None = Field(
        None, ge=1, description="`dynprop run` only: close the loop, estimating κ from "
        "each such span of the run's own telemetry and moving the tab as `dynprop trim` "
        "recommends from the next sample on (trim_loop.csv); null flies the tab fixed (days)")


DEFAULT_OUTPUT_INTERVAL_S = 64.0   # 125 samples of 0.512 s
TELEMETRY_AUTO_MAX_S = 2 * DAY_S


class Output(_Section):
    """What `dynprop run` writes, as Basilisk recorders' sampling time, 42's DTOUT or
    S2E's log period set it.  The rows of truth.csv, estimate.csv and comparison.npz
    are the samples every ``interval_s`` (each the value at that sample, not an
    average); every figure in summary.json and daily.csv is accumulated at the full
    sample rate, and the figures draw a min/max envelope per output interval, so
    the decimation hides no peak.  Full-rate telemetry is ~14 MB per simulated day
    as CSV (5 GB a year), which is why ``auto`` writes it only for short runs."""

    interval_s: float | None = Field(
        None, gt=0, description="spacing of the rows of truth.csv, estimate.csv and "
        "comparison.npz: a whole multiple of sample_interval_s; null (the default) takes "
        f"the multiple nearest {DEFAULT_OUTPUT_INTERVAL_S:g} s "
        f"({DEFAULT_OUTPUT_INTERVAL_S:g} s at 0.512 s); sample_interval_s writes every "
        "sample (s)")
    telemetry: Literal["auto", True, False] = Field(
        "auto", description="telemetry.csv at every sample: true, false, or auto = "
        f"written when duration_s is at most {TELEMETRY_AUTO_MAX_S:g} s (two days); "
        "`dynprop estimate` needs it")
