"""The ``dynprop`` command line (docs/outputs.md).

Exit status: 0 on success, 2 for bad input (one line per problem, each naming the
key, column or argument; no traceback, no directory written), 1 for an internal error (one line;
``DYNPROP_DEBUG=1`` shows the traceback), 130 when interrupted.
"""

from __future__ import annotations

import math
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
# Where estimator.known_torques reaches the filter (or, simulate, the columns are written).
KNOWN_TORQUE_COMMANDS = ("run", "montecarlo", "simulate")


def _tuned(args) -> tuple[list[str], dict | None]:
    """``--tuned-from``'s overrides (before the user's own ``--set``, which win) and the
    note for the summary; nothing without it."""
    if getattr(args, "tuned_from", None) is None:
        return [], None
    from .tune.noise import tuned_noise
    return tuned_noise(args.tuned_from)


def _telemetry_overrides(args) -> list[str]:
    """``--column``, ``--unit`` and ``--epoch-utc`` as the ``telemetry`` keys they set
    (names and epochs quoted, so that YAML reads them as text: a column ``ON``), before
    the user's own ``--set``: for `estimate`, `tune`, `trim` and `batch` alike."""
    import json
    out = [f"telemetry.columns.{k}={json.dumps(v)}" for k, v in getattr(args, "column", [])]
    out += [f"telemetry.units.{k}={json.dumps(v)}" for k, v in getattr(args, "unit", [])]
    if getattr(args, "epoch_utc", None) is not None:
        out.append(f"telemetry.epoch_utc={json.dumps(args.epoch_utc)}")
    return out


def load_with_overrides(args, streams: bool = False):
    """The scenario with --set, --seed and --duration-s applied (validated together),
    after `estimate`'s --column, --unit and --epoch-utc (the ``telemetry`` keys).
    A command that holds whole arrays (``streams=False``) refuses runs over 30 days."""
    from .config.loader import load_scenario
    overrides = _tuned(args)[0] + _telemetry_overrides(args) + list(args.set)
    # Their messages name the option the user typed, not the key it sets.
    if args.seed is not None:
        overrides.append((f"seed={args.seed}", shlex.join(["--seed", args.seed])))
    if args.duration_s is not None:
        overrides.append((f"duration_s={args.duration_s}",
                          shlex.join(["--duration-s", args.duration_s])))
    s = load_scenario(args.scenario, overrides)
    if not streams and s.duration_s > WHOLE_ARRAY_MAX_S:
        raise InputError(f"duration_s: {s.duration_s:g} s is over {WHOLE_ARRAY_MAX_S:g} s "
                         f"(30 days), the most `dynprop {args.command}` holds in memory; "
                         "`dynprop run` streams longer runs")
    if s.trim.every_days is not None and args.command in LOOPLESS:
        raise InputError(f"trim.every_days: the trim loop steers the truth from the filter's "
                         f"estimates, which only `dynprop run` carries; `dynprop "
                         f"{args.command}` would fly one tab: remove it or use `dynprop run`")
    if s.estimator.known_torques and args.command not in KNOWN_TORQUE_COMMANDS:
        raise InputError(f"estimator.known_torques: the torquers' dipoles reach the filter in "
                         f"`dynprop run` and `montecarlo` only; `dynprop {args.command}` reads "
                         "a telemetry file, whose readers do not carry torquer_*_Am2 columns "
                         "yet: remove it")
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
        if args.report:
            # Inside the stage: the directory appears whole, page included, or not at all.
            from .review.report import write_report
            write_report(stage, _command(args))
    from .console import run_lines
    for line in run_lines(scenario.name, summary, time.perf_counter() - start):
        print(line)
    print(f"figures: {out}/plots/" + (f"; review page: {out}/report.html" if args.report
                                       else ""))
    return 0


def _command(args) -> str:
    return shlex.join(["dynprop", *args.argv])


def _cmd_report(args) -> int:
    from .review.report import write_report
    start = time.perf_counter()
    path = write_report(args.dir, _command(args), args.yaw_requirement_deg)
    size = path.stat().st_size / 1e6
    print(f"wrote {path} ({size:.1f} MB, {time.perf_counter() - start:.1f} s): one "
          "self-contained page, open it in a browser (no network needed)")
    return 0


def _cmd_export(args) -> int:
    from .export.compare import lines
    from .export.write import export_run
    start = time.perf_counter()
    r = export_run(args.dir, args.format, args.what, args.frame, args.at, args.out,
                   args.truth, args.object_id, args.force)
    if r.format == "aem":
        n = len(r.segments)
        span = f"{r.segments[0][0]} to {r.segments[-1][1]}"
        what = f"{r.rows} rows in {n} segment{'s' * (n != 1)}, {span}"
    else:
        what = f"at {r.epoch}"
    print(f"wrote {r.path}: the {r.what}, {r.frame} -> SC_BODY_1, {what} UTC "
          f"({time.perf_counter() - start:.1f} s)")
    for line in lines(r.comparison) if r.comparison is not None else ():
        print(line)
    return 0


def _cmd_estimate(args) -> int:
    from .commands import estimate_into
    from .files.rundir import check_out_dir, staged_run_dir

    # The telemetry, not the scenario's duration, sets how much is held in memory.
    scenario = load_with_overrides(args, streams=True)
    check_out_dir(args.out, args.force)
    start = time.perf_counter()
    with staged_run_dir(args.out, force=args.force) as stage:
        summary = estimate_into(scenario, args.telemetry, args.truth, stage)
        _note_tuned(args, stage / "summary.json")
        written = sorted(p.relative_to(stage) for p in stage.rglob("*") if p.is_file())
    from .console import estimate_lines
    for line in estimate_lines(scenario.name, summary, scenario.sample_interval_s,
                               time.perf_counter() - start):
        print(line)
    print(f"wrote {args.out}/: " + ", ".join(str(p) for p in written))
    return 0


def _cmd_scenarios(args) -> int:
    from .config.loader import bundled_names, load_scenario
    names = bundled_names()
    width = max(map(len, names))
    for name in names:
        print(f"{name:<{width}}  {load_scenario(name).description}")
    return 0


def _cmd_scenario_template(args) -> int:
    from .config.loader import load_scenario
    from .config.template import template
    sys.stdout.write(template(None if args.scenario is None else load_scenario(args.scenario)))
    return 0


def _check_writable(plots: Path) -> None:
    """Refuse a run whose plots/ cannot be written, naming that directory, before a
    figure is drawn (a read-only run would otherwise fail on whichever file the
    drawing touches first, even one the run never had)."""
    import tempfile
    if not (plots.parent / "scenario.yaml").is_file():
        return   # not a run directory: plot_run says so
    where = plots if plots.is_dir() else plots.parent   # plots/ is made by the drawing
    try:
        fd, probe = tempfile.mkstemp(prefix=".write-test.", dir=where)
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise InputError(f"{where}: cannot write the figures there "
                         f"({exc.strerror or exc})") from None


def _cmd_plot(args) -> int:
    from .figures.run import plot_run
    _check_writable(args.run_dir / "plots")
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
    d = run_trim(args.run_dir, args.from_s, args.to_s, args.telemetry, args.verify,
                 _telemetry_overrides(args))
    print(one_line(d))
    for line in d["warnings"]:
        print(f"warning: {line}")
    print(f"{time.perf_counter() - start:.1f} s; wrote {args.run_dir}/trim/: trim.json, "
          "trim.md, trim.png" + (", verify/" if args.verify else ""))
    return 0


def _cmd_batch(args) -> int:
    from .batch.report import one_line, run_batch
    for name in ("span_h", "overlap_h"):
        v = getattr(args, name)
        if v is not None and not (math.isfinite(v) and v >= 0 and (v > 0 or name == "overlap_h")):
            raise InputError(f"--{name.replace('_', '-')}: {v:g} must be a positive number of "
                             "hours" + (" or 0" if name == "overlap_h" else ""))
    start = time.perf_counter()
    d, out = run_batch(args.source, args.scenario, _telemetry_overrides(args) + list(args.set),
                       args.truth, args.out, args.model,
                       args.span_h, args.overlap_h, force=args.force or args.out is None,
                       command=shlex.join(["dynprop", *args.argv]))
    print(one_line(d))
    for line in d["warnings"]:
        print(f"warning: {line}")
    print(f"{time.perf_counter() - start:.1f} s; wrote {out}/: estimate_batch.csv, "
          "batch.json, batch.png")
    # A batch that did not converge is reported, and the command says so in its status.
    return 0 if d["converged"] else 1


def _cmd_tune(args) -> int:
    from .tune.fit import TuneOptions
    from .tune.report import one_line, run_tune
    kw = {} if args.params is None else {"params": args.params}
    options = TuneOptions(tie_xz=args.tie_xz, roll_variance=args.roll_variance,
                          bounds={k: (lo, hi) for k, lo, hi in args.bounds}, **kw)
    start = time.perf_counter()
    d, out = run_tune(args.source, args.scenario, _telemetry_overrides(args) + list(args.set),
                      args.out, options,
                      force=args.force or args.out is None,
                      command=shlex.join(["dynprop", *args.argv]))
    print(one_line(d))
    for line in d["warnings"]:
        print(f"warning: {line}")
    print(f"{time.perf_counter() - start:.1f} s; wrote {out}/: tune.json, tune.md, "
          "tuned_noise.yaml, tune.png")
    return 0


def _cmd_observability(args) -> int:
    from dynprop.estimator.analysis.observability import format_rank_table
    from dynprop.estimator.augmented.model import BIAS_NAMES

    from .config.build import estimator_model
    s = load_with_overrides(args)
    params, _ = estimator_model(s)
    biases = BIAS_NAMES if args.biases == "all" else s.estimator.bias_states.on()
    print(format_rank_table(params, biases=biases))
    return 0


def _cmd_covariance(args) -> int:
    from dynprop.estimator.analysis.covariance_report import format_covariance_report

    from .bridge.covariance import scenario_covariance_report
    print(format_covariance_report(scenario_covariance_report(load_with_overrides(args))))
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
    if result.cases > args.runs:
        # A set only grows: montecarlo.json never drops a case it holds.
        print(f"dynprop: note: the set in {args.out} holds {result.cases} cases; --runs "
              f"{args.runs} adds none, and montecarlo.json summarizes all {result.cases} "
              "(a smaller set needs another --out)", file=sys.stderr)
    verb = "resumed" if result.resumed else "new"
    print(f"{scenario.name}: {verb} set, ran {result.ran} of {result.cases} cases "
          f"({result.cases - result.ran} already stored) in "
          f"{time.perf_counter() - start:.1f} s; {one_line(s)}")
    for f in s["failed"]:
        print(f"  case {f['case']} failed: {f['error']}", file=sys.stderr)
    print(f"wrote {args.out}/montecarlo.json and {args.out}/plots/")
    return 1 if s["runs_failed"] else 0


COMMANDS = {"simulate": _cmd_simulate, "scenarios": _cmd_scenarios, "plot": _cmd_plot,
            "scenario-template": _cmd_scenario_template,
            "run": _cmd_run, "estimate": _cmd_estimate,
            "observability": _cmd_observability, "covariance": _cmd_covariance,
            "linearization": _cmd_linearization, "montecarlo": _cmd_montecarlo,
            "trim": _cmd_trim, "tune": _cmd_tune,
            "batch": _cmd_batch, "report": _cmd_report, "export": _cmd_export}


def os_error_line(exc: OSError, args) -> str:
    """One line for a file that could not be read or written: the file (a staging
    directory named by the directory it becomes), else the directory the command
    writes; never an empty name (a full disk's write names no file)."""
    import errno

    from .files.rundir import public_path
    why = exc.strerror or str(exc) or type(exc).__name__
    if exc.filename is not None and exc.filename2 is not None:
        where = f"{public_path(exc.filename)} -> {public_path(exc.filename2)}"
    elif exc.filename is not None:
        where = public_path(exc.filename)
    else:
        target = next((getattr(args, k) for k in ("out", "run_dir", "source")
                       if getattr(args, k, None) is not None), None)
        where = f"writing {target}" if target is not None else "dynprop"
    if exc.errno in (errno.ENOSPC, errno.EDQUOT):
        why += " (free some space, or write elsewhere with --out)" \
            if getattr(args, "out", None) is not None else " (free some space)"
    return f"{where}: {why}"


# The exceptions that mean bad input (exit 2), by the module that defines each.
INPUT_ERRORS = (("dynprop.scenarios.files.rundir", "RunDirError"),
                ("dynprop.scenarios.config.loader", "ScenarioError"),
                ("dynprop.scenarios.montecarlo", "SchedulerError"),
                ("dynprop.scenarios.trim.batch", "TrimError"),
                ("dynprop.scenarios.tune.source", "TuneError"),
                ("dynprop.estimator.batch.linear", "BatchError"),
                ("dynprop.scenarios.export.source", "ExportError"),
                ("dynprop.scenarios.files.aem", "AemError"))


def input_errors() -> tuple[type[Exception], ...]:
    """``InputError`` and the ``INPUT_ERRORS`` of the modules loaded: one never
    imported raised nothing.  Looked up as an exception is matched, so that a command
    does not import every analysis (scipy: 0.3 s of start-up) to name their errors."""
    return (InputError, *(getattr(sys.modules[m], name) for m, name in INPUT_ERRORS
                          if m in sys.modules))


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    # The command line as given, for the reports that record it (main([...]) from
    # Python or a test has its own, not the interpreter's sys.argv).
    args.argv = list(sys.argv[1:] if argv is None else argv)
    try:
        return COMMANDS[args.command](args)
    except input_errors() as exc:
        # One line per problem, each naming its key path, column or argument.
        for line in str(exc).splitlines() or [""]:
            print(f"dynprop: error: {line}", file=sys.stderr)
        return 2
    except OSError as exc:
        # Files the user named (or their directories) could not be read or written.
        print(f"dynprop: error: {os_error_line(exc, args)}", file=sys.stderr)
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
