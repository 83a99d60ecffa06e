"""The scenario's inputs to Section 6's covariance analysis (`dynprop covariance`):
the paper's model and noise, the sensor numbers, and the weight the run's filter
gives a DSS yaw (``inputs.yaw_correlation_inflation``), so that the analysis
assumes the yaw measurement a run of the same scenario uses."""

from __future__ import annotations

import numpy as np
from dynprop.estimator.analysis.covariance_report import covariance_report

from ..config import build
from ..config.schema import Scenario
from .inputs import yaw_correlation_inflation

DSS_HEAD = 0.0   # telemetry's sun_head index of sensors.sun.dss


def dss_yaw_weighting(s: Scenario) -> dict:
    """``covariance_report``'s yaw keywords for scenario ``s``: a DSS yaw weighed as a
    run weighs it (the head that sees the Sun last before the gap, which sets the
    gap-end σ)."""
    return {"yaw_inflation": float(yaw_correlation_inflation(s, np.array([DSS_HEAD]))[0]),
            "yaw_correlation_s": s.estimator.dss_error_correlation_s}


def scenario_covariance_report(s: Scenario) -> dict:
    """``covariance_report`` of scenario ``s``, its yaw weighed as a run weighs it."""
    params, noise = build.estimator_model(s)
    return covariance_report(params, noise, build.estimator_sensor_specs(s),
                             **dss_yaw_weighting(s))
