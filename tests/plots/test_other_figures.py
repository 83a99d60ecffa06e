"""The non-run figures (trim, Monte Carlo, linearization): legends off the data, the
σ band that trim.png states, time axes laid out by decor.time_axis, and a "not
tested" note in a panel that has nothing to show (a 6 h run has no Sun-gap end)."""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
import pytest
from matplotlib.collections import PolyCollection

from plots.linearization import plot_estimation
from plots.montecarlo import plot_ensemble_errors, plot_ensemble_nees, plot_gap_end_yaw
from plots.trim import plot_trim

from .legend_checks import legend_clear_of_axes_and_caption

SIDEREAL_DAY_S = 86164.0


# --------------------------------------------------------------------------- trim.png

def _trim_inputs(days=2.0):
    """A solar torque shape like the default run's: a sidereal-day sinusoid in roll
    and yaw, zero during a 1 h eclipse a day."""
    t = np.arange(0.0, days * 86400.0, 60.0)
    phase = 2 * np.pi * t / SIDEREAL_DAY_S
    shape = np.column_stack([np.sin(phase), np.cos(phase)])
    shape[(t % 86400.0) > 82800.0] = 0.0
    rng = np.random.default_rng(3)
    filt = 1e-6 * shape + 3e-7 * rng.standard_normal(shape.shape)
    return t, shape, filt


def test_trim_band_is_three_sigma_of_kappa_and_the_legend_is_off_the_curves():
    t, shape, filt = _trim_inputs()
    kappa, sigma = 1.0e-6, 7.4e-8        # the default two-day run's κ̂ and σ(κ̂)
    fig = plot_trim(t, shape, kappa, sigma, t, filt, "trim", t, 1e-6 * shape)
    try:
        for i, ax in enumerate(fig.axes):
            bands = [c for c in ax.collections if isinstance(c, PolyCollection)
                     and c.get_label().startswith("±3σ")]
            assert len(bands) == 1, [c.get_label() for c in ax.collections]
            assert "σ = 7.4e-08 N m" in bands[0].get_label()
            y = np.concatenate([p.vertices[:, 1] for p in bands[0].get_paths()])
            # The band's edges: κ̂·shape ± 3σ(κ̂)·|shape|, computed here from the inputs.
            assert y.max() == pytest.approx(np.max(kappa * shape[:, i]
                                                   + 3 * sigma * np.abs(shape[:, i])),
                                            rel=1e-9)
            assert y.min() == pytest.approx(np.min(kappa * shape[:, i]
                                                   - 3 * sigma * np.abs(shape[:, i])),
                                            rel=1e-9)
            # Visible: not a hairline of the axis height.
            lo, hi = ax.get_ylim()
            assert 6 * sigma / (hi - lo) > 0.02
        assert fig.axes[-1].get_xlabel().startswith("time (")
        assert fig.axes[-1].get_xlim() == pytest.approx((t[0] / 3600, t[-1] / 3600))
        legend_clear_of_axes_and_caption(fig)
    finally:
        plt.close(fig)


# --------------------------------------------------------------------------- Monte Carlo

def _ensemble(hours=6.0, grid_s=33.0, gaps_h=()):
    rng = np.random.default_rng(5)
    t = np.linspace(0.0, hours * 3600.0, int(round(hours * 3600.0 / grid_s)) + 1)
    n = t.size
    sigma = np.tile([2e-3, 1e-5, 0.03, 1e-5, 1.2e-5, 1e-7, 1e-7, 1e-7, 1e-7], (n, 1))
    rms = sigma * (0.7 + 0.1 * rng.random((n, 9)))
    d = {"t_s": t, "gaps_h": np.reshape(np.asarray(gaps_h, dtype=float), (-1, 2)),
         "rms": rms, "sigma_rms": sigma, "mean_err": 0.3 * rms,
         "nees_avg": 3 + rng.random(n), "nsq": 0.3 + rng.random((n, 9)),
         "nsq_bounds": (0.121, 2.786)}
    summary = {"nees": {"dof": 9, "runs": 4, "bounds_95": [5.33, 13.61],
                        "fraction_after_convergence": None,
                        "diagnosis": "the run ends before the convergence time: no NEES test"},
               "gap_end_yaw": []}
    return d, summary


@pytest.mark.parametrize("which", ["errors", "nees"])
def test_mc_figures_legend_below_the_panels_and_time_axis_laid_out(which):
    d, summary = _ensemble()
    fig = (plot_ensemble_errors(d, 0.0397, 4, 6.0, "caption: scenario, seed, command")
           if which == "errors" else
           plot_ensemble_nees(d, summary, 6.0, "caption: scenario, seed, command"))
    try:
        legend_clear_of_axes_and_caption(fig)
        ax = fig.axes[-1]
        assert ax.get_xlabel().startswith("time (")
        assert ax.get_xlim() == pytest.approx((0.0, d["t_s"][-1] / 3600))
        labels = [t.get_text() for t in fig.legends[0].get_texts()]
        if which == "nees":
            # No sample after the convergence time: the legend says "not tested", not
            # a share of samples inside the bounds.
            assert any("nees" in s.lower() and "not tested" in s for s in labels), labels
        else:
            assert "no NEES test" in fig.axes[0].get_title()
    finally:
        plt.close(fig)


def test_mc_gap_end_figure_without_a_gap_end_says_not_tested():
    d, summary = _ensemble()
    fig = plot_gap_end_yaw(d, summary, "caption")
    try:
        texts = [t.get_text() for t in fig.axes[0].texts]
        assert any(s.startswith("not tested: no Sun gap ends within the runs")
                   and "6 h" in s for s in texts), texts
        legend_clear_of_axes_and_caption(fig)
    finally:
        plt.close(fig)


# --------------------------------------------------------------------------- linearization

def _estimation(with_gap_end: bool):
    deltas = [0.01, 0.1, 1.0, 3.0, 10.0]
    v = (lambda x: list(x)) if with_gap_end else (lambda x: [np.nan] * len(deltas))
    one = {"real": v(np.geomspace(1e-3, 0.3, 5)), "linear": v(np.geomspace(1e-3, 0.2, 5)),
           "sigma": v(np.full(5, 0.04)), "nees_real": [2.5, 2.5, 2.6, 2.8, 21.8],
           "nees_linear": [2.5, 2.5, 2.6, 2.7, 2.8]}
    return deltas, {"attitude": one, "rate": dict(one)}


def test_linearization_estimation_panels_without_a_gap_end_say_why():
    deltas, est = _estimation(with_gap_end=False)
    why = "not tested: the 6 h run has no Sun-gap end"
    fig = plot_estimation(deltas, est, (2.7, 19.0), "caption", why_empty=why)
    try:
        top = fig.axes[:2]
        for ax in top:
            assert why in [t.get_text() for t in ax.texts], ax.get_title()
            assert ax.get_legend() is None
        for ax in fig.axes[2:]:                  # NEES is tested without a gap end
            assert not ax.texts
    finally:
        plt.close(fig)
    deltas, est = _estimation(with_gap_end=True)
    fig = plot_estimation(deltas, est, (2.7, 19.0), "caption", why_empty=why)
    try:
        assert not any(ax.texts for ax in fig.axes)
    finally:
        plt.close(fig)
