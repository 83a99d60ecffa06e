"""season.png (plots.season): what it promises for a year and for a few days."""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
import pytest

from plots.season import continuous_day, outside_3sigma, plot_season

from .legend_checks import legend_clear_of_axes_and_caption


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
        labels = [t.get_text() for t in fig.legends[0].get_texts()]
        assert any("1 of 364 outside ±3σ" in s for s in labels), labels
        assert any("Eq. 55" in s for s in labels)
        # The headline's verdict: the one miss, 0.2° against σ = 0.045°, on day 179.
        assert (f"363 of 364 within ±3σ, worst |e|/σ = {0.2 / 0.045:.2f} (day of year 179)"
                in fig._suptitle.get_text())
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
        labels = [t.get_text() for t in fig.legends[0].get_texts()]
        assert any("0 of 0 outside" in s for s in labels), labels
        texts = [t.get_text() for t in fig.axes[0].texts]
        assert any(s.startswith("not tested: no Sun-gap end") for s in texts), texts
        assert "not tested (no Sun-gap end in these 3 days)" in fig._suptitle.get_text()
        assert fig.axes[2].get_xlabel() == "day of year"
    finally:
        plt.close(fig)


@pytest.mark.parametrize("n", [2, 30])
def test_short_tables(n):
    fig = plot_season({k: v[:n] for k, v in _year().items()}, "short")
    plt.close(fig)


def _month(n=30):
    """A month like the default scenario's: gap-end errors of a few thousandths of a
    degree against a filter σ of ~0.045°, the case that read as a flat row when the
    axis was set by the ±3σ band."""
    daily = {k: v[:n].copy() for k, v in _year().items()}
    rng = np.random.default_rng(11)
    daily["gap_end_yaw_error_deg"] = -0.005 + 0.003 * rng.standard_normal(n)
    daily["gap_end_yaw_sigma_deg"] = 0.041 + 0.01 * np.exp(-np.arange(n) / 2.0)
    return daily


@pytest.mark.parametrize("make", [_year, _month])
def test_the_legend_sits_outside_every_panel(make):
    """One legend for the figure, drawn where no axes are: it cannot cover days
    103–108 (or any data) of any panel."""
    fig = plot_season(make(), "legend")
    try:
        legend_clear_of_axes_and_caption(fig)
    finally:
        plt.close(fig)


def test_gap_end_errors_are_scaled_to_themselves_and_the_title_gives_the_verdict():
    daily = _month()
    e, s = daily["gap_end_yaw_error_deg"], daily["gap_end_yaw_sigma_deg"]
    fig = plot_season(daily, "goes_next_equinox — seed 1")
    try:
        top = fig.axes[0]
        lo, hi = top.get_ylim()
        biggest = np.abs(e).max()
        # Every error inside the axes, and the axes no more than 10x the largest error
        # (the σ-sized scale made them a flat row: 3σ ≈ 0.15° against |e| ≤ 0.015°).
        assert lo < e.min() and e.max() < hi
        assert max(-lo, hi) < 10 * biggest
        # The ±3σ band (0.12–0.15°) is beyond the axes: the panel says so.
        assert "beyond the axes" in top.get_title(loc="right")
        assert "filter ±3σ 0.123–0.153°" in top.get_title(loc="right")
        # The headline: what the figure shows and the verdict, from the rows.
        z = np.abs(e) / s
        k = int(np.argmax(z))
        head = fig._suptitle.get_text()
        assert "Sun-gap end against the filter's ±3σ" in head
        assert f"30 of 30 within ±3σ, worst |e|/σ = {z[k]:.2f}" in head
        assert f"day of year {int(daily['day_of_year'][k])})" in head
        assert "goes_next_equinox — seed 1" in head
    finally:
        plt.close(fig)


def test_a_gap_end_near_the_band_keeps_the_band_on_the_axes():
    """When the errors reach the ±3σ levels, the levels are drawn inside the axes."""
    daily = _month()
    daily["gap_end_yaw_error_deg"][7] = 0.1      # 2.4σ
    fig = plot_season(daily, "near")
    try:
        lo, hi = fig.axes[0].get_ylim()
        assert hi > 3 * daily["gap_end_yaw_sigma_deg"].max() and -lo > 0.1
        assert fig.axes[0].get_title(loc="right") == ""
        assert "30 of 30 within ±3σ" in fig._suptitle.get_text()
    finally:
        plt.close(fig)


def test_a_day_range_without_eclipses_says_so():
    daily = _year()
    daily = {k: v[60:90] for k, v in daily.items()}      # May–June: no eclipse
    assert not np.any(daily["eclipse_min"] > 0)
    fig = plot_season(daily, "solstice")
    try:
        texts = [t.get_text() for t in fig.axes[1].texts]
        assert any("no eclipse" in s for s in texts), texts
    finally:
        plt.close(fig)


def test_the_runs_warnings_are_drawn_above_the_panels_and_only_then():
    """A long run's warnings (truth outside the linear range, real − linearized over
    10% of σ) belong where its season is drawn; none given, none drawn."""
    daily = _month()
    message = "truth max |yaw| 0.378° at day 29.7: beyond the 0.19° ..."

    def texts(fig):
        return [t.get_text() for a in fig.axes for t in a.texts]
    with_w = plot_season(daily, "warned", warnings=[message])
    drawn = [t for t in texts(with_w) if t.startswith("WARNING:")]
    assert len(drawn) == 1 and "0.378°" in drawn[0]
    panels = [a for a in with_w.axes if a.get_visible() and a.axison]
    top = max(a.get_position().y1 for a in panels)
    holder = next(a for a in with_w.axes if any(t.get_text().startswith("WARNING:")
                                                for t in a.texts))
    assert holder.get_position().y0 >= top - 1e-9
    assert not any(t.startswith("WARNING:") for t in texts(plot_season(daily, "clean")))
