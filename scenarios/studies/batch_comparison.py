"""The paper's filter against the batch least-squares estimator it set aside (Section 5:
"a batch estimator must use at least one-third of an orbit, or 8 hours, of data ...
the dynamic models are not accurate enough to propagate across this interval without
accounting for process noise"), on the same telemetry (docs/validation.md):

    python -m dynprop.scenarios.studies.batch_comparison --cases 50 --mc-spans 8 24 48 \\
        --workers 2 --out /tmp/study          # about an hour on two shared cores

Three cases, two days each: ``equinox`` (goes_next_equinox), ``paper_torques``
(goes_next_paper_torques: the paper's Eq. 45 torque, which no estimator models) and
``offset_5deg`` (goes_next_equinox flying an initial yaw of 5°, with the filter's
prior ``estimator.initial_sigma.yaw_deg`` widened to 5°, so that the filter and the
batch's first a priori, which is that same prior, are consistent with the error).
Estimators: the filter, the filter plus RTS smoother, the nonlinear batch
(Gauss–Newton on the gyrostat) at spans of 8, 12, 24 and 48 h with chained a priori
(``batch.apriori``, default ``chain``), and the linear batch (the paper's model) at
24 h.  Each is judged at every Sun-gap end at the last sample before the Sun returns
(``batch.compare``): yaw error, σ and, for the batches, the consider σ; and by its
yaw RMS error after the first hour (on the ``montecarlo.grid_s`` grid).

First the nominal run of each case (the bundled seed), then a Monte Carlo of cases
0 … N−1 per case (``montecarlo.dispersions`` drawn as `dynprop montecarlo` draws
case K; goes_next_paper_torques has none, so its cases differ in their torque,
sensor and ripple draws only).  Every estimator is designed from the nominal
scenario; the truth flies the dispersed one.  Each finished case is one JSON line in
OUT/cases.jsonl, so an interrupted study resumes where it stopped.  ``--set KEY=VALUE``
changes every case (``--set batch.apriori=scenario``: independent batches; a sweep
of ``environment.disturbance.sigma_Nm``); give it its own ``--out``.
"""

from __future__ import annotations

import argparse
import importlib
import json
import sys
import time
import traceback
from concurrent.futures import FIRST_COMPLETED, wait
from pathlib import Path

import numpy as np

from ..batch.compare import compare
from ..batch.spans import solve_spans
from ..bridge.inputs import measured
from ..config.loader import load_scenario
from ..montecarlo.case import grid_stride
from ..montecarlo.dispersions import draw_case
from ..run.simulate import simulate
from ..run.whole import run_scenario
from ..samples import sun_gaps
from ..units import HOUR_S
from ..workers import blas_one_thread, clean_start_context, worker_pool
from . import write_json

CASES = {"equinox": ("goes_next_equinox", ()),
         "paper_torques": ("goes_next_paper_torques", ()),
         "offset_5deg": ("goes_next_equinox", ("initial_state.yaw_deg=5.0",
                                               "estimator.initial_sigma.yaw_deg=5.0"))}
SPANS_H = (8.0, 12.0, 24.0, 48.0)
LINEAR_SPAN_H = 24.0
SKIP_S = HOUR_S   # the RMS leaves out the first hour (the wheel control's transient)
WORKER_MODULE = __spec__.name if __spec__ else __name__   # importable, not __main__


def nominal(case: str, extra=()):
    """The nominal scenario of ``case`` (CASES), with the overrides ``extra``."""
    name, overrides = CASES[case]
    return load_scenario(name, [*overrides, *extra])


def batch_entry(run, judged: dict) -> dict:
    """A batch run's ``compare`` entry with its convergence and fit figures."""
    sols = run.solutions
    return judged | {"batches": len(sols),
                     "not_converged": sum(not sol.converged for sol in sols),
                     "iterations": [int(sol.iterations) for sol in sols],
                     "residual_over_sigma_max": [
                         float(np.nanmax(v)) if np.isfinite(v).any() else None
                         for v in np.array([sol.residual_normalized for sol in sols]).T]}


@blas_one_thread()
def one_case(case: str, k: int | None, spans_h: tuple[float, ...], extra=()) -> dict:
    """The record of Monte Carlo case ``k`` of ``case`` (None: the nominal run), with
    the overrides ``extra``: every estimator against the truth.  Never raises: a
    failure is a record."""
    start = time.perf_counter()
    head = {"case": case, "k": k, "overrides": list(extra)}
    try:
        s = nominal(case, extra)
        flying = s if k is None else draw_case(s, k)[1]
        run = 0 if k is None else k
        runs = run_scenario(s, simulate(flying, run), run=run, truth_scenario=flying,
                            twin=False)
        tel, t = measured(runs.sim.telemetry), runs.sim.truth.t_s
        n = len(t)
        gaps = [(a, b) for a, b in sun_gaps(np.isfinite(tel.yaw_rad), s.sample_interval_s,
                                            s.estimator.sun_gap_min_h) if b < n]
        grid = np.arange(0, n, grid_stride(s))
        rows = np.union1d(grid[t[grid] >= SKIP_S], [b - 1 for _, b in gaps]).astype(np.int64)
        truth = runs.truth_model[rows]
        out = compare(t, rows, truth, {
            "filter": (runs.real.x[rows], runs.real.sigma[rows]),
            "smoother": (runs.smoothed.x[rows], runs.smoothed.sigma[rows])}, gaps)
        pitch = runs.sim.telemetry.pitch_rad
        jobs = [("nonlinear", h) for h in spans_h] + [("linear", LINEAR_SPAN_H)]
        for model, span_h in jobs:
            b = solve_spans(s, tel, pitch, rows, None, model, span_h, 0.0)
            judged = compare(t, rows, truth, {"batch": (b.x_rows, b.sigma_rows)}, gaps,
                             b.sigma_consider_rows)
            out[f"{model}_{span_h:g}h"] = batch_entry(b, judged["batch"])
        return head | {"status": "ok", "epoch_utc": flying.epoch_utc,
                       "wall_s": time.perf_counter() - start, **out}
    except Exception as exc:  # recorded, so one bad case cannot stop the study
        return head | {"status": "failed", "error": f"{type(exc).__name__}: {exc}",
                       "traceback": traceback.format_exception(exc)[-3:],
                       "wall_s": time.perf_counter() - start}


def run_all(jobs: list[tuple], workers: int, store: Path) -> None:
    """Run ``jobs`` (case, k, spans, overrides) in a pool, appending each record to
    ``store`` as it arrives."""
    worker = importlib.import_module(WORKER_MODULE).one_case
    with clean_start_context([WORKER_MODULE]) as ctx, worker_pool(workers, ctx) as pool, \
            store.open("a") as fh:
        todo, running = list(jobs), {}
        while todo or running:
            while todo and len(running) < 2 * workers:
                job = todo.pop(0)
                running[pool.submit(worker, *job)] = job
            done, _ = wait(running, return_when=FIRST_COMPLETED)
            for fut in done:
                running.pop(fut)
                rec = fut.result()
                fh.write(json.dumps(rec) + "\n")
                fh.flush()
                print(f"{rec['case']} case {rec['k']}: {rec['status']} "
                      f"({rec['wall_s']:.0f} s)", file=sys.stderr, flush=True)


def load_records(store: Path, extra=()) -> dict[tuple, dict]:
    """The latest successful record of each (case, k) in ``store`` made with the
    overrides ``extra``."""
    out = {}
    if store.is_file():
        for line in store.read_text().splitlines():
            rec = json.loads(line)
            if rec["status"] == "ok" and rec.get("overrides", []) == list(extra):
                out[(rec["case"], rec["k"])] = rec
    return out


def estimators(rec: dict) -> list[str]:
    """The estimator keys of a record, in table order."""
    return ["filter", "smoother"] + [k for k in rec if k.startswith(("nonlinear_", "linear_"))]


def _over(values, f) -> float | None:
    """``f`` (np.mean, _rms) of the values that are not None (None if there are none)."""
    v = np.asarray([x for x in values if x is not None], dtype=float)
    return float(f(v)) if v.size else None


def _rms(v) -> float:
    """Root mean square."""
    return np.sqrt(np.mean(np.square(v)))


def summarize(records: list[dict]) -> dict:
    """Per estimator over the cases: at each gap end the error RMS, mean σ (and consider
    σ), the fractions within 3σ; the RMS of the yaw RMS; unconverged batches."""
    n_gaps = min(len(r["gap_end_t_s"]) for r in records)
    out = {"cases": len(records), "gap_end_t_h": [
        _over([r["gap_end_t_s"][j] / HOUR_S for r in records], np.mean) for j in range(n_gaps)]}
    for name in (e for e in estimators(records[0]) if all(e in r for r in records)):
        ends = []
        for j in range(n_gaps):
            g = {key: [r[name]["gap_ends"][j].get(key) for r in records] for key in (
                "error_deg", "sigma_deg", "sigma_consider_deg", "within_3sigma",
                "within_3sigma_consider")}
            ends.append({"judged": sum(e is not None for e in g["within_3sigma"]),
                         "error_rms_deg": _over(g.pop("error_deg"), _rms)}
                        | {key.replace("_deg", "_mean_deg"): _over(v, np.mean)
                           for key, v in g.items()})
        entry = {"gap_ends": ends,
                 "yaw_rms_deg": _over([r[name]["yaw_rms_deg"] for r in records], _rms)}
        if "batches" in records[0][name]:
            entry |= {key: sum(r[name][key] for r in records)
                      for key in ("batches", "not_converged")}
        out[name] = entry
    return out


LABELS = {"filter": "filter", "smoother": "filter + RTS smoother"}


def label(name: str) -> str:
    """The table's name of an estimator key."""
    if name in LABELS:
        return LABELS[name]
    model, span = name.split("_")
    return f"{model} batch, {span[:-1]} h"


def _cells(values, fmt: str) -> str:
    """One table cell: the values by ``fmt``, '—' for None, joined by ' / '."""
    return " / ".join("—" if v is None else format(v, fmt) for v in values)


def single_table(rec: dict) -> list[str]:
    """The nominal run of a case: gap ends as 'gap 1 / gap 2'."""
    lines = ["| estimator | gap-end yaw error (deg) | σ (deg) | consider σ (deg) | \\|e\\|/σ "
             "| yaw RMS after 1 h (deg) | batches not converged | iterations |",
             "|---|---|---|---|---|---|---|---|"]
    for name in estimators(rec):
        e = rec[name]
        g = e["gap_ends"]
        err, sig = [x["error_deg"] for x in g], [x["sigma_deg"] for x in g]
        ratio = [None if a is None else abs(a) / b for a, b in zip(err, sig, strict=True)]
        nc = f"{e['not_converged']} of {e['batches']}" if "batches" in e else ""
        its = ", ".join(map(str, e.get("iterations", [])))
        lines.append(f"| {label(name)} | {_cells(err, '+.4f')} | {_cells(sig, '.4f')} | "
                     f"{_cells([x.get('sigma_consider_deg') for x in g], '.4f')} | "
                     f"{_cells(ratio, '.2f')} | {_cells([e['yaw_rms_deg']], '.4f')} | {nc} | "
                     f"{its} |")
    return lines


def mc_table(summary: dict) -> list[str]:
    """The Monte Carlo of a case: gap ends as 'gap 1 / gap 2'."""
    lines = ["| estimator | gap-end yaw error RMS (deg) | mean σ (deg) | mean consider σ (deg) "
             "| within 3σ | within 3σ consider | yaw RMS after 1 h (deg) "
             "| batches not converged |", "|---|---|---|---|---|---|---|---|"]
    for name in (k for k in summary if k in LABELS or k.startswith(("nonlinear", "linear"))):
        e = summary[name]
        cells = [_cells([x[key] for x in e["gap_ends"]], fmt) for key, fmt in (
            ("error_rms_deg", ".4f"), ("sigma_mean_deg", ".4f"),
            ("sigma_consider_mean_deg", ".4f"), ("within_3sigma", ".0%"),
            ("within_3sigma_consider", ".0%"))]
        nc = f"{e['not_converged']} of {e['batches']}" if "batches" in e else ""
        lines.append(f"| {label(name)} | {' | '.join(cells)} | "
                     f"{_cells([e['yaw_rms_deg']], '.4f')} | {nc} |")
    return lines


def markdown(result: dict) -> str:
    """Every table, ready for docs/validation.md."""
    lines = []
    for case, r in result.items():
        nom = r["nominal"]
        if nom is not None:
            ends = ", ".join(f"{t / HOUR_S:.1f} h" for t in nom["gap_end_t_s"])
            lines += [f"**{case}**, nominal run (gap ends at {ends}; gap 1 / gap 2):", "",
                      *single_table(nom), ""]
        if r.get("montecarlo"):
            mc = r["montecarlo"]
            lines += [f"**{case}**, Monte Carlo of {mc['cases']} cases:", "", *mc_table(mc), ""]
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m dynprop.scenarios.studies.batch_comparison",
                                 description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=50, help="Monte Carlo cases per case "
                    "(0: the nominal runs only)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--only", nargs="+", choices=list(CASES), default=list(CASES))
    ap.add_argument("--spans", type=float, nargs="+", default=list(SPANS_H),
                    help="the nonlinear batch's spans (h) for the nominal runs")
    ap.add_argument("--mc-spans", type=float, nargs="+",
                    help="the nonlinear batch's spans (h) in the Monte Carlo (default: --spans)")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="an override of every case's scenario (e.g. batch.apriori=scenario)")
    ap.add_argument("--out", type=Path, default=Path("batch_comparison"),
                    help="cases.jsonl, batch_comparison.md and .json go here")
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    store = args.out / "cases.jsonl"
    spans, mc_spans = tuple(args.spans), tuple(args.mc_spans or args.spans)
    extra = tuple(args.set)
    have = load_records(store, extra)
    # Case by case across the three, so that a study stopped early is even.
    jobs = [(c, k, spans if k is None else mc_spans, extra) for k in [None, *range(args.cases)]
            for c in args.only if (c, k) not in have]
    if jobs:
        run_all(jobs, args.workers, store)
    have = load_records(store, extra)
    result = {}
    for c in args.only:
        mc = [have[c, k] for k in range(args.cases) if (c, k) in have]
        result[c] = {"nominal": have.get((c, None)), "montecarlo": summarize(mc) if mc else None,
                     "failed": args.cases - len(mc)}
    text = markdown(result)
    print(text)
    (args.out / "batch_comparison.md").write_text(text + "\n")
    write_json(str(args.out / "batch_comparison.json"), result)
    return 0


if __name__ == "__main__":
    sys.exit(main())
