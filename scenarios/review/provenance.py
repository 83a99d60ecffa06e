"""Where a page's numbers came from: the scenario as resolved YAML, the run's and
the page's provenance, and links to the directory's files.

The run's own command line is not stored in its directory (a rerun must give the
same bytes, so nothing there holds a date or a path); its scenario.yaml is fully
resolved, so the page gives the command that reproduces it from that file.  The
page's provenance is the report's: this dynprop's version, its git commit when it
runs from a checkout, the `dynprop report` command line and the date, which
``SOURCE_DATE_EPOCH`` fixes for a reproducible page (the reproducible-builds
convention).
"""

from __future__ import annotations

import datetime as dt
import os
import subprocess
from functools import lru_cache
from pathlib import Path

from .. import __version__
from ..files.rundir import public_path
from .cells import Table, text
from .render import Section
from .source import Source

# Records and folders listed under Files, with what each is.
NOTES = {
    "scenario.yaml": "the resolved scenario", "summary.json": "the run's figures",
    "truth.csv": "the truth at the output interval", "telemetry.csv": "the telemetry",
    "estimate.csv": "the filter's estimate and σ", "estimate_ekf.csv": "the EKF's",
    "smoothed.csv": "the RTS smoother", "daily.csv": "one row per day",
    "comparison.npz": "the series the figures are drawn from",
    "montecarlo.json": "the ensemble figures", "montecarlo.npz": "the ensemble series",
    "report.json": "the linearization report's figures", "report.md": "its text",
    "trim.json": "the trim recommendation", "trim.md": "its report",
    "tune.json": "the tuned noise", "tune.md": "its report",
    "batch.json": "the batch estimates", "plots": "the PNG figures",
}


@lru_cache(maxsize=1)
def git_commit() -> str | None:
    """The commit of the dynprop code writing the page, with "+ local changes" when
    its checkout differs from it; None outside a git checkout."""
    here = Path(__file__).resolve().parent
    try:
        head = subprocess.run(["git", "-C", str(here), "rev-parse", "HEAD"],
                              capture_output=True, text=True, timeout=10)
        if head.returncode != 0:
            return None
        dirty = subprocess.run(["git", "-C", str(here), "status", "--porcelain",
                                "--untracked-files=no"], capture_output=True, text=True,
                               timeout=10)
    except (OSError, subprocess.SubprocessError):
        return None
    return head.stdout.strip() + (" + local changes" if dirty.stdout.strip() else "")


def now_utc() -> str:
    fixed = os.environ.get("SOURCE_DATE_EPOCH")
    when = (dt.datetime.fromtimestamp(int(fixed), dt.UTC) if fixed and fixed.isdigit()
            else dt.datetime.now(dt.UTC))
    return when.strftime("%Y-%m-%dT%H:%M:%SZ")


def _written(path: Path) -> str:
    t = dt.datetime.fromtimestamp(path.stat().st_mtime, dt.UTC)
    return t.strftime("%Y-%m-%dT%H:%M:%SZ")


def reproduce(src: Source, kind: str) -> str:
    """The command that writes the directory again, from its own scenario.yaml (a
    `run --report` page is built in the stage: named by the directory it becomes)."""
    d = public_path(src.path)
    if kind == "estimate":
        tel = (src.record.get("telemetry") or {})
        truth = f" --truth {tel['truth_file']}" if tel.get("truth_file") else ""
        return (f"dynprop estimate {tel.get('file', 'TELEMETRY.csv')} --scenario "
                f"{d}/scenario.yaml{truth} --out NEW_DIR")
    if kind == "run" and src.record.get("montecarlo_case") is not None:
        return (f"dynprop run {d}/scenario.yaml --montecarlo-case "
                f"{src.record['montecarlo_case']} --out NEW_DIR")
    if kind == "montecarlo":
        return (f"dynprop montecarlo {d}/scenario.yaml --runs "
                f"{src.record.get('runs_requested', 'N')} --out NEW_DIR")
    return f"dynprop {kind} {d}/scenario.yaml --out NEW_DIR"


def sections(src: Source, command: str | None, kind: str) -> list[Section]:
    """The scenario, provenance and files sections every page ends with."""
    out = []
    scenario_file = src.path / "scenario.yaml"
    if scenario_file.is_file():
        out.append(Section("scenario", "Scenario", "scenario.yaml as the run resolved it: "
                           "every key with its value, defaults filled.",
                           pre=scenario_file.read_text()))
    rec, scen = src.record, src.scenario or {}
    run_rows = [("scenario", rec.get("scenario") or scen.get("name")),
                ("seed", rec.get("seed", scen.get("seed"))),
                ("epoch (UTC)", rec.get("epoch_utc") or scen.get("epoch_utc")),
                ("dynprop version that wrote it",
                 rec.get("dynprop_version") or scen.get("dynprop_version")),
                ("CasADi backend", rec.get("backend")),
                # tune, batch and linearization record the command that wrote them
                ("command that wrote it", rec.get("command") or (rec.get("meta") or {})
                 .get("command")),
                ("written (file time, UTC)", _written(_record_file(src))),
                ("reproduce with", reproduce(src, kind) if scenario_file.is_file() else None)]
    page_rows = [("dynprop version", __version__), ("git commit", git_commit() or "not known"),
                 ("command line", command or "the Python API"), ("date (UTC)", now_utc())]
    tables = [Table("provenance-run", [], [[text(k), text(str(v))] for k, v in run_rows
                                                 if v is not None], "The run"),
              Table("provenance-page", [], [[text(k), text(str(v))]
                                                  for k, v in page_rows], "This page")]
    out.append(Section("provenance", "Provenance", tables=tables))
    out.append(Section("files", "Files", "The directory's files, relative to this page.",
                       links=files(src.path)))
    return out


def _record_file(src: Source) -> Path:
    for name in ("summary.json", "montecarlo.json", "report.json", "trim.json", "tune.json",
                 "batch.json", "scenario.yaml"):
        if (src.path / name).is_file():
            return src.path / name
    return src.path


def files(path: Path) -> list[tuple[str, str, str]]:
    out = []
    for p in sorted(path.iterdir()):
        if p.name.startswith(".") or p.name == "report.html":
            continue
        if p.is_dir():
            inner = sorted(q.name for q in p.iterdir() if not q.name.startswith("."))
            shown = ", ".join(inner[:6]) + (f", … ({len(inner)} in all)" if len(inner) > 6
                                              else "")
            note = NOTES.get(p.name, "")
            out.append((f"{p.name}/", f"{p.name}/", f"{note}{': ' if note else ''}{shown}"))
            if (p / "report.html").is_file():   # trim/, tune/, batch/: their own page
                out.append((f"{p.name}/report.html", f"{p.name}/report.html",
                            "its review page"))
            continue
        size = p.stat().st_size
        human = f"{size / 1e6:.1f} MB" if size >= 1e5 else f"{size / 1e3:.1f} kB"
        note = NOTES.get(p.name, "")
        out.append((p.name, p.name, f"{note}{', ' if note else ''}{human}"))
    return out
