"""`dynprop trim RUN_DIR`: read a run (or `dynprop estimate`) directory, estimate κ
(``trim``), write RUN_DIR/trim/ (trim.json, trim.md, trim.png) and, with
``--verify``, fly the recommended tab over the same span (RUN_DIR/trim/verify/, a
`dynprop run` directory) and compare before and after."""

from __future__ import annotations

import contextlib
import json
import tempfile
from pathlib import Path

import numpy as np

from ..config.loader import load_scenario
from ..config.schema import Scenario
from ..files.csvio import read_csv
from ..files.screen import screen_messages
from ..run.windowed import DAYS, Windows
from .batch import (
    ASSUMED_KNOWN,
    ESTIMATED,
    Batch,
    TrimError,
    TrimResult,
    choose_batch,
    kappa_from_source,
    trim_q_Nm2s,
    true_kappa_Nm,
)


def telemetry_path(run_dir: Path, given: Path | None) -> Path:
    """The telemetry the batch filter reads: ``given``, else the run's telemetry.csv,
    else the file a `dynprop estimate` directory names in its summary."""
    from ..files.rundir import RunDirError
    from ..files.telemetry_file import run_telemetry
    if given is not None:
        return given
    try:
        found = run_telemetry(run_dir)
    except RunDirError as exc:
        raise TrimError(f"{exc}; give it with --telemetry FILE") from None
    if found is not None:
        return found
    raise TrimError(f"{run_dir}: no telemetry.csv (a run longer than 2 days writes it only "
                    "with output.telemetry: true); give one with --telemetry FILE")


@contextlib.contextmanager
def read_run(run_dir: Path, telemetry: Path | None, overrides=(),
             block_rows: int | None = None):
    """The run's scenario (with ``overrides``: --column, --unit, --epoch-utc), its
    telemetry as `dynprop estimate` reads it (on the filter grid, or at its own times)
    as a ``TelemetrySource`` read by range, its scratch files in a temporary folder
    removed on leaving, and whether the run has a truth."""
    from ..files.telemetry_source import open_source
    if not (run_dir / "scenario.yaml").is_file():
        raise TrimError(f"{run_dir}: not a run directory (no scenario.yaml)")
    s = load_scenario(run_dir / "scenario.yaml", list(overrides))
    path = telemetry_path(run_dir, telemetry)
    with tempfile.TemporaryDirectory(prefix="dynprop-trim-") as scratch:
        source = open_source(path, s, Path(scratch), block_rows)
        try:
            yield s, source, (run_dir / "truth.csv").is_file()
        finally:
            source.close()


def _batch_of(s: Scenario, source, from_s, to_s) -> Batch:
    """``choose_batch`` from the telemetry's first and last sample times."""
    ends = np.r_[source.columns(0, 1, ["t_s"])["t_s"],
                 source.columns(source.n - 1, source.n, ["t_s"])["t_s"]]
    return choose_batch(ends, s.sample_interval_s, from_s, to_s, source.regular)


def _truth_solar(run_dir: Path, batch) -> tuple[np.ndarray, np.ndarray] | None:
    path = run_dir / "truth.csv"
    if not path.is_file():
        return None
    cols = read_csv(path)
    t = cols["t_s"]
    keep = (t >= batch.from_s - 1e-9) & (t <= batch.to_s + 1e-9)
    return t[keep], np.column_stack([cols["solar_x_Nm"][keep], cols["solar_z_Nm"][keep]])


def _end_torque_states(run_dir: Path, to_s: float) -> dict | None:
    """|N_p| and |N_c| of the run's own (paper) filter at the last estimate.csv row
    at or before ``to_s``."""
    path = run_dir / "estimate.csv"
    if not path.is_file():
        return None
    c = read_csv(path)
    k = int(np.searchsorted(c["t_s"], to_s + 1e-9)) - 1
    return {"t_s": float(c["t_s"][k]),
            "periodic_Nm": float(np.hypot(c["N_px_Nm"][k], c["N_pz_Nm"][k])),
            "constant_Nm": float(np.hypot(c["N_cx_Nm"][k], c["N_cz_Nm"][k]))}


def _gap_ends(run_dir: Path) -> dict:
    """The run's gap-end yaw σ and (with a truth) error, from its summary.json."""
    path = run_dir / "summary.json"
    if not path.is_file():
        return {}
    d = json.loads(path.read_text())
    return {"gap_end_sigma_deg": d.get("yaw_sigma_at_gap_end_deg"),
            "gap_end_error_deg": d.get("yaw_error_at_gap_end_deg")}


def report_dict(s: Scenario, r: TrimResult, truth: bool) -> dict:
    f, rec, solar = r.fit, r.rec, s.environment.solar
    out = {
        "scenario": s.name,
        "batch": {"from_s": r.batch.from_s, "to_s": r.batch.to_s,
                  "duration_h": (r.batch.to_s - r.batch.from_s) / 3600.0,
                  "sunlit_fraction": r.sunlit_fraction},
        "assumed_known": list(ASSUMED_KNOWN),
        "estimated": list(ESTIMATED),
        "tuning": {"torque_error_Nm": s.trim.torque_error_Nm,
                   "correlation_time_s": s.trim.correlation_time_s,
                   "q_Nm2s": trim_q_Nm2s(s)},
        "kappa_Nm": f.kappa_Nm, "kappa_sigma_Nm": f.sigma_Nm,
        "constant_torque_Nm": {"roll": f.constants_Nm[0], "yaw": f.constants_Nm[1]},
        "constant_torque_sigma_Nm": {"roll": f.constants_sigma_Nm[0],
                                     "yaw": f.constants_sigma_Nm[1]},
        "out_of_phase": {"chi2_1dof": f.out_of_phase_chi2, "amplitude_Nm": f.out_of_phase_Nm,
                         "consistent": f.out_of_phase_chi2 <= 6.63},
        "recommendation": {"move": rec.move, "trim_tab_deg": rec.trim_tab_deg,
                           "trim_tab_deg_new": rec.trim_tab_deg_new,
                           "sigma_deg": rec.sigma_deg,
                           "residual_after_Nm": rec.residual_after_Nm,
                           "tab_effectiveness_Nm_per_deg": solar.tab_effectiveness_Nm_per_deg},
        "truth": None,
    }
    if truth:
        k_true = true_kappa_Nm(s)
        out["truth"] = {
            "kappa_Nm": k_true, "solar_enabled": s.environment.solar.enabled,
            "error_over_sigma": (f.kappa_Nm - k_true) / f.sigma_Nm,
            "full_trim_tab_deg": solar.untrimmed_torque_Nm / solar.tab_effectiveness_Nm_per_deg,
            "kappa_after_Nm": k_true - f.kappa_Nm if rec.move else k_true,
        }
    return out


def _e(v: float) -> str:
    return f"{v:+.3e}".replace("e-0", "e-").replace("e+0", "e+")


def report_md(d: dict) -> str:
    b, rec, tr = d["batch"], d["recommendation"], d["truth"]
    lines = [f"# Trim tab from the estimated torque: {d['scenario']}", "",
             f"Batch {b['from_s']:g} … {b['to_s']:g} s ({b['duration_h']:.1f} h, "
             f"{100 * b['sunlit_fraction']:.1f}% sunlit).", "",
             f"**κ̂ = {_e(d['kappa_Nm'])} ± {d['kappa_sigma_Nm']:.2e} N m** (1σ, at 1 AU).", ""]
    if rec["move"]:
        lines.append(f"**Recommendation: move the tab from {rec['trim_tab_deg']:.3f}° to "
                     f"{rec['trim_tab_deg_new']:.3f}° ± {rec['sigma_deg']:.3f}°**, leaving a "
                     f"residual of about {rec['residual_after_Nm']:.1e} N m (1σ).")
    else:
        move = d["kappa_Nm"] / rec["tab_effectiveness_Nm_per_deg"]
        lines.append(f"**Recommendation: keep the tab at {rec['trim_tab_deg']:.3f}°.** κ̂ is "
                     f"within 3σ of zero: a move of {move:+.3f}° would be noise (1σ "
                     f"{rec['sigma_deg']:.3f}°).")
    c, cs = d["constant_torque_Nm"], d["constant_torque_sigma_Nm"]
    oop = d["out_of_phase"]
    lines += ["", "| quantity | value |", "|---|---|",
              f"| constant roll torque | {_e(c['roll'])} ± {cs['roll']:.1e} N m |",
              f"| constant yaw torque | {_e(c['yaw'])} ± {cs['yaw']:.1e} N m |",
              f"| periodic torque out of phase with the Sun | {oop['amplitude_Nm']:.1e} N m, "
              f"χ²(1) = {oop['chi2_1dof']:.2f}"
              + ("" if oop["consistent"] else " (**more than the Sun explains: check the "
                                                 "known torques**)") + " |",
              f"| tuning: torque error, correlation time | {d['tuning']['torque_error_Nm']:.1e} "
              f"N m, {d['tuning']['correlation_time_s']:g} s (q = "
              f"{d['tuning']['q_Nm2s']:.2e} (N m)² s) |"]
    if tr is not None:
        lines += [f"| true κ | {_e(tr['kappa_Nm'])} N m"
                  + ("" if tr["solar_enabled"] else " (solar torque disabled)") + " |",
                  f"| κ̂ − κ | {tr['error_over_sigma']:+.2f} σ |",
                  f"| true full-trim tab | {tr['full_trim_tab_deg']:.3f}° |"]
    lines += ["", "Assumed known:", ""] + [f"- {k}" for k in d["assumed_known"]]
    lines += ["", "Estimated: " + "; ".join(d["estimated"]) + "."]
    v = d.get("verify")
    if v is not None:
        lines += ["", "## Verification: the recommended tab flown over the same span", "",
                  "| | before | after |", "|---|---|---|"]
        def g(x):
            return f"{x:.2e}"
        for key, label, f in (("kappa_true_Nm", "true κ (N m)", _e),
                              ("kappa_Nm", "κ̂ (N m)", _e),
                              ("kappa_sigma_Nm", "σ(κ̂) (N m)", g),
                              ("periodic_Nm", "filter \\|N_p\\| at the end (N m)", g),
                              ("constant_Nm", "filter \\|N_c\\| at the end (N m)", g),
                              ("gap_end_error_deg", "gap-end yaw error (deg)",
                               lambda x: ", ".join(f"{e:+.4f}" for e in x)),
                              ("gap_end_sigma_deg", "gap-end yaw σ (deg)",
                               lambda x: ", ".join(f"{e:.4f}" for e in x))):
            b0, a0 = v["before"].get(key), v["after"].get(key)
            lines.append(f"| {label} | {'–' if b0 is None else f(b0)} | "
                         f"{'–' if a0 is None else f(a0)} |")
        if v.get("residual_fall") is not None:
            lines += ["", f"The true residual falls {v['residual_fall']:.0f}×."]
    return "\n".join(lines) + "\n"


def _side(s: Scenario, r: TrimResult, run_dir: Path, truth: bool) -> dict:
    ends = _end_torque_states(run_dir, r.batch.to_s) or {}
    return {"trim_tab_deg": s.environment.solar.trim_tab_deg,
            "kappa_true_Nm": true_kappa_Nm(s) if truth else None,
            "kappa_Nm": r.fit.kappa_Nm, "kappa_sigma_Nm": r.fit.sigma_Nm,
            "periodic_Nm": ends.get("periodic_Nm"), "constant_Nm": ends.get("constant_Nm"),
            **_gap_ends(run_dir)}


def verify(s: Scenario, r: TrimResult, run_dir: Path, stage: Path, truth: bool,
           windows: Windows = DAYS) -> dict:
    """Fly the recommended tab from the start to the batch end (the same span and
    seed; telemetry written), into ``stage``/verify, and estimate κ again there."""
    from ..files.rundir import staged_run_dir
    from ..run.stream.directory import stream_to_directory
    new = load_scenario(run_dir / "scenario.yaml", [
        f"environment.solar.trim_tab_deg={r.rec.trim_tab_deg_new!r}",
        f"duration_s={r.batch.to_s!r}", "output.telemetry=true"])
    out = stage / "verify"
    with staged_run_dir(out, label="") as vstage:
        stream_to_directory(new, vstage)
    with read_run(out, None) as (flown, source, _):    # the run just flown: on its grid
        after = kappa_from_source(new, source, _batch_of(flown, source, r.batch.from_s,
                                                         r.batch.to_s), windows=windows)
    result = {"before": _side(s, r, run_dir, truth), "after": _side(new, after, out, True),
              "residual_fall": None}
    if truth and result["after"]["kappa_true_Nm"]:
        result["residual_fall"] = abs(result["before"]["kappa_true_Nm"]) \
            / abs(result["after"]["kappa_true_Nm"])
    return result


def _moved_tab(s) -> str:
    """What moved the solar array's tab or offset during the run, or "" if nothing did:
    the on-board solar management or a scheduled command (issue 45)."""
    if s.momentum_management.solar.enabled:
        return "momentum_management.solar, see momentum_management.csv"
    kinds = sorted({e.kind for e in s.events if e.kind in ("trim_tab", "array_offset")})
    return " and ".join(f"{k} events" for k in kinds)


def run_trim(run_dir: Path, from_s: float | None = None, to_s: float | None = None,
             telemetry: Path | None = None, do_verify: bool = False,
             overrides=(), windows: Windows = DAYS, block_rows: int | None = None) -> dict:
    """Everything `dynprop trim` does; returns the trim.json dictionary.  ``overrides``
    are scenario keys for reading the telemetry (`dynprop estimate`'s --column, --unit,
    --epoch-utc); ``windows`` and ``block_rows`` how the telemetry is read
    (``run.windowed``, the reader's block; test hooks)."""
    from ..figures.trim import trim_figure
    from ..files.rundir import staged_run_dir
    if (Path(run_dir) / "trim_loop.csv").is_file():
        raise TrimError(f"{run_dir}: this run moved its tab as it flew (trim.every_days, see "
                        "trim_loop.csv); dynprop trim needs a run flown at one tab setting")
    with read_run(Path(run_dir), telemetry, overrides, block_rows) as (s, source, truth):
        moved = _moved_tab(s)
        if moved:
            raise TrimError(f"{run_dir}: this run moved its tab or array offset as it flew "
                            f"({moved}); dynprop trim needs a run flown at one setting")
        r = kappa_from_source(s, source, _batch_of(s, source, from_s, to_s),
                              windows=windows)
        screened = source.screen
    d = report_dict(s, r, truth)
    d["screened"] = None if screened is None else screened.summary()
    d["warnings"] = screen_messages(d["screened"])
    # RUN_DIR/trim is trim's own, replaced each time (there is no --out to name).
    with staged_run_dir(run_dir / "trim", force=True, label="") as stage:
        if do_verify:
            d["verify"] = verify(s, r, run_dir, stage, truth, windows)
        (stage / "trim.json").write_text(json.dumps(d, indent=2, allow_nan=False) + "\n")
        (stage / "trim.md").write_text(report_md(d))
        true_solar = _truth_solar(run_dir, r.batch)
        filt = r.torque_xz - np.asarray(r.fit.constants_Nm)
        trim_figure(stage / "trim.png", r.shape_t_s, r.shape_xz, r.fit.kappa_Nm,
                    r.fit.sigma_Nm, r.rows_t_s, filt, _title(s, r, d), true_solar)
    return d


def _title(s: Scenario, r: TrimResult, d: dict) -> str:
    t = f"{s.name}: κ̂ = {r.fit.kappa_Nm:.3e} ± {r.fit.sigma_Nm:.1e} N m"
    if d["truth"] is not None:
        t += f" (true {d['truth']['kappa_Nm']:.3e})"
    rec = r.rec
    t += (f"; tab {rec.trim_tab_deg:.2f}° → {rec.trim_tab_deg_new:.3f}° ± {rec.sigma_deg:.3f}°"
          if rec.move else f"; keep the tab at {rec.trim_tab_deg:.2f}°")
    return t


def one_line(d: dict) -> str:
    rec = d["recommendation"]
    text = f"{d['scenario']}: kappa {d['kappa_Nm']:+.3e} +- {d['kappa_sigma_Nm']:.1e} N m; "
    if rec["move"]:
        text += (f"move the tab {rec['trim_tab_deg']:.3f} -> {rec['trim_tab_deg_new']:.3f} deg "
                 f"+- {rec['sigma_deg']:.3f}")
    else:
        text += f"keep the tab at {rec['trim_tab_deg']:.3f} deg (kappa within 3 sigma of zero)"
    if d["truth"] is not None:
        tr = d["truth"]
        text += f"; true kappa {tr['kappa_Nm']:+.3e} ({tr['error_over_sigma']:+.2f} sigma)"
    v = d.get("verify")
    if v is not None and v["residual_fall"] is not None:
        text += (f"; verified: true residual {v['before']['kappa_true_Nm']:.2e} -> "
                 f"{v['after']['kappa_true_Nm']:.2e} N m ({v['residual_fall']:.0f}x)")
    return text
