"""The scenario's ``telemetry.screen`` section: what a telemetry value may be before
the filter sees it (``files.screen``, docs/telemetry.md "What dynprop does with bad
values").

Every limit defaults to null, which derives it from the spacecraft and its sensors, so
a scenario that changes the wheels or the sensors screens by its own numbers.
"""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field

# The Earth sensor's range when the scenario does not give one: GOES-class horizon
# sensors read a few degrees to ±15° about nadir; the simulator's own reads any angle,
# and the paper's filter was found to work only up to 3° (validation §4).
EARTH_RANGE_DEG = 15.0
# A wheel's speed limit when not given, as a multiple of the nominal speed.  Momentum
# management moves a bias wheel's speed by a few per cent; the simulator has no speed
# limit, and its loops swing large_offset's wheels from −0.5 to 2.5 × nominal while
# they take 4° of yaw out through a 1.656° cant.
WHEEL_SPEED_FACTOR = 3.0
# A bound on a momentum wheel's motor torque.  The simulator has no motor limit, and its
# loops command up to 1.3 N m to take large_offset's 3° out; the motors of GOES-class
# wheels deliver well under that.  Above it, a change of speed is not the wheel's.
WHEEL_TORQUE_MAX_NM = 2.0
# The allowance of noise and quantisation in a jump test, in the reading's σ and its
# quantum: 20σ, the simulator's default outlier, is left to the χ² gate, not screened.
JUMP_NOISE_SIGMAS = 25.0
JUMP_QUANTA = 2.0
# Samples on each side of a reading in the jump test's running median.
HALF_WINDOW = 2


class TelemetryScreen(BaseModel):
    """Which telemetry values are physically impossible for this spacecraft and become
    a dropout of their sensor (docs/telemetry.md)."""

    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False, frozen=True)

    enabled: bool = Field(True, description="screen every value before the filter; false "
                          "passes the file as it is")
    earth_range_deg: float = Field(EARTH_RANGE_DEG, gt=0, le=90,
                                   description="the Earth sensor's range: a roll or pitch "
                                   "reading beyond ± this is screened (deg)")
    wheel_speed_max_rpm: float | None = Field(
        None, gt=0, description="a tachometer reading beyond ± this is screened; null: "
        f"{WHEEL_SPEED_FACTOR:g} × |spacecraft.wheels.speed_rpm| (rpm)")
    wheel_torque_max_Nm: float = Field(
        WHEEL_TORQUE_MAX_NM, gt=0, description="the largest motor torque: a tachometer "
        "reading further from its neighbours' running median than this torque, the "
        f"tachometer's quantum and {JUMP_NOISE_SIGMAS:g}σ of its noise allow is screened (N m)")
    attitude_rate_max_degps: float | None = Field(
        None, gt=0, description="the fastest the attitude can move: a roll or pitch reading "
        "further from its neighbours' running median than this rate, the Earth sensor's "
        f"quantum and {JUMP_NOISE_SIGMAS:g}σ of its noise allow is screened; null: the "
        "nutation frequency |H|/√(I_x I_z) times earth_range_deg, the fastest a "
        "momentum-biased body swings inside the sensor's range (deg/s)")
