"""The figures of a Monte Carlo set (`dynprop montecarlo`, `dynprop plot SET`)."""

from __future__ import annotations


def ensemble_figures(summary: dict, fig: dict, converged_after_h: float, caption: str
                     ) -> tuple:
    """The ensemble's errors against the filter's σ and Eq. 55, its averaged NEES, and
    the yaw at each Sun-gap end, from montecarlo.json's dict and the ensemble arrays
    (``montecarlo.stats.ensemble``)."""
    from dynprop.plots.montecarlo import plot_ensemble_errors, plot_ensemble_nees, plot_gap_end_yaw
    return (plot_ensemble_errors(fig, summary["analytic_sigma_yaw_deg"], summary["runs_ok"],
                                 converged_after_h, caption),
            plot_ensemble_nees(fig, summary, converged_after_h, caption),
            plot_gap_end_yaw(fig, summary, caption))
