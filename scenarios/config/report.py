"""The scenario's ``report`` section: what `dynprop report` judges the run against
(docs/report.md)."""

from __future__ import annotations

from pydantic import Field

from .sections import _Section


class Report(_Section):
    """`dynprop report`: the review page's requirement line."""

    yaw_requirement_deg: float | None = Field(
        None, gt=0, description="the yaw knowledge requirement the page judges the run "
        "against: a 3σ bound over 24 h (three times each day's RMS yaw error, and every "
        "Sun-gap-end error, within it), as GOES states its navigation metrics; null: not "
        "set, the page says \"not tested\" (deg)")
