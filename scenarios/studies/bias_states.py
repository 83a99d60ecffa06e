"""The filter with sensor-bias states against the paper's, on the same dispersed
Monte Carlo cases (docs/validation.md §11):

    dynprop montecarlo goes_next_equinox --runs 50 --out mc_plain
    dynprop montecarlo goes_next_equinox --runs 50 --out mc_bias \\
        --set estimator.bias_states.earth_roll.model=constant \\
        --set estimator.bias_states.dss_yaw.model=constant
    python -m dynprop.scenarios.studies.bias_states mc_plain mc_bias

Both sets fly the same cases (the dispersions, including the truth's Earth-sensor
roll bias and DSS β bias, are drawn from the seed alone); only the filter differs.
Per set: the yaw error over σ at every Sun-gap end (its RMS, the fraction within
3σ) and the gap-end yaw error RMS; with bias states, each bias's final error over
its σ across the cases, and the mean NEES of the augmented state over the cases
against the χ² bounds of that mean (n·N degrees of freedom over N cases).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
from scipy.stats import chi2

from . import write_json


def _records(directory: Path) -> list[dict]:
    return [json.loads(p.read_text()) for p in sorted((Path(directory) / "cases")
                                                       .glob("case-*.json"))]


def _ok(records: list[dict]) -> list[dict]:
    return [r for r in records if r.get("status") == "ok"]


def gap_ends(records: list[dict]) -> dict:
    """Every Sun-gap end of every case: yaw error, σ, and their ratio's statistics."""
    err = np.array([e for r in records for e in r["yaw_error_at_gap_end_deg"]])
    sig = np.array([s for r in records for s in r["yaw_sigma_at_gap_end_deg"]])
    if not err.size:   # no verdict from no gap end
        return {"gap_ends": 0, "not_tested": "no Sun-gap end in any case"}
    z = err / sig
    return {"gap_ends": int(len(err)), "yaw_error_rms_deg": float(np.sqrt(np.mean(err**2))),
            "yaw_sigma_mean_deg": float(np.mean(sig)),
            "error_over_sigma_rms": float(np.sqrt(np.mean(z**2))),
            "within_1sigma": float(np.mean(np.abs(z) <= 1)),
            "within_3sigma": float(np.mean(np.abs(z) <= 3))}


def biases(records: list[dict]) -> dict:
    """Each bias state's final error over σ across the cases (a consistent filter: RMS
    ≈ 1, nearly all within 3), the truth's spread, and the filter's σ."""
    names = sorted({n for r in records for n in (r.get("bias_states") or {})})
    out = {}
    for name in names:
        rows = [r["bias_states"][name] for r in records if r.get("bias_states")
                and r["bias_states"][name]["truth_deg"] is not None]
        if not rows:
            out[name] = {"cases": 0, "not_tested": "no case knows the truth's bias"}
            continue
        z = np.array([b["error_over_sigma"] for b in rows])
        out[name] = {"cases": len(rows),
                     "error_over_sigma_rms": float(np.sqrt(np.mean(z**2))),
                     "within_3sigma": float(np.mean(np.abs(z) <= 3)),
                     "truth_rms_deg": float(np.sqrt(np.mean([b["truth_deg"] ** 2
                                                              for b in rows]))),
                     "estimate_error_rms_deg": float(np.sqrt(np.mean(
                         [(b["estimate_deg"] - b["truth_deg"]) ** 2 for b in rows]))),
                     "sigma_mean_deg": float(np.mean([b["sigma_deg"] for b in rows]))}
    return out


def augmented_nees(records: list[dict]) -> dict | None:
    """The mean over the cases of each case's converged mean NEES of the augmented
    state, against the two-sided 95% bounds of a mean of N χ²(n) draws.  A case's own
    mean is over correlated samples, so this bound is a loose check of the ensemble,
    as the per-state test of ``montecarlo.stats`` is."""
    values = [r["nees_mean_augmented"] for r in records
              if r.get("nees_mean_augmented") is not None]
    if not values:
        return None
    n, dof = len(values), records[0]["nees_dof_augmented"]
    lo, hi = chi2.ppf([0.025, 0.975], n * dof) / n
    mean = float(np.mean(values))
    return {"cases": n, "dof": dof, "mean": mean, "bounds_95": [float(lo), float(hi)],
            "verdict": "conservative" if mean < lo else "overconfident" if mean > hi
            else "not rejected"}


def compare(plain: Path, biased: Path) -> dict:
    a, b = _ok(_records(plain)), _ok(_records(biased))
    return {"without_bias_states": {"set": str(plain), "cases": len(a), **gap_ends(a)},
            "with_bias_states": {"set": str(biased), "cases": len(b), **gap_ends(b),
                                 "biases": biases(b), "nees_augmented": augmented_nees(b)}}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m dynprop.scenarios.studies.bias_states",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("plain", type=Path, help="Monte Carlo set without bias states")
    parser.add_argument("biased", type=Path, help="the same set with bias states")
    parser.add_argument("--out", type=Path, help="also write the result as JSON here")
    args = parser.parse_args(argv)
    result = compare(args.plain, args.biased)
    text = json.dumps(result, indent=1)
    print(text)
    if args.out:
        write_json(args.out, result)
    return 0


if __name__ == "__main__":
    sys.exit(main())
