"""`dynprop plot DIR`: read a run directory's files and hand arrays to ``plots``."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import yaml

from plots.telemetry import plot_telemetry
from plots.truth import plot_truth

from .csvio import read_csv
from .rundir import RunDirError


def _save(fig, path: Path) -> Path:
    # Write beside the target and rename, so a figure is never half written.
    tmp = path.with_name(f".{path.name}.tmp")
    fig.savefig(tmp, dpi=120, format="png")
    os.replace(tmp, path)
    return path


def plot_run(run_dir: Path) -> list[Path]:
    run_dir = Path(run_dir)
    needed = [run_dir / n for n in ("scenario.yaml", "truth.csv", "telemetry.csv")]
    missing = [p.name for p in needed if not p.is_file()]
    if missing:
        raise RunDirError(f"{run_dir}: not a run directory (missing {', '.join(missing)})")
    scenario = yaml.safe_load((run_dir / "scenario.yaml").read_text())
    title = (f"{scenario['name']} — epoch {scenario['epoch_utc']}, seed {scenario['seed']}, "
             f"dynprop {scenario.get('dynprop_version', '?')}")
    truth = read_csv(run_dir / "truth.csv")
    tel = read_csv(run_dir / "telemetry.csv")
    out = run_dir / "plots"
    out.mkdir(exist_ok=True)
    sources = sorted({k[:-5] for k in truth if k.endswith("_x_Nm")}
                     - {"wheel_ripple", "wheel_input", "external"})
    torques = {s: np.column_stack([truth[f"{s}_{a}_Nm"] for a in "xyz"]) for s in sources}
    written = [_save(plot_truth(
        truth["t_s"], {n: truth[f"{n}_deg"] for n in ("yaw", "roll", "pitch")}, truth["h_Nms"],
        torques, truth["eclipse"] > 0, f"Truth: {title}"), out / "truth.png")]
    heads = [k[:-10] for k in tel if k.endswith("_alpha_deg")]
    sun_head = np.where(np.isfinite(tel["sun_head"]), tel["sun_head"], -1).astype(int)
    written.append(_save(plot_telemetry(
        tel["t_s"], truth["yaw_deg"], tel["yaw_deg"], tel["yaw_sigma_deg"], sun_head, heads,
        tel["roll_deg"] - truth["roll_deg"], tel["pitch_deg"] - truth["pitch_deg"],
        ~np.isfinite(tel["yaw_deg"]), f"Telemetry: {title}"), out / "telemetry.png"))
    import matplotlib.pyplot as plt
    plt.close("all")
    return written
