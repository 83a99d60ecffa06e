"""`dynprop plot DIR`: read a run directory's files and hand arrays to ``plots``."""

from __future__ import annotations

import os
from multiprocessing import get_context
from pathlib import Path

import numpy as np
import yaml

from estimator import model as em
from estimator.consistency import chi2_bounds
from plots.run_figures import (
    plot_consistency,
    plot_errors,
    plot_telemetry_overview,
    plot_torques,
)
from plots.telemetry import plot_telemetry
from plots.truth import plot_truth

from .csvio import read_csv
from .rundir import RunDirError
from .workers import worker_pool

# Columns of the comparison arrays: the model's state indices (estimator.model).
COLUMNS = {"roll": em.R, "yaw": em.Y, "h": em.H_WHEEL, "N_px": em.NPX, "N_pz": em.NPZ,
           "N_cx": em.NCX, "N_cz": em.NCZ}


def save_figure(fig, path: Path) -> Path:
    # Write beside the target and rename, so a figure is never half written.
    tmp = path.with_name(f".{path.name}.tmp")
    fig.savefig(tmp, dpi=120, format="png")
    os.replace(tmp, path)
    import matplotlib.pyplot as plt
    plt.close(fig)
    return path


def _draw(job) -> Path:
    function, args, path = job
    return save_figure(function(*args), path)


def _draw_all(jobs) -> list[Path]:
    """Draw and save figures, two at a time on two cores (rendering dominates)."""
    if len(jobs) < 2 or (os.cpu_count() or 1) < 2:
        return [_draw(j) for j in jobs]
    with worker_pool(2, get_context("fork")) as pool:
        return list(pool.map(_draw, jobs))


def _title(scenario: dict) -> str:
    return (f"{scenario['name']} — seed {scenario['seed']}, epoch {scenario['epoch_utc']}, "
            f"dynprop {scenario.get('dynprop_version') or '?'}")


def plot_run_figures(run_dir: Path, telemetry: dict | None = None) -> list[Path]:
    """The four `dynprop run` figures from comparison.npz and telemetry.csv."""
    run_dir = Path(run_dir)
    scenario = yaml.safe_load((run_dir / "scenario.yaml").read_text())
    title = _title(scenario)
    c = dict(np.load(run_dir / "comparison.npz"))
    tel = telemetry if telemetry is not None else read_csv(run_dir / "telemetry.csv")
    t = c["t_s"]
    gap = c["yaw_present"] < 0.5
    col = COLUMNS

    def series(name, unit):
        i = col[name]
        return {"unit": unit, "real": c["err_real"][:, i], "linear": c["err_linear"][:, i],
                "sigma": c["sigma"][:, i], "smoothed": c["err_smoothed"][:, i]}

    out = run_dir / "plots"
    out.mkdir(exist_ok=True)
    torques = ("N_px", "N_pz", "N_cx", "N_cz")
    nis = {m: c["nis_real"][:, i] for i, m in enumerate(("roll", "yaw", "h"))}
    euler = c["true_euler_deg"]
    wheels = {k: tel[k] for k in tel if k.startswith("wheel") and k.endswith("_rpm")}
    def held(a):
        # NEES is stored every 10th sample; hold each value until the next (drawing only).
        idx = np.where(np.isfinite(a), np.arange(len(a)), 0)
        return a[np.maximum.accumulate(idx)]

    jobs = [
        (plot_errors, (t, gap, {"roll": series("roll", "deg"), "yaw": series("yaw", "deg"),
                                "h": series("h", "N m s")}, title,
                       # Sun gaps as summary.json counts them (not the noon outages).
                       3600.0 * scenario["estimator"]["sun_gap_min_h"]), out / "errors.png"),
        (plot_consistency, (t, held(c["nees_real"]), held(c["nees_linear"]), em.N_STATES,
                            chi2_bounds(em.N_STATES), nis, chi2_bounds(1), title),
         out / "consistency.png"),
        (plot_torques, (t, gap, {k: c["x_real"][:, col[k]] for k in torques},
                        {k: c["truth_model"][:, col[k]] for k in torques},
                        {k: c["sigma"][:, col[k]] for k in torques}, title),
         out / "torques.png"),
        (plot_telemetry_overview,
         (t, {"roll": tel["roll_deg"], "pitch": tel["pitch_deg"], "yaw": tel["yaw_deg"]},
          {"roll": euler[:, 1], "pitch": euler[:, 2], "yaw": euler[:, 0]}, wheels, gap, title),
         out / "telemetry_overview.png"),
    ]
    return _draw_all(jobs)


def plot_run(run_dir: Path) -> list[Path]:
    run_dir = Path(run_dir)
    needed = [run_dir / n for n in ("scenario.yaml", "truth.csv", "telemetry.csv")]
    missing = [p.name for p in needed if not p.is_file()]
    if missing:
        raise RunDirError(f"{run_dir}: not a run directory (missing {', '.join(missing)})")
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
    heads = [k[:-10] for k in tel if k.endswith("_alpha_deg")]
    sun_head = np.where(np.isfinite(tel["sun_head"]), tel["sun_head"], -1).astype(int)
    written.append(save_figure(plot_telemetry(
        tel["t_s"], truth["yaw_deg"], tel["yaw_deg"], tel["yaw_sigma_deg"], sun_head, heads,
        tel["roll_deg"] - truth["roll_deg"], tel["pitch_deg"] - truth["pitch_deg"],
        ~np.isfinite(tel["yaw_deg"]), f"Telemetry: {title}"), out / "telemetry.png"))
    if (run_dir / "comparison.npz").is_file():
        written += plot_run_figures(run_dir, tel)
    import matplotlib.pyplot as plt
    plt.close("all")
    return written
