"""`dynprop estimate` through the run's engine: a telemetry file of any length,
window by window, written as `run` writes its directory (docs/outputs.md).

The source (``files.telemetry_source``) answers for samples by range, so memory
holds a window or two whatever the file's length; the windows are `run`'s
(``file_windows``), filtered, smoothed (with the smoothed 1σ, for smoothed.csv) and
tallied by the same stages and ``engine`` as a run's, so a run's telemetry.csv gives
back the run's estimate.csv, daily.csv and comparison.npz.
"""

from __future__ import annotations

from itertools import islice
from pathlib import Path

import numpy as np

from ...config import build
from ...config.schema import Scenario, resolved_yaml
from ...files.checks import add_checks
from ...files.summary import assemble_summary, write_summary
from ...records import Window
from ...units import DAY_S
from ..filtering import design_of, filter_section
from .directory import Progress
from .engine import Engine
from .file_windows import FileTruth, file_plan, file_windows
from .stages import filtered, smoothed


def file_windows_of(s: Scenario, source, plan, truth=None):
    """The plan, then each window of the file filtered, smoothed and joined."""
    records = smoothed(s, filtered(s, file_windows(s, source, plan, truth)), True,
                       covariance=True)
    yield next(records)
    params, _ = build.estimator_model(s)
    for rec in records:
        yield Window.join(rec.window, None, params=params, real=rec.real,
                          nees_real=rec.nees_real, smoothed_x=rec.smoothed_x,
                          filters=rec.filters, pitch=rec.pitch,
                          smoothed_sigma=rec.smoothed_sigma, pitch_rows=rec.pitch_rows)


def estimate_stream(s: Scenario, source, stage: Path, sources: dict,
                    window_samples: int | None = None, progress: bool = True,
                    truth_path: Path | None = None) -> dict:
    """`dynprop estimate` on ``source`` into ``stage``; returns the summary.
    ``sources``: the input files' names, for summary.json; ``window_samples``: the
    windows' length in samples (a test hook; None: `run`'s plan); ``truth_path``: a
    truth.csv, whose errors are then formed where it has rows (``run.estimate_truth``'s
    rules: at every sample as `run`'s, or at its rows and the gap ends judged there)."""
    stage = Path(stage)
    from ..ekf import check_ekf_columns
    check_ekf_columns(s, source.names)
    (stage / "scenario.yaml").write_text(resolved_yaml(s))
    params, _ = build.estimator_model(s)
    plan = file_plan(s, source, window_samples)
    n = plan.n_samples
    t0 = float(source.columns(0, 1, ["t_s"])["t_s"][0])
    t_last = float(source.columns(n - 1, n, ["t_s"])["t_s"][0])
    step = None if source.regular else source.median_step_s()
    truth = None
    if truth_path is not None:
        from ...files.truth_file import truth_columns
        truth = FileTruth(s, truth_path, truth_columns(truth_path), source, t0)
    engine = Engine(s, stage, plan, truth=truth is not None, twin=False, t0_s=t0,
                    smoothed=True, step_s=step,
                    span_s=None if source.regular else (t0, t_last))
    bar = Progress((t_last - t0) / DAY_S, progress and len(plan.bounds) > 1, "estimated")
    records = file_windows_of(s, source, plan, truth)
    next(records)
    try:
        for w in islice(records, len(plan.bounds)):
            engine.add(w)
            bar.update((w.t_s[-1] - t0) / DAY_S)
            del w
        bar.close()
        step_s = s.sample_interval_s if source.regular else step
        engine.finish(plan.stride * step_s)
        screened = source.screened_t_s()
        if screened.size:
            _add_screened(stage / "comparison.npz", screened)
    finally:
        records.close()
        engine.close()
        bar.close()
    tally = engine.tally
    if truth is not None and not truth.rows_seen:
        from ...files.rundir import RunDirError
        raise RunDirError(f"{truth_path}: no row at a time of the telemetry's samples, so no "
                          "error can be computed: use a truth.csv of the same run or "
                          "simulation")
    summary = assemble_summary(s, params, tally.backend, truth is not None, False,
                               tally.statistics(n))
    if not source.regular:
        summary["sun_gaps_h"] = tally.gaps.hours
    summary["filters"] = ["paper", *engine.extra]
    # The truth's biases are known only from a simulated run's scenario; a real file's
    # are what the filter is for.
    summary.update(filter_section(s, design_of(s), engine.last_bias, engine.rejected,
                                  None if truth is None else build.truth_biases_rad(s)))
    for name, (figs, _) in engine.extra.items():
        summary[name] = figs.summary()
    summary["pitch"] = engine.pitch.summary() if engine.pitch.backend is not None else None
    summary.update(output_interval_s=plan.stride * step_s, telemetry_written=None,
                   daily="daily.csv")
    summary["telemetry"] = {**sources, **source.stats(s.sample_interval_s),
                            **_truth_section(truth, tally)}
    # summary.json before the figures: they draw its verdicts and warnings.
    write_summary(stage / "summary.json", add_checks(summary))
    from ...figures.run import plot_run_figures
    plot_run_figures(stage)
    return summary


def _truth_section(truth, tally) -> dict:
    """summary.json's ``telemetry`` keys on the truth the errors were formed against
    (``run.estimate``'s ``_truth_section``)."""
    if truth is None:
        return {"truth_rows": None, "compared_rows": None, "compared_cadence_s": None,
                "gap_end_compared_at_s": None, "truth_holds": None}
    t = np.concatenate(truth.t_seen)
    steps = np.diff(t)
    return {"truth_rows": truth.file_rows, "compared_rows": int(len(t)),
            "compared_cadence_s": float(np.median(steps)) if steps.size else None,
            "gap_end_compared_at_s": tally.compared_at, "truth_holds": "every state"}


def _add_screened(path: Path, t_s: np.ndarray) -> None:
    """comparison.npz's ``screened_t_s``: the times of the rows with a screened value,
    which the figures and the page mark."""
    import zipfile
    with zipfile.ZipFile(path, "a", zipfile.ZIP_STORED, allowZip64=True) as zf:
        info = zipfile.ZipInfo("screened_t_s.npy", date_time=(1980, 1, 1, 0, 0, 0))
        with zf.open(info, "w", force_zip64=True) as f:
            np.lib.format.write_array(f, np.asarray(t_s, dtype=float))
