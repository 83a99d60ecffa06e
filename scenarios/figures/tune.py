"""tune.png of `dynprop tune` (``tune``): the likelihood along each determined
parameter, NIS per hour and the innovations' autocorrelation, before and after."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from . import save_figure


def tune_figure(path: Path, r) -> Path:
    """tune.png of a ``tune.fit.TuneResult``."""
    from dynprop.plots.tune import plot_tune
    profiles = {}
    for name, (theta, dll) in r.profiles.items():
        j = r.names.index(name)
        profiles[name] = (np.log(theta / r.fit.theta[j]), dll, float(r.fit.sigma_log[j]))
    settings = {"scenario": r.before, "tuned": r.after}
    nis = {k: {kind: h for kind, h in d.hourly_nis.items() if d.nis[kind]["updates"]}
           for k, d in settings.items()}
    rho = {k: {kind: v for kind, v in d.rho.items() if d.nis[kind]["updates"]}
           for k, d in settings.items()}
    pairs = {kind: r.after.nis[kind]["updates"] for kind in r.after.nis}
    bounds = {kind: tuple(r.after.nis[kind]["bounds"] or (np.nan, np.nan))
              for kind in r.after.nis}
    gain = r.after.loglik - r.before.loglik
    title = (f"{r.source.scenario.name}: noise by maximum likelihood on "
             f"{r.source.span_s / 3600:.1f} h of telemetry; ln L +{gain:.1f}; "
             "steady-state gap-end σ_yaw "
             f"{r.before.sigma_yaw_deg['gap_end']:.4f}° → {r.after.sigma_yaw_deg['gap_end']:.4f}°")
    # The lags are in samples of the innovation series: the grid's step on it, the
    # median cadence off it.
    return save_figure(plot_tune(profiles, nis, bounds, rho, r.source.cadence_s, pairs, title),
                       path)
