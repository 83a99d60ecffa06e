"""The figures of the trim-tab estimate (`dynprop trim`) and of the batch-length
study (``studies.trim_batch``); the trim loop's is a run figure (``run``)."""

from __future__ import annotations

from pathlib import Path

from . import save_figure


def trim_figure(path: Path, shape_t_s, shape_xz, kappa_Nm: float, sigma_Nm: float, rows_t_s,
                filtered_xz, title: str, true_solar=None) -> Path:
    """trim.png: the filter's torque estimates against κ̂ times the unit-κ solar
    torque (and the true solar torque when the run has it)."""
    from dynprop.plots.trim import plot_trim
    return save_figure(plot_trim(shape_t_s, shape_xz, kappa_Nm, sigma_Nm, rows_t_s,
                                 filtered_xz, title,
                                 *(true_solar if true_solar is not None else (None, None))),
                       path)


def batch_study_figure(path: Path, table: dict, labels, paper_trimmed_Nm: float) -> Path:
    """σ(κ̂) against the batch length."""
    from dynprop.plots.trim import plot_batch_study
    return save_figure(plot_batch_study(table, labels, paper_trimmed_Nm), path)
