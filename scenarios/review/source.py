"""What kind of directory `dynprop report` was given, and its files, read and checked
before anything is written.

A directory is known by the record its command writes last: summary.json (`run`,
`estimate`, `run --montecarlo-case`), montecarlo.json, report.json
(`linearization`), trim.json, tune.json, batch.json; a `simulate` directory by its
truth.csv and telemetry.csv.  A record that is missing where the other files say
it should be, or that does not parse (a run killed while writing it), is bad
input: one line, exit 2, nothing written.
"""

from __future__ import annotations

import json
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from ..files.rundir import RunDirError

# kind → (the record that marks it, the other files its page needs)
KINDS = {
    "run": ("summary.json", ("scenario.yaml", "comparison.npz")),
    "montecarlo": ("montecarlo.json", ("scenario.yaml", "montecarlo.npz")),
    "linearization": ("report.json", ()),
    "trim": ("trim.json", ()),
    "tune": ("tune.json", ()),
    "batch": ("batch.json", ()),
}
# Files that only a `run`/`estimate` writes: with them and no summary.json, the
# summary is missing (the command was killed), not the directory of another kind.
RUN_FILES = ("comparison.npz", "estimate.csv", "daily.csv")
# Keys a page reads from each record: a file without them is not that record
# (another version's, or a stranger's file of that name).
REQUIRED = {
    "summary.json": ("scenario", "seed", "duration_s", "checks"),
    # (a set whose every case failed has no nees or gap_end_yaw: its page says so)
    "montecarlo.json": ("runs_requested", "runs_ok"),
    "report.json": ("meta", "verdict", "budget"),
    "trim.json": ("scenario", "kappa_Nm", "kappa_sigma_Nm", "recommendation"),
    "tune.json": ("estimated",),
    "batch.json": ("batches",),
}


class ReportInputError(RunDirError):
    """A directory `dynprop report` cannot make a page of (exit 2, one line)."""


@dataclass(frozen=True)
class Source:
    kind: str
    path: Path
    record: dict                      # the marking record, parsed
    scenario: dict | None = None      # scenario.yaml, parsed, where there is one
    extra: dict = field(default_factory=dict)


def read_json(path: Path, required: tuple[str, ...] = ()) -> dict:
    """A JSON record, with a one-line error for a missing, half-written or foreign
    file."""
    if not path.is_file():
        raise ReportInputError(f"{path}: missing")
    try:
        data = json.loads(path.read_text())
    except UnicodeDecodeError:
        raise ReportInputError(f"{path}: not a text file") from None
    except ValueError as exc:
        raise ReportInputError(f"{path}: not valid JSON ({_where(exc)}): half-written? "
                               "rerun the command that wrote it") from None
    if not isinstance(data, dict):
        raise ReportInputError(f"{path}: not a JSON object")
    missing = [k for k in required if k not in data]
    if missing:
        raise ReportInputError(f"{path}: no key {', '.join(map(repr, missing))}: not "
                               "the record dynprop writes, or a half-written one")
    return data


def read_scenario(path: Path) -> dict:
    if not path.is_file():
        raise ReportInputError(f"{path}: missing")
    try:
        data = yaml.safe_load(path.read_text())
    except (yaml.YAMLError, UnicodeDecodeError) as exc:
        raise ReportInputError(f"{path}: not valid YAML ({str(exc).splitlines()[0]})") \
            from None
    if not isinstance(data, dict) or "name" not in data:
        raise ReportInputError(f"{path}: not a scenario (no name)")
    return data


def kind_of(path: Path) -> str:
    """The kind of directory ``path`` is, or a ReportInputError saying why it is none."""
    if not path.exists():
        raise ReportInputError(f"{path}: no such directory")
    if not path.is_dir():
        raise ReportInputError(f"{path}: not a directory (give the directory a dynprop "
                               "command wrote)")
    have = {p.name for p in path.iterdir()}
    for kind, (record, _) in KINDS.items():
        if record in have:
            return kind
    if have & set(RUN_FILES):
        raise ReportInputError(f"{path}/summary.json: missing: the run did not finish "
                               "(its other files are there); rerun it")
    if {"truth.csv", "telemetry.csv", "scenario.yaml"} <= have:
        return "simulate"
    records = ", ".join(r for r, _ in KINDS.values())
    raise ReportInputError(f"{path}: not a directory dynprop wrote (none of {records}, "
                           "nor a `simulate` directory's truth.csv and telemetry.csv)")


def load(path: Path | str) -> Source:
    """The directory's kind and its records, every file the page needs checked."""
    path = Path(path)
    kind = kind_of(path)
    if kind == "simulate":
        return Source(kind, path, {}, read_scenario(path / "scenario.yaml"))
    record_name, needs = KINDS[kind]
    record = read_json(path / record_name, REQUIRED[record_name])
    for name in needs:
        if not (path / name).is_file():
            raise ReportInputError(f"{path}/{name}: missing (beside {record_name}); rerun "
                                   "the command that wrote the directory")
    for name in needs:
        if name.endswith(".npz"):
            _check_npz(path / name)
    scenario = read_scenario(path / "scenario.yaml") if "scenario.yaml" in needs else None
    return Source(kind, path, record, scenario)


def _check_npz(path: Path) -> None:
    try:
        with zipfile.ZipFile(path) as z:
            bad = z.testzip()
    except (zipfile.BadZipFile, OSError) as exc:
        raise ReportInputError(f"{path}: not a readable .npz ({exc}): half-written? rerun "
                               "the command that wrote it") from None
    if bad is not None:
        raise ReportInputError(f"{path}: {bad} is corrupt: rerun the command that wrote it")


def _where(exc: ValueError) -> str:
    line, col = getattr(exc, "lineno", None), getattr(exc, "colno", None)
    return f"line {line}, column {col}" if line is not None else str(exc)
