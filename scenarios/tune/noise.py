"""A `dynprop tune` result read back for `run`, `estimate` and `montecarlo`
(``--tuned-from DIR``): the tuned ``estimator.process_noise`` as overrides of the
scenario, and the note summary.json (montecarlo.json) carries of where it came from."""

from __future__ import annotations

import json
from pathlib import Path

from dynprop.estimator.tuning.likelihood import NOISE_KEYS

from .source import TuneError


def tune_json(path: Path) -> Path:
    """DIR/tune.json, or DIR/tune/tune.json for the run directory it was tuned on."""
    path = Path(path)
    for candidate in (path, path / "tune.json", path / "tune" / "tune.json"):
        if candidate.is_file():
            return candidate
    raise TuneError(f"--tuned-from {path}: no tune.json there (nor in {path}/tune/): run "
                    "`dynprop tune` first")


def tuned_noise(path: Path) -> tuple[list[str], dict]:
    """The ``--set`` overrides that give a scenario the tuned process noise, and the
    note for its summary: which file, and the values."""
    file = tune_json(path)
    try:
        d = json.loads(file.read_text())
        values = {k: float(d["tuned_process_noise"][k]) for k in NOISE_KEYS}
    except (ValueError, KeyError, TypeError):
        raise TuneError(f"--tuned-from {file}: not a dynprop tune.json (no "
                        "tuned_process_noise with every process-noise key)") from None
    bad = [k for k, v in values.items() if not v >= 0]
    if bad:
        raise TuneError(f"--tuned-from {file}: {', '.join(bad)} not a non-negative number")
    overrides = [f"estimator.process_noise.{k}={v!r}" for k, v in values.items()]
    note = {"source": "tuned", "tune_json": str(file), "telemetry": d.get("telemetry", {})
            .get("file"), **values}
    return overrides, note


def note_summary(path: Path, note: dict | None) -> None:
    """Add ``process_noise`` (the tune it came from) to a written summary.json or
    montecarlo.json; a run on the scenario's own noise has none, its scenario.yaml says."""
    if note is None or not Path(path).is_file():
        return
    d = json.loads(Path(path).read_text())
    d["process_noise"] = note
    Path(path).write_text(json.dumps(d, indent=2, allow_nan=False) + "\n")
