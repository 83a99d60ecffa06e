"""`dynprop batch`: the chained batches (``spans``) on a run's or a file's telemetry,
the filter and smoother on the same telemetry beside them, the truth comparison
(``compare``), and the files: estimate_batch.csv, batch.json, batch.png
(docs/batch.md, docs/outputs.md)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from dynprop.estimator.batch.linear import BatchError

from ..bridge.coordinates import model_truth, truth_torques
from ..config import build
from ..config.schema import output_stride
from ..files.columns import STATE_COLUMNS, display_factors, estimate_columns
from ..files.csvio import write_csv
from ..files.screen import screen_messages
from ..run.estimate_truth import gap_end_rows
from ..run.windowed import DAYS, Windows
from ..samples import output_rows, sun_gaps, sun_gaps_at
from ..units import RAD2DEG
from .compare import compare
from .histories import WINDOWS, Histories, histories_at
from .source import open_batch_source, span_data
from .spans import PAPER_MIN_SPAN_H, BatchRun, solve_chain


def _state_dict(x, omega_n: float, prefix: str = "") -> dict:
    f = display_factors(omega_n)
    return {f"{prefix}{name}": None if not np.isfinite(v) else float(v * abs(f[k]) if prefix
                                                                      else v * f[k])
            for k, (name, v) in enumerate(zip(STATE_COLUMNS, x, strict=True))}


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
            "overlap": run.overlaps[sp.index],
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
              force: bool = True, command: str | None = None,
              windows: Windows | None = None, block_rows: int | None = None
              ) -> tuple[dict, Path]:
    """Everything `dynprop batch` does; returns batch.json's dictionary and the
    directory written (default: RUN_DIR/batch, or batch/ beside the file).  The
    telemetry is read span by span and window by window, never whole (``source``,
    ``histories``); ``windows`` and ``block_rows`` (the reader's block) are test hooks
    that cut a short record as a long one is cut."""
    with open_batch_source(Path(source), scenario, overrides, truth, block_rows) as src:
        return _run_batch(src, out, model, span_h, overlap_h, force, command, windows)


def _yaw_present(tel, block: int = 1 << 20) -> np.ndarray:
    """Where the telemetry has a yaw, read a block at a time."""
    return np.concatenate([np.isfinite(tel.columns(a, min(a + block, tel.n), ["yaw_deg"])
                                       ["yaw_deg"]) for a in range(0, tel.n, block)])


def _run_batch(src, out, model, span_h, overlap_h, force, command, windows
               ) -> tuple[dict, Path]:
    from ..figures.batch import batch_figure
    from ..files.rundir import check_out_dir, staged_run_dir
    out = Path(out) if out is not None else (src.run_dir or src.telemetry.parent) / "batch"
    # An unusable --out is refused before the batches are solved, as `run` and
    # `estimate` refuse it (staged_run_dir checks it again when writing).
    check_out_dir(out, force)
    s, tel, t = src.scenario, src.source, src.t
    model = model or s.batch.model
    span_h = s.batch.span_h if span_h is None else span_h
    overlap_h = s.batch.overlap_h if overlap_h is None else overlap_h
    n = len(t)
    if model == "nonlinear" and "pitch_deg" not in tel.names:
        raise BatchError(f"{src.telemetry}: no pitch_deg column: the nonlinear batch takes "
                         "pitch from the Earth sensor; add it, or use --model linear")
    present = _yaw_present(tel)
    min_h = s.estimator.sun_gap_min_h
    dt = s.sample_interval_s
    gaps = sun_gaps(present, dt, min_h) if tel.regular else sun_gaps_at(present, t, min_h)
    gaps = [(a, b) for a, b in gaps if b < n]
    step_s = dt if tel.regular else float(np.median(np.diff(t)))
    stride = output_stride(s) if tel.regular else max(1, round(dt * output_stride(s) / step_s))
    k = output_rows(0, n, stride)
    truth_rows = np.zeros(0, dtype=np.int64) if src.truth is None else src.truth.rows
    # The gap ends too: batch.json gives each one's estimates with or without a truth.
    rows = np.union1d(np.union1d(k, truth_rows), [b for _, b in gaps]).astype(np.int64)
    run = solve_chain(s, t, span_data(s, tel, t, model, windows or DAYS), rows, model,
                      span_h, overlap_h)
    params, _ = build.estimator_model(s)
    wn = params.omega_n_radps
    hist = histories_at(s, tel, t, rows, windows or WINDOWS)
    sig_b, sig_c = run.sigma_rows, run.sigma_consider_rows
    at_k = np.searchsorted(rows, k)
    screen = None if tel.screen is None else tel.screen.summary()
    d = {"scenario": s.name, "command": command, "model": model, "span_h": span_h,
         "overlap_h": overlap_h, "apriori": s.batch.apriori,
         "telemetry": {"file": str(src.telemetry.resolve()), "samples": n,
                       "first_t_s": float(t[0]), "last_t_s": float(t[-1]),
                       "screened": screen},
         "converged": all(sol.converged for sol in run.solutions),
         "not_converged": [sp.index for sp, sol in zip(run.spans, run.solutions, strict=True)
                           if not sol.converged],
         "warnings": screen_messages(screen) + _warnings(run, span_h),
         "batches": _batch_entries(run, t, wn),
         "gap_ends": _gap_ends(t, gaps, rows, run.x_rows, sig_b, hist),
         "truth": None}
    sigmas = {"filter": hist.filter_sigma, "smoother": hist.smoother_sigma, "batch": sig_b}
    estimates = {"filter": hist.filter_x, "smoother": hist.smoother_x, "batch": run.x_rows}
    errors = None
    if src.truth is not None:
        tt = truth_torques(src.truth, s.estimator.model_torques, params.omega0_radps)
        tm = model_truth(params, src.truth, tt)
        at = np.searchsorted(rows, truth_rows)
        d["truth"] = compare(t, truth_rows, tm,
                             {name: (x[at], sigmas[name][at]) for name, x in estimates.items()},
                             gap_end_rows(gaps, truth_rows, hist.filter_sigma_at(), n),
                             sig_c[at])
        errors = {name: (x[at] - tm)[:, [2, 0]] * RAD2DEG for name, x in estimates.items()}
    columns = estimate_columns(t[k], run.x_rows[at_k], sig_b[at_k], wn)
    consider = estimate_columns(t[k], run.x_rows[at_k], sig_c[at_k], wn)
    columns |= {name.replace("sigma_", "sigma_consider_"): consider[name]
                for name in consider if name.startswith("sigma_")}
    columns["batch"] = run.owner_rows[at_k].astype(float)
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


def _gap_ends(t, gaps, rows, x_batch, sig_batch, hist: Histories) -> list[dict]:
    """Each Sun-gap end's yaw (at the sample the Sun sensor's yaw returns): the batch's
    and the filter's, their σ and the batch's less the filter's, truth or none."""
    out = []
    for _, b in gaps:
        i = int(np.searchsorted(rows, b))
        yb, sb = x_batch[i, 2] * RAD2DEG, sig_batch[i, 2] * RAD2DEG
        yf, sf = hist.filter_x[i, 2] * RAD2DEG, hist.filter_sigma[i, 2] * RAD2DEG
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

