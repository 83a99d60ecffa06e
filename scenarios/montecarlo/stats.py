"""Ensemble statistics of a Monte Carlo set: the Monte Carlo version of the
paper's accuracy claim (ensemble RMS against the filter's σ and Eq. 55), the
averaged-NEES test, and the yaw error at the end of each Sun gap.

Averaged NEES: with N independent runs, N·ε̄(t) ~ χ²(9N) when the filter is
consistent, so ε̄(t) must lie in the χ²(9N)/N bounds 95% of the time (Bar-Shalom,
Li & Kirubarajan, *Estimation with Applications to Tracking and Navigation*,
Section 5.4.2).  Per state, N·mean((e/σ)²) ~ χ²(N) likewise; that decomposition
shows which states make the NEES what it is.

Gap-end quantiles: the |e| quantile at a Gaussian's 1σ/2σ/3σ coverage (68.3%,
95.4%, 99.7%) is a sample quantile of N values, not a σ.  Each comes with its
distribution-free 95% interval between order statistics (David & Nagaraja, *Order
Statistics*, 3rd ed., Section 7.1), which is open above until N ≥ ln(0.025)/ln(p):
10 cases for 68.3%, 80 for 95.4%, 1365 for 99.7%.
"""

from __future__ import annotations

import numpy as np
from dynprop.estimator.kalman.consistency import chi2_bounds
from dynprop.estimator.linear.model import H_WHEEL, N_STATES, R, Y
from scipy import stats as sps

from .. import __version__
from ..config.build import estimator_model
from ..config.schema import Scenario
from ..files.columns import PITCH_COLUMNS, STATE_COLUMNS
from ..files.summary import eq55_sigma_yaw_deg

# |e| quantiles that a Gaussian puts at 1σ, 2σ and 3σ (the keys of montecarlo.json
# name the Gaussian level; the values are sample quantiles, not σ).
SIGMA_LEVELS = {"1sigma": 0.682689492, "2sigma": 0.954499736, "3sigma": 0.997300204}
QUANTILE_CONFIDENCE = 0.95


def quantile_label(p: float) -> str:
    """'99.7%' for 0.9973: the name a quantile goes by in text and figures."""
    return f"{100 * p:.1f}%"


def quantile_interval(values, p: float, confidence: float = QUANTILE_CONFIDENCE
                      ) -> list[float | None]:
    """Distribution-free interval [X_(r), X_(s)] holding the p-quantile of |e| with
    probability ≥ ``confidence``: the number B of values at or below the quantile is
    Binomial(N, p), X_(r) ≤ ξ_p iff B ≥ r and X_(s) > ξ_p iff B < s, each side
    taking (1 − confidence)/2.  X_(0) = 0 (|e| ≥ 0); None above when even the
    largest value is not above ξ_p with that probability (too few cases)."""
    a = np.sort(np.abs(np.asarray(values, dtype=float)))
    n, tail = a.size, (1 - confidence) / 2
    r = next((r for r in range(n, 0, -1) if sps.binom.sf(r - 1, n, p) >= 1 - tail), 0)
    s = next((s for s in range(1, n + 1) if sps.binom.cdf(s - 1, n, p) >= 1 - tail), None)
    return [float(a[r - 1]) if r else 0.0, None if s is None else float(a[s - 1])]


def runs_to_bound_quantile(p: float, confidence: float = QUANTILE_CONFIDENCE) -> int:
    """Fewest cases for which the interval of ``quantile_interval`` is closed above:
    the largest value must exceed ξ_p with probability 1 − p^N ≥ 1 − (1 − confidence)/2."""
    return int(np.ceil(np.log((1 - confidence) / 2) / np.log(p)))


def _fraction(v, lo, hi) -> dict | None:
    v = np.asarray(v)
    if not v.size:
        return None
    return {"inside": float(np.mean((v >= lo) & (v <= hi))), "below": float(np.mean(v < lo)),
            "above": float(np.mean(v > hi))}


def _mean(v, axis=None):
    """Mean, or None where there is nothing to average (a run shorter than the
    convergence time)."""
    v = np.asarray(v)
    if not v.size:
        return None
    m = v.mean(axis=axis)
    return float(m) if np.ndim(m) == 0 else [float(x) for x in m]


def _gap_stats(errors: np.ndarray, sigmas: np.ndarray | None) -> dict:
    a = np.abs(errors)
    out = {"n": int(errors.size), "mean_deg": float(errors.mean()),
           "std_deg": float(errors.std(ddof=1)) if errors.size > 1 else None,
           "rms_deg": float(np.sqrt(np.mean(errors**2)))}
    out["abs_quantile_deg"] = {name: float(np.quantile(a, p)) for name, p in SIGMA_LEVELS.items()}
    out["abs_quantile_level"] = dict(SIGMA_LEVELS)
    out["abs_quantile_ci95_deg"] = {name: quantile_interval(a, p)
                                    for name, p in SIGMA_LEVELS.items()}
    if sigmas is not None:
        out["predicted_sigma_deg"] = float(np.sqrt(np.mean(sigmas**2)))
        out["fraction_within"] = {f"{k}sigma": float(np.mean(a <= k * sigmas)) for k in (1, 2, 3)}
    return out


def _root(v):
    return None if v is None else float(np.sqrt(v))


def _other_filter(name: str, mean: dict, conv, bounds, wanted: dict, ok: list, n_gaps: int,
                  fig: dict) -> dict:
    """montecarlo.json's section of a filter besides the paper's (``estimator.filters``):
    its ensemble RMS and σ after convergence, averaged NEES, and gap-end yaw."""
    nees_avg = mean[f"nees_{name}"]
    out = {"nees": {"mean_after_convergence": _mean(nees_avg[conv]),
                    "fraction_after_convergence": _fraction(nees_avg[conv], *bounds)},
           "rms_after_convergence": {
               col: {"ensemble_rms": _root(_mean(mean[f"err2_{name}"][conv, k])),
                     "filter_sigma_rms": _root(_mean(mean[f"sig2_{name}"][conv, k]))}
               for col, k in (("roll_deg", R), ("yaw_deg", Y), ("h_Nms", H_WHEEL))},
           "gap_end_yaw": []}
    fig[f"rms_{name}"] = np.sqrt(mean[f"err2_{name}"])
    fig[f"nees_avg_{name}"] = nees_avg
    for j in range(n_gaps):
        have = [k for k in ok if len(wanted[k][f"yaw_error_{name}_at_gap_end_deg"]) > j]
        e = np.array([wanted[k][f"yaw_error_{name}_at_gap_end_deg"][j] for k in have])
        sg = np.array([wanted[k][f"yaw_sigma_{name}_at_gap_end_deg"][j] for k in have])
        out["gap_end_yaw"].append({"gap": j + 1, **_gap_stats(e, sg)})
        fig[f"gap{j + 1}_yaw_error_{name}_deg"] = e
    return out


def _pitch_section(mean: dict, conv, m: int, fig: dict) -> dict:
    """montecarlo.json's ``pitch``: the pitch filter's (``run.pitch``) averaged 3-state
    NEES against χ²(3) bounds for the ``m`` cases, and its ensemble RMS and σ after
    convergence, apart from the 9-state figures."""
    nees_avg = mean["nees_pitch"]
    bounds = chi2_bounds(3, m)
    fig["rms_pitch"] = np.sqrt(mean["err2_pitch"])
    fig["nees_avg_pitch"] = nees_avg
    return {"nees": {"dof": 3, "bounds_95": list(bounds),
                     "mean_after_convergence": _mean(nees_avg[conv]),
                     "fraction_after_convergence": _fraction(nees_avg[conv], *bounds)},
            "rms_after_convergence": {
                col: {"ensemble_rms": _root(_mean(mean["err2_pitch"][conv, k])),
                      "filter_sigma_rms": _root(_mean(mean["sig2_pitch"][conv, k]))}
                for k, col in enumerate(PITCH_COLUMNS)}}


def ensemble(s: Scenario, records: dict[int, dict], load_arrays, n_runs: int,
             command: str) -> tuple[dict, dict[str, np.ndarray]]:
    """montecarlo.json and the arrays the figures are drawn from (montecarlo.npz)."""
    wanted = {k: r for k, r in records.items() if k < n_runs}
    ok = sorted(k for k, r in wanted.items() if r["status"] == "ok")
    fails = [{"case": k, "error": wanted[k]["error"]} for k in sorted(wanted)
             if wanted[k]["status"] != "ok"]
    summary = {"scenario": s.name, "seed": s.seed, "dynprop_version": __version__,
               "runs_requested": n_runs, "runs_ok": len(ok), "runs_failed": len(fails),
               "runs_missing": n_runs - len(wanted), "failed": fails,
               "dispersions": {k: d.model_dump() for k, d in s.montecarlo.dispersions.items()},
               "grid_s": None, "converged_after_h": s.montecarlo.converged_after_h,
               "analytic_sigma_yaw_deg": eq55_sigma_yaw_deg(s, estimator_model(s)[0]),
               "reproduce_case": command}
    if not ok:
        return summary, {}
    # Running sums over the cases, one case in memory at a time: a set of thousands
    # of two-day cases never holds its grids all at once.
    sums: dict[str, np.ndarray] = {}
    linear = pitch = True
    others = [f for f in s.estimator.filters if f != "paper"]
    for k in ok:
        a = load_arrays(k)
        err, sig = a["err"].astype(float), a["sigma"].astype(float)
        terms = {"err": err, "err2": err**2, "sig2": sig**2, "nsq": (err / sig) ** 2,
                 "nees": a["nees"].astype(float)}
        linear = linear and "err_linear" in a
        if linear:
            terms["err2_linear"] = a["err_linear"].astype(float) ** 2
            terms["nees_linear"] = a["nees_linear"].astype(float)
        # A set resumed from cases run before the pitch filter has none of its arrays.
        pitch = pitch and "err_pitch" in a
        if pitch:
            terms["err2_pitch"] = a["err_pitch"].astype(float) ** 2
            terms["sig2_pitch"] = a["sigma_pitch"].astype(float) ** 2
            terms["nees_pitch"] = a["nees_pitch"].astype(float)
        for name in others:
            if f"err_{name}" not in a:
                raise ValueError(f"case {k} has no {name} arrays: it was run without that "
                                 "filter (rerun it with --retry-failed after removing it)")
            terms[f"err2_{name}"] = a[f"err_{name}"].astype(float) ** 2
            terms[f"sig2_{name}"] = a[f"sigma_{name}"].astype(float) ** 2
            terms[f"nees_{name}"] = a[f"nees_{name}"].astype(float)
        for name, v in terms.items():
            sums[name] = sums[name] + v if name in sums else v
        t_s = a["t_s"]
    m = len(ok)
    mean = {name: v / m for name, v in sums.items()}
    summary["grid_s"] = float(t_s[1] - t_s[0]) if len(t_s) > 1 else None
    conv = t_s >= s.montecarlo.converged_after_h * 3600

    nees_avg, nsq = mean["nees"], mean["nsq"]          # (G,), (G, 9)
    bounds = chi2_bounds(N_STATES, m)
    b1 = chi2_bounds(1, m)
    summary["nees"] = {
        "dof": N_STATES, "runs": m, "bounds_95": list(bounds),
        "points_after_convergence": int(conv.sum()),
        "last_point_h": float(t_s[-1] / 3600.0),
        "mean_after_convergence": _mean(nees_avg[conv]),
        "fraction_after_convergence": _fraction(nees_avg[conv], *bounds),
        "per_state_bounds_95": list(b1),
        "per_state_mean_after_convergence": dict(zip(
            STATE_COLUMNS, _mean(nsq[conv], axis=0) or [None] * N_STATES, strict=True)),
    }
    fig = {"t_s": t_s, "rms": np.sqrt(mean["err2"]), "sigma_rms": np.sqrt(mean["sig2"]),
           "nees_avg": nees_avg, "nees_bounds": np.array(bounds), "nsq": nsq,
           "nsq_bounds": np.array(b1), "mean_err": mean["err"]}
    if linear:
        nees_l = mean["nees_linear"]
        summary["nees"]["linear"] = {
            "mean_after_convergence": _mean(nees_l[conv]),
            "fraction_after_convergence": _fraction(nees_l[conv], *bounds)}
        fig["rms_linear"] = np.sqrt(mean["err2_linear"])
        fig["nees_avg_linear"] = nees_l
    summary["rms_after_convergence"] = {
        name: {"ensemble_rms": _root(_mean(mean["err2"][conv, k])),
               "filter_sigma_rms": _root(_mean(mean["sig2"][conv, k]))}
        for name, k in (("roll_deg", R), ("yaw_deg", Y), ("h_Nms", H_WHEEL))}

    # Yaw at the end of each Sun gap (gap j of every case: same local time, since
    # epochs move by whole days).
    gaps = []
    n_gaps = max(len(wanted[k]["yaw_error_at_gap_end_deg"]) for k in ok)
    for j in range(n_gaps):
        have = [k for k in ok if len(wanted[k]["yaw_error_at_gap_end_deg"]) > j]
        e = np.array([wanted[k]["yaw_error_at_gap_end_deg"][j] for k in have])
        sg = np.array([wanted[k]["yaw_sigma_at_gap_end_deg"][j] for k in have])
        g = {"gap": j + 1,
             "start_h_median": float(np.median([wanted[k]["sun_gaps_h"][j][0] for k in have])),
             "end_h_median": float(np.median([wanted[k]["gap_end_h"][j] for k in have])),
             **_gap_stats(e, sg)}
        fig[f"gap{j + 1}_yaw_error_deg"] = e
        fig[f"gap{j + 1}_yaw_sigma_deg"] = sg
        if all("yaw_error_linear_at_gap_end_deg" in wanted[k] for k in have):
            el = np.array([wanted[k]["yaw_error_linear_at_gap_end_deg"][j] for k in have])
            g["linear"] = _gap_stats(el, sg)
            fig[f"gap{j + 1}_yaw_error_linear_deg"] = el
        gaps.append(g)
    summary["gap_end_yaw"] = gaps
    summary["pitch"] = _pitch_section(mean, conv, m, fig) if pitch else None
    for name in others:
        summary[name] = _other_filter(name, mean, conv, bounds, wanted, ok, n_gaps, fig)
    summary["nees"]["per_state_test_95"] = per_state_test(summary["nees"])
    summary["nees"]["diagnosis"] = diagnose(summary["nees"], s.montecarlo.converged_after_h)
    fig["gaps_h"] = np.array([[g["start_h_median"], g["end_h_median"]] for g in gaps]
                             ).reshape(-1, 2)
    return summary, fig


def per_state_test(n: dict) -> dict[str, str] | None:
    """Each state's time-averaged (e/σ)² against the per-state 95% bounds of
    χ²(N)/N: "below", "inside" or "above".

    Those bounds hold one grid point of a consistent filter 95% of the time.  The
    time average of such points scatters less about 1 than one point does (as much
    when the points are fully correlated, less the less they are), so the bounds
    are conservative for it whatever the time correlation: outside them is a real
    departure, inside is no evidence either way.  "Below 1" alone is not a test:
    with N = 6 cases one grid point of a consistent state lies anywhere in
    [0.21, 2.4]."""
    states = n["per_state_mean_after_convergence"]
    if any(v is None for v in states.values()):
        return None
    lo, hi = n["per_state_bounds_95"]
    return {k: "below" if v < lo else "above" if v > hi else "inside"
            for k, v in states.items()}


def untested_why(n: dict, converged_h: float) -> str:
    """Why a set has no NEES test: its grid has no point at or after the time from
    which the filter counts as converged (``converged_h``)."""
    return (f"no grid point at or after montecarlo.converged_after_h = "
            f"{converged_h:g} h: the last is at {n['last_point_h']:.3g} h")


def nees_inside_needed(points: int) -> float:
    """The share of grid points inside the averaged NEES's 95% bounds a consistent
    filter reaches: 95% on average, so half of consistent ensembles score a little
    less; allow 3 binomial standard deviations (counting the grid points as
    independent, which makes the allowance a lower bound)."""
    return 0.95 - 3 * np.sqrt(0.95 * 0.05 / max(1, points))


def diagnose(n: dict, converged_h: float | None = None) -> str:
    """One sentence on where the averaged NEES sits and which states put it there
    (every state, grouped by ``per_state_test``); with the linear twin, whether the
    linearization or the filter's own model is the cause (the twin obeys that model
    exactly)."""
    frac = n["fraction_after_convergence"]
    if frac is None:
        return f"not tested ({untested_why(n, converged_h)})"
    lo, hi = n["per_state_bounds_95"]
    states = n["per_state_mean_after_convergence"]
    test = per_state_test(n)
    if frac["inside"] >= 0.95:
        head = f"consistent: inside the bounds {100 * frac['inside']:.0f}% of the time"
    elif frac["inside"] >= nees_inside_needed(n["points_after_convergence"]):
        head = (f"consistent within sampling scatter: inside the bounds "
                f"{100 * frac['inside']:.1f}% of the time, just under 95%")
    elif frac["below"] > frac["above"]:
        head = (f"over-conservative: below the bounds {100 * frac['below']:.0f}% of the "
                "time (the filter's σ is larger than its errors)")
    else:
        head = (f"over-confident: above the bounds {100 * frac['above']:.0f}% of the time "
                "(errors larger than the filter's σ)")
    groups = {where: ", ".join(f"{k} {states[k]:.2g}" for k in states if test[k] == where)
              or "none" for where in ("below", "inside", "above")}
    parts = [head,
             f"per state, mean (e/σ)² against its 95% bounds [{lo:.2g}, {hi:.2g}] "
             f"(χ²(N)/N, N = {n['runs']}): below {groups['below']} — inside "
             f"{groups['inside']} — above {groups['above']}"]
    lin = n.get("linear")
    if lin and lin["mean_after_convergence"] is not None:
        real, twin = n["mean_after_convergence"], lin["mean_after_convergence"]
        if abs(real - twin) <= 0.05 * twin:
            parts.append(f"the linear twin gives the same ({twin:.2f} against {real:.2f}), "
                         "so the cause is the filter's model and tuning, not the linearization")
        else:
            parts.append(f"the linear twin gives {twin:.2f} against {real:.2f}: the "
                         "linearization accounts for the difference")
    return "; ".join(parts)
