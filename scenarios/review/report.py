"""`dynprop report DIR`: the directory's kind, its page, DIR/report.html.

Everything the page needs is read and checked before anything is written, and the
page is written whole (render.write), so a bad directory gets one line and exit 2
with nothing written, and an existing report.html is replaced only by a complete
one.
"""

from __future__ import annotations

import math
from pathlib import Path

from . import render, source

REPORT = "report.html"


def _builder(kind: str):
    if kind == "run":
        from .run_page import build
        return build
    from .pages import batch, ensemble, linearization, simulate, trim, tune
    return {"montecarlo": ensemble.build, "linearization": linearization.build,
            "trim": trim.build, "tune": tune.build, "batch": batch.build,
            "simulate": simulate.build}[kind]


def check_requirement(value: float | None) -> float | None:
    if value is not None and not (math.isfinite(value) and value > 0):
        raise source.ReportInputError(f"--yaw-requirement-deg: {value:g} must be a positive "
                                      "finite angle (deg)")
    return value


def build_page(path: Path | str, command: str | None = None,
               requirement_deg: float | None = None) -> render.Page:
    src = source.load(path)
    return _builder(src.kind)(src, command, check_requirement(requirement_deg))


def write_report(path: Path | str, command: str | None = None,
                 requirement_deg: float | None = None) -> Path:
    """DIR/report.html for the directory at ``path``; returns its path."""
    page = build_page(path, command, requirement_deg)
    return render.write(page, Path(path) / REPORT)
