"""`dynprop montecarlo`: run (or resume) a set, then write the ensemble results."""

from __future__ import annotations

import contextlib
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..config.schema import Scenario
from .execute import connect, default_workers, run_dask, run_local
from .stats import ensemble, quantile_label, runs_to_bound_quantile, untested_why
from .store import SetDirectory, atomic_write, npz_bytes

FIGURES = ("mc_errors.png", "mc_nees.png", "mc_gap_yaw.png")


@dataclass(frozen=True)
class SetResult:
    summary: dict
    ran: int          # cases run by this invocation
    resumed: bool     # the directory already held part of this set
    cases: int        # cases in the set, and in montecarlo.json: n_runs or more


def pending_cases(store: SetDirectory, n_runs: int, keep, retry_failed: bool) -> list[int]:
    records = store.records()
    return [k for k in range(n_runs)
            if k not in records
            or (retry_failed and records[k]["status"] != "ok")
            or (k in keep and records[k]["status"] == "ok" and not store.has_full(k))]


def run_set(s: Scenario, n_runs: int, out: Path, workers: int | None = None,
            scheduler: str | None = None, keep=(), force: int = 0,
            retry_failed: bool = False, command: str = "") -> SetResult:
    """Cases 0 … n_runs−1 of ``s``'s dispersions, skipping those already stored in
    ``out``; then montecarlo.json, montecarlo.npz and the figures.  A set that already
    holds more cases keeps them all, and montecarlo.json summarizes them all: a
    summary never drops a stored case (``SetResult.cases`` says how many)."""
    # Connect first: an unreachable scheduler must not leave a new directory behind.
    with connect(scheduler) if scheduler else contextlib.nullcontext() as client:
        store = SetDirectory(out)
        resumed = store.open(s, force)
        store.clean_temporaries()
        n_runs = max(n_runs, 1 + max(store.records(), default=-1))
        keep = {k for k in keep if k < n_runs}
        todo = pending_cases(store, n_runs, keep, retry_failed)
        if todo:
            kwargs = dict(on_done=store.save, done_before=n_runs - len(todo), total=n_runs)
            if client is not None:
                run_dask(s, todo, keep, client, **kwargs)
            else:
                run_local(s, todo, keep, workers or default_workers(), **kwargs)
    summary = write_results(s, store, n_runs, command)
    return SetResult(summary, len(todo), resumed, n_runs)


def write_results(s: Scenario, store: SetDirectory, n_runs: int, command: str) -> dict:
    summary, fig = ensemble(s, store.records(), store.arrays, n_runs, command)
    out = store.out
    atomic_write(out / "montecarlo.npz", npz_bytes(fig))
    if fig:
        draw_figures(out / "plots", s, summary, fig, command)
    atomic_write(out / "montecarlo.json",
                 (json.dumps(summary, indent=2, allow_nan=False) + "\n").encode())
    return summary


def redraw(out: Path) -> list[Path]:
    """`dynprop plot` on a set directory: the figures again from montecarlo.json and
    montecarlo.npz, without touching a case."""
    from ..config.loader import load_scenario
    out = Path(out)
    s = load_scenario(out / "scenario.yaml")
    summary = json.loads((out / "montecarlo.json").read_text())
    with np.load(out / "montecarlo.npz") as data:
        fig = {k: data[k] for k in data.files}
    if not fig:
        return []
    draw_figures(out / "plots", s, summary, fig, summary["reproduce_case"])
    return [out / "plots" / name for name in FIGURES]


def caption(s: Scenario, summary: dict, command: str) -> str:
    failed = f", {summary['runs_failed']} failed" if summary["runs_failed"] else ""
    return (f"scenario {s.name}, seed {s.seed}, {summary['runs_ok']} runs{failed}; "
            f"{command}")


def ensemble_figures(s: Scenario, summary: dict, fig: dict, command: str) -> dict:
    """The set's figures as matplotlib Figures, by file name (``FIGURES``)."""
    from ..figures.montecarlo import ensemble_figures as draw
    return dict(zip(FIGURES, draw(summary, fig, s.montecarlo.converged_after_h,
                                  caption(s, summary, command)), strict=True))


def draw_figures(plots: Path, s: Scenario, summary: dict, fig: dict, command: str) -> None:
    from ..figures import save_figure
    plots.mkdir(exist_ok=True)
    for name, f in ensemble_figures(s, summary, fig, command).items():
        save_figure(f, plots / name)


def one_line(summary: dict) -> str:
    """The headline of a set for the terminal."""
    if not summary["runs_ok"]:
        return f"no successful runs ({summary['runs_failed']} failed)"
    n = summary["nees"]
    lo, hi = n["bounds_95"]
    frac = n["fraction_after_convergence"]
    parts = [f"{summary['runs_ok']} runs ({summary['runs_failed']} failed)"]
    if frac is None:
        parts.append(f"NEES not tested ({untested_why(n, summary['converged_after_h'])})")
    else:
        parts.append(f"averaged NEES {n['mean_after_convergence']:.2f} after "
                     f"{summary['converged_after_h']:g} h, inside [{lo:.2f}, {hi:.2f}] "
                     f"{100 * frac['inside']:.0f}% of the time (below "
                     f"{100 * frac['below']:.0f}%)")
    if not summary["gap_end_yaw"]:
        parts.append("yaw at Sun-gap ends not tested (no case has a Sun-gap end)")
    for g in summary["gap_end_yaw"]:
        parts.append(f"yaw at gap {g['gap']} end: {gap_quantiles(g)} vs filter σ "
                     f"{g['predicted_sigma_deg']:.4f} deg")
    e = summary.get("ekf")
    if e is not None and e["nees"]["fraction_after_convergence"] is not None:
        parts.append(f"EKF: averaged NEES {e['nees']['mean_after_convergence']:.2f}, inside "
                     f"{100 * e['nees']['fraction_after_convergence']['inside']:.0f}%")
    parts.append(f"Eq. 55: {summary['analytic_sigma_yaw_deg']:.4f} deg")
    return "; ".join(parts)


def gap_quantiles(g: dict) -> str:
    """The 68.3% and 99.7% quantiles of |e| at a gap end, named as quantiles (they are
    not σ), with a note when the cases are too few to bound them (stats.quantile_interval)."""
    q, level, ci = g["abs_quantile_deg"], g["abs_quantile_level"], g["abs_quantile_ci95_deg"]
    keys = ("1sigma", "3sigma")
    text = (f"{'/'.join(quantile_label(level[k]) for k in keys)} quantiles of |e| "
            f"{'/'.join(f'{q[k]:.4f}' for k in keys)} deg")
    open_ = [k for k in keys if ci[k][1] is None]
    if open_:
        need = " and ".join(f"≥ {runs_to_bound_quantile(level[k])}" for k in open_)
        text += (f" (poorly determined from N = {g['n']} cases: a 95% upper bound on the "
                 f"{' and '.join(quantile_label(level[k]) for k in open_)} quantile"
                 f"{'s' if len(open_) > 1 else ''} needs {need} cases)")
    return text
