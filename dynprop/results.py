"""What the API functions return: a run directory (the very files the command
writes) seen as pandas tables, a dict and figures.

A result made by ``dynprop.run`` or ``dynprop.montecarlo`` lives in a private
temporary directory until ``save(dir)`` copies it out whole (staged, so a
directory is never half written) or the object is collected; ``open_run`` reads
an existing one in place.
"""

from __future__ import annotations

import json
import shutil
import weakref
from pathlib import Path

import numpy as np
import pandas as pd

from dynprop.scenarios.export.write import ExportResult, export_run
from dynprop.scenarios.files.columns import STATE_COLUMNS
from dynprop.scenarios.files.csvio import read_csv
from dynprop.scenarios.files.rundir import staged_run_dir


def _table(path: Path) -> pd.DataFrame | None:
    """A CSV of the run as a DataFrame indexed by ``t_s`` (None if not written)."""
    if not path.is_file():
        return None
    cols = read_csv(path)
    index = pd.Index(cols.pop("t_s"), name="t_s") if "t_s" in cols else None
    return pd.DataFrame(cols, index=index)


def export_directory(path: Path, format, what, frame, at, out, truth, object_id,
                     force) -> ExportResult:
    """``dynprop.export`` and ``Result.export``: `dynprop export` on a directory, the
    paths given as text or ``Path``.  Here rather than in ``api`` so that ``api``
    imports ``results`` and never the other way round."""
    return export_run(Path(path), format, what, frame, at,
                      None if out is None else Path(out),
                      None if truth is None else Path(truth), object_id, force)


def _png_figure(path: Path):
    """A saved PNG as a matplotlib Figure (an image of the file)."""
    import matplotlib.image as mpimg
    import matplotlib.pyplot as plt
    img = mpimg.imread(path)
    fig, ax = plt.subplots(figsize=(img.shape[1] / 100, img.shape[0] / 100))
    ax.imshow(img)
    ax.axis("off")
    return fig


class _Directory:
    """A directory of files the CLI writes, owned (temporary) or borrowed."""

    def __init__(self, path: Path, owner: Path | None = None):
        self.path = Path(path)
        self._owner = owner
        # Where ``save`` last copied the files, and the ``report`` page asked for (its
        # yaw requirement), so that the page goes where the files went.
        self._saved: Path | None = None
        self._page: tuple[float | None] | None = None
        if owner is not None:
            # The temporary directory goes with the object (or at exit), silently.
            weakref.finalize(self, shutil.rmtree, owner, True)

    def save(self, out: str | Path, force: bool = False) -> Path:
        """Copy every file to ``out``: byte for byte what the command writes there.
        ``out`` must not exist unless ``force`` (then it is replaced whole).  A page
        ``report()`` made is written again there, naming ``out`` rather than the
        temporary directory (its "reproduce with" line)."""
        from dynprop.scenarios.files.rundir import check_out_dir
        from dynprop.scenarios.review.report import write_report
        out = Path(out)
        check_out_dir(out, force)
        with staged_run_dir(out, force=force) as stage:
            shutil.copytree(self.path, stage, dirs_exist_ok=True)
            if self._page is not None:
                write_report(stage, None, *self._page)
        self._saved = out
        return out

    def report(self, yaw_requirement_deg: float | None = None) -> Path:
        """The directory's review page, as `dynprop report`: report.html written into
        the directory ``save`` last wrote (else into the result's own, and ``save``
        writes it too); returns its path."""
        from dynprop.scenarios.review.report import write_report
        self._page = (yaw_requirement_deg,)
        return write_report(self._saved or self.path, None, yaw_requirement_deg)

    def __repr__(self) -> str:
        where = "temporary" if self._owner is not None else str(self.path)
        return f"<{type(self).__name__} {where}>"


class SimulationResult(_Directory):
    """`dynprop simulate`: ``truth`` and ``telemetry`` (DataFrames indexed by t_s)."""

    @property
    def truth(self) -> pd.DataFrame:
        return _table(self.path / "truth.csv")

    @property
    def telemetry(self) -> pd.DataFrame:
        return _table(self.path / "telemetry.csv")

    @property
    def scenario_yaml(self) -> str:
        return (self.path / "scenario.yaml").read_text()

    def export(self, format: str = "aem", what: str = "estimate", frame: str = "inertial",
               at=None, out=None, truth=None, object_id: str | None = None,
               force: bool = False):
        """The attitude as a CCSDS AEM or APM, as `dynprop export` (``dynprop.export``):
        written into the directory (``estimate.aem``, ...; ``save`` copies it too)
        unless ``out``; returns an ``ExportResult``."""
        return export_directory(self.path, format, what, frame, at, out, truth, object_id,
                                force)


class RunResult(SimulationResult):
    """`dynprop run` or `dynprop estimate`: ``truth``, ``telemetry`` (None when not
    written: `output.telemetry`), ``estimate`` (and ``estimate_ekf`` with
    `estimator.filters: [paper, ekf]`), ``daily``, ``summary`` (dict), ``errors()``
    and ``figure(name)``."""

    @property
    def estimate(self) -> pd.DataFrame:
        return _table(self.path / "estimate.csv")

    @property
    def estimate_ekf(self) -> pd.DataFrame | None:
        return _table(self.path / "estimate_ekf.csv")

    @property
    def daily(self) -> pd.DataFrame | None:
        return _table(self.path / "daily.csv")

    @property
    def summary(self) -> dict:
        return json.loads((self.path / "summary.json").read_text())

    def errors(self, filter: str = "paper") -> pd.DataFrame:
        """Estimate − truth at the output rows, in estimate.csv's columns and units
        (comparison.npz's ``err_real``, or ``err_ekf`` for ``filter="ekf"``)."""
        key = "err_real" if filter == "paper" else f"err_{filter}"
        with np.load(self.path / "comparison.npz") as c:
            if key not in c.files:
                raise KeyError(f"this run has no {key} (no truth, or no {filter} filter)")
            return pd.DataFrame(c[key].astype(float), columns=list(STATE_COLUMNS),
                                index=pd.Index(c["t_s"], name="t_s"))

    def figure(self, name: str = "errors"):
        """A figure of the run as a matplotlib Figure, the drawing the CLI saves in
        plots/ ("errors", "consistency", "torques", "telemetry_overview", "season")."""
        from dynprop.scenarios.figures.run import run_figure
        return run_figure(self.path, name)


class MonteCarloResult(_Directory):
    """`dynprop montecarlo`: ``summary`` (montecarlo.json), ``cases`` (one row per
    case record) and ``figure(name)`` ("mc_errors", "mc_nees", "mc_gap_yaw")."""

    @property
    def summary(self) -> dict:
        return json.loads((self.path / "montecarlo.json").read_text())

    @property
    def cases(self) -> pd.DataFrame:
        records = [json.loads(p.read_text())
                   for p in sorted((self.path / "cases").glob("case-*.json"))]
        return pd.DataFrame(records).set_index("case") if records else pd.DataFrame()

    def figure(self, name: str = "mc_nees"):
        from dynprop.scenarios.config.loader import load_scenario
        from dynprop.scenarios.montecarlo.runset import ensemble_figures
        summary = self.summary
        with np.load(self.path / "montecarlo.npz") as data:
            fig = {k: data[k] for k in data.files}
        s = load_scenario(self.path / "scenario.yaml")
        figures = ensemble_figures(s, summary, fig, summary["reproduce_case"])
        key = name if name.endswith(".png") else f"{name}.png"
        return figures[key]


class LinearizationResult:
    """`dynprop linearization`: ``report`` (report.json's dict), ``verdict``,
    ``markdown`` (report.md) and ``save(dir)`` (report.md, report.json, figures)."""

    def __init__(self, report: dict, arrays: dict):
        self.report, self._arrays = report, arrays

    @property
    def verdict(self) -> str:
        return self.report["verdict"]

    @property
    def markdown(self) -> str:
        from dynprop.scenarios.linearization.report import render_markdown
        return render_markdown(self.report)

    def save(self, out: str | Path, force: bool = False) -> Path:
        from dynprop.scenarios.files.rundir import check_out_dir
        from dynprop.scenarios.linearization.report import write_report
        out = Path(out)
        check_out_dir(out, force)
        with staged_run_dir(out, force=force) as stage:
            write_report(stage, self.report, self._arrays)
        return out

    def __str__(self) -> str:
        return self.verdict


class TextReport:
    """What `dynprop observability` / `covariance` print (``str()``), with the
    numbers behind it where there are any (``data``)."""

    def __init__(self, text: str, data=None):
        self.text, self.data = text, data

    def __str__(self) -> str:
        return self.text

    def __repr__(self) -> str:
        return self.text


class _Report(_Directory):
    """A command's directory of one JSON report, an optional markdown page and one
    figure (``JSON``, ``MD``, ``PNG``, the file names)."""

    JSON = MD = PNG = ""

    @property
    def summary(self) -> dict:
        return json.loads((self.path / self.JSON).read_text())

    @property
    def markdown(self) -> str:
        if not self.MD:
            raise AttributeError(f"{type(self).__name__} has no markdown page")
        return (self.path / self.MD).read_text()

    def figure(self):
        """The command's figure as a matplotlib Figure (an image of the saved file)."""
        return _png_figure(self.path / self.PNG)


class TuneResult(_Report):
    """`dynprop tune`: ``summary`` (tune.json's dict), ``estimated`` (each tuned
    ``estimator.process_noise`` key: value, σ, status, limit, the value used),
    ``overrides`` (the tuned noise as ``load_scenario(set=...)`` takes it),
    ``markdown`` (tune.md), ``figure()`` (tune.png) and ``save(dir)``."""

    JSON, MD, PNG = "tune.json", "tune.md", "tune.png"

    @property
    def estimated(self) -> dict:
        return self.summary["estimated"]

    @property
    def overrides(self) -> dict:
        return {f"estimator.process_noise.{k}": v
                for k, v in self.summary["tuned_process_noise"].items()}


class BatchResult(_Report):
    """`dynprop batch`: ``summary`` (batch.json's dict), ``batches`` (one dict per batch:
    epoch, converged, iterations, cost, residuals, state, σ and consider σ),
    ``estimate`` (estimate_batch.csv as a DataFrame indexed by t_s), ``figure()``
    (batch.png) and ``save(dir)``."""

    JSON, PNG = "batch.json", "batch.png"

    @property
    def batches(self) -> list[dict]:
        return self.summary["batches"]

    @property
    def estimate(self) -> pd.DataFrame:
        return _table(self.path / "estimate_batch.csv")


class TrimResult(_Report):
    """`dynprop trim`: ``summary`` (trim.json's dict), ``recommendation`` (the tab to
    command, ± σ), ``markdown`` (trim.md), ``figure()`` (trim.png), ``verify`` (the
    flown check as a ``RunResult``, with ``verify=True``) and ``save(dir)``."""

    JSON, MD, PNG = "trim.json", "trim.md", "trim.png"

    @property
    def recommendation(self) -> dict:
        return self.summary["recommendation"]

    @property
    def verify(self) -> RunResult | None:
        d = self.path / "verify"
        if not (d / "summary.json").is_file():
            return None
        # Borrowed: the files are this result's, kept as long as the run is held.
        run = RunResult(d)
        run._parent = self
        return run
