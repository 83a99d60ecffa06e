"""The figures of `dynprop linearization`'s report (docs/validation.md §5)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from dynprop.estimator.kalman.consistency import chi2_bounds
from dynprop.estimator.linear.model import N_STATES


def _sweep_values(report, model: str, key: str, kind: str) -> list[float]:
    return [c["divergence"][model][key] for c in report["sweep"]["cases"] if c["kind"] == kind]


def draw_report_figures(out: Path, report: dict, arrays: dict, sweep_deg, kinds
                        ) -> list[Path]:
    """The report's figures into ``out`` (``linearization.report.FIGURES``), drawn
    from report.json's dict and the divergence envelopes; ``sweep_deg`` are the
    sweep's initial errors and ``kinds`` its kinds, in the report's order."""
    import matplotlib.pyplot as plt
    from dynprop.plots import linearization as pl
    m = report["meta"]
    cap = f"{m['scenario']} · seed {m['seed']} · {m['command']}"
    c, sw, b = report["coefficients"], report["sweep"], report["budget"]
    rows = [r for r in c["rows"] if not r["coefficient"].startswith("pitch")]
    figs = {"coefficients.png": pl.plot_coefficients(
        [r["coefficient"] for r in rows],
        {"Eq. 7 / 11c (both)": [r["rel_eq7_vs_jacobian"] for r in rows],
         "Eq. 5 only (I_x = I_z)": [r["rel_eq5_only"] for r in rows],
         "Eq. 6 only (drop ω0(I_y − I))": [r["rel_eq6_only"] for r in rows],
         "products ±30 kg m²": [r["rel_products"] for r in rows]}, cap)}
    th = sw["thresholds"]
    levels = {"roll": {"10% σ": th["ten_percent_roll_sigma_deg"],
                       "Earth sensor": th["earth_sensor_noise_deg"]},
              "yaw": {"10% σ": th["ten_percent_yaw_sigma_deg"],
                      "Earth sensor": th["earth_sensor_noise_deg"]}}
    gap = sw["gap_samples"]
    gap_h = None if gap is None else (gap[0] * m["sample_interval_s"] / 3600,
                                      gap[1] * m["sample_interval_s"] / 3600)
    figs["divergence_time.png"] = pl.plot_divergence_time(arrays["envelopes"], sweep_deg,
                                                          levels, gap_h, cap)
    values = {k: {f"Eq. 11 {ax}": _sweep_values(report, "eq11", f"max_{ax}_deg", k)
                  for ax in ("yaw", "roll")} for k in kinds}
    for k in kinds:
        for ax in ("yaw", "roll"):
            values[k][f"Jacobian {ax}"] = _sweep_values(report, "jacobian", f"max_{ax}_deg", k)
    figs["divergence_sweep.png"] = pl.plot_divergence_sweep(
        sweep_deg, values, {"10% σ_yaw": th["ten_percent_yaw_sigma_deg"],
                            "Earth sensor": th["earth_sensor_noise_deg"]}, cap)
    if b:
        col = b["columns"][0]
        figs["budget.png"] = pl.plot_budget(
            [r["label"] for r in b["rows"]],
            {"torque model": [r["contribution"][col]["torque_model_deg"] for r in b["rows"]],
             "dynamics": [r["contribution"][col]["dynamics_deg"] for r in b["rows"]]},
            {"torque model": b["total"][col]["torque_model_deg"],
             "dynamics": b["total"][col]["dynamics_deg"]},
            [r["in_scenario"] for r in b["rows"]], cap,
            ideal={"torque model": b["ideal"][col]["torque_model_deg"],
                   "dynamics": b["ideal"][col]["dynamics_deg"]})
    est = {}
    for k in kinds:
        cs = [x["estimation"] for x in sw["cases"] if x["kind"] == k]
        last = [(e["yaw_error_gap_end_real_deg"] or [np.nan])[-1] for e in cs]
        est[k] = {"real": last,
                  "linear": [(e["yaw_error_gap_end_linear_deg"] or [np.nan])[-1] for e in cs],
                  "sigma": [(e["yaw_sigma_gap_end_deg"] or [np.nan])[-1] for e in cs],
                  "nees_real": [e["nees_mean_real"] for e in cs],
                  "nees_linear": [e["nees_mean_linear"] for e in cs]}
    why = (f"not tested: the {m['duration_s'] / 3600:g} h run has no Sun-gap end"
           if sw["gap_samples"] is None else "not tested: no Sun-gap end in the sweep's runs")
    figs["estimation.png"] = pl.plot_estimation(sweep_deg, est, chi2_bounds(N_STATES, 1), cap,
                                                why_empty=why)
    paths = []
    for name, fig in figs.items():
        path = out / name
        fig.savefig(path, dpi=110)
        plt.close(fig)
        paths.append(path)
    return paths
