"""Issue 29's figure items: what errors.png, consistency.png and the time axes
promise a reviewer, asserted on the drawn matplotlib figures.  Small synthetic
runs (two days of 64 s rows, as a default `run` stores) keep each test quick."""

from __future__ import annotations

import json

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from plots import decor  # noqa: E402
from plots.consistency import per_state_text, plot_consistency  # noqa: E402
from plots.errors import plot_errors  # noqa: E402
from plots.run_figures import plot_torques  # noqa: E402

ROW = 64.0
N = 2700                                     # two days of 64 s rows
BOUNDS = (2.700, 19.023)
NIS_BOUNDS = (0.000982, 5.024)
SUN_GAP, SHORT = "Sun gap: no head sees the Sun", "noon outage: Sun near the yaw axis"
PER_STATE = {"roll_deg": 0.71, "roll_rate_degps": 0.30, "yaw_deg": 0.38,
             "yaw_rate_degps": 0.5, "h_Nms": 0.98, "N_px_Nm": 0.023, "N_pz_Nm": 0.008,
             "N_cx_Nm": 0.032, "N_cz_Nm": 0.016}


def _run(n=N, seed=4):
    """Errors with the given σ; a 1.3 h outage at 4.5 h and an 8 h Sun gap at 13 h
    each day."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * ROW
    hod = (t / 3600.0) % 24.0
    gap = ((hod >= 4.5) & (hod < 5.8)) | ((hod >= 13.0) & (hod < 21.0))
    series = {}
    for name, unit, style, sig in (("roll", "deg", "envelope", 2e-3),
                                   ("yaw", "deg", "trace", 1.5e-2),
                                   ("h", "N m s", "envelope", 1.2e-5)):
        sigma = np.full(n, sig)
        real = rng.normal(0.0, sig, n)
        series[name] = {"unit": unit, "real": real, "sigma": sigma, "style": style,
                        "linear": real + rng.normal(0, 1e-3 * sig, n)}
    return t, gap, series


def _legend(fig) -> list[str]:
    return [t.get_text() for t in fig.legends[0].get_texts()] if fig.legends else []


def _ylabels(fig) -> dict[str, object]:
    return {ax.get_ylabel().split("\n")[0].split(" (")[0]: ax for ax in fig.axes}


@pytest.fixture
def figs():
    made = []
    yield made
    for f in made:
        plt.close(f)


# --------------------------------------------------------------------------- time axes

@pytest.mark.parametrize("days, label", [(2, "time (h)"), (3, "time (h)"), (30, "time (days)"),
                                         (365, "time (days)")])
def test_time_axis_reads_in_days_beyond_three_days(days, label, figs):
    """Data stay in hours; beyond three days the ticks fall on whole days and are
    labelled in days, at most 16 of them."""
    t_h = np.linspace(0.0, 24.0 * days, 500)
    fig, ax = plt.subplots()
    figs.append(fig)
    ax.plot(t_h, np.zeros_like(t_h))
    decor.time_axis(ax, t_h)
    fig.canvas.draw()
    assert ax.get_xlabel() == label
    assert ax.get_xlim() == (0.0, 24.0 * days)
    ticks = [v for v in ax.get_xticks() if 0 <= v <= 24.0 * days]
    assert 3 <= len(ticks) <= 17
    if days > 3:
        np.testing.assert_allclose(np.array(ticks) % 24.0, 0.0, atol=1e-9)
        label_of = ax.xaxis.get_major_formatter()
        assert [label_of(v, i) for i, v in enumerate(ticks)] == [f"{v / 24.0:g}" for v in ticks]
        assert float(label_of(ticks[1], 1)) >= 1.0      # whole days, not hours


def test_a_30_day_figure_has_a_time_axis_in_days(figs):
    n = 30 * 24 * 60          # one row a minute
    t = np.arange(n) * 60.0
    est = {k: np.zeros(n) for k in ("N_px", "N_pz", "N_cx", "N_cz")}
    sig = {k: np.full(n, 1e-6) for k in est}
    fig = plot_torques(t, np.zeros(n, bool), est, sig, "30 days", truth=est)
    figs.append(fig)
    assert {ax.get_xlabel() for ax in fig.axes[2:]} == {"time (days)"}


# --------------------------------------------------------------------------- errors.png

def test_errors_draw_every_row_and_one_rms_interval_for_all_panels(figs):
    """One binning for every panel, and said: each error panel draws the real error
    at every stored row (comparable with ±3σ one by one), the noisy ones add ±RMS
    per one interval, the same for every panel; the share of rows outside ±3σ in
    each title is the share in the data."""
    t, gap, series = _run()
    series["roll"]["real"][100:103] = 1.0          # three rows far outside 3σ
    fig = plot_errors(t, gap, series, "rows", 3600.0, paper_sigma_deg=0.0397)
    figs.append(fig)
    panels = _ylabels(fig)
    intervals = set()
    for name in ("roll", "yaw", "h"):
        ax = panels[f"{name} error"]
        title = ax.get_title(loc="left")
        assert "every 64 s row" in title, title
        s = series[name]
        share = 100 * np.mean(np.abs(s["real"]) > 3 * s["sigma"])
        assert f"{share:.2g}% of rows outside the filter's ±3σ" in title, title
        if s["style"] == "envelope":
            intervals.add(title.split("±RMS per ")[1].split(")")[0])
            dots = [ln for ln in ax.get_lines() if ln.get_marker() == "."
                    and ln.get_color() == "C3"]
            assert len(dots) == 1 and len(dots[0].get_ydata()) == N
            np.testing.assert_array_equal(dots[0].get_ydata(), s["real"])
    assert intervals == {"10 min"}
    # No per-row extremes of the error are drawn beside 3σ (they cross it by construction).
    assert not any("real, full-rate min–max" in t for t in _legend(fig))


def test_errors_shade_sun_gaps_and_short_outages_apart(figs):
    t, gap, series = _run()
    fig = plot_errors(t, gap, series, "gaps", 4 * 3600.0, paper_sigma_deg=0.0397,
                      gap_labels=(SUN_GAP, SHORT))
    figs.append(fig)
    assert SUN_GAP in _legend(fig) and SHORT in _legend(fig)
    yaw = _ylabels(fig)["yaw error"]
    spans = {p.get_label(): p for p in yaw.patches if p.get_label() in (SUN_GAP, SHORT)}
    x_sun, x_short = (np.array([spans[k].get_x(), spans[k].get_x() + spans[k].get_width()])
                      for k in (SUN_GAP, SHORT))
    # The first Sun gap runs 13–21 h, the first short outage 4.5–5.8 h (to a row).
    assert 12.9 <= x_sun.min() <= 13.1 and 20.9 <= x_sun.max() <= 21.1
    assert 4.4 <= x_short.min() <= 4.6 and 5.7 <= x_short.max() <= 5.9


def test_errors_with_the_ekf_have_its_sigma_and_difference_panels(figs):
    """With the EKF's error and σ: its ±3σ on each error panel and an "EKF − paper
    filter" panel per state holding exactly that difference."""
    t, gap, series = _run()
    rng = np.random.default_rng(9)
    for s in series.values():
        s["ekf"] = s["real"] + rng.normal(0.0, 0.01 * s["sigma"][0], N)
        s["ekf_sigma"] = 1.5 * s["sigma"]
    fig = plot_errors(t, gap, series, "ekf", 3600.0, paper_sigma_deg=0.0397)
    figs.append(fig)
    panels = _ylabels(fig)
    assert "EKF ±3σ" in _legend(fig)
    for name, s in series.items():
        diff = panels[f"Δ EKF {name}"]
        assert "EKF − paper filter" in diff.get_title(loc="left")
        d = s["ekf"] - s["real"]
        drawn = np.concatenate([ln.get_ydata() for ln in diff.get_lines()
                                if ln.get_marker() == "." or (s["style"] == "trace" and
                                                             len(ln.get_ydata()) == N)])
        np.testing.assert_allclose(np.sort(drawn), np.sort(d))
        edge = [ln for ln in panels[f"{name} error"].get_lines() if ln.get_label() == "EKF ±3σ"]
        np.testing.assert_allclose(np.nanmax(edge[0].get_ydata()), 3 * 1.5 * s["sigma"][0])
    # Without the EKF, none of it.
    plain = plot_errors(t, gap, _run()[2], "paper", 3600.0, paper_sigma_deg=0.0397)
    figs.append(plain)
    assert not any("EKF" in k for k in _ylabels(plain)) and "EKF ±3σ" not in _legend(plain)


@pytest.mark.parametrize("warnings", [None, [], ["truth left the linear range", "NEES low"]])
def test_errors_write_the_warnings_only_when_there_are_some(warnings, figs):
    t, gap, series = _run()
    fig = plot_errors(t, gap, series, "w", 3600.0, paper_sigma_deg=0.0397, warnings=warnings)
    figs.append(fig)
    texts = [x.get_text() for ax in fig.axes for x in ax.texts] + \
        [x.get_text() for x in fig.texts]
    red = [x for x in texts if x.startswith("WARNING")]
    if warnings:
        assert len(red) == 1
        assert all(f"WARNING: {w}" in red[0] for w in warnings)
    else:
        assert not red and not any("WARNING" in x for x in texts)


# --------------------------------------------------------------------------- consistency.png

def _consistency(summary=None, warnings=None):
    rng = np.random.default_rng(6)
    t = np.arange(N) * ROW
    nees = 0.3 * rng.chisquare(9, N)
    nis = {m: rng.chisquare(1, N) for m in ("roll", "yaw", "h")}
    return plot_consistency(t, np.zeros(N, bool), {"real": nees, "linear": nees * 1.001}, 9,
                            BOUNDS, nis, NIS_BOUNDS, "c", summary=summary, warnings=warnings)


def test_consistency_box_gives_summary_numbers_full_rate_and_the_states(figs):
    """summary.json's full-rate mean and share inside replace the rows' own; the
    states far below 1 are named from nees_mean_per_state with their share of the
    shortfall computed here independently."""
    summary = {"nees_mean": 4.321, "nees_fraction_inside_95": 0.4567,
               "nees_mean_linear": 4.322, "nees_fraction_inside_95_linear": 0.4568,
               "nees_mean_per_state": PER_STATE}
    fig = _consistency(summary)
    figs.append(fig)
    box = "\n".join(t.get_text() for t in fig.axes[0].texts)
    assert "mean 4.32 against the expected 9; full-rate, summary.json" in box
    assert "inside its 95% bounds 46% of the time" in box
    assert "CONSERVATIVE" in box
    quiet = {k: v for k, v in PER_STATE.items() if v < 0.2}
    assert set(quiet) == {"N_px_Nm", "N_pz_Nm", "N_cx_Nm", "N_cz_Nm"}
    share = sum(1 - v for v in quiet.values()) / (9 - sum(PER_STATE.values()))
    one_line = " ".join(box.split())
    for k in quiet:
        assert k.removesuffix("_Nm") in one_line
    assert "yaw_rate" not in one_line     # 0.5: not far below 1
    assert f"make {100 * share:.0f}% of the shortfall" in one_line
    # Without the summary the rows' own numbers, said to be the drawn rows'.
    rows = _consistency()
    figs.append(rows)
    assert "drawn rows" in "\n".join(t.get_text() for t in rows.axes[0].texts)


def test_per_state_text_over_confident_names_the_loud_states():
    per_state = dict.fromkeys(PER_STATE, 1.0) | {"yaw_deg": 9.0, "h_Nms": 3.0}
    text = per_state_text(per_state, 9)
    assert "yaw 9" in text and "h 3" in text and "roll" not in text
    assert "100% of the excess" in text
    assert per_state_text(dict.fromkeys(PER_STATE, 1.0), 9) == ""


def test_consistency_draws_the_twin_visibly_over_the_real(figs):
    """The twin's running mean is dashed and on top of the real one, so both show
    where they coincide."""
    fig = _consistency()
    figs.append(fig)
    lines = {ln.get_label(): ln for ln in fig.axes[0].get_lines()}
    real = next(v for k, v in lines.items() if k.startswith("NEES real") and "mean" in k)
    twin = next(v for k, v in lines.items() if k.startswith("NEES linear twin") and "mean" in k)
    assert twin.get_zorder() > real.get_zorder()
    assert twin.get_linestyle() not in ("-", "solid") and twin.get_linewidth() < \
        real.get_linewidth()


@pytest.mark.parametrize("warnings", [None, ["mean NEES 2.66: conservative"]])
def test_consistency_writes_its_warning_only_when_given(warnings, figs):
    fig = _consistency(warnings=warnings)
    figs.append(fig)
    red = [t.get_text() for ax in fig.axes for t in ax.texts if t.get_text().startswith("WARN")]
    assert red == ([f"WARNING: {warnings[0]}"] if warnings else [])


# --------------------------------------------------------------------------- run directory

def test_a_run_directory_draws_summary_json(tmp_path, figs):
    """scenarios.figures.run reads summary.json: every warning on errors.png, only
    the NEES ones on consistency.png, Eq. 55's σ as the console writes it, and the
    summary's NEES mean."""
    from scenarios.config.loader import load_scenario
    from scenarios.config.schema import resolved_yaml
    from scenarios.figures.run import run_figure

    from .test_figure_set import arrays
    d = tmp_path / "run"
    d.mkdir()
    (d / "scenario.yaml").write_text(resolved_yaml(load_scenario("goes_next_equinox")))
    np.savez(d / "comparison.npz", **arrays(True, True)[1])
    summary = {"nees_mean": 7.654, "nees_fraction_inside_95": 0.5,
               "warnings": [{"check": "linear_range", "message": "truth beyond 0.19°"},
                            {"check": "nees", "message": "mean NEES low"},
                            {"check": "ekf_nees", "message": "EKF NEES low"}]}
    (d / "summary.json").write_text(json.dumps(summary))
    errors, cons = run_figure(d, "errors"), run_figure(d, "consistency")
    figs += [errors, cons]

    def red(fig):
        return " ".join(t.get_text() for ax in fig.axes for t in ax.texts
                        if t.get_text().startswith("WARNING"))
    assert all(m in red(errors) for m in ("truth beyond 0.19°", "mean NEES low", "EKF NEES low"))
    assert "mean NEES low" in red(cons) and "EKF NEES low" in red(cons)
    assert "truth beyond" not in red(cons)
    assert any("(Eq. 55: 0.0397°)" in t for t in _legend(errors))
    assert "mean 7.65 against the expected 9; full-rate" in \
        "\n".join(t.get_text() for t in cons.axes[1].texts)
    # No summary.json: no warnings, the rows' numbers.
    (d / "summary.json").unlink()
    bare = run_figure(d, "errors")
    figs.append(bare)
    assert not red(bare)
