"""Run figures: realistic sizes (2 days at 0.512 s), units on axes, inputs intact.

How long drawing takes is measured by `make bench` (benchmarks/run.py), not here:
a wall-clock limit flakes on shared cores."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from plots import run_figures as rf  # noqa: E402

DT = 0.512
N = 337_501                       # 2 days at 0.512 s
TITLE = "goes_next_equinox — epoch 2026-03-20T12:00:00Z, seed 7"
NEES_DOF = 9
NEES_BOUNDS = (2.700, 19.023)     # χ²(9) 2.5% / 97.5%
NIS_BOUNDS = (0.000982, 5.024)    # χ²(1) 2.5% / 97.5%


def _colored(rng, n, corr_samples):
    """Unit-variance low-pass noise (moving average of white noise)."""
    w = rng.standard_normal(n + corr_samples)
    c = np.cumsum(np.r_[0.0, w])
    y = (c[corr_samples:] - c[:-corr_samples])[:n]
    return y / np.sqrt(corr_samples)


def make_run(seed: int = 1) -> dict:
    """Synthetic arrays shaped like one estimation run (no physics, just plausible)."""
    rng = np.random.default_rng(seed)
    t = np.arange(N) * DT
    t_h = t / 3600.0
    hod = t_h % 24.0
    gap = (hod >= 14.0) & (hod < 22.0)               # 8 h daily gap, both end in the record
    into_gap = np.where(gap, hod - 14.0, 0.0)        # h since the gap began
    since_gap = np.where(~gap & (hod >= 22.0), hod - 22.0, 24.0)
    since_gap = np.where(~gap & (hod < 14.0), hod + 2.0, since_gap)
    start = np.exp(-t / 1800.0)                      # initial convergence, 30 min

    # yaw σ: 0.003° lit, growing to ~0.0408° at the gap end, back within minutes of Sun.
    sig_yaw = 0.003 + np.where(gap, 0.0378 * (into_gap / 8.0) ** 1.5,
                               0.0378 * np.exp(-since_gap * 60 / 5.0)) + 0.05 * start
    sig_roll = 0.0025 + 0.03 * start
    sig_h = 0.004 + 0.002 * gap + 0.05 * start       # N m s
    series = {}
    for name, sig, unit in (("roll", sig_roll, "deg"), ("yaw", sig_yaw, "deg"),
                            ("h", sig_h, "N m s")):
        lin = sig * _colored(rng, N, 400)
        real = lin + 0.4 * sig * np.sin(2 * np.pi * t / 86164.0) + \
            0.6 * sig * _colored(rng, N, 2000)
        smoothed = 0.4 * sig * _colored(rng, N, 800)
        series[name] = {"unit": unit, "real": real, "linear": lin, "sigma": sig,
                        "smoothed": smoothed}
    series["h"]["smoothed"] = None

    est, tru, tsig = {}, {}, {}
    for k, name in enumerate(rf.TORQUE_NAMES):
        truth_val = (2.0 + k) * 1e-6 * (-1) ** k
        tru[name] = truth_val + 1e-7 * np.sin(2 * np.pi * t / 86164.0 + k)
        s = 3e-7 * (1 + 4 * gap * (name == "N_cz")) + 3e-5 * start
        tsig[name] = s
        est[name] = tru[name] + s * _colored(rng, N, 1000) - truth_val * start

    nees_lin = rng.chisquare(NEES_DOF, N)
    nees_real = nees_lin * (1 + 300 * gap * (into_gap / 8.0) ** 2 + 5 * start)
    nis = {n: rng.chisquare(1, N) for n in ("roll", "yaw", "h")}
    nis["yaw"][gap] = np.nan
    nis["roll"] = nis["roll"] * 1.3

    orbit = 2 * np.pi * t / 86164.0
    truth_att = {"roll": 0.004 * np.sin(orbit), "pitch": 0.006 * np.cos(orbit) + 0.002,
                 "yaw": 0.02 * np.sin(orbit + 0.5)}
    measured = {n: v + 0.015 * rng.standard_normal(N) for n, v in truth_att.items()}
    measured["yaw"][gap] = np.nan
    wheels = {"MW1": 5485.0 + 2.0 * np.sin(orbit) + 0.05 * rng.standard_normal(N),
              "MW2": 5470.0 - 1.5 * np.sin(orbit) + 0.05 * rng.standard_normal(N)}
    return {"t_s": t, "gap": gap, "series": series, "est": est, "tru": tru, "tsig": tsig,
            "nees_real": nees_real, "nees_lin": nees_lin, "nis": nis,
            "measured": measured, "truth_att": truth_att, "wheels": wheels}


def figure_calls(run: dict) -> dict:
    """name -> zero-argument callable drawing that figure from ``run``."""
    return {
        "errors": lambda: rf.plot_errors(run["t_s"], run["gap"], run["series"], TITLE),
        "torques": lambda: rf.plot_torques(run["t_s"], run["gap"], run["est"], run["tru"],
                                           run["tsig"], TITLE),
        "consistency": lambda: rf.plot_consistency(
            run["t_s"], run["nees_real"], run["nees_lin"], NEES_DOF, NEES_BOUNDS, run["nis"],
            NIS_BOUNDS, TITLE),
        "telemetry": lambda: rf.plot_telemetry_overview(
            run["t_s"], run["measured"], run["truth_att"], run["wheels"], run["gap"], TITLE),
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


UNITS = {"errors": ("deg", "N m s"), "torques": ("N m",), "consistency": (),
         "telemetry": ("deg", "rpm")}


@pytest.mark.parametrize("name", ["errors", "torques", "consistency", "telemetry"])
def test_figure(run, name, tmp_path):
    """Each figure draws, labels its axes with units and leaves its inputs intact.
    Identity is the requirement for the inputs: drawing must not change a bit of
    the caller's arrays."""
    before = {p: a.copy() for p, a in _arrays(run)}
    for _, a in _arrays(run):
        a.flags.writeable = False          # any in-place write raises
    try:
        fig = figure_calls(run)[name]()
        out = tmp_path / f"{name}.png"
        fig.savefig(out, dpi=120)
    finally:
        for _, a in _arrays(run):
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
        with_legend = [ax for ax in axes if ax.get_legend() is not None]
        assert with_legend == axes or (name == "torques" and len(with_legend) == 2)
    finally:
        plt.close(fig)
    after = dict(_arrays(run))
    assert before.keys() == after.keys()
    for p, a in before.items():
        assert np.array_equal(a, after[p], equal_nan=True), p


def test_error_units_per_panel(run):
    fig = figure_calls(run)["errors"]()
    try:
        labels = [ax.get_ylabel() for ax in fig.axes]
        assert "deg" in labels[0] and labels[0].startswith("roll")
        assert "deg" in labels[1] and labels[1].startswith("yaw")
        assert "N m s" in labels[2] and labels[2].startswith("h")
    finally:
        plt.close(fig)


def test_torque_units(run):
    fig = figure_calls(run)["torques"]()
    try:
        labels = [ax.get_ylabel() for ax in fig.axes]
        assert [lab.split(" (")[0] for lab in labels] == list(rf.TORQUE_NAMES)
        # Torques of ~1e-6 N m: ticks in 10⁻⁶ N m, said in the label, no offset text.
        assert all(lab.endswith("(10⁻⁶ N m)") for lab in labels), labels
    finally:
        plt.close(fig)


def test_yaw_panel_marks_paper_sigma_at_gap_ends(run):
    fig = figure_calls(run)["errors"]()
    try:
        yaw = fig.axes[1]
        texts = [t.get_text() for t in yaw.get_legend().get_texts()]
        assert any("paper σ_yaw = 0.040° (Eq. 56)" in t for t in texts)
        gap = run["gap"]
        ends = np.flatnonzero(gap[:-1] & ~gap[1:])
        assert ends.size == 2
        marks = [ln for ln in yaw.get_lines() if "paper" in str(ln.get_label())]
        ys = np.unique(np.round(np.concatenate([m.get_ydata() for m in marks]), 6))
        np.testing.assert_allclose(ys, [-0.12, -0.04, 0.04, 0.12])
        xs = np.unique(np.round(np.concatenate([m.get_xdata() for m in marks]), 9))
        np.testing.assert_allclose(xs, run["t_s"][ends] / 3600.0)
        # The filter σ at the last gap end is written on the panel.
        s_last = run["series"]["yaw"]["sigma"][ends[-1]]
        notes = [c.get_text() for c in yaw.texts]
        assert any(f"{s_last:.4f}°" in n for n in notes), notes
        # Envelope and paper ±3σ marks fit inside the axes.
        lo, hi = yaw.get_ylim()
        assert hi >= 0.12 and lo <= -0.12
    finally:
        plt.close(fig)


def test_envelope_visible(run):
    """The ±3σ band occupies a visible share of every error panel, lit and in the gap."""
    fig = figure_calls(run)["errors"]()
    try:
        for ax, name in zip(fig.axes[:3], ("roll", "yaw", "h"), strict=True):
            sig = run["series"][name]["sigma"]
            lit = np.median(3 * sig[~run["gap"]])
            lo, hi = ax.get_ylim()
            tr = ax.transScale.transform
            y0 = tr([[0, 0]])[0, 1]
            frac = (tr([[0, lit]])[0, 1] - y0) / (tr([[0, hi]])[0, 1] - tr([[0, lo]])[0, 1])
            assert frac > 0.05, (name, frac)
    finally:
        plt.close(fig)


def test_minmax_keeps_extremes_and_inputs():
    """Identity is the requirement: min/max decimation selects samples, so the
    extremes it keeps are the input's values exactly, and the input is unchanged."""
    y = np.sin(np.linspace(0, 50, 100_000))
    y[12_345] = 7.0
    y[54_321] = np.nan
    copy = y.copy()
    t = np.arange(y.size) / 3600.0
    x, yy = rf._minmax_line(t, y)
    assert yy.size <= 2 * rf._NBINS
    assert np.nanmax(yy) == 7.0 and np.nanmin(yy) == np.nanmin(y)
    assert np.array_equal(y, copy, equal_nan=True)
    assert np.all(np.diff(x) >= 0)


def test_running_mean_nan_aware():
    y = np.ones(1000)
    y[100:700] = np.nan
    m = rf._running_mean(y, 50)
    # Sums of ones are whole numbers, exact in floating point, and n/n is 1 exactly.
    assert np.all(m[:70] == 1.0)
    assert np.all(np.isnan(m[200:600]))
