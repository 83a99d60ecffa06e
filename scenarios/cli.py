"""The ``dynprop`` command line (docs/outputs.md).

Exit status: 0 on success, 2 for bad input (one line per problem, each naming the
key, column or argument; no traceback, no directory written), 1 for an internal error (one line;
``DYNPROP_DEBUG=1`` shows the traceback), 130 when interrupted.
"""

from __future__ import annotations

import os
import shlex
import sys
import time
from pathlib import Path

from .arguments import build_parser


class InputError(ValueError):
    """Bad user input: reported as one line with exit status 2."""


# Commands that hold a run's whole arrays in memory (a truth day is ~70 MB of them);
# `dynprop run` streams in windows and takes any duration the schema allows.
WHOLE_ARRAY_MAX_S = 30 * 86400.0
LOOPLESS = ("simulate", "montecarlo", "linearization")   # they simulate without the filter


def _tuned(args) -> tuple[list[str], dict | None]:
    """``--tuned-from``'s overrides (before the user's own ``--set``, which win) and the
    note for the summary; nothing without it."""
    if getattr(args, "tuned_from", None) is None:
        return [], None
    from .tune.noise import tuned_noise
    return tuned_noise(args.tuned_from)


def load_with_overrides(args, streams: bool = False):
    """The scenario with --set, --seed and --duration-s applied (validated together).
    A command that holds whole arrays (``streams=False``) refuses runs over 30 days."""
    from .config.loader import load_scenario
    overrides = _tuned(args)[0] + list(args.set)
    if args.seed is not None:
        overrides.append(f"seed={args.seed}")
    if args.duration_s is not None:
        overrides.append(f"duration_s={args.duration_s}")
    s = load_scenario(args.scenario, overrides)
    if not streams and s.duration_s > WHOLE_ARRAY_MAX_S:
        raise InputError(f"duration_s: {s.duration_s:g} s is over {WHOLE_ARRAY_MAX_S:g} s "
                         f"(30 days), the most `dynprop {args.command}` holds in memory; "
                         "`dynprop run` streams longer runs")
    if s.trim.every_days is not None and args.command in LOOPLESS:
        raise InputError(f"trim.every_days: the trim loop steers the truth from the filter's "
                         f"estimates, which only `dynprop run` carries; `dynprop "
                         f"{args.command}` would fly one tab: remove it or use `dynprop run`")
    return s


def _note_tuned(args, path: Path) -> None:
    note = _tuned(args)[1]
    if note is not None:
        from .tune.noise import note_summary
        note_summary(path, note)


def _cmd_simulate(args) -> int:
    from .commands import simulate_to_directory
    from .files.rundir import check_out_dir, staged_run_dir

    scenario = load_with_overrides(args)
    check_out_dir(args.out, args.force)
    start = time.perf_counter()
    with staged_run_dir(args.out, force=args.force) as stage:
        result = simulate_to_directory(scenario, stage)
    days = scenario.duration_s / 86400.0
    tel = result.telemetry
    print(f"{scenario.name}: {days:.2f} d simulated and written in "
          f"{time.perf_counter() - start:.1f} s ({result.truth.backend}); "
          f"Sun-sensor yaw on {100 * (tel.yaw_head >= 0).mean():.0f}% of samples; "
          f"wrote {args.out}/{{scenario.yaml,truth.csv,telemetry.csv}}")
    return 0


def _cmd_run(args) -> int:
    from .commands import run_to_directory
    from .files.rundir import check_out_dir, staged_run_dir

    scenario = load_with_overrides(args, streams=args.montecarlo_case is None)
    case = args.montecarlo_case
    if case is not None and not scenario.montecarlo.dispersions:
        raise InputError(f"--montecarlo-case: scenario {scenario.name} declares no "
                         "montecarlo.dispersions")
    suffix = "" if case is None else f"-case{case}"
    out = args.out or Path("runs") / f"{scenario.name}{suffix}-{time.strftime('%Y%m%dT%H%M%S')}"
    check_out_dir(out, args.force)
    start = time.perf_counter()
    with staged_run_dir(out, force=args.force) as stage:
        summary = run_to_directory(scenario, stage, montecarlo_case=case)
        _note_tuned(args, stage / "summary.json")
    errs, sigs = summary["yaw_error_at_gap_end_deg"], summary["yaw_sigma_at_gap_end_deg"]
    if len(errs) <= 6:
        ends = ", ".join(f"{e:+.4f}" for e in errs) or "none"
        sig = ", ".join(f"{e:.4f}" for e in sigs) or "none"
        at_ends = f"at Sun-gap ends {ends} deg (filter sigma {sig}; "
    else:
        # A season of gap ends: the worst one, and where the rest are (daily.csv).
        k = max(range(len(errs)), key=lambda i: abs(errs[i]) / sigs[i])
        inside = sum(abs(e) <= 3 * s for e, s in zip(errs, sigs, strict=True))
        at_ends = (f"{inside} of {len(errs)} Sun-gap ends within 3 sigma, worst "
                   f"{errs[k]:+.4f} deg against sigma {sigs[k]:.4f} (daily.csv; ")
    print(f"{scenario.name}: yaw error RMS {summary['yaw_error_rms_deg']:.4f} deg; {at_ends}"
          f"Eq. 55: {summary['analytic_sigma_yaw_deg']:.4f}); "
          f"{time.perf_counter() - start:.1f} s")
    e = summary.get("ekf")
    if e is not None and e["yaw_error_at_gap_end_deg"] is not None:
        ratios = [x / sg for x, sg in zip(e["yaw_error_at_gap_end_deg"],
                                          e["yaw_sigma_at_gap_end_deg"], strict=True)]
        worst = max(ratios, key=abs, default=None)
        print(f"EKF: yaw error RMS {e['yaw_error_rms_deg']:.4f} deg; "
              + (f"worst Sun-gap end {worst:+.2f} sigma (paper's filter "
                 f"{max((x / sg for x, sg in zip(errs, sigs, strict=True)), key=abs):+.2f})"
                 if worst is not None else "no Sun-gap end")
              + f"; mean NEES {e['nees_mean']:.2f} (paper's {summary['nees_mean']:.2f})")
    print(f"figures: {out}/plots/")
    return 0


def _cmd_estimate(args) -> int:
    from .config.loader import load_scenario
    from .files.rundir import check_out_dir, staged_run_dir
    from .run.estimate import estimate_inputs, estimate_to_directory

    scenario = load_scenario(args.scenario, _tuned(args)[0])
    check_out_dir(args.out, args.force)
    start = time.perf_counter()
    grid, truth = estimate_inputs(scenario, args.telemetry, args.truth)
    sources = {"file": str(args.telemetry),
               "truth_file": None if args.truth is None else str(args.truth)}
    with staged_run_dir(args.out, force=args.force) as stage:
        summary = estimate_to_directory(scenario, grid, truth, stage, sources)
        _note_tuned(args, stage / "summary.json")
        written = sorted(p.relative_to(stage) for p in stage.rglob("*") if p.is_file())
    tel = summary["telemetry"]
    print(f"{scenario.name}: filtered {tel['rows']} telemetry rows on {tel['filter_steps']} "
          f"steps of {scenario.sample_interval_s:g} s ({tel['missing_steps']} without a row, "
          f"{tel['dropouts']} dropouts, longest {tel['longest_dropout_s']:g} s) in "
          f"{time.perf_counter() - start:.1f} s")
    sig = ", ".join(f"{e:.4f}" for e in summary["yaw_sigma_at_gap_end_deg"]) or "none"
    if summary["yaw_error_rms_deg"] is None:
        print(f"filter yaw sigma at Sun-gap ends {sig} deg (Eq. 55: "
              f"{summary['analytic_sigma_yaw_deg']:.4f}); no --truth, so no errors")
    else:
        ends = ", ".join(f"{e:+.4f}" for e in summary["yaw_error_at_gap_end_deg"]) or "none"
        print(f"yaw error RMS {summary['yaw_error_rms_deg']:.4f} deg; at Sun-gap ends {ends} "
              f"deg (filter sigma {sig}; Eq. 55: {summary['analytic_sigma_yaw_deg']:.4f}); "
              f"NEES mean {summary['nees_mean']:.2f} (expected {summary['nees_dof']})")
    print(f"wrote {args.out}/: " + ", ".join(str(p) for p in written))
    return 0


def _cmd_scenarios(args) -> int:
    from .config.loader import bundled_names, load_scenario
    names = bundled_names()
    width = max(map(len, names))
    for name in names:
        print(f"{name:<{width}}  {load_scenario(name).description}")
    return 0


def _cmd_plot(args) -> int:
    from .figures.run import plot_run
    if (args.run_dir / "montecarlo.json").is_file():
        from .montecarlo.runset import redraw
        written = redraw(args.run_dir)
    else:
        written = plot_run(args.run_dir)
    for path in written:
        print(path)
    return 0


def _cmd_trim(args) -> int:
    from .trim.report import one_line, run_trim
    start = time.perf_counter()
    d = run_trim(args.run_dir, args.from_s, args.to_s, args.telemetry, args.verify)
    print(one_line(d))
    print(f"{time.perf_counter() - start:.1f} s; wrote {args.run_dir}/trim/: trim.json, "
          "trim.md, trim.png" + (", verify/" if args.verify else ""))
    return 0


def _cmd_tune(args) -> int:
    from .tune.fit import TuneOptions
    from .tune.report import one_line, run_tune
    kw = {} if args.params is None else {"params": args.params}
    options = TuneOptions(tie_xz=args.tie_xz, roll_variance=args.roll_variance,
                          bounds={k: (lo, hi) for k, lo, hi in args.bounds}, **kw)
    start = time.perf_counter()
    d, out = run_tune(args.source, args.scenario, args.set, args.out, options,
                      force=args.force or args.out is None,
                      command=shlex.join(["dynprop", *sys.argv[1:]]))
    print(one_line(d))
    print(f"{time.perf_counter() - start:.1f} s; wrote {out}/: tune.json, tune.md, "
          "tuned_noise.yaml, tune.png")
    return 0


def _cmd_observability(args) -> int:
    from dynprop.estimator.observability import format_rank_table

    from .config.build import estimator_model
    params, _ = estimator_model(load_with_overrides(args))
    print(format_rank_table(params))
    return 0


def _cmd_covariance(args) -> int:
    from dynprop.estimator.covariance_report import covariance_report, format_covariance_report

    from .config.build import estimator_model, estimator_sensor_specs
    scenario = load_with_overrides(args)
    params, noise = estimator_model(scenario)
    print(format_covariance_report(covariance_report(params, noise,
                                                     estimator_sensor_specs(scenario))))
    return 0


def _reproduce_command(args, command: str | None = None, out: bool = True) -> str:
    """The command line that reproduces a report, as the user would type it into a
    shell (quoted where a value has spaces)."""
    parts = ["dynprop", command or args.command, args.scenario]
    if args.seed is not None:
        parts += ["--seed", args.seed]
    if args.duration_s is not None:
        parts += ["--duration-s", args.duration_s]
    for s in args.set:
        parts += ["--set", s]
    return shlex.join(parts + (["--out", "DIR"] if out else []))


def _cmd_linearization(args) -> int:
    from .files.rundir import check_out_dir, staged_run_dir
    from .linearization.report import build_report, write_report

    scenario = load_with_overrides(args)
    check_out_dir(args.out, args.force)
    start = time.perf_counter()
    report, arrays = build_report(scenario, _reproduce_command(args))
    with staged_run_dir(args.out, force=args.force) as stage:
        write_report(stage, report, arrays)
    print(report["verdict"])
    print(f"{time.perf_counter() - start:.1f} s; wrote {args.out}/report.md, report.json "
          "and figures")
    return 0


def _cmd_montecarlo(args) -> int:
    from .montecarlo.runset import one_line, pending_cases, run_set
    from .montecarlo.store import SetDirectory

    scenario = load_with_overrides(args)
    if not scenario.montecarlo.dispersions:
        print(f"dynprop: note: scenario {scenario.name} declares no montecarlo.dispersions; "
              "cases differ only in their noise draws", file=sys.stderr)
    command = _reproduce_command(args, "run", out=False) + " --montecarlo-case K"
    start = time.perf_counter()
    try:
        result = run_set(scenario, args.runs, args.out, args.workers, args.scheduler,
                         args.keep_trajectories, args.force, args.retry_failed, command)
    except KeyboardInterrupt:
        store = SetDirectory(args.out)
        left = len(pending_cases(store, args.runs, set(), False)) \
            if store.cases_dir.is_dir() else args.runs
        print(f"dynprop: interrupted; {args.runs - left} of {args.runs} cases are stored in "
              f"{args.out}; rerun the same command to finish the other {left}",
              file=sys.stderr)
        return 130
    _note_tuned(args, args.out / "montecarlo.json")
    s = result.summary
    verb = "resumed" if result.resumed else "new"
    print(f"{scenario.name}: {verb} set, ran {result.ran} of {args.runs} cases "
          f"({args.runs - result.ran} already stored) in {time.perf_counter() - start:.1f} s; "
          f"{one_line(s)}")
    for f in s["failed"]:
        print(f"  case {f['case']} failed: {f['error']}", file=sys.stderr)
    print(f"wrote {args.out}/montecarlo.json and {args.out}/plots/")
    return 1 if s["runs_failed"] else 0


COMMANDS = {"simulate": _cmd_simulate, "scenarios": _cmd_scenarios, "plot": _cmd_plot,
            "run": _cmd_run, "estimate": _cmd_estimate,
            "observability": _cmd_observability, "covariance": _cmd_covariance,
            "linearization": _cmd_linearization, "montecarlo": _cmd_montecarlo,
            "trim": _cmd_trim, "tune": _cmd_tune}


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    from .config.loader import ScenarioError
    from .files.rundir import RunDirError
    from .montecarlo import SchedulerError
    from .trim.batch import TrimError
    from .tune.source import TuneError
    try:
        return COMMANDS[args.command](args)
    except (InputError, RunDirError, ScenarioError, SchedulerError, TrimError,
            TuneError) as exc:
        # One line per problem, each naming its key path, column or argument.
        for line in str(exc).splitlines() or [""]:
            print(f"dynprop: error: {line}", file=sys.stderr)
        return 2
    except OSError as exc:
        # Files the user named (or their directories) could not be read or written.
        print(f"dynprop: error: {exc.filename or ''}: {exc.strerror or exc}", file=sys.stderr)
        return 2
    except FloatingPointError as exc:
        # A valid scenario whose closed loop diverges (its gains, its step): not a
        # bug in dynprop, but nothing to write either.
        print(f"dynprop: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("dynprop: interrupted; nothing was written", file=sys.stderr)
        return 130
    except Exception as exc:
        if os.environ.get("DYNPROP_DEBUG"):
            raise
        print(f"dynprop: internal error: {type(exc).__name__}: {exc} "
              "(set DYNPROP_DEBUG=1 for a traceback)", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
