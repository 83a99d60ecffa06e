"""What `dynprop tune` writes: tune.json, tune.md, tuned_noise.yaml and tune.png
(docs/outputs.md), staged so that a failed tune leaves the directory as it was."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import yaml
from dynprop.estimator.analysis.covariance import PAPER_SIGMA_YAW_DEG
from dynprop.estimator.tuning.likelihood import NOISE_KEYS

from ..files.screen import screen_messages
from .fit import ROLL, Diagnostics, TuneOptions, TuneResult, option_problems, tune
from .source import TuneError, locate
from .streamed import open_streamed

LABELS = {"q_x": "roll torque q_x", "q_z": "yaw torque q_z", "q_w": "wheel torque q_w",
          "q_px": "periodic roll torque walk q_px", "q_pz": "periodic yaw torque walk q_pz",
          "q_cx": "constant roll torque walk q_cx", "q_cz": "constant yaw torque walk q_cz",
          "q_x=q_z": "roll and yaw torque q_x = q_z", ROLL: "roll variance factor"}
UNITS = {"q_x": "(N m)² s", "q_z": "(N m)² s", "q_w": "(N m)² s", "q_px": "(N m)²/s",
         "q_pz": "(N m)²/s", "q_cx": "(N m)²/s", "q_cz": "(N m)²/s", "q_x=q_z": "(N m)² s",
         ROLL: "-"}


def _diag(d: Diagnostics) -> dict:
    return {"loglik": d.loglik, "nis": d.nis, "whiteness": d.whiteness,
            "sigma_yaw_deg": d.sigma_yaw_deg}


def estimated(r: TuneResult) -> dict:
    """tune.json's ``estimated``: each tuned ``estimator.process_noise`` key (a tied
    pair under both of its keys) with its value and σ and what the fit made of it."""
    out = {}
    for name, e in r.entries.items():
        if name == ROLL:
            continue
        for key in (("q_x", "q_z") if name == "q_x=q_z" else (name,)):
            out[key] = {**e, "tied": name == "q_x=q_z"}
    return out


def report_dict(r: TuneResult, command: str | None = None) -> dict:
    src, fit = r.source, r.fit
    roll = None
    if ROLL in r.entries:
        e = r.entries[ROLL]
        base = src.roll_variance()
        roll = {**e, "variance_rad2": base * e["value"],
                "sigma_deg": float(np.degrees(np.sqrt(base * e["value"]))),
                "note": "reported only: the scenario's sensors section sets both the "
                        "simulated Earth sensor and the filter's roll variance"}
    return {
        "scenario": src.scenario.name,
        "warnings": screen_messages(src.stats.get("screened")),
        "telemetry": {"file": str(src.telemetry),
                      "run_dir": None if src.run_dir is None else str(src.run_dir),
                      "span_h": src.span_s / 3600, **src.stats,
                      "updates": src.updates(),
                      "sun_gap_h": src.gap_s() / 3600,
                      # The periodic covariance's gap: measured, or the paper's 8 h.
                      "sun_gap_measured": src.measured_gap_s() is not None},
        "method": {"estimator": "maximum likelihood of the paper filter's innovations "
                                "(prediction-error decomposition), Fisher scoring in ln θ",
                   "tuned": r.names, "tied_xz": r.options.tie_xz,
                   "roll_variance": r.options.roll_variance},
        "estimated": estimated(r),
        "roll_variance": roll,
        "tuned_process_noise": {k: getattr(r.applied, k) for k in NOISE_KEYS},
        "scenario_process_noise": {k: getattr(src.noise, k) for k in NOISE_KEYS},
        "loglik": {"start": fit.start.loglik, "maximum": fit.best.loglik,
                   "tuned": r.after.loglik},
        "optimizer": {"iterations": fit.iterations, "converged": fit.converged,
                      "passes": r.passes, "seconds": r.seconds,
                      "gradient_ln": [float(v) for v in fit.log_gradient]},
        "before": _diag(r.before), "after": _diag(r.after),
        "paper_sigma_yaw_deg": PAPER_SIGMA_YAW_DEG,
        "command": command,
    }


def noise_yaml(d: dict) -> str:
    """tuned_noise.yaml: the tuned ``estimator.process_noise`` as a scenario fragment."""
    head = [f"# dynprop tune: {d['scenario']}, {d['telemetry']['file']} "
            f"({d['telemetry']['span_h']:.1f} h)",
            "# Merge into a scenario file, or pass the run: dynprop run S --tuned-from DIR."]
    for k, e in d["estimated"].items():
        if e["status"] not in ("determined", "weakly determined"):
            how = (f"its 95% {e['limit_side']} limit, the allowed value nearest the "
                   "scenario's" if e["limit_95"] is not None
                   else "the scenario's value, which the telemetry allows")
            head.append(f"# {k}: {e['status']}; set to {how}")
    body = yaml.safe_dump({"estimator": {"process_noise": d["tuned_process_noise"]}},
                          sort_keys=False)
    return "\n".join(head) + "\n" + body


def _g(v) -> str:
    return "–" if v is None else f"{v:.3g}"


def report_md(d: dict) -> str:
    t = d["telemetry"]
    gap = "" if t["sun_gap_measured"] else " (no whole gap in the file: the paper's)"
    lines = [f"# Noise tuned from the telemetry: {d['scenario']}", "",
             f"Telemetry {t['file']}: {t['span_h']:.1f} h, {t['updates']['roll']} roll, "
             f"{t['updates']['yaw']} yaw and {t['updates']['h']} h updates; Sun gap "
             f"{t['sun_gap_h']:.1f} h{gap}.  Maximum likelihood of the paper filter's "
             "innovations (docs/tune.md), no truth used.", "",
             "| parameter | scenario | estimate | σ | status | 95% limit | used |",
             "|---|---|---|---|---|---|---|"]
    for k, e in d["estimated"].items():
        sig = "–" if e["sigma"] is None else f"{e['sigma']:.2g} (ln: {e['sigma_ln']:.2g})"
        if e["limit_95"] is not None:
            limit = f"{'<' if e['limit_side'] == 'upper' else '>'} {e['limit_95']:.3g}"
        else:
            limit = "scenario's allowed" if e["scenario_allowed"] else "–"
        lines.append(f"| {LABELS[k]} ({UNITS[k]}) | {e['start']:.3g} | {_g(e['value'])} | {sig} "
                     f"| {e['status']} | {limit} | {e['applied']:.3g} |")
    if d["roll_variance"] is not None:
        r = d["roll_variance"]
        lines += ["", f"Earth-sensor roll: variance factor {r['value']:.3g} "
                  f"(σ {_g(r['sigma'])}), σ_roll = {r['sigma_deg']:.4f}°; {r['note']}."]
    b, a = d["before"], d["after"]
    lines += ["", "| | scenario's noise | tuned noise |", "|---|---|---|",
              f"| ln L | {b['loglik']:.1f} | {a['loglik']:.1f} "
              f"(+{a['loglik'] - b['loglik']:.1f}) |"]
    for kind in ("roll", "yaw", "h"):
        nb, na = b["nis"][kind], a["nis"][kind]
        if nb["mean"] is None:
            continue
        lo, hi = nb["bounds"]
        lines.append(f"| mean NIS, {kind} (χ²₁ bounds {lo:.3f}–{hi:.3f}) | {nb['mean']:.3f} | "
                     f"{na['mean']:.3f} |")
    for kind in ("roll", "yaw", "h"):
        wb, wa = b["whiteness"][kind], a["whiteness"][kind]
        if wb["fraction_outside"] is None:
            continue
        lines.append(f"| {kind} innovations: lags outside ±1.96/√N (white: 5%), ρ(1) | "
                     f"{100 * wb['fraction_outside']:.0f}%, {wb['rho_1']:+.3f} | "
                     f"{100 * wa['fraction_outside']:.0f}%, {wa['rho_1']:+.3f} |")
    sb, sa = b["sigma_yaw_deg"], a["sigma_yaw_deg"]
    lines += [f"| σ_yaw, Eq. 55 (paper: {d['paper_sigma_yaw_deg']:.3f}°) | {sb['eq55']:.4f}° | "
              f"{sa['eq55']:.4f}° |",
              f"| σ_yaw at the gap end, periodic covariance | {sb['gap_end']:.4f}° | "
              f"{sa['gap_end']:.4f}° |", ""]
    o = d["optimizer"]
    lines += [f"Optimiser: {o['iterations']} iterations, "
              f"{'converged' if o['converged'] else '**not converged**'}; "
              f"{o['passes']['score']} score passes and {o['passes']['likelihood']} "
              f"likelihood passes, {o['seconds']:.1f} s.", "",
              "Use it: `dynprop run SCENARIO --tuned-from DIR` (also `estimate`, "
              "`montecarlo`), or merge tuned_noise.yaml into the scenario, or",
              "", "```", "--set 'estimator.process_noise={" + ", ".join(
                  f"{k}: {v!r}" for k, v in d["tuned_process_noise"].items()) + "}'",
              "```", ""]
    return "\n".join(lines)


def run_tune(source: Path, scenario=None, overrides: list[str] = (), out: Path | None = None,
             options: TuneOptions | None = None, force: bool = True,
             command: str | None = None, block_rows: int | None = None
             ) -> tuple[dict, Path]:
    """Everything `dynprop tune` does; returns tune.json's dictionary and the directory.
    ``block_rows``: ``streamed.open_streamed``'s test hook."""
    options = options or TuneOptions()
    from ..figures.tune import tune_figure
    from ..files.rundir import staged_run_dir
    source = Path(source)
    locate(source, scenario, overrides)      # what is wrong with the arguments, first
    problems = option_problems(options)
    if problems:
        raise TuneError("\n".join(problems))
    out = Path(out) if out is not None else (source if source.is_dir() else
                                             source.parent) / "tune"
    # The telemetry is read into scratch files in the stage, removed before it becomes
    # ``out``; a file refused, or a tune that fails, leaves nothing.
    with staged_run_dir(out, force=force) as stage:
        with open_streamed(source, scenario, overrides, stage / ".scratch",
                           block_rows) as src:
            r = tune(src, options)
            d = report_dict(r, command)
        (stage / "tune.json").write_text(json.dumps(d, indent=2, allow_nan=False) + "\n")
        (stage / "tune.md").write_text(report_md(d))
        (stage / "tuned_noise.yaml").write_text(noise_yaml(d))
        tune_figure(stage / "tune.png", r)
    return d, out


def one_line(d: dict) -> str:
    parts = []
    for k, e in d["estimated"].items():
        if e["status"] in ("determined", "weakly determined"):
            parts.append(f"{k} {e['value']:.2e} +- {e['sigma']:.1e}")
        elif e["limit_95"] is not None:
            parts.append(f"{k} {'<' if e['limit_side'] == 'upper' else '>'} "
                         f"{e['limit_95']:.1e}")
    sb, sa = d["before"]["sigma_yaw_deg"], d["after"]["sigma_yaw_deg"]
    # The periodic steady state's (every day's gap alike), not a run's own gap ends,
    # which start from the filter's prior and differ: say which.
    return (f"{d['scenario']}: " + "; ".join(parts) + f"; steady-state gap-end sigma_yaw "
            f"{sb['gap_end']:.4f} -> {sa['gap_end']:.4f} deg (periodic covariance, "
            f"{d['telemetry']['sun_gap_h']:.2f} h gap)")
