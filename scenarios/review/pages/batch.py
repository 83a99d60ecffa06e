"""The page of a `dynprop batch` directory (RUN_DIR/batch/): whether every batch
converged, the gap-end yaw of the batch, the filter and the smoother against the
truth, one row per batch, and the errors against time (docs/outputs.md, "Batch";
docs/batch.md).

The errors: estimate_batch.csv (at the run's output rows) less the truth in model
coordinates, comparison.npz's ``truth_model`` in the run directory the batch was
made from, when its rows are estimate_batch.csv's (batch.json's own yaw RMS is
that difference's); the filter's and the smoother's errors are comparison.npz's
``err_real`` and ``err_smoothed``.  Without them, the batch's estimates and ±3σ.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...files.csvio import read_csv
from .. import traces as tr
from ..cells import Table, cell, text
from ..page_parts import page, record_table, run_dir_of, verdict, vline
from ..render import Page, Section
from ..run_figures import STARTUP_S, Plot
from ..source import ReportInputError, Source, read_json

BATCH = "batch.json"
CSV = "estimate_batch.csv"
ESTIMATORS = (("batch", "batch"), ("filter", "filter"), ("smoother", "filter + RTS smoother"))
OWN = ("batches", "truth")
PANELS = (("yaw", 2), ("roll", 0))
COLOR = {"batch": tr.COLORS["ekf"], "filter": tr.COLORS["real"],
         "smoother": tr.COLORS["smoothed"]}


def verdicts(b: dict) -> list:
    """Every batch converged (``converged``); per estimator, every gap-end yaw error
    within its ±3σ (``truth.<estimator>.gap_ends_within_3sigma``, "not tested"
    without a truth), the batch also against its consider σ."""
    bad = b.get("not_converged") or []
    out = [verdict("Converged", b.get("converged"), [
        text(f"{len(b.get('batches') or [])} batch(es) of "), cell(b.get("span_h"), BATCH,
                                                                    "span_h", "h"),
        text("; not converged: "), cell(bad, BATCH, "not_converged") if bad else text("none")])]
    truth = b.get("truth")
    if not truth:
        return out + [verdict(f"{n[0].upper()}{n[1:]} σ", None, [text("not tested: no truth")])
                      for _, n in ESTIMATORS]
    for key, name in ESTIMATORS:
        est = truth.get(key) or {}
        parts = [text("gap-end yaw error within ±3σ: ")]
        for j, g in enumerate(est.get("gap_ends") or []):
            k = f"truth.{key}.gap_ends[{j}]"
            parts += [text(f"{'; ' if j else ''}gap end {j + 1} "),
                      cell(g.get("error_deg"), BATCH, f"{k}.error_deg", "°"), text(" against σ "),
                      cell(g.get("sigma_deg"), BATCH, f"{k}.sigma_deg", "°")]
        out.append(verdict(f"{name[0].upper()}{name[1:]} σ", est.get("gap_ends_within_3sigma"),
                           parts))
        if key == "batch":
            flags = [g.get("within_3sigma_consider") for g in est.get("gap_ends") or []]
            ok = None if not flags or None in flags else all(flags)
            parts = [text("gap-end yaw error within ±3σ with the consider parameters: ")]
            for j, g in enumerate(est.get("gap_ends") or []):
                parts += [text(f"{'; ' if j else ''}gap end {j + 1} σ "),
                          cell(g.get("sigma_consider_deg"), BATCH,
                               f"truth.batch.gap_ends[{j}].sigma_consider_deg", "°")]
            out.append(verdict("Batch consider σ", ok, parts))
    return out


def batch_table(b: dict) -> Table:
    rows = []
    for i, e in enumerate(b.get("batches") or []):
        k = f"batches[{i}]"
        span = e.get("span_s") or [None, None]
        meas = e.get("measurements") or {}
        rr, rs = e.get("residual_rms") or {}, e.get("residual_rms_over_sigma") or {}
        over = e.get("overlap") or {}
        row = [cell(e.get("index"), BATCH, f"{k}.index"), cell(e.get("epoch_s"), BATCH,
                                                              f"{k}.epoch_s"),
               cell(span[0], BATCH, f"{k}.span_s[0]"), cell(span[1], BATCH, f"{k}.span_s[1]"),
               cell(e.get("samples"), BATCH, f"{k}.samples")]
        row += [cell(meas.get(m), BATCH, f"{k}.measurements.{m}") for m in ("roll", "yaw", "h")]
        row += [cell(e.get("converged"), BATCH, f"{k}.converged",
                     css="" if e.get("converged") else "failed"),
                cell(e.get("iterations"), BATCH, f"{k}.iterations"),
                cell(e.get("cost"), BATCH, f"{k}.cost"),
                cell(e.get("cost_per_measurement"), BATCH, f"{k}.cost_per_measurement")]
        row += [cell(rr.get(m), BATCH, f"{k}.residual_rms.{m}")
                for m in ("roll_deg", "yaw_deg", "h_Nms")]
        row += [cell(rs.get(m), BATCH, f"{k}.residual_rms_over_sigma.{m}")
                for m in ("roll", "yaw", "h")]
        row += [cell(e.get("fixed_states"), BATCH, f"{k}.fixed_states"),
                cell(over.get("yaw_rms_deg"), BATCH, f"{k}.overlap.yaw_rms_deg") if over
                else cell(e.get("overlap"), BATCH, f"{k}.overlap"),
                cell(e.get("a_priori"), BATCH, f"{k}.a_priori"),
                cell(e.get("message"), BATCH, f"{k}.message")]
        rows.append(row)
    cols = ["batch", "epoch (s)", "from (s)", "to (s)", "samples", "roll meas.", "yaw meas.",
            "h meas.", "converged", "iterations", "cost", "cost / measurement",
            "residual RMS roll (°)", "yaw (°)", "h (N m s)", "RMS/σ roll", "yaw", "h",
            "fixed states", "overlap yaw RMS (°)", "a priori", "message"]
    return Table("batch-batches", cols, rows, "One row per batch (batch.json batches; about 1 in "
                 "RMS/σ where the fit is consistent)")


def state_table(b: dict) -> Table:
    """The solution at each batch's epoch with its σ and consider σ."""
    batches = b.get("batches") or []
    names = list(batches[0].get("state") or {}) if batches else []
    rows = []
    for s in names:
        row = [text(s)]
        for i, e in enumerate(batches):
            row += [cell((e.get("state") or {}).get(s), BATCH, f"batches[{i}].state.{s}"),
                    cell((e.get("sigma") or {}).get(f"sigma_{s}"), BATCH,
                         f"batches[{i}].sigma.sigma_{s}"),
                    cell((e.get("sigma_consider") or {}).get(f"sigma_consider_{s}"), BATCH,
                         f"batches[{i}].sigma_consider.sigma_consider_{s}")]
        rows.append(row)
    cols = ["state"] + [f"batch {e.get('index', i)} {q}" for i, e in enumerate(batches)
                        for q in ("estimate", "σ", "consider σ")]
    return Table("batch-states", cols, rows, "The solution at each batch's epoch (estimate.csv's "
                 "units), its σ and its σ with the consider parameters")


def truth_table(b: dict) -> Table | None:
    truth = b.get("truth")
    if not truth:
        return None
    n = max((len((truth.get(k) or {}).get("gap_ends") or []) for k, _ in ESTIMATORS), default=0)
    rows = []
    for key, name in ESTIMATORS:
        est = truth.get(key) or {}
        row = [text(name), cell(est.get("yaw_rms_deg"), BATCH, f"truth.{key}.yaw_rms_deg"),
               cell(est.get("roll_rms_deg"), BATCH, f"truth.{key}.roll_rms_deg"),
               cell(est.get("gap_ends_within_3sigma"), BATCH,
                    f"truth.{key}.gap_ends_within_3sigma")]
        for j in range(n):
            g = (est.get("gap_ends") or [])[j] if j < len(est.get("gap_ends") or []) else {}
            k = f"truth.{key}.gap_ends[{j}]"
            row += [cell(g.get(f), BATCH, f"{k}.{f}", css="failed" if g.get(f) is False else "")
                    if f in g else text("—") for f in ("error_deg", "sigma_deg", "within_3sigma",
                                                       "sigma_consider_deg",
                                                       "within_3sigma_consider")]
        rows.append(row)
    cols = ["estimator", "yaw RMS (°)", "roll RMS (°)", "every gap end within 3σ"]
    cols += [f"gap end {j + 1} {q}" for j in range(n)
             for q in ("error (°)", "σ (°)", "within 3σ", "consider σ (°)",
                       "within 3 consider σ")]
    return Table("batch-truth", cols, rows, "Against the truth (batch.json truth; each gap end "
                 "judged at the last truth sample inside the gap)")


def _optional_json(path: Path) -> dict | None:
    try:
        return read_json(path) if path.is_file() else None
    except ReportInputError:
        return None


def errors_figure(src: Source, run_dir: Path | None) -> Plot | None:
    """Yaw and roll: the batch's error with its ±3σ and consider ±3σ beside the
    filter's and the smoother's errors and the filter's ±3σ; Sun gaps shaded,
    the batches' epochs dotted.  The estimates and ±3σ without a truth."""
    f = src.path / CSV
    if not f.is_file():
        return None
    est = read_csv(f)
    t = est["t_s"]
    c = None
    if run_dir is not None and (run_dir / "comparison.npz").is_file():
        with np.load(run_dir / "comparison.npz") as z:
            if "truth_model" in z.files and len(z["t_s"]) == len(t) \
                    and np.allclose(z["t_s"], t):
                c = {k: z[k] for k in ("truth_model", "err_real", "err_smoothed", "sigma")
                     if k in z.files}
    scale, unit = tr.time_unit(float(t[-1] - t[0]) if len(t) else 0.0)
    x = t / scale
    summary = _optional_json(run_dir / "summary.json") if run_dir else None
    gaps = [(a * 3600 / scale, b * 3600 / scale) for a, b in
            (summary or {}).get("sun_gaps_h") or []]
    shapes = tr.shades(gaps, "sun_gap")
    shapes += [vline(e["epoch_s"] / scale, tr.COLORS["ekf"]) for e in src.record.get("batches")
               or [] if e.get("epoch_s") is not None]
    data = [tr.legend_only("Sun gap", tr.SHADES["sun_gap"])] if gaps else []
    panels = []
    for i, (n, col) in enumerate(PANELS):
        y, first = tr.axis(i), i == 0
        b_est, s = est[f"{n}_deg"], est[f"sigma_{n}_deg"]
        sc = est.get(f"sigma_consider_{n}_deg")
        if c is not None:
            err = b_est - c["truth_model"][:, col]
            data += tr.sigma_band(x, c["sigma"][:, col], y, "filter ±3σ", tr.COLORS["sigma"],
                                  group="fsig", show=first)
            data += tr.series(x, c["err_real"][:, col], "filter error", COLOR["filter"], y,
                              group="filter", show=first)
            if "err_smoothed" in c:
                data += tr.series(x, c["err_smoothed"][:, col], "smoother error",
                                  COLOR["smoother"], y, group="smoother", show=first)
            centre = None
            rng = tr.robust_range([3 * c["sigma"][:, col], err], x, STARTUP_S, scale)
        else:
            err, centre, rng = b_est, b_est, None
        data += _about(x, centre, s, "batch ±3σ", "dash", "bsig", first, y,
                       COLOR["batch"] if c is not None else tr.COLORS["sigma"])
        if sc is not None:
            data += _about(x, centre, sc, "batch consider ±3σ", "dot", "bcon", first, y,
                           COLOR["batch"] if c is not None else tr.COLORS["linear"])
        data += tr.series(x, err, "batch error" if c is not None else "batch estimate",
                          COLOR["batch"], y, group="batch", show=first)
        panels.append({"title": f"{n} {'error ' if c is not None else ''}(deg)", "range": rng})
    layout = tr.stacked_layout(panels, f"time since epoch ({unit})", 240, shapes,
                               (float(x[0]), float(x[-1])) if len(x) else None)
    caption = ("The batch's error (estimate_batch.csv less the run's truth in model "
               "coordinates) with its ±3σ (dashed) and its consider ±3σ (dotted), beside the "
               "filter's and the smoother's errors (the run's comparison.npz) and the filter's "
               "±3σ; green dotted verticals: the batches' epochs. The first hour is left out "
               "of the initial scales." if c is not None else
               "No truth at estimate_batch.csv's rows: the batch's estimates with their ±3σ "
               "(grey) and consider ±3σ (orange); green dotted verticals: the batches' epochs.")
    return Plot("batch-errors", "Errors against the truth" if c is not None
                else "The batch's estimates", caption, {"data": data, "layout": layout})


def _about(x, centre, sigma, name, dash, group, show, y, color) -> list[dict]:
    """±3σ: about zero for errors (``centre`` None: two lines, the widest 3σ per bin
    as ``tr.sigma_band``), about the estimate otherwise (binned as any series: there
    the colour tells the two σ apart, a band has no dash)."""
    if centre is None:
        return tr.sigma_band(x, sigma, y, name, color, dash, group=group, show=show)
    return (tr.series(x, centre + 3 * sigma, name, color, y, group=group, show=show)
            + tr.series(x, centre - 3 * sigma, name, color, y, group=group, show=False))


def build(src: Source, command: str | None, requirement_deg: float | None = None) -> Page:
    b = src.record
    tel = b.get("telemetry") or {}
    hint = str(Path(tel["file"]).parent) if tel.get("file") else None
    run_dir = run_dir_of(src, hint)
    warnings = b.get("warnings") or []
    intro = ("Definitive attitude: Gauss–Newton batch least squares over spans of the "
             "telemetry, against the filter and the filter plus smoother on the same "
             "telemetry (docs/batch.md)." + (" Warnings: " + " ".join(warnings)
                                              if warnings else ""))
    tables = [t for t in (truth_table(b),) if t is not None]
    sections = [Section("verdict", "Verdict", intro, verdicts(b), tables)]
    fig = errors_figure(src, run_dir)
    sections.append(Section("errors", "Errors", plots=[fig] if fig else []))
    sections.append(Section("batches", "Batches", tables=[batch_table(b), state_table(b)]))
    rest = [record_table("batch-record", b, BATCH, "batch.json, the rest: what was run and on "
                         "what", skip=OWN)]
    if b.get("truth"):
        rest.append(record_table("batch-truth-record", b["truth"], BATCH, "batch.json truth: "
                                 "where the gap ends were judged", skip=("filter", "smoother",
                                                                         "batch"),
                                 prefix="truth"))
    sections.append(Section("tables", "Tables", tables=rest))
    return page(src, command, "batch", f"{b.get('scenario')}: dynprop batch",
                f"{b.get('model')} model, {b.get('span_h')} h spans, overlap "
                f"{b.get('overlap_h')} h, a priori {b.get('apriori')}; {b.get('command') or ''}",
                sections, run_dir)
