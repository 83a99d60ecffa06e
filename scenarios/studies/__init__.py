"""Studies: one-off experiments behind docs/validation.md's tables, run as
``python -m dynprop.scenarios.studies.<name>`` and not by any command:
``ekf_crossover`` (where the paper's filter gives way to the EKF) and
``trim_batch`` (σ of the trim-tab estimate against the batch length) and
``bias_states`` (the filter with sensor-bias states against the paper's, on one Monte
Carlo set).

May import every room below the command layer (``run``, the analyses, ``figures``
and what they import); nothing imports them.
"""

from __future__ import annotations

import json


def write_json(path: str | None, data) -> None:
    """The study's table as JSON at ``path`` (nothing when None)."""
    if path:
        with open(path, "w") as fh:
            json.dump(data, fh, indent=2)
