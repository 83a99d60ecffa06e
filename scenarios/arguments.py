"""The ``dynprop`` command line's arguments (``cli`` runs the commands): one
sub-command each, bad arguments reported as one line with exit status 2."""

from __future__ import annotations

import argparse
from pathlib import Path


class _Parser(argparse.ArgumentParser):
    """argparse that reports bad arguments as one line (no usage block), exit 2."""

    def error(self, message: str):
        self.exit(2, f"dynprop: error: {message}\n")


def _scenario_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("scenario", metavar="SCENARIO", help="a YAML path or a bundled name")
    p.add_argument("--seed", help="override the scenario seed")
    p.add_argument("--duration-s", help="override the scenario duration")
    p.add_argument("--set", action="append", default=[], metavar="KEY.PATH=VALUE",
                   help="override any scenario key (repeatable); VALUE is YAML")


def _out_args(p: argparse.ArgumentParser, help: str, required: bool = True,
              force: str = "replace a non-empty --out") -> None:
    p.add_argument("--out", required=required, type=Path, help=help)
    p.add_argument("--force", action="count", default=0,
                   help=force + "; only a directory of dynprop's own files, unless given "
                   "twice (--force --force: whatever it holds)")


def _scenario_command(sub, name: str, help: str, out: str | None = None,
                      **out_kw) -> argparse.ArgumentParser:
    """A command on a scenario (``--seed``, ``--set``, ...), with ``--out``/``--force``
    when it writes a directory (``out``: its help)."""
    p = sub.add_parser(name, help=help)
    _scenario_args(p)
    if out is not None:
        _out_args(p, out, **out_kw)
    return p


def _source_command(sub, name: str, help: str) -> argparse.ArgumentParser:
    """A command that reads telemetry (`tune`, `batch`): a run directory or a file with
    ``--scenario``, ``--set``, `estimate`'s telemetry group (``_telemetry_args``), and
    ``--out`` defaulting to RUN_DIR/<name>."""
    p = sub.add_parser(name, help=help)
    p.add_argument("source", type=Path, metavar="RUN_DIR|TELEMETRY.csv",
                   help="a `dynprop run` or `estimate` directory, or a telemetry file "
                   "(with --scenario)")
    p.add_argument("--scenario", help="scenario (default: the run directory's "
                   "scenario.yaml)")
    p.add_argument("--set", action="append", default=[], metavar="KEY.PATH=VALUE",
                   help="override a scenario key (repeatable); VALUE is YAML")
    _telemetry_args(p)
    _out_args(p, f"output directory (default: RUN_DIR/{name}, or {name}/ beside the file)",
              required=False, force=f"replace a non-empty --out (RUN_DIR/{name} is replaced "
              "anyway)")
    return p


def _whole(text: str, minimum: int) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if value < minimum:
        raise argparse.ArgumentTypeError(f"{value} must be at least {minimum}")
    return value


def _positive_int(text: str) -> int:
    return _whole(text, 1)


def _case_number(text: str) -> int:
    return _whole(text, 0)


def _case_list(text: str) -> tuple[int, ...]:
    return tuple(_case_number(part) for part in text.split(",") if part.strip())


def _tuned_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument("--tuned-from", type=Path, metavar="DIR", help="the process noise `dynprop "
                   "tune` estimated (DIR/tune.json, or DIR/tune/tune.json of a tuned run), "
                   "in place of the scenario's; summary.json says so")


def _pair(text: str) -> tuple[str, str]:
    name, sep, value = text.partition("=")
    if not (sep and name.strip() and value.strip()):
        raise argparse.ArgumentTypeError(f"{text!r} is not NAME=VALUE")
    return name.strip(), value.strip()


def _telemetry_args(p: argparse.ArgumentParser) -> None:
    """How a telemetry file that is not dynprop's own is read: the scenario's
    ``telemetry`` section, key by key (docs/telemetry.md)."""
    p.add_argument("--column", action="append", default=[], type=_pair, metavar="NAME=FILECOL",
                   help="the file's column of a quantity (repeatable; telemetry.columns.NAME): "
                   "roll=ES_ROLL, time_utc=UTC, wheel1=TACH1")
    p.add_argument("--unit", action="append", default=[], type=_pair, metavar="NAME=UNIT",
                   help="the unit of a column as the file holds it (repeatable; "
                   "telemetry.units.NAME): roll=urad, yaw=rad, wheels=rad/s")
    p.add_argument("--epoch-utc", metavar="ISO8601", help="the epoch of the file's t_s "
                   "column when the file does not say (telemetry.epoch_utc)")


def _noise_keys(text: str) -> tuple[str, ...]:
    return tuple(part.strip() for part in text.split(",") if part.strip())


def _bound(text: str) -> tuple[str, float, float]:
    key, sep, rng = text.partition("=")
    low, sep2, high = rng.partition(":")
    try:
        if not (sep and sep2):
            raise ValueError
        return key.strip(), float(low), float(high)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not KEY=LOW:HIGH") from None


def build_parser() -> argparse.ArgumentParser:
    from . import __version__
    parser = _Parser(
        prog="dynprop",
        description="Dynamic attitude propagation for momentum-biased Earth-pointing "
                    "spacecraft (GOES-Next): nonlinear truth vs the paper's linear filter.")
    parser.add_argument("--version", action="version", version=f"dynprop {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    _scenario_command(sub, "simulate", "truth + telemetry: scenario.yaml, truth.csv, "
                      "telemetry.csv", "new run directory")
    run = _scenario_command(sub, "run", "truth, telemetry, the filter on it and on the "
                            "linear twin; errors, summary and figures",
                            "new run directory (default runs/NAME-TIME)", required=False)
    _tuned_arg(run)
    run.add_argument("--report", action="store_true", help="also write report.html, the "
                     "run's review page (as `dynprop report`)")
    run.add_argument("--montecarlo-case", type=_case_number, metavar="K",
                     help="fly Monte Carlo case K of the scenario's dispersions (the filter "
                     "stays nominal), reproducing `dynprop montecarlo`'s case K bit for bit")
    mc = _scenario_command(sub, "montecarlo", "dispersed Monte Carlo set: ensemble errors, "
                           "averaged NEES, yaw at the Sun-gap end; resumable")
    mc.add_argument("--runs", required=True, type=_positive_int, metavar="N",
                    help="number of cases (0 … N−1)")
    mc.add_argument("--workers", type=_positive_int, metavar="K",
                    help="local worker processes (default: every core)")
    mc.add_argument("--scheduler", metavar="ADDRESS",
                    help="run on this dask.distributed scheduler (e.g. tcp://host:8786)")
    _out_args(mc, "set directory; rerunning the same command resumes it",
              force="replace an --out that holds something else")
    mc.add_argument("--keep-trajectories", type=_case_list, default=(), metavar="K,K,…",
                    help="also store these cases' whole trajectories")
    mc.add_argument("--retry-failed", action="store_true", help="rerun cases that failed")
    _tuned_arg(mc)
    est = sub.add_parser("estimate", help="the filter and smoother on a telemetry file "
                         "(dropouts and other cadences on the filter step allowed): "
                         "estimate.csv, smoothed.csv, summary.json, plots/")
    est.add_argument("telemetry", type=Path, metavar="TELEMETRY.csv")
    est.add_argument("--scenario", required=True, help="scenario (e.g. the run's scenario.yaml)")
    est.add_argument("--truth", type=Path, metavar="TRUTH.csv|X.aem",
                     help="a truth.csv (every sample, or a run's at output.interval_s), or a "
                     "CCSDS AEM (attitude only: roll, yaw and pitch errors): also "
                     "compute the errors, NEES and run's summary, at the samples it has")
    est.add_argument("--set", action="append", default=[], metavar="KEY.PATH=VALUE",
                     help="override a scenario key (repeatable, after --tuned-from's); "
                     "VALUE is YAML")
    est.set_defaults(seed=None, duration_s=None)   # as load_with_overrides reads them
    _telemetry_args(est)
    _tuned_arg(est)
    _out_args(est, "new output directory")
    sub.add_parser("scenarios", help="list the bundled scenarios")
    template = sub.add_parser("scenario-template", help="print a scenario as annotated YAML: "
                              "every key with its value, unit, range and meaning")
    template.add_argument("scenario", nargs="?", metavar="NAME",
                          help="a bundled name or a YAML path whose values to print "
                          "(default: the GOES-Next defaults)")
    obs = _scenario_command(sub, "observability", "rank tables of the paper's Section 4")
    obs.add_argument("--biases", choices=("scenario", "all"), default="scenario",
                     help="the sensor-bias states to append to the state: those the "
                     "scenario switches on (estimator.bias_states; default), or all four")
    _scenario_command(sub, "covariance", "steady-state yaw accuracy of Section 6")
    _scenario_command(sub, "linearization", "linearization-validation report: Jacobian vs "
                      "the paper, nonlinear vs linear propagation, error budget",
                      "new report directory")
    trim = sub.add_parser("trim", help="solar trim-tab setting from the estimated torque: "
                          "κ ± σ and the tab move (RUN_DIR/trim/); --verify flies it")
    trim.add_argument("run_dir", type=Path, metavar="RUN_DIR",
                      help="a `dynprop run` or `dynprop estimate` directory")
    trim.add_argument("--from-s", type=float, metavar="T", help="batch start (s, default: the "
                      "telemetry's first sample)")
    trim.add_argument("--to-s", type=float, metavar="T", help="batch end (s, default: the last)")
    trim.add_argument("--telemetry", type=Path, metavar="FILE",
                      help="telemetry CSV (default: RUN_DIR/telemetry.csv)")
    _telemetry_args(trim)
    trim.add_argument("--verify", action="store_true", help="fly the recommended tab over the "
                      "same span (RUN_DIR/trim/verify/) and compare before and after")
    tune = _source_command(sub, "tune", "the filter's noise from its own telemetry by "
                           "maximum likelihood, no truth: tune.json, tune.md, "
                           "tuned_noise.yaml, tune.png (RUN_DIR/tune/)")
    tune.add_argument("--params", type=_noise_keys, metavar="KEY,KEY,…",
                      default=None, help="the process-noise keys to tune (default: q_x, q_z, "
                      "q_w, q_px, q_pz, q_cx, q_cz)")
    tune.add_argument("--tie-xz", action="store_true", help="tune q_x and q_z as one (the "
                      "paper takes them equal, Eq. 43)")
    tune.add_argument("--roll-variance", action="store_true", help="also a factor on the Earth "
                      "sensor's roll variance (reported, not applied)")
    tune.add_argument("--bounds", action="append", default=[], type=_bound,
                      metavar="KEY=LOW:HIGH", help="search bounds of a tuned key (repeatable; "
                      "roll_variance for the factor)")
    batch = _source_command(sub, "batch", "batch least squares over spans of the telemetry, "
                            "the paper's alternative to its filter, beside the filter and "
                            "the smoother: estimate_batch.csv, batch.json, batch.png "
                            "(RUN_DIR/batch/)")
    batch.add_argument("--truth", type=Path, metavar="TRUTH.csv", help="the truth to judge "
                       "the estimates against (default: the run directory's truth.csv)")
    batch.add_argument("--span-h", type=float, metavar="H", help="length of each batch "
                       "(default: batch.span_h, 24 h)")
    batch.add_argument("--overlap-h", type=float, metavar="H", help="how far each batch "
                       "reaches into the previous one's span (default: batch.overlap_h, 0)")
    batch.add_argument("--model", choices=("linear", "nonlinear"), help="the paper's linear "
                       "model (one least-squares solve) or the full gyrostat (Gauss–Newton); "
                       "default: batch.model, nonlinear")
    report = sub.add_parser("report", help="one self-contained HTML page of a directory "
                            "dynprop wrote, opened offline: verdict, interactive figures, "
                            "tables, scenario, provenance (DIR/report.html)")
    report.add_argument("dir", type=Path, metavar="DIR", help="a `run`, `estimate`, "
                        "`simulate`, `montecarlo`, `linearization`, `trim`, `tune` or "
                        "`batch` directory")
    report.add_argument("--yaw-requirement-deg", type=float, metavar="DEG",
                        help="the yaw requirement to judge against, 3σ over 24 h (default: "
                        "the scenario's report.yaw_requirement_deg; none: not tested)")
    export = sub.add_parser("export", help="a run's attitude (estimate or truth) as a CCSDS "
                            "attitude message: an AEM of every row (DIR/estimate.aem) or an "
                            "APM at one time, EME2000 or orbit frame to SC_BODY_1")
    export.add_argument("dir", type=Path, metavar="DIR", help="a `run`, `estimate` or "
                        "`simulate` directory (its scenario.yaml and estimate.csv/truth.csv)")
    export.add_argument("--format", required=True, choices=("aem", "apm"),
                        help="aem: every row, a segment per stretch without dropouts; apm: "
                        "one time (--at)")
    export.add_argument("--what", choices=("estimate", "truth"), default="estimate",
                        help="estimate.csv (default) or truth.csv")
    export.add_argument("--frame", choices=("inertial", "orbit"), default="inertial",
                        help="REF_FRAME_A: EME2000 (inertial, default; composed with the "
                        "run's orbit and epoch) or LVLH_ROTATING (the orbit frame)")
    export.add_argument("--at", metavar="T", help="the APM's time: seconds after epoch_utc "
                        "or an ISO 8601 UTC time (2026-03-20T18:00:00Z); between rows, "
                        "interpolated as an AEM reader would")
    export.add_argument("--out", type=Path, metavar="FILE", help="the file to write "
                        "(default: DIR/estimate.aem, DIR/truth.apm, ...)")
    export.add_argument("--force", action="store_true", help="replace an existing --out")
    export.add_argument("--object-id", metavar="ID", help="OBJECT_ID (default SIMULATED: "
                        "the spacecraft is dynprop's; give the real designator, e.g. 2016-071A)")
    export.add_argument("--truth", type=Path, metavar="FILE.aem", help="another tool's "
                        "attitude (an AEM, EME2000/J2000/ICRF/GCRF or LVLH_ROTATING): print "
                        "the rotation angle and roll/pitch/yaw differences, exported - FILE, "
                        "at the exported epochs inside its segments")
    plot = sub.add_parser("plot", help="(re)draw the figures of a run or Monte Carlo directory")
    plot.add_argument("run_dir", type=Path, metavar="DIR")
    return parser
