"""The paper's filter against the extended Kalman filter on the same telemetry, as
the attitude error grows (docs/validation.md §8):

    python -m dynprop.scenarios.studies.ekf_crossover --workers 2

Each case is the linearization report's sweep (``linearization.propagation.
sweep_changes``): an initial error δ on roll, pitch and yaw, or initial roll,
pitch and yaw rates of δ·|ω_n| (a nutation cone of about δ), with the filters'
initial σ widened to cover it, over two days of the equinox scenario.  For each
filter: the yaw error over σ at both Sun-gap ends, and the mean NEES (every 10th
sample) over the run and after its first hour.
"""

from __future__ import annotations

import argparse
import json
import sys
from multiprocessing import get_context

import numpy as np
from dynprop.estimator.kalman.consistency import chi2_bounds, nees
from dynprop.estimator.kalman.filter import unpack

from ..config import build
from ..config.loader import load_scenario
from ..linearization.propagation import sweep_changes
from ..run.ekf import run_ekf
from ..run.whole import run_scenario
from . import write_json

CASES = (("attitude", 0.0), ("attitude", 0.1), ("attitude", 1.0), ("attitude", 3.0),
         ("attitude", 5.0), ("attitude", 7.0),
         ("attitude", 10.0), ("rate", 3.0))
SKIP_S = 3600.0   # the wheel control's first-hour transient, shared by both filters


def _nees(x, P_packed, truth, keep):
    return nees(x[keep], unpack(P_packed[keep]), truth[keep])


def one_case(job) -> dict:
    kind, deg, scenario, duration_s = job
    s = load_scenario(scenario, [f"duration_s={duration_s}"])
    params, _ = build.estimator_model(s)
    changes = sweep_changes(s, kind, deg, params.omega_n_radps) if deg else []
    s = load_scenario(scenario, [f"duration_s={duration_s}",
                                 *(f"{k}={json.dumps(v)}" for k, v in changes)])
    two = run_scenario(s, smooth=False, twin=False)
    tel = two.sim.telemetry
    head = np.where(tel.yaw_head >= 0, tel.yaw_head, np.nan)
    ekf = run_ekf(s, tel.roll_rad, tel.pitch_rad, tel.yaw_rad, tel.wheel_speeds_radps,
                  tel.yaw_sigma_rad, head)
    idx = np.flatnonzero(np.isfinite(tel.yaw_rad))
    ends = idx[1:][np.diff(idx) > 4 * 3600 / s.sample_interval_s] - 1
    t = two.sim.truth.t_s
    keep = np.arange(0, len(t), 10)
    late = keep[t[keep] >= SKIP_S]
    out = {"kind": kind, "size_deg": deg, "gap_end_t_h": list(t[ends] / 3600)}
    for name, r in (("paper", two.real), ("ekf", ekf)):
        e = (r.x[ends, 2] - two.truth_model[ends, 2]) * 180 / np.pi
        sig = r.sigma[ends, 2] * 180 / np.pi
        out[name] = {"gap_end_error_deg": list(e), "gap_end_sigma_deg": list(sig),
                     "nees_mean": float(np.mean(_nees(r.x, r.P_packed, two.truth_model, keep))),
                     "nees_mean_after_1h": float(np.mean(_nees(r.x, r.P_packed,
                                                               two.truth_model, late)))}
    return out


def study(workers: int, scenario: str = "goes_next_equinox", duration_s: float = 172800.0
          ) -> list[dict]:
    jobs = [(k, d, scenario, duration_s) for k, d in CASES]
    with get_context("fork").Pool(workers, maxtasksperchild=1) as pool:
        return pool.map(one_case, jobs, chunksize=1)


def markdown(rows: list[dict]) -> str:
    lo, hi = chi2_bounds(9)
    lines = ["| initial error | filter | gap-end yaw error / σ | gap-end σ (deg) | mean NEES "
             "| mean NEES after 1 h |", "|---|---|---|---|---|---|"]
    for r in rows:
        what = ("none" if not r["size_deg"] else
                f"{r['size_deg']:g}° on each axis" if r["kind"] == "attitude" else
                f"rates of {r['size_deg']:g}°·\\|ω_n\\|")
        for name in ("paper", "ekf"):
            f = r[name]
            ratio = ", ".join(f"{e / s:+.2f}" for e, s in zip(f["gap_end_error_deg"],
                                                           f["gap_end_sigma_deg"], strict=True))
            sig = ", ".join(f"{s:.4f}" for s in f["gap_end_sigma_deg"])
            lines.append(f"| {what} | {name} | {ratio} | {sig} | {f['nees_mean']:.2f} | "
                         f"{f['nees_mean_after_1h']:.2f} |")
    lines += ["", f"χ²(9) 95% bounds for a single sample: {lo:.2f} … {hi:.2f}."]
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m dynprop.scenarios.studies.ekf_crossover")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--json", help="also write the rows here")
    args = ap.parse_args(argv)
    rows = study(args.workers)
    print(markdown(rows))
    write_json(args.json, rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
