"""season.png (plots.season): what it promises for a year and for a few days."""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
import pytest

from plots.season import continuous_day, outside_3sigma, plot_season


def _year(n=365, start_doy=79):
    rng = np.random.default_rng(4)
    doy = (start_doy - 1 + np.arange(n)) % 365 + 1
    x = continuous_day(doy)
    # Eclipse seasons: ~72 min at the equinoxes (day 79 and 265), none 23 days away.
    ecl = np.zeros(n)
    for eq in (79.0, 265.0, 79.0 + 365):
        ecl = np.maximum(ecl, 72.0 * np.clip(1 - ((x - eq) / 23.0) ** 2, 0, None))
    sig = np.full(n, 0.045)
    err = rng.normal(0, 0.02, n)
    err[100] = 0.2                  # one gap end outside ±3σ
    err[200] = np.nan               # a day without a gap end
    sig[200] = np.nan
    return {"day": np.arange(n, dtype=float), "day_of_year": doy.astype(float),
            "gap_end_yaw_error_deg": err, "gap_end_yaw_sigma_deg": sig,
            "eq55_sigma_yaw_deg": np.full(n, 0.0397), "eclipse_min": ecl,
            "yaw_error_rms_deg": np.full(n, 0.013), "yaw_error_rms_linear_deg": np.full(n, 0.013),
            "yaw_error_rms_real_minus_linear_deg": np.full(n, 2e-4)}


def test_continuous_day_never_goes_back():
    d = continuous_day([364, 365, 1, 2])
    assert np.all(np.diff(d) > 0) and d[2] == 366


def test_a_year_shows_both_eclipse_seasons_and_counts_the_misses():
    daily = _year()
    assert outside_3sigma(daily["gap_end_yaw_error_deg"],
                          daily["gap_end_yaw_sigma_deg"]) == (1, 364)
    fig = plot_season(daily, "a year")
    try:
        top, ecl, rms = fig.axes
        # The eclipse panel draws a bar per day: both seasons are there.
        heights = np.array([p.get_height() for p in ecl.patches])
        x = np.array([p.get_x() + p.get_width() / 2 for p in ecl.patches])
        assert len(heights) == 365
        assert heights[(x > 60) & (x < 100)].max() > 60      # March–April
        assert heights[(x > 245) & (x < 290)].max() > 60     # September–October
        assert heights[(x > 130) & (x < 220)].max() == 0     # none at the solstice
        labels = [t.get_text() for t in top.get_legend().get_texts()]
        assert any("1 of 364 outside ±3σ" in s for s in labels), labels
        assert any("Eq. 55" in s for s in labels)
        # The miss is inside the axes, not clipped.
        assert top.get_ylim()[1] >= 0.2
        assert rms.get_yscale() == "log"   # 0.013° against 2e-4°: decades apart
        assert [t.get_text() for t in rms.get_xticklabels()][:2] == ["Apr", "May"]
    finally:
        plt.close(fig)


def test_a_few_days_without_gap_ends_still_draw():
    daily = {k: v[:3] for k, v in _year().items()}
    daily["gap_end_yaw_error_deg"][:] = np.nan
    daily["gap_end_yaw_sigma_deg"][:] = np.nan
    fig = plot_season(daily, "three days")
    try:
        assert "0 of 0 outside" in fig.axes[0].get_legend().get_texts()[-1].get_text()
        assert fig.axes[2].get_xlabel() == "day of year"
    finally:
        plt.close(fig)


@pytest.mark.parametrize("n", [2, 30])
def test_short_tables(n):
    fig = plot_season({k: v[:n] for k, v in _year().items()}, "short")
    plt.close(fig)
