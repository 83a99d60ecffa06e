"""The scenario's ``batch`` section: `dynprop batch`'s spans, model, stopping rule and
consider parameters (docs/batch.md, docs/scenario-reference.md)."""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field, field_validator

from .sections import Matrix3, _Section

# The bundled Monte Carlo's mass-property knowledge: 2% on the principal moments of
# GOES-Next, 10 kg m² on the products.
DEFAULT_INERTIA_SIGMA_KGM2 = ((67.0, 10.0, 10.0), (10.0, 19.0, 10.0), (10.0, 10.0, 69.0))


class Consider(_Section):
    """What the batch does not estimate but is uncertain: its σ with and without them
    (the consider covariance, docs/batch.md)."""

    inertia_sigma_kgm2: Matrix3 = Field(
        DEFAULT_INERTIA_SIGMA_KGM2, description="1σ of each entry of the inertia, "
        "symmetric, non-negative (kg m²)")
    wheel_speed_sigma_rpm: float = Field(25.0, ge=0, description="1σ of the wheels' "
                                         "nominal speed, which sets the paper model's H (rpm)")
    cant_sigma_deg: float = Field(0.1, ge=0, description="1σ of the wheels' cant, which "
                                  "scales the tachometers' H and h (deg)")

    @field_validator("inertia_sigma_kgm2")
    @classmethod
    def _symmetric(cls, v):
        a = np.asarray(v, dtype=float)
        if not np.all(np.isfinite(a)) or np.any(a < 0) or not np.allclose(a, a.T):
            raise ValueError("must be symmetric, finite and non-negative")
        return v


class Batch(_Section):
    """`dynprop batch`: batch least squares over spans of the telemetry (docs/batch.md)."""

    span_h: float = Field(24.0, gt=0, description="length of each batch; 24 h covers a "
                          "night's Sun gap and the orbit's once-a-day torque (h)")
    overlap_h: float = Field(0.0, ge=0, description="how far each batch reaches back into "
                             "the previous one's span; their difference there is the "
                             "overlap comparison (h)")
    model: Literal["linear", "nonlinear"] = Field(
        "nonlinear", description="linear: the paper's model, one least-squares solve; "
        "nonlinear: the full gyrostat, Gauss–Newton")
    apriori: Literal["chain", "scenario"] = Field(
        "chain", description="each batch's a priori: chain = the previous solution and "
        "covariance propagated to its epoch (the first takes the filter's prior); "
        "scenario = the filter's prior for every batch")
    max_iterations: int = Field(20, ge=1, description="Gauss–Newton passes before a "
                                "batch is reported unconverged")
    tolerance_sigma: float = Field(0.01, gt=0, description="converged when the "
                                   "Gauss–Newton step is below this fraction of its own σ")
    consider: Consider = Field(default_factory=Consider)
