"""The figures of a run directory (`dynprop run`, `estimate`, `simulate`, and
`dynprop plot DIR`): read its files and hand arrays to ``plots``.

A `run` or `estimate` directory is drawn from scenario.yaml and comparison.npz
alone (cut at its telemetry gaps, ``marks``), by ``plot_run_figures``, which both
the commands and `dynprop plot` call:
``figure_set`` decides the figures from the keys comparison.npz holds, so a redraw
gives exactly the set the command drew.  A `simulate` directory (no comparison.npz)
gets truth.png and telemetry.png from its CSV files.
"""

from __future__ import annotations

import contextlib
import json
import os
from collections.abc import Iterator
from multiprocessing import get_context
from pathlib import Path

import numpy as np
import yaml
from dynprop.estimator.kalman.consistency import chi2_bounds
from dynprop.estimator.linear import model as em
from dynprop.plots.consistency import plot_consistency
from dynprop.plots.errors import plot_errors, plot_estimates
from dynprop.plots.run_figures import TORQUE_NAMES, plot_torques
from dynprop.plots.season import plot_season
from dynprop.plots.telemetry import plot_telemetry_overview
from dynprop.plots.trim import plot_trim_loop
from dynprop.plots.truth import plot_truth

from ..files.csvio import read_csv
from ..files.rundir import RunDirError
from ..workers import worker_pool
from . import save_figure
from .marks import cut_at_gaps, shifted, summary_events

# Columns of the comparison arrays: the model's state indices (estimator.linear.model).
COLUMNS = {"roll": em.R, "yaw": em.Y, "h": em.H_WHEEL, "N_px": em.NPX, "N_pz": em.NPZ,
           "N_cx": em.NCX, "N_cz": em.NCZ}
UNITS = {"roll": "deg", "yaw": "deg", "h": "N m s"}
# Every figure name a run directory can hold: a redraw removes those not in its set.
RUN_FIGURES = ("errors.png", "estimates.png", "consistency.png", "torques.png",
               "telemetry_overview.png", "season.png", "trim_loop.png")
SIMULATE_FIGURES = ("truth.png", "telemetry.png")


def _draw(job) -> Path:
    function, args, kwargs, path = job
    return save_figure(function(*args, **kwargs), path)


def _title(scenario: dict) -> str:
    return (f"{scenario['name']} — seed {scenario['seed']}, epoch {scenario['epoch_utc']}, "
            f"dynprop {scenario.get('dynprop_version') or '?'}")


def figure_set(keys) -> list[str]:
    """The figures of a run directory, from the keys of its comparison.npz alone:
    errors.png with a truth (``err_real``), else estimates.png; consistency.png and
    torques.png always; telemetry_overview.png when the telemetry is stored."""
    keys = set(keys)
    return ["errors.png" if "err_real" in keys else "estimates.png", "consistency.png",
            "torques.png"] + (["telemetry_overview.png"] if "tel_yaw_deg" in keys else [])


def _summary(run_dir: Path) -> dict | None:
    """The run's summary.json (its full-rate NEES figures, per-state means and
    warnings), or None when the directory has none (yet)."""
    path = Path(run_dir) / "summary.json"
    if not path.is_file():
        return None
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


def _warnings(summary: dict | None, only: str | None = None) -> list[str]:
    """summary.json's ``warnings`` messages (``only``: those whose check ends so,
    e.g. "nees"); none without the key."""
    items = (summary or {}).get("warnings") or []
    return [w["message"] for w in items if isinstance(w, dict) and w.get("message")
            and (only is None or str(w.get("check", "")).endswith(only))]


def _gap_labels(scenario: dict, min_gap_s: float) -> tuple[str, str]:
    """What the two kinds of yaw outage are (decor.shade_gaps): a Sun gap, where no
    head sees the Sun, and a shorter outage (at the default geometry the noon band,
    where the Sun is too near the yaw axis for the ground to solve yaw)."""
    sep = float(scenario.get("sensors", {}).get("sun", {}).get("min_sun_separation_deg",
                                                                10.0))
    h = f"{min_gap_s / 3600:g} h"
    return (f"Sun gap (≥ {h} without yaw): no Sun-sensor head sees the Sun",
            f"yaw outage under {h}: Sun within {sep:g}° of the yaw axis (noon), or a dropout")


def _eq55_deg(scenario: dict) -> float:
    """Eq. 55's σ_yaw for this scenario, as summary.json's analytic_sigma_yaw_deg
    and the console give it."""
    from ..config import build
    from ..config.loader import validate
    from ..files.summary import eq55_sigma_yaw_deg
    s = validate(scenario)
    return eq55_sigma_yaw_deg(s, build.estimator_model(s)[0])


def _dss_note(scenario: dict) -> str | None:
    """Why yaw NIS is small in DSS periods, with the filter's σ inflation for the DSS
    (``bridge.inputs.yaw_correlation_inflation``, the function the filter used)."""
    from ..bridge.inputs import yaw_correlation_inflation
    from ..config.loader import validate
    s = validate(scenario)
    factor = float(np.sqrt(yaw_correlation_inflation(s, [0.0])[0]))
    if factor <= 1.0:
        return None
    return (f"DSS yaw deliberately down-weighted:\nthe filter's σ is {factor:.0f}× the "
            f"telemetry's\n(quantization error correlated over\nestimator."
            f"dss_error_correlation_s = {s.estimator.dss_error_correlation_s:g} s),\n"
            f"so yaw NIS ≈ 1/{factor ** 2:.0f} here by design")


def _errors_job(c: dict, gap, title: str, min_gap_s: float, scenario: dict,
                summary: dict | None):
    eq55 = _eq55_deg(scenario)
    kwargs = {"paper_sigma_deg": eq55, "paper_sigma_label": f"Eq. 55: {eq55:.4f}°",
              "gap_labels": _gap_labels(scenario, min_gap_s), "warnings": _warnings(summary),
              "screened_t_s": c.get("screened_t_s")}
    if summary_events(summary):     # a run without events: the call of before
        kwargs["events"] = summary_events(summary)
    if "err_real" not in c:
        series = {n: {"unit": UNITS[n], "estimate": c["x_real"][:, COLUMNS[n]],
                      "sigma": c["sigma"][:, COLUMNS[n]]} for n in UNITS}
        if "x_pitch" in c:
            series["pitch"] = {"unit": "deg", "estimate": c["x_pitch"][:, 0],
                               "sigma": c["sigma_pitch"][:, 0]}
        return plot_estimates, (c["t_s"], gap, series, title, min_gap_s), kwargs
    series = {}
    for j, n in enumerate(UNITS):
        i = COLUMNS[n]
        if not np.isfinite(c["err_real"][:, i]).any():
            continue    # a truth without that state (an AEM: the attitude only)
        s = {"unit": UNITS[n], "real": c["err_real"][:, i], "sigma": c["sigma"][:, i],
             "style": "trace" if n == "yaw" else "envelope"}
        if "err_linear" in c:
            s["linear"] = c["err_linear"][:, i]
        if "err_real_minus_linear" in c:
            s["difference"] = c["err_real_minus_linear"][:, j]
        if "err_real_max" in c:   # decimated rows: the full-rate extremes between them
            s.update(real_min=c["err_real_min"][:, i], real_max=c["err_real_max"][:, i],
                     row_interval=float(c["output_interval_s"]))
            if "err_real_minus_linear_max" in c:
                s.update(difference_min=c["err_real_minus_linear_min"][:, j],
                         difference_max=c["err_real_minus_linear_max"][:, j])
        if "err_smoothed" in c:
            s["smoothed"] = c["err_smoothed"][:, i]
        if "err_ekf" in c:
            s["ekf"] = c["err_ekf"][:, i]
            if "sigma_ekf" in c:
                s["ekf_sigma"] = c["sigma_ekf"][:, i]
        if n == "yaw":
            s["reference"] = (eq55, "σ_yaw, Eq. 55")
        series[n] = s
    if "err_pitch" in c:
        # The pitch filter's (Eq. 3b): its own panel, no twin or EKF beside it.
        s = {"unit": "deg", "real": c["err_pitch"][:, 0], "sigma": c["sigma_pitch"][:, 0],
             "style": "envelope"}
        if "err_pitch_max" in c:
            s.update(real_min=c["err_pitch_min"][:, 0], real_max=c["err_pitch_max"][:, 0],
                     row_interval=float(c["output_interval_s"]))
        series["pitch"] = s
    return plot_errors, (c["t_s"], gap, series, title, min_gap_s), kwargs


def _consistency_job(c: dict, gap, title: str, scenario: dict, min_gap_s: float,
                     summary: dict | None):
    nees = {k: c[f"nees_{k}"] for k in ("real", "linear") if f"nees_{k}" in c} or None
    for k in ("real", "linear"):
        if nees is not None and f"nees_{k}_max" in c:
            nees[f"{k}_max"] = c[f"nees_{k}_max"]
    nis = {m: c["nis_real"][:, i] for i, m in enumerate(("roll", "yaw", "h"))}
    dss = None
    if "tel_sun_head" in c:
        dss = (c["tel_sun_head"] == 0) & (c["yaw_present"] > 0.5)
    note = _dss_note(scenario) if dss is not None and dss.any() else None
    return plot_consistency, (c["t_s"], gap, nees, em.N_STATES, chi2_bounds(em.N_STATES),
                              nis, chi2_bounds(1), title), {
        "dss": dss, "dss_note": note, "summary": summary, "warnings": _warnings(summary, "nees"),
        "min_gap_s": min_gap_s, "gap_labels": _gap_labels(scenario, min_gap_s)}


def _torques_job(c: dict, gap, title: str, labels: dict):
    truth = {k: c["truth_model"][:, COLUMNS[k]] for k in TORQUE_NAMES} \
        if "truth_model" in c else None
    return plot_torques, (c["t_s"], gap, {k: c["x_real"][:, COLUMNS[k]] for k in TORQUE_NAMES},
                          {k: c["sigma"][:, COLUMNS[k]] for k in TORQUE_NAMES}, title), \
        {"truth": truth, **labels}


def _telemetry_job(c: dict, gap, title: str, labels: dict):
    measured = {n: c[f"tel_{n}_deg"] for n in ("roll", "pitch", "yaw") if f"tel_{n}_deg" in c}
    truth = None
    if "true_euler_deg" in c:
        e = c["true_euler_deg"]
        truth = {"yaw": e[:, 0], "roll": e[:, 1], "pitch": e[:, 2]}
    wheels = {k[4:]: c[k] for k in c if k.startswith("tel_wheel") and k.endswith("_rpm")}
    return plot_telemetry_overview, (c["t_s"], measured, truth, wheels, gap, title), \
        {"yaw_sigma": c.get("tel_yaw_sigma_deg"), "sun_head": c.get("tel_sun_head"), **labels}


def _run_builders(run_dir: Path) -> tuple[list[str], dict]:
    """The figure names of a `run` or `estimate` directory and, for each, a builder
    returning (drawing function, args, kwargs)."""
    run_dir = Path(run_dir)
    scenario = yaml.safe_load((run_dir / "scenario.yaml").read_text())
    title = _title(scenario)
    with np.load(run_dir / "comparison.npz") as npz:
        cut = cut_at_gaps({k: npz[k] for k in npz.files})
    c = dict(cut)
    # Computed on every row, then cut: an outage running through a telemetry gap stays one.
    gap = cut.rows(cut.source["yaw_present"] < 0.5)
    # Sun gaps as summary.json counts them (not the noon outages).
    min_gap_s = 3600.0 * scenario["estimator"]["sun_gap_min_h"]
    summary = _summary(run_dir)
    labels = {"min_gap_s": min_gap_s, "gap_labels": _gap_labels(scenario, min_gap_s)}
    builders = {
        "errors.png": lambda: _errors_job(c, gap, title, min_gap_s, scenario, summary),
        "estimates.png": lambda: _errors_job(c, gap, title, min_gap_s, scenario, summary),
        "consistency.png": lambda: _consistency_job(c, gap, title, scenario, min_gap_s,
                                                    summary),
        "torques.png": lambda: _torques_job(c, gap, title, labels),
        "telemetry_overview.png": lambda: _telemetry_job(c, gap, title, labels),
    }
    names = figure_set(c)
    daily = run_dir / "daily.csv"
    if daily.is_file():
        # A run's days against the season: a figure for runs over two days (the
        # streamed, multi-window ones).
        rows = read_csv(daily)
        if len(rows["day"]) >= 3:
            names.append("season.png")
            season = {"warnings": _warnings(summary)}
            if summary_events(summary):
                # daily.csv's days start at the first row (t = 0 in a run).
                season["events"] = shifted(summary_events(summary),
                                           float(cut.source["t_s"][0]))
            builders["season.png"] = lambda: (plot_season, (rows, title), season)
        if (run_dir / "trim_loop.csv").is_file():
            names.append("trim_loop.png")
            builders["trim_loop.png"] = lambda: (plot_trim_loop, (
                read_csv(run_dir / "trim_loop.csv"), rows, title), {})
    return names, builders


def run_figure(run_dir: Path, name: str):
    """One figure of a `run` or `estimate` directory as a matplotlib Figure, the very
    drawing ``plot_run_figures`` saves (``name`` without ".png": "errors", ...)."""
    names, builders = _run_builders(run_dir)
    key = name if name.endswith(".png") else f"{name}.png"
    if key not in names:
        raise KeyError(f"no figure {name!r} for this run; it has "
                       + ", ".join(n[:-4] for n in names))
    fn, args, kwargs = builders[key]()
    return fn(*args, **kwargs)


def plot_run_figures(run_dir: Path) -> list[Path]:
    """The figures of a `run` or `estimate` directory, from scenario.yaml and
    comparison.npz (and daily.csv for season.png, when it holds three days or more);
    the set is ``figure_set`` of the stored keys, and figures of another set left by
    an earlier drawing are removed."""
    with run_figures_drawn(run_dir) as written:
        pass
    return written


@contextlib.contextmanager
def run_figures_drawn(run_dir: Path) -> Iterator[list[Path]]:
    """``plot_run_figures``, drawn in two worker processes while the block runs: the
    caller waits for something else meanwhile (`run`: its producer writing the last
    of truth.csv and telemetry.csv).  The yielded list holds the figures' paths once
    the block has ended and every figure is saved; an error in the block stops the
    drawing."""
    jobs = _run_jobs(run_dir)
    written: list[Path] = []
    # Two at a time on two cores (rendering dominates); one figure needs no pool.
    if len(jobs) < 2 or (os.cpu_count() or 1) < 2:
        yield written
        written.extend(_draw(j) for j in jobs)
        return
    with worker_pool(2, get_context("fork")) as pool:
        drawing = [pool.submit(_draw, j) for j in jobs]
        yield written
        written.extend(f.result() for f in drawing)


def _run_jobs(run_dir: Path) -> list:
    run_dir = Path(run_dir)
    names, builders = _run_builders(run_dir)
    out = run_dir / "plots"
    out.mkdir(exist_ok=True)
    for stale in set(RUN_FIGURES + SIMULATE_FIGURES) - set(names):
        if (out / stale).exists():   # (on a read-only run, no error naming a file it never had)
            (out / stale).unlink()
    return [(*builders[name](), out / name) for name in names]


def plot_simulation(run_dir: Path) -> list[Path]:
    """truth.png and telemetry.png of a `simulate` directory, from its CSV files."""
    scenario = yaml.safe_load((run_dir / "scenario.yaml").read_text())
    title = _title(scenario)
    truth = read_csv(run_dir / "truth.csv")
    tel = read_csv(run_dir / "telemetry.csv")
    out = run_dir / "plots"
    out.mkdir(exist_ok=True)
    sources = sorted({k[:-5] for k in truth if k.endswith("_x_Nm")}
                     - {"wheel_ripple", "wheel_input", "external"})
    torques = {s: np.column_stack([truth[f"{s}_{a}_Nm"] for a in "xyz"]) for s in sources}
    written = [save_figure(plot_truth(
        truth["t_s"], {n: truth[f"{n}_deg"] for n in ("yaw", "roll", "pitch")}, truth["h_Nms"],
        torques, truth["eclipse"] > 0, f"Truth: {title}"), out / "truth.png")]
    angles = ("roll", "pitch", "yaw")
    wheels = {k: tel[k] for k in tel if k.startswith("wheel") and k.endswith("_rpm")}
    written.append(save_figure(plot_telemetry_overview(
        tel["t_s"], {n: tel[f"{n}_deg"] for n in angles}, {n: truth[f"{n}_deg"] for n in angles},
        wheels, ~np.isfinite(tel["yaw_deg"]), title, yaw_sigma=tel.get("yaw_sigma_deg"),
        sun_head=tel.get("sun_head")), out / "telemetry.png"))
    return written


def plot_run(run_dir: Path) -> list[Path]:
    """`dynprop plot` on a run directory: a `run`/`estimate` one (comparison.npz) is
    redrawn exactly as the command drew it; a `simulate` one gets its two figures."""
    run_dir = Path(run_dir)
    have = {p.name for p in run_dir.iterdir()} if run_dir.is_dir() else set()
    if {"scenario.yaml", "comparison.npz"} <= have:
        written = plot_run_figures(run_dir)
    elif {"scenario.yaml", "truth.csv", "telemetry.csv"} <= have:
        written = plot_simulation(run_dir)
    else:
        missing = [n for n in ("scenario.yaml", "truth.csv", "telemetry.csv") if n not in have]
        raise RunDirError(f"{run_dir}: not a run directory (missing {', '.join(missing)}; "
                          "or scenario.yaml and comparison.npz)")
    import matplotlib.pyplot as plt
    plt.close("all")
    return written

