"""`dynprop batch`: the chained batches (``spans``) on a run's or a file's telemetry,
the filter and smoother on the same telemetry beside them, the truth comparison
(``compare``), and the files: estimate_batch.csv, batch.json, batch.png
(docs/batch.md, docs/outputs.md)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from dynprop.estimator.batch.linear import BatchError
from dynprop.estimator.linear.model import N_STATES
from dynprop.estimator.linear.steps import StepTable
from dynprop.estimator.linear.transition import discretize

from ..bridge.coordinates import model_truth, truth_torques
from ..bridge.inputs import telemetry_inputs
from ..config import build
from ..config.schema import output_stride
from ..files.columns import STATE_COLUMNS, display_factors, estimate_columns
from ..files.csvio import write_csv
from ..files.screen import screen_messages
from ..run.estimate_truth import gap_end_rows
from ..run.filtering import design_of, paper_smoother
from ..run.whole import filter_telemetry
from ..samples import output_rows, sun_gaps, sun_gaps_at
from ..units import DEG, RAD2DEG
from .compare import compare
from .source import read_source
from .spans import PAPER_MIN_SPAN_H, BatchRun, solve_spans


def _state_dict(x, omega_n: float, prefix: str = "") -> dict:
    f = display_factors(omega_n)
    return {f"{prefix}{name}": None if not np.isfinite(v) else float(v * abs(f[k]) if prefix
                                                                      else v * f[k])
            for k, (name, v) in enumerate(zip(STATE_COLUMNS, x, strict=True))}


def _overlap(run: BatchRun, j: int) -> dict | None:
    """Batch j against batch j − 1 where both fitted the samples (an overlap): the
    RMS and largest difference of their roll and yaw, the overlap comparison of
    definitive solutions.  None without an overlap or a converged pair."""
    if j == 0:
        return None
    prev, cur = run.spans[j - 1], run.spans[j]
    a, b = cur.a, min(prev.b, cur.b)
    sp, sc = run.solutions[j - 1], run.solutions[j]
    if b <= a or not (sp.converged and sc.converged):
        return None
    d = (sc.x[0:b - a] - sp.x[a - prev.a:b - prev.a])[:, [0, 2]] * RAD2DEG
    return {"samples": int(b - a),
            "roll_rms_deg": float(np.sqrt(np.mean(d[:, 0] ** 2))),
            "yaw_rms_deg": float(np.sqrt(np.mean(d[:, 1] ** 2))),
            "roll_max_deg": float(np.max(np.abs(d[:, 0]))),
            "yaw_max_deg": float(np.max(np.abs(d[:, 1])))}


def _batch_entries(run: BatchRun, t: np.ndarray, omega_n: float) -> list[dict]:
    out = []
    for sp, sol, prior in zip(run.spans, run.solutions, run.priors, strict=True):
        n_meas = int(sol.n_measurements.sum())
        rms = sol.residual_rms
        sc = None if sol.P0_consider is None else np.sqrt(np.diag(sol.P0_consider))
        out.append({
            "index": sp.index, "epoch_s": float(t[sp.a]),
            "span_s": [float(t[sp.a]), float(t[sp.b - 1])], "samples": sp.b - sp.a,
            "measurements": dict(zip(("roll", "yaw", "h"), map(int, sol.n_measurements),
                                     strict=True)),
            "a_priori": prior, "converged": bool(sol.converged),
            "iterations": int(sol.iterations), "cost": float(sol.cost),
            "cost_per_measurement": float(sol.cost / n_meas) if n_meas else None,
            "residual_rms": {"roll_deg": _deg(rms[0]), "yaw_deg": _deg(rms[1]),
                             "h_Nms": None if not np.isfinite(rms[2]) else float(rms[2])},
            "residual_rms_over_sigma": dict(zip(("roll", "yaw", "h"), (
                None if not np.isfinite(v) else float(v) for v in sol.residual_normalized),
                strict=True)),
            "fixed_states": list(sol.fixed), "message": sol.message or None,
            "overlap": _overlap(run, sp.index),
            "state": _state_dict(sol.x0, omega_n),
            "sigma": _state_dict(np.sqrt(np.diag(sol.P0)), omega_n, "sigma_"),
            "sigma_consider": None if sc is None else _state_dict(sc, omega_n,
                                                                  "sigma_consider_")})
    return out


def _deg(v) -> float | None:
    return None if not np.isfinite(v) else float(v * RAD2DEG)


def run_batch(source: Path, scenario=None, overrides=(), truth: Path | None = None,
              out: Path | None = None, model: str | None = None,
              span_h: float | None = None, overlap_h: float | None = None,
              force: bool = True, command: str | None = None) -> tuple[dict, Path]:
    """Everything `dynprop batch` does; returns batch.json's dictionary and the
    directory written (default: RUN_DIR/batch, or batch/ beside the file)."""
    from ..figures.batch import batch_figure
    from ..files.rundir import check_out_dir, staged_run_dir
    src = read_source(Path(source), scenario, overrides, truth)
    out = Path(out) if out is not None else (src.run_dir or src.telemetry.parent) / "batch"
    # An unusable --out is refused before the batches are solved, as `run` and
    # `estimate` refuse it (staged_run_dir checks it again when writing).
    check_out_dir(out, force)
    s, grid = src.scenario, src.grid
    model = model or s.batch.model
    span_h = s.batch.span_h if span_h is None else span_h
    overlap_h = s.batch.overlap_h if overlap_h is None else overlap_h
    cols = grid.columns
    t = cols["t_s"]
    n = len(t)
    tel = telemetry_inputs(s, cols)
    pitch = cols.get("pitch_deg")
    if model == "nonlinear" and pitch is None:
        raise BatchError(f"{src.telemetry}: no pitch_deg column: the nonlinear batch takes "
                         "pitch from the Earth sensor; add it, or use --model linear")
    present = np.isfinite(cols["yaw_deg"])
    min_h = s.estimator.sun_gap_min_h
    dt = s.sample_interval_s
    gaps = sun_gaps(present, dt, min_h) if grid.regular else sun_gaps_at(present, t, min_h)
    gaps = [(a, b) for a, b in gaps if b < n]
    step_s = dt if grid.regular else float(np.median(np.diff(t)))
    stride = output_stride(s) if grid.regular else max(1, round(dt * output_stride(s) / step_s))
    k = output_rows(0, n, stride)
    truth_rows = np.zeros(0, dtype=np.int64) if src.truth is None else src.truth.rows
    # The gap ends too: batch.json gives each one's estimates with or without a truth.
    rows = np.union1d(np.union1d(k, truth_rows), [b for _, b in gaps]).astype(np.int64)
    run = solve_spans(s, tel, None if pitch is None else pitch * DEG, rows, t, model, span_h,
                      overlap_h, on_grid=grid.regular)
    params, noise = build.estimator_model(s)
    wn = params.omega_n_radps
    disc = discretize(params, noise, dt) if grid.regular else StepTable(params, noise,
                                                                        grid.steps)
    real, args = filter_telemetry(s, params, disc, *tel, t_s=None if grid.regular else t)
    smoothed = paper_smoother(design_of(s), real, disc, **args)
    sig_b, sig_c = run.sigma_rows, run.sigma_consider_rows
    at_k = np.searchsorted(rows, k)
    d = {"scenario": s.name, "command": command, "model": model, "span_h": span_h,
         "overlap_h": overlap_h, "apriori": s.batch.apriori,
         "telemetry": {"file": str(src.telemetry.resolve()), "samples": n,
                       "first_t_s": float(t[0]), "last_t_s": float(t[-1]),
                       "screened": None if grid.screen is None else grid.screen.summary()},
         "converged": all(sol.converged for sol in run.solutions),
         "not_converged": [sp.index for sp, sol in zip(run.spans, run.solutions, strict=True)
                           if not sol.converged],
         "warnings": screen_messages(None if grid.screen is None else grid.screen.summary())
         + _warnings(run, span_h),
         "batches": _batch_entries(run, t, wn),
         "gap_ends": _gap_ends(t, gaps, rows, run.x, sig_b, real),
         "truth": None}
    sigmas = {"filter": real.sigma[rows][:, :N_STATES],
              "smoother": smoothed.sigma[rows][:, :N_STATES], "batch": sig_b}
    estimates = {"filter": real.x[rows][:, :N_STATES],
                 "smoother": smoothed.x[rows][:, :N_STATES], "batch": run.x[rows]}
    errors = None
    if src.truth is not None:
        tt = truth_torques(src.truth, s.estimator.model_torques, params.omega0_radps)
        tm = model_truth(params, src.truth, tt)
        at = np.searchsorted(rows, truth_rows)
        d["truth"] = compare(t, truth_rows, tm,
                             {name: (x[at], sigmas[name][at]) for name, x in estimates.items()},
                             gap_end_rows(gaps, truth_rows, real.sigma[:, 2], n), sig_c[at])
        errors = {name: (x[at] - tm)[:, [2, 0]] * RAD2DEG for name, x in estimates.items()}
    columns = estimate_columns(t[k], run.x[k], sig_b[at_k], wn)
    consider = estimate_columns(t[k], run.x[k], sig_c[at_k], wn)
    columns |= {name.replace("sigma_", "sigma_consider_"): consider[name]
                for name in consider if name.startswith("sigma_")}
    columns["batch"] = run.owner[k].astype(float)
    with staged_run_dir(out, force=force) as stage:
        write_csv(stage / "estimate_batch.csv", columns)
        (stage / "batch.json").write_text(json.dumps(d, indent=2, allow_nan=False) + "\n")
        gap = np.zeros(n, dtype=bool)
        for a, b in gaps:
            gap[a:b] = True
        if errors is not None:
            tr = truth_rows
            batch_figure(stage / "batch.png", t[tr], errors,
                         {key: v[at][:, [2, 0]] * RAD2DEG for key, v in sigmas.items()},
                         gap[tr], [t[sp.a] for sp in run.spans],
                         f"{s.name}: {model} batch, {span_h:g} h spans, against the truth",
                         sig_c[at][:, [2, 0]] * RAD2DEG)
        else:
            # No truth: the three estimates and their ±3σ about the batch's.
            est = {key: (x - estimates["batch"])[:, [2, 0]] * RAD2DEG
                   for key, x in estimates.items()}
            batch_figure(stage / "batch.png", t[rows], est,
                         {key: v[:, [2, 0]] * RAD2DEG for key, v in sigmas.items()},
                         gap[rows], [t[sp.a] for sp in run.spans],
                         f"{s.name}: {model} batch, {span_h:g} h spans: estimates less "
                         "the batch's (no truth)", sig_c[:, [2, 0]] * RAD2DEG)
    return d, out


def _gap_ends(t, gaps, rows, x_batch, sig_batch, real) -> list[dict]:
    """Each Sun-gap end's yaw (at the sample the Sun sensor's yaw returns): the batch's
    and the filter's, their σ and the batch's less the filter's, truth or none."""
    out = []
    for _, b in gaps:
        i = int(np.searchsorted(rows, b))
        yb, sb = x_batch[b, 2] * RAD2DEG, sig_batch[i, 2] * RAD2DEG
        yf, sf = real.x[b, 2] * RAD2DEG, real.sigma[b, 2] * RAD2DEG
        out.append({"t_s": float(t[b]), "batch_yaw_deg": _finite(yb),
                    "batch_sigma_deg": _finite(sb), "filter_yaw_deg": float(yf),
                    "filter_sigma_deg": float(sf), "batch_minus_filter_deg": _finite(yb - yf)})
    return out


def _finite(v) -> float | None:
    return float(v) if np.isfinite(v) else None


def _warnings(run: BatchRun, span_h: float) -> list[str]:
    w = []
    if span_h < PAPER_MIN_SPAN_H:
        w.append(f"batch.span_h: {span_h:g} h is shorter than the paper's 8 h (a third of "
                 "an orbit, Section 5): yaw is seen only through roll's orbit-rate coupling, "
                 "and a shorter span determines it poorly")
    for sp, sol in zip(run.spans, run.solutions, strict=True):
        if sol.fixed:
            w.append(f"batch {sp.index}: no yaw measurement in its span: the constant yaw "
                     f"torque ({', '.join(sol.fixed)}) is unobservable (Section 4) and is "
                     "held at its a priori")
        if not sol.converged:
            w.append(f"batch {sp.index}: {sol.message}; its estimates are not written "
                     "(NaN in estimate_batch.csv)")
    return w


def one_line(d: dict) -> str:
    parts = [f"{d['scenario']}: {d['model']} batch, {len(d['batches'])} span(s) of "
             f"{d['span_h']:g} h"]
    its = [b["iterations"] for b in d["batches"]]
    parts.append("converged in " + ", ".join(map(str, its)) + " iteration(s)"
                 if d["converged"] else f"NOT converged: batch(es) {d['not_converged']}")
    for g in d.get("gap_ends", ()):
        if g["batch_yaw_deg"] is None:
            continue
        parts.append(f"gap end {g['t_s'] / 3600:.2f} h: batch yaw {g['batch_yaw_deg']:+.4f} "
                     f"± {g['batch_sigma_deg']:.4f} deg, filter {g['filter_yaw_deg']:+.4f} "
                     f"± {g['filter_sigma_deg']:.4f}, batch − filter "
                     f"{g['batch_minus_filter_deg']:+.4f}")
    tr = d["truth"]
    if tr is not None and tr["gap_end_judged_at_t_s"] != tr["gap_end_t_s"]:
        parts.append("gap ends judged at the truth's t = " + ", ".join(
            "not tested" if t is None else f"{t:.3f}" for t in tr["gap_end_judged_at_t_s"])
            + " s (the ends are at " + ", ".join(f"{t:.3f}" for t in tr["gap_end_t_s"])
            + " s)")
    if tr is not None and tr["gap_end_t_s"]:
        for name in ("filter", "smoother", "batch"):
            ends = [g["error_deg"] for g in tr[name]["gap_ends"] if g["error_deg"] is not None]
            if ends:
                parts.append(f"{name} gap-end yaw " + ", ".join(f"{e:+.4f}" for e in ends)
                             + " deg")
    return "; ".join(parts)

