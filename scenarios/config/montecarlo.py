"""The scenario's ``montecarlo`` section: which keys are dispersed and how.

Each dispersion names a scenario key by its dotted path and gives a distribution
whose parameters are *offsets from the nominal value*, in the key's own unit:

    montecarlo:
      dispersions:
        spacecraft.inertia_kgm2:
          {distribution: normal, sigma: [[67, 10, 10], [10, 19, 10], [10, 10, 69]]}
        initial_state.yaw_deg: {distribution: normal, sigma: 0.5}
        epoch_utc: {distribution: uniform, low: -10, high: 10}     # whole days
        events.0.time_s: {distribution: normal, sigma: 600}         # the first event's

A list's entries are addressed by their index (``events.0.torque_Nm``).

Parameters are a number (every component gets it) or have the key's shape.
3×3 keys (the inertia tensor) are drawn symmetric: the upper triangle is drawn and
mirrored, so their parameters must be symmetric too.  ``epoch_utc`` offsets are in
days and rounded to whole days, so that the time of day, and with it the Sun-gap
timing, is the same in every case and the ensemble stays aligned in time.  The
estimator is designed from the nominal scenario, so ``estimator.*`` keys are not
dispersed; nor are the run's length and step, which set the common time grid.
"""

from __future__ import annotations

from typing import Annotated, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, Strict, field_validator, model_validator

_Float = Annotated[float, Strict()]
_Vec3 = Annotated[tuple[_Float, _Float, _Float], Strict(False)]
_Matrix3 = Annotated[tuple[_Vec3, _Vec3, _Vec3], Strict(False)]
Param = _Float | _Vec3 | _Matrix3

# Keys that are not physical inputs of the truth, or that every case must share.
FIXED_KEYS = ("name", "description", "dynprop_version", "seed", "duration_s",
              "sample_interval_s")
FIXED_SECTIONS = ("estimator", "montecarlo")


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False, frozen=True)


class Normal(_Section):
    """Gaussian: nominal + mean + sigma · N(0, 1), per component."""

    distribution: Literal["normal"] = Field(description="the distribution's tag")
    sigma: Param = Field(description="standard deviation, not negative (the key's unit; "
                         "days for epoch_utc)")
    mean: Param = Field(0.0, description="offset of the mean from the nominal value (the "
                        "key's unit; days for epoch_utc)")

    @field_validator("sigma")
    @classmethod
    def _non_negative(cls, v):
        if np.any(np.asarray(v) < 0):
            raise ValueError("must not be negative")
        return v


class Uniform(_Section):
    """Uniform: nominal + U(low, high), per component."""

    distribution: Literal["uniform"] = Field(description="the distribution's tag")
    low: Param = Field(description="lowest offset from the nominal value (the key's unit; "
                       "days for epoch_utc)")
    high: Param = Field(description="highest offset from the nominal value, not below low "
                        "(the key's unit; days for epoch_utc)")

    @model_validator(mode="after")
    def _check(self):
        lo, hi = np.broadcast_arrays(np.asarray(self.low), np.asarray(self.high))
        if np.any(lo > hi):
            raise ValueError("low must not exceed high")
        return self


Dispersion = Annotated[Normal | Uniform, Field(discriminator="distribution")]
DISTRIBUTION_TAGS = ("normal", "uniform")


class MonteCarlo(_Section):
    """Dispersions and ensemble settings for `dynprop montecarlo`; `dynprop run` ignores
    them except with `--montecarlo-case K`."""

    dispersions: dict[str, Dispersion] = Field(
        default_factory=dict, description="dotted scenario key → {distribution: normal, "
        "sigma, mean} or {distribution: uniform, low, high}; offsets from the nominal "
        "value in the key's unit (epoch_utc: whole days); 3×3 keys drawn symmetric")
    grid_s: float = Field(60.0, gt=0, description="spacing of the common time grid on which "
                          "each case's errors, σ and NEES are kept (s)")
    converged_after_h: float = Field(6.0, ge=0, description="the ensemble NEES test counts "
                                     "from this time on (h)")
    linear_twin: bool = Field(False, description="also run the filter on the linear twin's "
                              "telemetry in every case, for the linearized errors; about 1.8× "
                              "the time per case")


def parameter_shape(value) -> tuple[int, ...]:
    return np.shape(np.asarray(value, dtype=float))


def check_dispersion(key: str, nominal, d: Normal | Uniform) -> None:
    """Raise ValueError (message starting with the key path) if ``d`` cannot disperse
    a key whose nominal value is ``nominal``."""
    where = f"montecarlo.dispersions.{key}"
    head = key.split(".")[0]
    if key in FIXED_KEYS or head in FIXED_SECTIONS:
        raise ValueError(f"{where}: cannot be dispersed (the filter is designed from the "
                         "nominal scenario, and every case shares name, seed, length and step)")
    params = (d.sigma, d.mean) if isinstance(d, Normal) else (d.low, d.high)
    if key == "epoch_utc":
        if any(parameter_shape(p) != () for p in params):
            raise ValueError(f"{where}: epoch offsets are one number of days")
        return
    if isinstance(nominal, bool) or not isinstance(nominal, int | float | tuple):
        raise ValueError(f"{where}: not a numeric key ({type(nominal).__name__} value)")
    shape = parameter_shape(nominal)
    for p in params:
        ps = parameter_shape(p)
        if ps not in ((), shape):
            raise ValueError(f"{where}: parameter shape {list(ps)} does not match the key's "
                             f"{list(shape) or 'number'}")
        if len(shape) == 2 and ps and not np.array_equal(np.asarray(p), np.asarray(p).T):
            raise ValueError(f"{where}: 3×3 dispersions are drawn symmetric, so their "
                             "parameters must be symmetric")
