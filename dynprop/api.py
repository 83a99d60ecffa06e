"""The functions of ``import dynprop``: the same code the CLI runs, returning result
objects (``results``) instead of printing.  Each writes exactly the run directory
its command writes, into a temporary directory that ``save`` copies out."""

from __future__ import annotations

import contextlib
import json
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path

from dynprop.scenarios.config.loader import ScenarioError
from dynprop.scenarios.config.schema import Scenario
from dynprop.scenarios.export.source import ExportError

from .results import (
    BatchResult,
    LinearizationResult,
    MonteCarloResult,
    RunResult,
    SimulationResult,
    TextReport,
    TrimResult,
    TuneResult,
    export_directory,
)

__all__ = ["ExportError", "ScenarioError", "batch", "covariance", "estimate", "export",
           "linearization", "load_scenario", "montecarlo", "observability", "open_run", "run",
           "simulate", "trim", "tune"]


def load_scenario(name_or_path: str | Path, set: dict | None = None, **overrides
                  ) -> Scenario:
    """A validated scenario: a bundled name (``dynprop scenarios`` lists them) or a
    YAML file, with overrides as ``--set`` gives them, by dotted key in ``set`` or
    as keywords for top-level keys (SI units, or the unit the key names)::

        s = dynprop.load_scenario("goes_next_equinox", duration_s=21600,
                                  set={"spacecraft.wheels.speed_rpm": 5000})
        print(s)   # the resolved YAML, every key

    A bad name, key, type or value raises ``ScenarioError`` with the CLI's message:
    one line per problem, a typo with the closest valid key."""
    pairs = {**(set or {}), **overrides}
    # JSON is YAML: every value reaches the loader as the CLI's --set would give it.
    return _load(name_or_path, [f"{k}={json.dumps(v)}" for k, v in pairs.items()])


def _load(source, items: list[str]) -> Scenario:
    from dynprop.scenarios.config.loader import load_scenario as load
    return load(source, items)


def _scenario(s) -> Scenario:
    return s if isinstance(s, Scenario) else load_scenario(s)


@contextlib.contextmanager
def _temporary(prefix: str) -> Iterator[tuple[Path, Path]]:
    """A private directory for a result (removed with the result object), and the run
    directory inside it that the command's code writes.  Removed at once if the
    command fails: no result object owns it then, and nothing else would."""
    owner = Path(tempfile.mkdtemp(prefix=f"dynprop-{prefix}-"))
    try:
        yield owner, owner / "run"
    except BaseException:
        shutil.rmtree(owner, ignore_errors=True)
        raise


def simulate(scenario: Scenario | str) -> SimulationResult:
    """Truth and telemetry (`dynprop simulate`)::

        sim = dynprop.simulate(s)
        sim.truth[["roll_deg", "yaw_deg"]].plot()"""
    from dynprop.scenarios.commands import simulate_to_directory
    from dynprop.scenarios.files.rundir import staged_run_dir
    s = _scenario(scenario)
    with _temporary("simulate") as (owner, out), staged_run_dir(out) as stage:
        simulate_to_directory(s, stage)
    return SimulationResult(out, owner)


def run(scenario: Scenario | str) -> RunResult:
    """Truth, telemetry, the paper's filter on it and on the linear twin (and the
    EKF with ``estimator.filters``), as `dynprop run`::

        r = dynprop.run(s)
        r.summary["yaw_error_at_gap_end_deg"], r.errors()["yaw_deg"].abs().max()
        r.figure("errors"); r.save("runs/eq")"""
    from dynprop.scenarios.commands import run_to_directory
    from dynprop.scenarios.files.rundir import staged_run_dir
    s = _scenario(scenario)
    with _temporary("run") as (owner, out), staged_run_dir(out) as stage:
        run_to_directory(s, stage)
    return RunResult(out, owner)


def _file(source, name: str) -> Path:
    """A file given as a path, or as a result (its directory's ``name``)."""
    return Path(source.path) / name if hasattr(source, "path") else Path(source)


def estimate(telemetry, scenario: Scenario | str | Path, truth=None, *,
             columns: dict | None = None, units: dict | None = None,
             epoch_utc: str | None = None, tuned_from=None, set: dict | None = None,
             **overrides) -> RunResult:
    """The filter and smoother on a telemetry file, as `dynprop estimate`: ``telemetry``
    a file (or a result, its telemetry.csv), ``scenario`` a bundled name, a YAML file
    or a ``Scenario``, ``truth`` a truth.csv or CCSDS AEM (or a result, its truth.csv)::

        e = dynprop.estimate("pass.csv", "goes_next_equinox", columns={"roll": "ES_ROLL"},
                             units={"roll": "urad"}, epoch_utc="2026-03-20T12:00:00Z")
        e.estimate[["yaw_deg", "sigma_yaw_deg"]]; e.summary["warnings"]; e.save("runs/pass")

    ``columns``, ``units``, ``epoch_utc`` and ``tuned_from`` are `estimate`'s
    ``--column``, ``--unit``, ``--epoch-utc`` and ``--tuned-from``; ``set`` and the
    keywords override scenario keys as in ``load_scenario`` (after them, as ``--set``).
    ``save(DIR)`` writes byte for byte what `dynprop estimate ... --out DIR` writes."""
    from dynprop.scenarios.commands import estimate_into
    from dynprop.scenarios.files.rundir import staged_run_dir
    items, note = [], None
    if tuned_from is not None:
        from dynprop.scenarios.tune.noise import tuned_noise
        items, note = tuned_noise(Path(getattr(tuned_from, "path", tuned_from)))
    # In the CLI's order: --tuned-from's, the telemetry keys, then --set's.
    pairs = {**{f"telemetry.columns.{k}": v for k, v in (columns or {}).items()},
             **{f"telemetry.units.{k}": v for k, v in (units or {}).items()},
             **({} if epoch_utc is None else {"telemetry.epoch_utc": epoch_utc}),
             **(set or {}), **overrides}
    items += [f"{k}={json.dumps(v)}" for k, v in pairs.items()]
    telemetry, truth = _file(telemetry, "telemetry.csv"), \
        None if truth is None else _file(truth, "truth.csv")
    with _temporary("estimate") as (owner, out):
        if isinstance(scenario, Scenario):
            if not items:
                s = scenario
            else:
                # Its resolved YAML, overridden as the CLI would a file of it.
                (owner / "scenario.yaml").write_text(str(scenario))
                s = _load(owner / "scenario.yaml", items)
        else:
            s = _load(scenario, items)
        with staged_run_dir(out) as stage:
            estimate_into(s, telemetry, truth, stage)
            if note is not None:
                from dynprop.scenarios.tune.noise import note_summary
                note_summary(stage / "summary.json", note)
    return RunResult(out, owner)


def trim(source, from_s: float | None = None, to_s: float | None = None, telemetry=None,
         verify: bool = False) -> TrimResult:
    """The solar trim-tab setting from the estimated torque, as `dynprop trim RUN_DIR`:
    ``source`` a `run` or `estimate` directory (or its result), ``from_s``/``to_s`` the
    batch's span (default: the whole telemetry), ``telemetry`` another file than the
    run's, ``verify`` flies the recommended tab over the same span::

        m = dynprop.run("goes_next_mistrimmed")
        t = dynprop.trim(m, verify=True)
        t.recommendation["trim_tab_deg_new"], t.verify.summary; t.save("runs/mis-trim")

    The CLI writes RUN_DIR/trim/; this leaves ``source`` untouched and writes the same
    files into the result's own directory (``save`` copies them)."""
    from dynprop.scenarios.files.rundir import RunDirError
    from dynprop.scenarios.trim.batch import TrimError
    from dynprop.scenarios.trim.report import run_trim
    run_dir = Path(getattr(source, "path", source))
    with _temporary("trim") as (owner, out):
        # The run seen through links to its files, so that `trim` writes its trim/
        # beside them in the temporary directory, not into the user's run.
        out.mkdir()
        if run_dir.is_dir():
            for p in run_dir.iterdir():
                if p.name != "trim":
                    (out / p.name).symlink_to(p.resolve())
        try:
            run_trim(out if run_dir.is_dir() else run_dir, from_s, to_s,
                     None if telemetry is None else _file(telemetry, "telemetry.csv"), verify)
        except (ScenarioError, TrimError, RunDirError) as exc:
            # The CLI's message, naming the user's directory rather than the links.
            raise type(exc)(str(exc).replace(str(out), str(run_dir))) from None
    return TrimResult(out / "trim", owner)


def report(path, yaw_requirement_deg: float | None = None) -> Path:
    """One self-contained HTML page of a directory the CLI (or ``save``) wrote, as
    `dynprop report DIR`: ``DIR/report.html``, returned.  ``path``: the directory, or
    a result object (``RunResult``, ``MonteCarloResult``, …; ``r.report()`` is the
    same)::

        dynprop.report("runs/eq", yaw_requirement_deg=0.1)   # runs/eq/report.html

    ``yaw_requirement_deg`` overrides the scenario's ``report.yaw_requirement_deg``."""
    if hasattr(path, "report"):
        # A result's page goes where the result was saved (``Result.report``).
        return path.report(yaw_requirement_deg)
    from dynprop.scenarios.review.report import write_report
    return write_report(Path(path), None, yaw_requirement_deg)


def export(path, format: str = "aem", what: str = "estimate", frame: str = "inertial",
           at=None, out=None, truth=None, object_id: str | None = None, force: bool = False):
    """A run's attitude as a CCSDS attitude message, as `dynprop export DIR`: an AEM of
    every row of estimate.csv (``what="truth"``: truth.csv) or an APM at one time
    (``format="apm"``, ``at``: seconds after epoch_utc, ISO 8601 UTC text or an aware
    datetime), in EME2000 (``frame="inertial"``) or the orbit frame (``"orbit"``,
    LVLH_ROTATING).  ``path``: the directory, or a result object (``r.export()`` is the
    same).  Written to ``DIR/estimate.aem`` (``truth.aem``, ``.apm``) unless ``out``;
    ``truth``: another tool's AEM to compare with::

        e = dynprop.export("runs/eq", truth="other_tool.aem")
        e.path, e.segments, e.comparison["angle_rms_deg"]

    Returns an ``ExportResult``; bad input raises ``ExportError`` (or ``ScenarioError``,
    ``AemError``) with the CLI's one-line message, and writes nothing."""
    return export_directory(Path(getattr(path, "path", path)), format, what, frame, at, out,
                            truth, object_id, force)


def open_run(path: str | Path):
    """A directory written by the CLI or by ``save``: a `run`/`estimate` directory
    as ``RunResult``, a Monte Carlo set as ``MonteCarloResult``, a `simulate` one as
    ``SimulationResult``.  The files are read in place."""
    from dynprop.scenarios.files.rundir import RunDirError
    path = Path(path)
    if (path / "montecarlo.json").is_file():
        return MonteCarloResult(path)
    if (path / "summary.json").is_file():
        return RunResult(path)
    if (path / "truth.csv").is_file():
        return SimulationResult(path)
    raise RunDirError(f"{path}: not a run directory (no summary.json, montecarlo.json "
                      "or truth.csv)")


def montecarlo(scenario: Scenario | str, runs: int = 20, workers: int | None = None,
               scheduler: str | None = None) -> MonteCarloResult:
    """The dispersed ensemble (`dynprop montecarlo`) on ``workers`` local processes
    (default: every core) or a dask ``scheduler`` address::

        mc = dynprop.montecarlo(s, runs=10)
        mc.summary["nees"]["mean_after_convergence"]; mc.figure("mc_nees")"""
    from dynprop.scenarios.montecarlo.runset import run_set
    s = _scenario(scenario)
    # The set's own scenario.yaml reruns case K wherever the set is saved.
    command = "dynprop run DIR/scenario.yaml --montecarlo-case K"
    with _temporary("montecarlo") as (owner, out):
        run_set(s, runs, out, workers, scheduler, command=command)
    return MonteCarloResult(out, owner)


def linearization(scenario: Scenario | str) -> LinearizationResult:
    """Which linearization assumption breaks first (`dynprop linearization`)::

        lin = dynprop.linearization(s); print(lin.verdict); lin.save("runs/lin")"""
    from dynprop.scenarios.linearization.report import build_report
    s = _scenario(scenario)
    report, arrays = build_report(s, f"dynprop linearization {s.name} --out DIR")
    return LinearizationResult(report, arrays)


def observability(scenario: Scenario | str, biases: str = "scenario") -> TextReport:
    """Section 4's rank tables (`dynprop observability`), with the sensor-bias states the
    scenario switches on (``biases="all"``: all four, as ``--biases all``)."""
    from dynprop.estimator.analysis.observability import format_rank_table
    from dynprop.estimator.augmented.model import BIAS_NAMES
    from dynprop.scenarios.config.build import estimator_model
    s = _scenario(scenario)
    params, _ = estimator_model(s)
    names = BIAS_NAMES if biases == "all" else s.estimator.bias_states.on()
    return TextReport(format_rank_table(params, biases=names))


def covariance(scenario: Scenario | str) -> TextReport:
    """Section 6's steady-state yaw σ by every method against the paper's 0.040°
    (`dynprop covariance`); ``.data`` is the report's dict."""
    from dynprop.estimator.analysis.covariance_report import format_covariance_report
    from dynprop.scenarios.bridge.covariance import scenario_covariance_report
    report = scenario_covariance_report(_scenario(scenario))
    return TextReport(format_covariance_report(report), report)


def tune(source, scenario: Scenario | str | None = None, params=None, tie_xz: bool = False,
         roll_variance: bool = False, bounds: dict | None = None) -> TuneResult:
    """The filter's noise from its own telemetry by maximum likelihood, no truth
    (`dynprop tune`): ``source`` a run (``RunResult`` or its directory, whose
    telemetry.csv it reads) or a telemetry file with its ``scenario``::

        t = dynprop.tune(r)                    # r = dynprop.run(s)
        t.estimated["q_z"]                     # {"value", "sigma", "status", ...}
        s2 = dynprop.load_scenario(s.name, set=t.overrides)   # the tuned noise
        t.figure(); t.save("runs/eq/tune")"""
    from dynprop.scenarios.tune.fit import TuneOptions
    from dynprop.scenarios.tune.report import run_tune
    path = getattr(source, "path", source)
    kw = {} if params is None else {"params": tuple(params)}
    options = TuneOptions(tie_xz=tie_xz, roll_variance=roll_variance,
                          bounds=dict(bounds or {}), **kw)
    with _temporary("tune") as (owner, out):
        if scenario is not None and not isinstance(scenario, str | Path):
            # A Scenario object goes to the loader as its resolved YAML, in the
            # result's own temporary directory (removed with it).
            (owner / "scenario.yaml").write_text(str(scenario))
            scenario = owner / "scenario.yaml"
        run_tune(Path(path), scenario, [], out, options, force=False)
    return TuneResult(out, owner)


def batch(source, scenario: Scenario | str | None = None, truth=None, model: str | None = None,
          span_h: float | None = None, overlap_h: float | None = None,
          set: dict | None = None) -> BatchResult:
    """Batch least squares over spans of the telemetry (`dynprop batch`), beside the
    filter and the smoother: ``source`` a run (``RunResult`` or its directory, with its
    truth.csv) or a telemetry file with its ``scenario`` (and ``truth``)::

        b = dynprop.batch(r, model="nonlinear", span_h=24)   # r = dynprop.run(s)
        b.batches[0]["state"], b.summary["truth"]["batch"]["gap_ends"]
        b.estimate[["yaw_deg", "sigma_yaw_deg"]].plot(); b.save("runs/eq/batch")

    A batch that did not converge is in ``b.summary["not_converged"]`` and its rows of
    ``b.estimate`` are NaN."""
    from dynprop.scenarios.batch.report import run_batch
    path = getattr(source, "path", source)
    overrides = [f"{k}={json.dumps(v)}" for k, v in (set or {}).items()]
    with _temporary("batch") as (owner, out):
        if scenario is not None and not isinstance(scenario, str | Path):
            (owner / "scenario.yaml").write_text(str(scenario))
            scenario = owner / "scenario.yaml"
        run_batch(Path(path), scenario, overrides, None if truth is None else Path(truth),
                  out, model, span_h, overlap_h, force=False)
    return BatchResult(out, owner)
