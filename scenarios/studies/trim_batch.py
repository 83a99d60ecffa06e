"""How long a batch `dynprop trim` needs, and in which season: σ(κ̂) from the batch
filter's covariance beside the spread of κ̂ − κ over a Monte Carlo of dispersed
cases (the scenario's ``montecarlo.dispersions``, drawn exactly as `dynprop
montecarlo` draws case K).  Every batch starts at t = 0.

    python -m dynprop.scenarios.studies.trim_batch --cases 20 --workers 2 \\
        --figure docs/figures/trim_batch.png                 # docs/validation.md §7

The analysis of each case knows what the ground knows (``trim.ASSUMED_KNOWN``):
the date (the case's epoch) and the commanded dipole profile; the filter and
everything else stay nominal, as they would in flight.
"""

from __future__ import annotations

import argparse
import sys
from multiprocessing import get_context
from pathlib import Path

import numpy as np

from ..config.loader import load_scenario
from ..files.columns import telemetry_columns
from ..montecarlo.dispersions import draw_case
from ..run.simulate import simulate
from ..trim.batch import choose_batch, estimate_kappa, true_kappa_Nm
from . import write_json

BATCHES_S = (21541.0, 86400.0, 2 * 86400.0, 4 * 86400.0, 7 * 86400.0)
# The undispersed case's covariance, finely, for the curve and the 1e-7 crossing.
FINE_DAYS = (BATCHES_S[0] / 86400.0, 0.375, 0.5, 0.625, 0.75, 0.875, 1.0, 1.25, 1.5, 1.75,
             2.0, 2.5, 3.0, 4.0, 5.0, 6.0, 7.0)
PAPER_TRIMMED_NM = 1e-7
BATCH_LABELS = ("quarter orbit", "1 day", "2 days", "4 days", "7 days")
SEASONS = {"equinox": "2026-03-20T12:00:00Z", "solstice": "2026-06-21T12:00:00Z"}
TRIM_TAB_DEG = 16.0   # goes_next_mistrimmed: κ = +1e-5 N m


def nominal(season: str, days: float):
    return load_scenario("goes_next_equinox", [
        f"epoch_utc={SEASONS[season]}", f"environment.solar.trim_tab_deg={TRIM_TAB_DEG}",
        f"duration_s={days * 86400.0}"])


def analysis_scenario(s, flying):
    """The nominal scenario with what the ground knows of the case: its date and
    its commanded dipole profile."""
    mag = flying.environment.magnetic
    return load_scenario("goes_next_equinox", [
        f"epoch_utc={flying.epoch_utc}", f"environment.solar.trim_tab_deg={TRIM_TAB_DEG}",
        f"duration_s={s.duration_s}",
        f"environment.magnetic.profile_amplitude_Am2={list(mag.profile_amplitude_Am2)}",
        f"environment.magnetic.profile_period_s={mag.profile_period_s}",
        f"environment.magnetic.profile_phase_deg={mag.profile_phase_deg}"])


def one_case(job) -> dict:
    """κ̂, σ and the true κ of case ``case`` (None: the undispersed scenario) for
    every batch length."""
    season, case, days = job
    s = nominal(season, days)
    if case is None:
        flying, run = s, 0
    else:
        _, flying = draw_case(s, case)
        run = case
    sim = simulate(flying, run=run)
    cols = telemetry_columns(sim.telemetry, sim.suite)
    del sim
    ana = analysis_scenario(s, flying)
    out = {"season": season, "case": case, "kappa_true_Nm": true_kappa_Nm(flying),
           "kappa_Nm": [], "sigma_Nm": []}
    def fit(length):
        return estimate_kappa(ana, cols, choose_batch(cols["t_s"], s.sample_interval_s, None,
                                                      length)).fit
    for length in (b for b in BATCHES_S if b <= days * 86400.0):
        f = fit(length)
        out["kappa_Nm"].append(f.kappa_Nm)
        out["sigma_Nm"].append(f.sigma_Nm)
    if case is None:
        out["fine_sigma_Nm"] = [fit(d * 86400.0).sigma_Nm for d in FINE_DAYS if d <= days]
    return out


def crossing_days(days, sigma, level: float = PAPER_TRIMMED_NM) -> float | None:
    """The batch length where σ first falls to ``level`` (log-log interpolation)."""
    d, s = np.log(np.asarray(days)), np.log(np.asarray(sigma))
    below = np.flatnonzero(s <= np.log(level))
    if not below.size or below[0] == 0:
        return None
    i = below[0]
    f = (np.log(level) - s[i - 1]) / (s[i] - s[i - 1])
    return float(np.exp(d[i - 1] + f * (d[i] - d[i - 1])))


def study(cases: int, workers: int, days: float = 7.0) -> dict:
    jobs = [(season, case, days) for season in SEASONS for case in [None, *range(cases)]]
    with get_context("fork").Pool(workers, maxtasksperchild=1) as pool:
        results = pool.map(one_case, jobs, chunksize=1)
    table = {}
    for season in SEASONS:
        rows = [r for r in results if r["season"] == season]
        nom = next(r for r in rows if r["case"] is None)
        mc = [r for r in rows if r["case"] is not None]
        err = np.array([np.subtract(r["kappa_Nm"], r["kappa_true_Nm"]) for r in mc])
        sig = np.array([r["sigma_Nm"] for r in mc])
        table[season] = {
            "batch_s": list(BATCHES_S),
            "sigma_covariance_Nm": nom["sigma_Nm"],
            "error_nominal_Nm": list(np.subtract(nom["kappa_Nm"], nom["kappa_true_Nm"])),
            "sigma_mc_Nm": list(np.sqrt(np.mean(err**2, axis=0))),
            "mean_error_mc_Nm": list(err.mean(axis=0)),
            "sigma_covariance_mc_mean_Nm": list(sig.mean(axis=0)),
            "worst_error_over_sigma": list(np.max(np.abs(err) / sig, axis=0)),
            "cases": len(mc),
            "fine_days": list(FINE_DAYS[:len(nom["fine_sigma_Nm"])]),
            "fine_sigma_covariance_Nm": nom["fine_sigma_Nm"],
        }
        table[season]["days_to_1e-7"] = crossing_days(table[season]["fine_days"],
                                                      nom["fine_sigma_Nm"])
    return table


def markdown(table: dict) -> str:
    lines = ["| season | batch | σ(κ̂), covariance (N m) | σ(κ̂), Monte Carlo RMS (N m) | "
             "MC / covariance | mean error (N m) | worst \\|error\\|/σ |",
             "|---|---|---|---|---|---|---|"]
    for season, t in table.items():
        for i, label in enumerate(BATCH_LABELS):
            cov, mc = t["sigma_covariance_Nm"][i], t["sigma_mc_Nm"][i]
            lines.append(f"| {season} | {label} | {cov:.2e} | {mc:.2e} | {mc / cov:.2f} | "
                         f"{t['mean_error_mc_Nm'][i]:+.1e} | "
                         f"{t['worst_error_over_sigma'][i]:.2f} |")
    lines.append("")
    for season, t in table.items():
        d = t["days_to_1e-7"]
        lines.append(f"{season}: the covariance's σ(κ̂) reaches {PAPER_TRIMMED_NM:g} N m after "
                     + ("more than the longest batch" if d is None else f"{d:.2f} days"))
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m dynprop.scenarios.studies.trim_batch",
                                 description=__doc__)
    ap.add_argument("--cases", type=int, default=20)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--json", help="also write the table here")
    ap.add_argument("--figure", help="draw σ(κ̂) against batch length here (PNG)")
    args = ap.parse_args(argv)
    table = study(args.cases, args.workers)
    print(markdown(table))
    if args.figure:
        from ..figures.trim import batch_study_figure
        batch_study_figure(Path(args.figure), table, BATCH_LABELS, PAPER_TRIMMED_NM)
    write_json(args.json, table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
