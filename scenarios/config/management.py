"""The scenario's ``momentum_management`` section: the loops that keep the momentum
bias along the orbit normal (issue 45; docs/conventions.md, "Momentum management").

Both parts are off by default, so a scenario that does not name them flies what it
always flew.  ``magnetic`` is the torquers' momentum-direction law
(``sim.control``); ``solar`` the daily autonomous solar torque management
(``sim.momentum``), which moves the trim tab and the array offset.
"""

from __future__ import annotations

from typing import Annotated

import numpy as np
from dynprop.sim.momentum import DAY_S, SolarManagement
from pydantic import Field, Strict, model_validator

from .sections import _Section

_LAW = SolarManagement()
_Float = Annotated[float, Strict()]
Range = Annotated[tuple[_Float, _Float], Strict(False)]


class MagneticManagement(_Section):
    enabled: bool = Field(False, description="torquers steer the whole momentum's roll and "
                          "yaw components in the orbit frame to zero, T = −k_d C_BR P H_R, "
                          "on top of unloading h (sim.control)")
    gain_per_s: float = Field(2e-5, gt=0, description="k_d: the orbit-rate pair at "
                              "−k_d ± iω0 (1/s)")


class SolarManagementSection(_Section):
    enabled: bool = Field(False, description="once a period, estimate the mean inertial "
                          "torque from the momentum history and move the trim tab and the "
                          "array offset (sim.momentum)")
    every_days: float = Field(_LAW.period_s / DAY_S, gt=0, description="the loop's "
                              "period T (days)")
    torque_gain: float = Field(_LAW.torque_gain, gt=0, le=1, description="g: the share of "
                               "the torque error corrected each period (-)")
    momentum_time_constant_days: float = Field(
        _LAW.momentum_time_constant_s / DAY_S, gt=0, description="τ: the solar torque "
        "commanded also unloads the momentum, −H/τ (days)")
    tab_limits_deg: Range = Field(_LAW.tab_limits_deg,
                                                  description="trim tab range (deg)")
    offset_limits_deg: Range = Field(_LAW.offset_limits_deg,
                                                     description="array offset range (deg)")

    @model_validator(mode="after")
    def _ranges(self):
        for name in ("tab_limits_deg", "offset_limits_deg"):
            lo, hi = getattr(self, name)
            if not lo < hi:
                raise ValueError(f"{name}: [{lo:g}, {hi:g}] must be increasing")
        return self

    def law(self) -> SolarManagement:
        return SolarManagement(self.every_days * DAY_S, self.torque_gain,
                               self.momentum_time_constant_days * DAY_S,
                               tuple(self.tab_limits_deg), tuple(self.offset_limits_deg))


class MomentumManagement(_Section):
    magnetic: MagneticManagement = Field(default_factory=MagneticManagement)
    solar: SolarManagementSection = Field(default_factory=SolarManagementSection)

    def on(self) -> bool:
        return self.magnetic.enabled or self.solar.enabled

    def summary(self, file: str) -> dict:
        """summary.json's ``momentum_management``: the loops flown, and the file of
        solar management's commands (one row a period)."""
        out: dict = {"magnetic": self.magnetic.model_dump()}
        out["solar"] = self.solar.model_dump() | (
            {"file": file} if self.solar.enabled else {})
        return out


TORQUER_COLUMNS = ("torquer_x_Am2", "torquer_y_Am2", "torquer_z_Am2")


def telemeters_torquers(s) -> bool:
    """Whether telemetry.csv carries the torquers' commanded dipoles: when the filter
    takes them as known, or the torquers manage the momentum's direction (a managed
    spacecraft telemeters its commands).  Never otherwise, so every other run writes
    the columns it always wrote."""
    return ("magnetic_control" in s.estimator.known_torques
            or s.momentum_management.magnetic.enabled)


def torquer_columns(dipole_Am2: np.ndarray) -> dict[str, np.ndarray]:
    return {name: dipole_Am2[:, k] for k, name in enumerate(TORQUER_COLUMNS)}
