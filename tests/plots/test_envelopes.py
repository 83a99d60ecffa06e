"""Decimated rows hide nothing: a spike between two output rows, present only in
the stored full-rate min/max (comparison.npz's ``<key>_min``/``_max``), is drawn
and counted by the errors and consistency figures."""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np

from estimator.analysis.covariance import PAPER_SIGMA_YAW_DEG
from plots.consistency import plot_consistency
from plots.errors import plot_errors

N = 2700                      # two days of 64 s rows
T = np.arange(N) * 64.0


def _series(with_envelope: bool):
    rng = np.random.default_rng(2)
    out = {}
    for name, unit, style in (("roll", "deg", "envelope"), ("yaw", "deg", "trace"),
                              ("h", "N m s", "envelope")):
        real = rng.normal(0, 1e-3, N)
        s = {"unit": unit, "real": real, "sigma": np.full(N, 2e-3), "style": style,
             "linear": real, "difference": rng.normal(0, 1e-6, N)}
        if with_envelope:
            lo, hi = real - 2e-3, real + 2e-3
            dlo, dhi = s["difference"] - 1e-6, s["difference"] + 1e-6
            dhi[1234] = 7.5e-4        # the largest real − linearized, between two rows
            s.update(real_min=lo, real_max=hi, difference_min=dlo, difference_max=dhi,
                     row_interval=64.0)
        out[name] = s
    return out


def _titles(fig) -> str:
    return "\n".join(ax.get_title(loc="left") for ax in fig.axes)


def test_the_difference_panel_reports_the_full_rate_extreme():
    gap = np.zeros(N, dtype=bool)
    fig = plot_errors(T, gap, _series(True), "decimated", paper_sigma_deg=PAPER_SIGMA_YAW_DEG)
    without = plot_errors(T, gap, _series(False), "rows only",
                          paper_sigma_deg=PAPER_SIGMA_YAW_DEG)
    try:
        assert "max |Δ| = 0.00075 deg at 21.94 h" in _titles(fig)
        assert "0.00075" not in _titles(without)
        yaw_diff = [ax for ax in fig.axes if ax.get_ylabel().startswith("Δ yaw")][0]
        assert yaw_diff.get_ylim()[1] >= 7.5e-4
        labels = [t.get_text() for t in fig.legends[0].get_texts()]
        assert any("full-rate min–max per 64 s row" in s for s in labels), labels
    finally:
        plt.close(fig)
        plt.close(without)


def test_the_nees_panel_holds_a_spike_between_rows():
    rng = np.random.default_rng(3)
    nees = rng.chisquare(9, N)
    peak = nees + 1.0
    peak[777] = 5e4
    nis = {m: rng.chisquare(1, N) for m in ("roll", "yaw", "h")}
    fig = plot_consistency(T, np.zeros(N, bool), {"real": nees, "real_max": peak}, 9,
                           (2.7, 19.0), nis, (0.001, 5.02), "decimated")
    try:
        assert fig.axes[0].get_ylim()[1] >= 5e4
    finally:
        plt.close(fig)
