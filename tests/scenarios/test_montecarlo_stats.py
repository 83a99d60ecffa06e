"""Ensemble statistics (scenarios/montecarlo/stats.py) on synthetic cases whose truth
the test controls: a consistent, an over-conservative and an over-confident filter
against the averaged-NEES χ² bounds, RMS against σ, and the gap-end quantiles of
a Gaussian.  Fractions are checked within 4 binomial standard deviations.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from scenarios.config.loader import load_scenario
from scenarios.montecarlo.stats import ensemble

from .mc_helpers import (
    STATES,
    YAW,
    binomial_tol,
    chi2_var_interval,
)

# --------------------------------------------------------------------------- 9. statistics


M_OK, G, N_GAPS = 400, 1000, 2
CONV_H = 2.0
GAP_SIGMA_DEG = 0.04
# Display-unit σ per state (deg, deg/s, N m s, N m): six orders of magnitude apart.
BASE_SIGMA = np.array([2e-3, 1e-5, 0.04, 2e-5, 1e-4, 3e-7, 3e-7, 2e-7, 2e-7])


def synthetic_set(scale: float, seed: int = 1):
    """M_OK consistent cases (errors N(0, σ²) with the σ stored), then scaled by
    ``scale``; 3 failed cases; one case past n_runs.  Before CONV_H the errors are
    10× σ: a start-up transient the test must leave out."""
    rng = np.random.default_rng(seed)
    t = np.arange(G) * 60.0
    arrays, records = {}, {}
    for k in range(M_OK):
        # σ varies over time and between cases, as a filter's would.
        sigma = BASE_SIGMA * (1 + 0.5 * np.sin(t / 5000 + k))[:, None]
        z, zl = rng.standard_normal((2, G, 9))
        z[t < CONV_H * 3600] *= 10
        zl[t < CONV_H * 3600] *= 10
        err, err_l = scale * sigma * z, scale * sigma * zl
        arrays[k] = {"t_s": t, "err": err.astype(np.float32),
                     "sigma": sigma.astype(np.float32),
                     "nees": np.sum((err / sigma) ** 2, axis=1).astype(np.float32),
                     "err_linear": err_l.astype(np.float32),
                     "nees_linear": np.sum((err_l / sigma) ** 2, axis=1).astype(np.float32)}
        # The last 20 cases end before their second gap does.
        gaps = N_GAPS if k < M_OK - 20 else 1
        e = scale * GAP_SIGMA_DEG * rng.standard_normal(gaps)
        el = scale * GAP_SIGMA_DEG * rng.standard_normal(gaps)
        records[k] = {"case": k, "status": "ok",
                      "sun_gaps_h": [[1.3 + 24 * j, 9.1 + 24 * j] for j in range(gaps)],
                      "gap_end_h": [9.1 + 24 * j for j in range(gaps)],
                      "yaw_error_at_gap_end_deg": [float(x) for x in e],
                      "yaw_sigma_at_gap_end_deg": [GAP_SIGMA_DEG] * gaps,
                      "yaw_error_linear_at_gap_end_deg": [float(x) for x in el]}
    for k in (M_OK, M_OK + 2, M_OK + 3):
        records[k] = {"case": k, "status": "failed", "error": f"ScenarioError: case {k}"}
    records[M_OK + 50] = {"case": M_OK + 50, "status": "ok"}   # beyond n_runs: ignored

    def load_arrays(k):
        return arrays[k]    # KeyError for a case that should not be loaded
    return records, load_arrays


@pytest.fixture(scope="module")
def stat_nominal():
    return load_scenario("goes_next_equinox", [f"montecarlo.converged_after_h={CONV_H}"])


def _ensemble(s, scale):
    records, load = synthetic_set(scale)
    return ensemble(s, records, load, M_OK + 5, "dynprop run x --montecarlo-case K")


def test_ensemble_counts_cases(stat_nominal):
    summary, _ = _ensemble(stat_nominal, 1.0)
    assert summary["runs_requested"] == M_OK + 5
    assert summary["runs_ok"] == M_OK and summary["runs_failed"] == 3
    assert summary["runs_missing"] == 2
    assert summary["failed"] == [{"case": k, "error": f"ScenarioError: case {k}"}
                                 for k in (M_OK, M_OK + 2, M_OK + 3)]
    assert summary["grid_s"] == 60.0
    assert summary["nees"]["runs"] == M_OK


def test_consistent_filter_passes_the_averaged_nees_test(stat_nominal):
    summary, fig = _ensemble(stat_nominal, 1.0)
    n = summary["nees"]
    lo, hi = stats.chi2.ppf([0.025, 0.975], 9 * M_OK) / M_OK
    assert n["dof"] == 9
    # The same scipy quantiles, divided by M: a few ulps (1e-10 allows other scipy).
    assert n["bounds_95"] == pytest.approx([lo, hi], rel=1e-10)
    lo1, hi1 = stats.chi2.ppf([0.025, 0.975], M_OK) / M_OK
    assert n["per_state_bounds_95"] == pytest.approx([lo1, hi1], rel=1e-10)
    g = int(np.sum(np.arange(G) * 60.0 >= CONV_H * 3600))   # grid points after convergence
    frac = n["fraction_after_convergence"]
    assert frac["inside"] == pytest.approx(0.95, abs=binomial_tol(0.95, g))
    assert frac["below"] == pytest.approx(0.025, abs=binomial_tol(0.025, g))
    assert frac["above"] == pytest.approx(0.025, abs=binomial_tol(0.025, g))
    assert frac["inside"] + frac["below"] + frac["above"] == pytest.approx(1.0)
    # Mean of M·g χ²(9) values / M: 9 ± 4·√(18/(M g)) (the transient is left out).
    assert n["mean_after_convergence"] == pytest.approx(9, abs=4 * math.sqrt(18 / (M_OK * g)))
    assert set(n["per_state_mean_after_convergence"]) == set(STATES)
    for name, v in n["per_state_mean_after_convergence"].items():
        assert v == pytest.approx(1, abs=4 * math.sqrt(2 / (M_OK * g))), name
    lin = n["linear"]
    assert lin["mean_after_convergence"] == pytest.approx(9, abs=4 * math.sqrt(18 / (M_OK * g)))
    assert lin["fraction_after_convergence"]["inside"] == pytest.approx(
        0.95, abs=binomial_tol(0.95, g))
    # The figures' arrays.
    assert fig["nees_avg"].shape == (G,)
    # The same doubles written twice (npz and JSON round-trip them): identity.
    assert np.array_equal(fig["nees_bounds"], np.array([n["bounds_95"][0],
                                                        n["bounds_95"][1]]))


def test_consistent_filter_is_diagnosed_consistent(stat_nominal):
    summary, _ = _ensemble(stat_nominal, 1.0)
    n = summary["nees"]
    g = int(np.sum(np.arange(G) * 60.0 >= CONV_H * 3600))
    # Consistent by construction, and the fraction inside agrees with 95% ...
    assert n["fraction_after_convergence"]["inside"] == pytest.approx(
        0.95, abs=binomial_tol(0.95, g))
    # ... so the diagnosis must say so.
    assert n["diagnosis"].startswith("consistent"), n["diagnosis"]


def test_ensemble_rms_matches_the_filter_sigma(stat_nominal):
    summary, fig = _ensemble(stat_nominal, 1.0)
    t = np.arange(G) * 60.0
    conv = t >= CONV_H * 3600
    sigma2 = np.array([(BASE_SIGMA[None, :] * (1 + 0.5 * np.sin(t[conv] / 5000 + k))[:, None])
                       ** 2 for k in range(M_OK)])                  # (M, g, 9)
    for name, i in (("roll_deg", 0), ("yaw_deg", YAW), ("h_Nms", 4)):
        r = summary["rms_after_convergence"][name]
        s2 = sigma2[..., i]
        want = math.sqrt(s2.mean())
        assert r["filter_sigma_rms"] == pytest.approx(want, rel=1e-6)   # float32 σ
        # mean(σ² z²) has relative sd √(2 E[σ⁴]/E[σ²]²/N); the root halves it.
        tol = 4 * math.sqrt(2 * np.mean(s2**2) / np.mean(s2) ** 2 / s2.size) / 2
        assert r["ensemble_rms"] == pytest.approx(want, rel=tol), name
    assert fig["rms"].shape == (G, 9)


def test_gap_end_yaw_statistics_of_a_gaussian(stat_nominal):
    summary, fig = _ensemble(stat_nominal, 1.0)
    gaps = summary["gap_end_yaw"]
    assert [g["gap"] for g in gaps] == [1, 2]
    assert [g["n"] for g in gaps] == [M_OK, M_OK - 20]
    assert gaps[0]["start_h_median"] == pytest.approx(1.3)
    assert gaps[1]["end_h_median"] == pytest.approx(33.1)
    sig = GAP_SIGMA_DEG
    for g in gaps:
        for stat in (g, g["linear"]):
            n = stat["n"]
            assert stat["mean_deg"] == pytest.approx(0, abs=4 * sig / math.sqrt(n))
            lo, hi = chi2_var_interval(n, sig)
            assert lo <= stat["std_deg"] ** 2 <= hi
            # √(mean of n equal σ²): the sum's rounding, ≲ n·ε = 1e-13.
            assert stat["predicted_sigma_deg"] == pytest.approx(sig, rel=1e-12)
            # The |e| quantile at a Gaussian's 1σ/2σ/3σ coverage p lies at kσ: the
            # Gaussian's coverage at the sample quantile is p within 4 binomial sd.
            for k, (name, p) in enumerate((("1sigma", 0.682689492), ("2sigma", 0.954499736),
                                           ("3sigma", 0.997300204)), start=1):
                q = stat["abs_quantile_deg"][name]
                coverage = 2 * stats.norm.cdf(q / sig) - 1
                assert coverage == pytest.approx(p, abs=binomial_tol(p, n)), (name, q / sig)
                within = stat["fraction_within"][f"{k}sigma"]
                assert within == pytest.approx(p, abs=binomial_tol(p, n)), (k, within)
    assert len(fig["gap1_yaw_error_deg"]) == M_OK
    assert fig["gaps_h"].shape == (2, 2)


def test_over_conservative_filter_falls_below_the_bounds(stat_nominal):
    summary, _ = _ensemble(stat_nominal, 0.5)
    n = summary["nees"]
    g = int(np.sum(np.arange(G) * 60.0 >= CONV_H * 3600))
    # Errors half of σ: averaged NEES ~ 9/4, far under the lower bound (≈ 8.6 for M = 400).
    assert n["fraction_after_convergence"]["below"] >= 0.99
    assert n["fraction_after_convergence"]["above"] == 0
    assert n["mean_after_convergence"] == pytest.approx(9 / 4, abs=4 * math.sqrt(
        18 / (M_OK * g)) / 4)
    for v in n["per_state_mean_after_convergence"].values():
        assert v == pytest.approx(0.25, abs=4 * math.sqrt(2 / (M_OK * g)) / 4)
    assert n["diagnosis"].startswith("over-conservative")
    # |e| ≤ σ now happens whenever |z| ≤ 2.
    for g_ in summary["gap_end_yaw"]:
        p = 0.954499736
        assert g_["fraction_within"]["1sigma"] == pytest.approx(p, abs=binomial_tol(p, g_["n"]))


def test_over_confident_filter_rises_above_the_bounds(stat_nominal):
    summary, _ = _ensemble(stat_nominal, 2.0)
    n = summary["nees"]
    assert n["fraction_after_convergence"]["above"] >= 0.99
    assert n["fraction_after_convergence"]["below"] == 0
    assert n["mean_after_convergence"] == pytest.approx(36, rel=0.01)
    assert n["diagnosis"].startswith("over-confident")


def test_no_successful_case_gives_a_summary_without_statistics(stat_nominal):
    records = {0: {"case": 0, "status": "failed", "error": "RuntimeError: boom"}}

    def load(k):
        raise AssertionError("no arrays of a failed case may be loaded")
    summary, fig = ensemble(stat_nominal, records, load, 2, "cmd")
    assert summary["runs_ok"] == 0 and summary["runs_failed"] == 1
    assert summary["runs_missing"] == 1
    assert fig == {}




# --------------------------------------------------------------------------- per-state diagnosis

# The 6-case set: (e/σ)² per state, averaged over runs and time.
SIX_CASES = {"roll_deg": 0.913, "roll_rate_degps": 0.315, "yaw_deg": 0.283,
             "yaw_rate_degps": 0.200, "h_Nms": 1.031, "N_px_Nm": 0.0351, "N_pz_Nm": 0.0303,
             "N_cx_Nm": 0.0425, "N_cz_Nm": 0.0608}


def _groups(diagnosis: str) -> dict[str, set[str]]:
    """The states the diagnosis lists below, inside and above the per-state bounds."""
    tail = diagnosis.split("N = ")[1].split("): ", 1)[1].split("; the linear twin")[0]
    out = {}
    for part in tail.split(" — "):
        where, _, names = part.partition(" ")
        out[where] = set() if names == "none" else {x.rsplit(" ", 1)[0]
                                                    for x in names.split(", ")}
    return out


@pytest.mark.parametrize("runs", [6, 50])
def test_diagnosis_places_every_state_against_its_chi2_bounds(runs):
    """Every state is listed, in the group its χ²(N)/N bounds put it in: with 6 runs
    roll rate (0.32) and yaw (0.28) are inside [0.21, 2.4], with 50 below [0.64, 1.4]."""
    from estimator.kalman.consistency import chi2_bounds
    from scenarios.montecarlo.stats import diagnose, per_state_test
    lo, hi = chi2_bounds(1, runs)
    states = dict(SIX_CASES, N_cz_Nm=3.0)       # one state above, too
    n = {"runs": runs, "points_after_convergence": 2500, "per_state_bounds_95": [lo, hi],
         "per_state_mean_after_convergence": states,
         "fraction_after_convergence": {"inside": 0.01, "below": 0.99, "above": 0.0}}
    want = {w: {k for k, v in states.items() if (v < lo, lo <= v <= hi, v > hi)[i]}
            for i, w in enumerate(("below", "inside", "above"))}
    assert ({"yaw_deg", "roll_rate_degps"} <= want["inside"]) == (runs == 6)
    assert ({"yaw_deg", "roll_rate_degps"} <= want["below"]) == (runs == 50)
    test = per_state_test(n)
    assert {w: {k for k, v in test.items() if v == w} for w in want} == want
    d = diagnose(n)
    assert _groups(d) == want, d
    for k, v in states.items():
        assert f"{k} {v:.2g}" in d
    assert f"N = {runs}" in d and "below 1" not in d


def test_ensemble_diagnosis_lists_all_states_below_the_bound(stat_nominal):
    """Synthetic cases whose errors are 0.3 σ in four states, 1.5 σ in one and σ in
    the rest: (e/σ)² ≈ 0.09, 2.25 and 1 against [0.87, 1.14] for 400 runs."""
    scale = np.ones(9)
    scale[[1, 2, 5, 8]] = 0.3
    scale[4] = 1.5
    records, load = synthetic_set(1.0)

    def scaled(k):
        a = dict(load(k))
        a["err"] = (a["err"] * scale).astype(np.float32)
        a["nees"] = np.sum((a["err"].astype(float) / a["sigma"]) ** 2, axis=1)
        return a
    summary, _ = ensemble(stat_nominal, records, scaled, M_OK + 5, "cmd")
    n = summary["nees"]
    expect = {STATES[i]: "below" for i in (1, 2, 5, 8)} | {STATES[4]: "above"}
    assert n["per_state_test_95"] == {s: expect.get(s, "inside") for s in STATES}
    g = _groups(n["diagnosis"])
    assert g["below"] == {STATES[i] for i in (1, 2, 5, 8)}
    assert g["above"] == {STATES[4]}
    assert g["inside"] == {STATES[i] for i in (0, 3, 6, 7)}


# --------------------------------------------------------------------------- gap-end quantiles


def test_quantile_interval_covers_the_true_quantile():
    """The order-statistic interval holds the true p-quantile of |N(0, 1)| at least
    95% of the time (here 2000 sets of 40), and is open above exactly when the set is
    smaller than ln(0.025)/ln(p)."""
    from scenarios.montecarlo.stats import quantile_interval, runs_to_bound_quantile
    rng = np.random.default_rng(7)
    for p in (0.682689492, 0.954499736):
        true = stats.norm.ppf((1 + p) / 2)
        hits = opens = 0
        for _ in range(2000):
            lo, hi = quantile_interval(rng.standard_normal(40), p)
            opens += hi is None
            hits += lo <= true and (hi is None or true <= hi)
        assert hits / 2000 >= 0.95 - binomial_tol(0.95, 2000), (p, hits)
        assert opens == (2000 if 40 < runs_to_bound_quantile(p) else 0)
    assert [runs_to_bound_quantile(p) for p in (0.682689492, 0.954499736, 0.997300204)] == \
        [10, 80, 1365]
    for n, p in ((9, 0.682689492), (10, 0.682689492), (1364, 0.997300204),
                 (1365, 0.997300204)):
        closed = quantile_interval(np.arange(1.0, n + 1), p)[1] is not None
        assert closed == (n >= runs_to_bound_quantile(p)), (n, p)


def test_one_line_calls_the_gap_quantiles_quantiles(stat_nominal):
    """400 cases bound the 68.3% quantile of |e| but not the 99.7% one (1365 needed)."""
    from scenarios.montecarlo.runset import one_line
    summary, _ = _ensemble(stat_nominal, 1.0)
    line = one_line(summary)
    assert "3σ" not in line and "1σ/" not in line
    for g in summary["gap_end_yaw"]:
        q = g["abs_quantile_deg"]
        assert (f"68.3%/99.7% quantiles of |e| {q['1sigma']:.4f}/{q['3sigma']:.4f} deg"
                in line)
        assert g["abs_quantile_ci95_deg"]["1sigma"][1] is not None
        assert g["abs_quantile_ci95_deg"]["3sigma"][1] is None
        assert (f"poorly determined from N = {g['n']} cases: a 95% upper bound on the "
                "99.7% quantile needs ≥ 1365 cases") in line
    assert "68.3% quantile needs" not in line


# --------------------------------------------------------------------------- gap-end figure


def test_gap_end_strip_plot_shows_every_case_on_a_fitted_axis(stat_nominal):
    """One column per gap end, one dot per case at e/σ, every dot inside the axis,
    the ±1/2/3 lines drawn, and the axis no wider than the data and the ±3 lines."""
    import matplotlib.pyplot as plt
    from matplotlib.collections import PathCollection

    from plots.montecarlo import plot_gap_end_yaw
    summary, fig = _ensemble(stat_nominal, 1.0)
    fig["gap2_yaw_error_deg"] = fig["gap2_yaw_error_deg"].copy()
    fig["gap2_yaw_error_deg"][5] = -5.0 * fig["gap2_yaw_sigma_deg"][5]    # one outlier
    f = plot_gap_end_yaw(fig, summary, "caption")
    ax = f.axes[0]
    lo, hi = ax.get_ylim()
    points = [c.get_offsets() for c in ax.collections if isinstance(c, PathCollection)]
    assert len(points) == 2 * len(summary["gap_end_yaw"])      # truth and twin per gap
    for g in summary["gap_end_yaw"]:
        j = g["gap"]
        for key, pts in ((f"gap{j}_yaw_error_deg", points[2 * (j - 1)]),
                         (f"gap{j}_yaw_error_linear_deg", points[2 * (j - 1) + 1])):
            z = fig[key] / fig[f"gap{j}_yaw_sigma_deg"]
            assert np.allclose(np.sort(pts[:, 1]), np.sort(z), rtol=1e-12)
            assert np.all(np.abs(pts[:, 0] - (j - 1)) < 0.5)  # its own column
    ys = np.concatenate([p[:, 1] for p in points])
    assert lo < ys.min() and ys.max() < hi
    assert lo < -3 and hi > 3 and max(-lo, hi) <= 1.15 * max(3, np.abs(ys).max())
    levels = sorted(round(line.get_ydata()[0], 12) for line in ax.lines
                    if line.get_ydata()[0] != 0)
    assert levels == [-3, -2, -1, 1, 2, 3]
    assert "runs" not in ax.get_ylabel()
    labels = [t.get_text() for t in ax.get_xticklabels()]
    assert len(labels) == 2 and all("quantiles of |e|" in t for t in labels)
    plt.close(f)
    # Six cases: the axis fits the ±3 lines, not ten times the data.
    from scenarios.montecarlo.stats import _gap_stats
    six = {k: v[:6] for k, v in fig.items() if k.startswith("gap1_")}
    g1 = {"gap": 1, "end_h_median": 9.1,
          **_gap_stats(six["gap1_yaw_error_deg"], six["gap1_yaw_sigma_deg"])}
    f = plot_gap_end_yaw(six, {"gap_end_yaw": [g1]}, "caption")
    lo, hi = f.axes[0].get_ylim()
    assert 3 < hi <= 3.5 and -3.5 <= lo < -3
    assert "poorly determined from N = 6" in f.axes[0].get_xticklabels()[0].get_text()
    plt.close(f)
