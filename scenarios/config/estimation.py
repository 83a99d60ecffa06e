"""The scenario's estimation and output sections: the paper filter's tuning and
prior (``estimator``), `dynprop trim`'s batch filter (``trim``) and what `dynprop
run` writes (``output``); docs/scenario-reference.md."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

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


class Estimator(_Section):
    filters: list[Literal["paper", "ekf"]] = Field(
        ["paper"], min_length=1, description="which filters `dynprop run` runs on the same "
        "telemetry: the paper's linear filter (always, first) and optionally the extended "
        "Kalman filter on the full nonlinear model (docs/validation.md §8)")
    process_noise: ProcessNoise = Field(default_factory=ProcessNoise)
    initial_sigma: InitialSigma = Field(default_factory=InitialSigma)
    model_torques: ModelTorques = Field(default_factory=ModelTorques)
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
        3600.0, gt=0, description="Longest telemetry dropout `dynprop estimate` propagates "
        "across (samples missing from its grid of sample_interval_s steps: no update, the "
        "covariance grows); a longer one is rejected with the row where it starts.")


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
