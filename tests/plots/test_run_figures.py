"""Run figures drawn from synthetic arrays of realistic size (2 days at 0.512 s):
what each figure promises, for every subset of inputs comparison.npz can hold
(with or without the linear twin, with or without a truth).

How long drawing takes is measured by `make bench` (benchmarks/run.py), not here:
a wall-clock limit flakes on shared cores."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402

from estimator.analysis.covariance import PAPER_SIGMA_YAW_DEG  # noqa: E402
from plots import reduce  # noqa: E402
from plots.consistency import nees_verdict, plot_consistency  # noqa: E402
from plots.errors import plot_errors, plot_estimates  # noqa: E402
from plots.run_figures import plot_torques  # noqa: E402
from plots.telemetry import plot_telemetry_overview  # noqa: E402

from .synthetic import (  # noqa: E402
    NEES_BOUNDS,
    NEES_DOF,
    NIS_BOUNDS,
    TITLE,
    TORQUES,
    YAW_DIFF_MAX,
    make_run,
)

SUBSETS = ("full", "no_twin", "no_truth")


def _without_twin(series: dict) -> dict:
    return {n: {k: v for k, v in s.items() if k not in ("linear", "difference")}
            for n, s in series.items()}


def figure_calls(run: dict, subset: str = "full") -> dict:
    """name -> zero-argument callable drawing that figure from ``run`` as the given
    subset of comparison.npz would (``scenarios.figures.run`` does the same)."""
    t, gap = run["t_s"], run["gap"]
    truth = subset != "no_truth"
    series = run["series"] if subset == "full" else _without_twin(run["series"])
    nees = {"real": run["nees_real"], "linear": run["nees_lin"]} if subset == "full" \
        else {"real": run["nees_real"]} if truth else None
    estimates = {n: {"unit": s["unit"], "estimate": s["real"], "sigma": s["sigma"]}
                 for n, s in run["series"].items()}
    return {
        "errors": (lambda: plot_errors(t, gap, series, TITLE, 3600.0,
                                       paper_sigma_deg=PAPER_SIGMA_YAW_DEG)) if truth
        else (lambda: plot_estimates(t, gap, estimates, TITLE, 3600.0,
                                     paper_sigma_deg=PAPER_SIGMA_YAW_DEG)),
        "torques": lambda: plot_torques(t, gap, run["est"], run["tsig"], TITLE,
                                        truth=run["tru"] if truth else None),
        "consistency": lambda: plot_consistency(
            t, gap, nees, NEES_DOF, NEES_BOUNDS, run["nis"], NIS_BOUNDS, TITLE,
            dss=run["dss"], dss_note="DSS yaw deliberately down-weighted"),
        "telemetry": lambda: plot_telemetry_overview(
            t, run["measured"], run["truth_att"] if truth else None, run["wheels"], gap, TITLE,
            yaw_sigma=run["yaw_sigma"], sun_head=run["sun_head"]),
    }


def _arrays(obj, path=""):
    if isinstance(obj, np.ndarray):
        yield path, obj
    elif isinstance(obj, dict):
        for k, v in obj.items():
            yield from _arrays(v, f"{path}/{k}")


@pytest.fixture(scope="module")
def run():
    return make_run()


@pytest.fixture(scope="module")
def small_run():
    """A shorter run for the subsets: the same shapes, a sixth of the drawing time."""
    return make_run(seed=2, n=60_000)


@pytest.fixture
def draw(run):
    """draw(name, subset) -> the figure, closed after the test."""
    figs = []

    def _draw(name, subset="full", which=None):
        fig = figure_calls(which if which is not None else run, subset)[name]()
        figs.append(fig)
        return fig
    yield _draw
    for fig in figs:
        plt.close(fig)


UNITS = {"errors": ("deg", "N m s"), "torques": ("N m",), "consistency": (),
         "telemetry": ("deg", "rpm")}


def _legend_texts(fig) -> list[str]:
    return [t.get_text() for t in fig.legends[0].get_texts()]


@pytest.mark.parametrize("subset", SUBSETS)
@pytest.mark.parametrize("name", ["errors", "torques", "consistency", "telemetry"])
def test_figure(run, small_run, name, subset, tmp_path):
    """Each figure draws from its subset, labels its axes with units, has one legend
    for the whole figure (none per panel), reduces its long traces for drawing, and
    leaves its inputs intact.  Identity is the requirement for the inputs: drawing
    must not change a bit of the caller's arrays."""
    data = run if subset == "full" else small_run
    before = {p: a.copy() for p, a in _arrays(data)}
    for _, a in _arrays(data):
        a.flags.writeable = False          # any in-place write raises
    try:
        fig = figure_calls(data, subset)[name]()
        out = tmp_path / f"{name}.png"
        fig.savefig(out, dpi=120)
    finally:
        for _, a in _arrays(data):
            a.flags.writeable = True
    try:
        assert out.stat().st_size > 50_000
        assert TITLE in fig._suptitle.get_text()
        axes = [ax for ax in fig.axes if ax.get_visible()]
        labels = [ax.get_ylabel() for ax in axes]
        assert all(labels), labels
        for unit in UNITS[name]:
            assert any(f"{unit})" in lab for lab in labels), (unit, labels)
        assert not any("rad" in lab for lab in labels)
        assert axes[-1].get_xlabel() == "time (h)"
        assert len(fig.legends) == 1 and not any(ax.get_legend() for ax in axes)
        texts = _legend_texts(fig)
        assert len(texts) == len(set(texts))
        # 337,500-sample traces are drawn reduced (min/max per pixel column, statistics
        # per interval, dot subsamples), never whole: no blobs.
        longest = max(len(ln.get_xdata()) for ax in axes for ln in ax.get_lines())
        assert longest <= 2 * reduce.MAX_DOTS + 10, longest
    finally:
        plt.close(fig)
    after = dict(_arrays(data))
    assert before.keys() == after.keys()
    for p, a in before.items():
        assert np.array_equal(a, after[p], equal_nan=True), p


# --------------------------------------------------------------------------- errors.png


def _panels(fig) -> dict[str, object]:
    """Error panels by state name and difference panels as 'Δ name'."""
    out = {}
    for ax in fig.axes:
        lab = ax.get_ylabel()
        out[lab.split("\n")[0].split(" (")[0].replace(" error", "")] = ax
    return out


def test_error_panels_in_order_with_units(draw):
    fig = draw("errors")
    labels = [ax.get_ylabel() for ax in fig.axes]
    assert [lab.split()[0] for lab in labels] == ["roll", "Δ", "yaw", "Δ", "h", "Δ"]
    assert "deg" in labels[0] and "deg" in labels[2] and "N m s" in labels[4]
    assert labels[3].startswith("Δ yaw") and "deg" in labels[3]


def test_difference_panels_show_the_difference_on_its_own_scale(run, draw):
    """real − linearized gets axes that hold its largest value and are at most ~10×
    it, so the default run's 7.5e-4° is legible next to errors of ±0.15°; the
    paper's σ (53× larger) is quoted, not drawn."""
    fig = draw("errors")
    panels = _panels(fig)
    for name in ("roll", "yaw", "h"):
        ax = panels[f"Δ {name}"]
        worst = np.max(np.abs(run["series"][name]["difference"]))
        lo, hi = ax.get_ylim()
        assert -lo >= worst and hi >= worst, name
        assert hi <= 10 * worst and -lo <= 10 * worst, (name, hi / worst)
    yaw = panels["Δ yaw"]
    assert np.max(np.abs(run["series"]["yaw"]["difference"])) == YAW_DIFF_MAX
    title = yaw.get_title(loc="left")
    assert "max |Δ| = 0.00075 deg" in title and "σ_yaw, Eq. 55" in title and "off scale" in title
    # The main yaw panel's scale is the filter's: there the difference would be invisible.
    assert panels["yaw"].get_ylim()[1] > 100 * YAW_DIFF_MAX


@pytest.mark.parametrize("ref_over_max", [0.3, 1.0, 3.0, 60.0])
def test_difference_panel_holds_its_maximum_whatever_the_reference(run, ref_over_max):
    """Where the linearization breaks, real − linearized exceeds the paper's σ: the
    axis still holds every value, and the reference is drawn only when it fits."""
    series = {"yaw": dict(run["series"]["yaw"])}
    series["yaw"]["reference"] = (ref_over_max * YAW_DIFF_MAX, "σ_yaw, Eq. 55")
    fig = plot_errors(run["t_s"], run["gap"], series, TITLE, 3600.0,
                      paper_sigma_deg=PAPER_SIGMA_YAW_DEG)
    try:
        ax = _panels(fig)["Δ yaw"]
        lo, hi = ax.get_ylim()
        assert hi >= YAW_DIFF_MAX and -lo >= YAW_DIFF_MAX
        assert hi <= 10 * YAW_DIFF_MAX
        dashed = [ln for ln in ax.get_lines() if ln.get_linestyle() == "--"]
        assert bool(dashed) == (ref_over_max * YAW_DIFF_MAX <= hi)
        assert ("off scale" in ax.get_title(loc="left")) == (not dashed)
    finally:
        plt.close(fig)


def test_no_silent_clipping(run, draw):
    """Every error trace is inside its axes, or the panel says how much is off scale
    and where its largest value is (the synthetic yaw starts at 0.67°)."""
    fig = draw("errors")
    panels = _panels(fig)
    for name in ("roll", "yaw", "h"):
        ax = panels[name]
        lo, hi = ax.get_ylim()
        s = run["series"][name]
        data = np.concatenate([s[k] for k in ("real", "linear", "smoothed")
                               if s.get(k) is not None])
        note = ax.get_title(loc="right")
        if data.min() < lo or data.max() > hi:
            assert "off scale" in note and "% of samples" in note, name
        else:
            assert "error off scale" not in note, name
    assert "max 0.67 deg at 0.00 h" in panels["yaw"].get_title(loc="right")
    # Only the start-up transient is cut; after it, noise tails are kept inside.
    for name in ("roll", "yaw", "h"):
        lo, hi = panels[name].get_ylim()
        s = run["series"][name]
        late = run["t_s"] > 3 * 3600.0
        assert max(np.abs(s[k][late]).max() for k in ("real", "linear")) <= hi, name


def test_torques_show_error_with_three_sigma_and_do_not_clip_silently(run, draw):
    """torques.png draws ±3σ like every other figure: the band's edges are 3× the
    σ given (not 1×), and what leaves the axes is said."""
    fig = draw("torques")
    for ax, name in zip(fig.axes, TORQUES, strict=True):
        assert ax.get_ylabel() == f"{name} error (10⁻⁶ N m)"
        assert ax.get_title(loc="left").startswith(f"{name}: ")
        lo, hi = ax.get_ylim()
        err = run["est"][name] - run["tru"][name]
        if err.min() < lo or err.max() > hi:
            assert "off scale" in ax.get_title(loc="right")
        sig = run["tsig"][name]
        edges = [ln for ln in ax.get_lines() if ln.get_color() == "darkgreen"]
        upper = max(edges, key=lambda ln: np.nanmax(ln.get_ydata()))
        # The band's upper edge, per drawing bin the largest 3σ of the bin.
        np.testing.assert_allclose(np.nanmedian(upper.get_ydata()), 3 * np.median(sig),
                                   rtol=0.05)
        assert hi >= 3 * np.median(sig)
    assert "filter ±3σ" in _legend_texts(fig)
    assert "estimate − truth with ±3σ" in fig._suptitle.get_text()


def test_yaw_panel_draws_the_papers_three_sigma_across_it(run, draw):
    """The paper's σ_yaw is a ±3σ line across the whole yaw panel, labelled as the
    caller names it (the console's "Eq. 55: 0.0397°"); the filter's ±3σ is marked at
    the last Sun-gap end and its σ written there."""
    fig = plot_errors(run["t_s"], run["gap"], run["series"], TITLE, 3600.0,
                      paper_sigma_deg=0.0397, paper_sigma_label="Eq. 55: 0.0397°")
    try:
        yaw = _panels(fig)["yaw"]
        assert any("Eq. 55: 0.0397°" in t for t in _legend_texts(fig))
        assert not any("Eq. 56" in t for t in _legend_texts(fig))
        paper = [ln for ln in yaw.get_lines() if "paper" in str(ln.get_label())]
        ys = sorted(float(ln.get_ydata()[0]) for ln in paper)
        np.testing.assert_allclose(ys, [-3 * 0.0397, 3 * 0.0397])
        for ln in paper:      # across the panel: x in axes fraction, 0 to 1
            np.testing.assert_allclose(ln.get_xdata(), [0, 1])
        gap = run["gap"]
        ends = np.flatnonzero(gap[:-1] & ~gap[1:])
        s_last = run["series"]["yaw"]["sigma"][ends[-1]]
        notes = [c.get_text() for c in yaw.texts]
        assert any(f"{s_last:.4f}° (Eq. 55: 0.0397°)" in n for n in notes), notes
        lo, hi = yaw.get_ylim()
        assert hi >= 3 * 0.0397 and lo <= -3 * 0.0397
    finally:
        plt.close(fig)


def test_envelope_visible(run, draw):
    """The ±3σ band occupies a visible share of every error panel."""
    fig = draw("errors")
    panels = _panels(fig)
    for name in ("roll", "yaw", "h"):
        ax = panels[name]
        sig = run["series"][name]["sigma"]
        lit = np.median(3 * sig[~run["gap"]])
        lo, hi = ax.get_ylim()
        tr = ax.transScale.transform
        y0 = tr([[0, 0]])[0, 1]
        frac = (tr([[0, lit]])[0, 1] - y0) / (tr([[0, hi]])[0, 1] - tr([[0, lo]])[0, 1])
        assert frac > 0.05, (name, frac)


def test_without_twin_no_linear_traces_and_no_difference_panels(small_run, draw):
    fig = draw("errors", "no_twin", small_run)
    assert [ax.get_ylabel().split()[0] for ax in fig.axes] == ["roll", "yaw", "h"]
    assert not any("linearized" in t or "twin" in t for t in _legend_texts(fig))


def test_without_truth_estimates_with_three_sigma(small_run, draw):
    fig = draw("errors", "no_truth", small_run)
    assert fig._suptitle.get_text().startswith("Estimates vs time")
    labels = [ax.get_ylabel() for ax in fig.axes]
    assert labels[:2] == ["roll (deg)", "yaw (deg)"] and labels[2] in ("h (N m s)",
                                                                      "h (10⁻⁶ N m s)")
    assert set(_legend_texts(fig)) >= {"estimate", "estimate ± filter 3σ"}


# --------------------------------------------------------------------------- consistency.png


def test_nees_verdict_words():
    rng = np.random.default_rng(5)
    chi = rng.chisquare(NEES_DOF, 20_000)
    assert nees_verdict(chi, NEES_DOF, NEES_BOUNDS)["word"] == "consistent"
    low = nees_verdict(0.3 * chi, NEES_DOF, NEES_BOUNDS)
    assert low["word"] == "conservative" and low["below"] > low["above"]
    assert low["mean"] == pytest.approx(0.3 * chi.mean())
    assert nees_verdict(3 * chi, NEES_DOF, NEES_BOUNDS)["word"] == "over-confident"
    assert nees_verdict(np.full(5, np.nan), NEES_DOF, NEES_BOUNDS) is None


def test_consistency_states_the_verdict(run, draw):
    """The NEES panel says in words where the NEES sits: the share inside its 95%
    bounds, the mean against the expected 9, and 'conservative'."""
    fig = draw("consistency")
    v = nees_verdict(run["nees_real"], NEES_DOF, NEES_BOUNDS)
    text = "\n".join(t.get_text() for t in fig.axes[0].texts)
    assert "Verdict (real run): CONSERVATIVE" in text
    assert f"inside its 95% bounds {100 * v['inside']:.0f}% of the time" in text
    assert f"mean {v['mean']:.2f} against the expected 9" in text
    assert "linear twin" in text


def test_consistency_shades_and_explains_the_dss_periods(run, draw):
    """The down-weighted DSS periods are shaded and labelled, the yaw NIS mean stays
    on the axes there, and a note says why it is small."""
    fig = draw("consistency")
    assert any("DSS" in t for t in _legend_texts(fig))
    yaw = next(ax for ax in fig.axes if ax.get_ylabel().startswith("NIS yaw"))
    mean = reduce.running_mean(run["nis"]["yaw"], reduce.window(run["t_s"], 600.0))
    assert yaw.get_ylim()[0] <= np.nanmin(mean[run["dss"]])
    assert any("down-weighted" in t.get_text() for t in yaw.texts)


def test_consistency_without_truth_has_nis_only(small_run, draw):
    fig = draw("consistency", "no_truth", small_run)
    assert [ax.get_ylabel().split("\n")[0] for ax in fig.axes] == ["NIS roll", "NIS yaw",
                                                                   "NIS h"]
    assert "no NEES" in fig._suptitle.get_text()


# --------------------------------------------------------------------------- telemetry


def test_telemetry_colours_heads_and_keeps_dss_visible(run, draw):
    """Each Sun-sensor head has its colour, and the DSS's small errors take a visible
    share of the yaw axis although the CASS's reach degrees."""
    fig = draw("telemetry")
    texts = _legend_texts(fig)
    for head in ("DSS", "CASS1", "CASS2"):
        assert f"yaw from {head}" in texts
    yaw = next(ax for ax in fig.axes if ax.get_ylabel().startswith("ground yaw"))
    err = run["measured"]["yaw"] - run["truth_att"]["yaw"]
    lo, hi = yaw.get_ylim()
    assert np.nanmax(np.abs(err)) <= hi and -np.nanmax(np.abs(err)) >= lo   # no clipping
    dss = np.percentile(np.abs(err[run["sun_head"] == 0]), 99)
    tr = yaw.transScale.transform
    frac = (tr([[0, dss]])[0, 1] - tr([[0, 0]])[0, 1]) / (tr([[0, hi]])[0, 1]
                                                          - tr([[0, lo]])[0, 1])
    assert frac > 0.08, frac


def test_telemetry_without_truth_shows_measured_values(small_run, draw):
    fig = draw("telemetry", "no_truth", small_run)
    labels = [ax.get_ylabel() for ax in fig.axes]
    assert not any("true" in lab for lab in labels), labels
    assert any(lab.startswith("ground yaw (deg)") for lab in labels)


# --------------------------------------------------------------------------- reductions


def test_minmax_keeps_extremes_and_inputs():
    """Identity is the requirement: min/max decimation selects samples, so the
    extremes it keeps are the input's values exactly, and the input is unchanged."""
    y = np.sin(np.linspace(0, 50, 100_000))
    y[12_345] = 7.0
    y[54_321] = np.nan
    copy = y.copy()
    t = np.arange(y.size) / 3600.0
    x, yy = reduce.minmax_line(t, y)
    assert yy.size <= 2 * reduce.NBINS
    assert np.nanmax(yy) == 7.0 and np.nanmin(yy) == np.nanmin(y)
    assert np.array_equal(y, copy, equal_nan=True)
    assert np.all(np.diff(x) >= 0)


def test_interval_stats_are_those_of_each_interval():
    rng = np.random.default_rng(3)
    t = np.arange(10_000) * 0.5
    y = rng.standard_normal(t.size)
    y[7] = np.nan
    x, lo, hi, rms = reduce.interval_stats(t, y, 600.0)
    k = 1200                                   # samples per 600 s interval
    first = y[:k][np.isfinite(y[:k])]
    assert x[0] == 0.0 and x[1] == t[k - 1] / 3600.0
    # The same samples reduced two ways: min/max exact, RMS to summation rounding.
    assert lo[0] == first.min() and hi[0] == first.max()
    assert rms[0] == pytest.approx(np.sqrt(np.mean(first**2)), rel=1e-12)
    assert lo.size == 2 * int(np.ceil(t.size / k))


def test_running_mean_nan_aware():
    y = np.ones(1000)
    y[100:700] = np.nan
    m = reduce.running_mean(y, 50)
    # Sums of ones are whole numbers, exact in floating point, and n/n is 1 exactly.
    assert np.all(m[:70] == 1.0)
    assert np.all(np.isnan(m[200:600]))


def test_stride_drops_nan_and_every_keeps_it():
    y = np.r_[np.ones(50), np.full(50, np.nan)]
    t = np.arange(100.0)
    assert np.isfinite(reduce.stride(t, y, 10)[1]).all()
    assert np.isnan(reduce.every(t, y, 10)[1]).any()


def test_no_figure_holds_an_unreduced_line(run, draw):
    """A Line2D longer than the reductions allow would be a 337,500-point blob."""
    fig = draw("errors")
    lines = [ln for ax in fig.axes for ln in ax.get_lines() if isinstance(ln, Line2D)]
    joined = [ln for ln in lines if ln.get_linestyle() not in ("None", "none", "")]
    dots = [ln for ln in lines if ln not in joined]
    assert max(len(ln.get_xdata()) for ln in joined) <= 2 * reduce.NBINS + 2
    assert max(len(ln.get_xdata()) for ln in dots) <= reduce.MAX_DOTS
