"""The figure of `dynprop batch` (batch.png)."""

from __future__ import annotations

from pathlib import Path

from . import save_figure


def batch_figure(path: Path, t_s, errors: dict, sigmas: dict, gap, epochs_s, title: str,
                 consider_sigma=None) -> Path:
    """The batch's errors beside the filter's and the smoother's, ±3σ, Sun gaps shaded."""
    from dynprop.plots.batch import plot_batch
    return save_figure(plot_batch(t_s, errors, sigmas, gap, epochs_s, title, consider_sigma),
                       path)
