"""A Monte Carlo set directory, written case by case so that it can be resumed.

    DIR/scenario.yaml            the nominal scenario, resolved (defines the set)
    DIR/cases/case-00007.json    case 7's record: seed, dispersed values, figures
    DIR/cases/case-00007.npz     its errors, σ and NEES on the common grid
    DIR/cases/case-00007.full.npz  whole trajectories, only for cases asked for
    DIR/montecarlo.json, montecarlo.npz, plots/   the ensemble, rewritten each time

Each file is written to a temporary name and renamed, and a case's JSON is written
last: a case counts as done only when its JSON exists, so a set killed at any
moment resumes with every finished case intact and no half-written one.
"""

from __future__ import annotations

import io
import json
import os
import shutil
import tempfile
from pathlib import Path

import numpy as np
import yaml

from ..config.schema import Scenario, resolved_yaml
from ..files.rundir import RunDirError, check_out_dir, names_file

SCENARIO_FILE = "scenario.yaml"


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def atomic_write(path: Path, data: bytes) -> None:
    """``data`` to ``path`` through a temporary sibling and a rename; an OSError
    names ``path`` (a full disk's names no file)."""
    with names_file(path):
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
        try:
            # mkstemp makes 0600; the finished file gets the user's usual permissions.
            os.fchmod(fd, 0o666 & ~_umask())
            with os.fdopen(fd, "wb") as f:
                f.write(data)
            os.replace(tmp, path)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise


def npz_bytes(arrays: dict[str, np.ndarray]) -> bytes:
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    return buf.getvalue()


def save_case(stem: Path, outcome: dict) -> None:
    """``stem``.npz (and .full.npz), then ``stem``.json, the marker that it is done."""
    if outcome.get("arrays") is not None:
        atomic_write(stem.with_suffix(".npz"), npz_bytes(outcome["arrays"]))
    if outcome.get("full") is not None:
        atomic_write(stem.with_suffix(".full.npz"), npz_bytes(outcome["full"]))
    atomic_write(stem.with_suffix(".json"),
                 (json.dumps(outcome["record"], indent=1, allow_nan=False) + "\n").encode())


def _set_definition(text: str) -> dict:
    """What the cases depend on: the resolved scenario without the version stamp and
    the ensemble-only setting (the NEES test's start can change without rerunning)."""
    data = yaml.safe_load(text)
    data.pop("dynprop_version", None)
    data.get("montecarlo", {}).pop("converged_after_h", None)
    return data


def _first_difference(a, b, path: str = "") -> str:
    if isinstance(a, dict) and isinstance(b, dict):
        for key in sorted(set(a) | set(b)):
            if a.get(key) != b.get(key):
                return _first_difference(a.get(key), b.get(key), f"{path}{key}.")
    return path.rstrip(".") or "scenario"


class SetDirectory:
    def __init__(self, out: Path):
        self.out = Path(out)
        self.cases_dir = self.out / "cases"

    def open(self, s: Scenario, force: int = 0) -> bool:
        """Create the set, or check that ``out`` holds this very set (returns True
        when resuming).  A directory of another set or other files is refused unless
        ``force``, which removes it first."""
        text = resolved_yaml(s)
        existing = self.out / SCENARIO_FILE
        if self.out.is_dir() and any(self.out.iterdir()):
            same = existing.is_file() and self.cases_dir.is_dir() and \
                _set_definition(existing.read_text()) == _set_definition(text)
            if same:
                atomic_write(existing, text.encode())
                return True
            if not force:
                if existing.is_file() and self.cases_dir.is_dir():
                    key = _first_difference(_set_definition(existing.read_text()),
                                            _set_definition(text))
                    why = f"it holds the set of another scenario ({key} differs)"
                else:
                    why = "it exists and is not a Monte Carlo set"
                raise RunDirError(f"--out {self.out}: {why}; use --force to start over or "
                                  "another --out")
            check_out_dir(self.out, force)   # never a directory of the user's own files
            shutil.rmtree(self.out)
        check_out_dir(self.out, force)
        self.cases_dir.mkdir(parents=True, exist_ok=True)
        atomic_write(existing, text.encode())
        return False

    def _stem(self, case: int) -> Path:
        return self.cases_dir / f"case-{case:05d}"

    def records(self) -> dict[int, dict]:
        """Every finished case (ok or failed), by case number."""
        out = {}
        for path in sorted(self.cases_dir.glob("case-*.json")):
            record = json.loads(path.read_text())
            out[int(record["case"])] = record
        return out

    def has_full(self, case: int) -> bool:
        return self._stem(case).with_suffix(".full.npz").is_file()

    def save(self, outcome: dict) -> None:
        save_case(self._stem(outcome["record"]["case"]), outcome)

    def arrays(self, case: int) -> dict[str, np.ndarray]:
        with np.load(self._stem(case).with_suffix(".npz")) as data:
            return {k: data[k] for k in data.files}

    def clean_temporaries(self) -> None:
        """Remove what a killed set may have left half written: the temporaries of
        ``atomic_write`` (``.NAME.XXXXXXXX``) for case files and the set's own files,
        and half-drawn figures (``plots/.NAME.png.tmp``)."""
        leftovers = [*self.cases_dir.glob(".case-*")]
        for name in (SCENARIO_FILE, "montecarlo.json", "montecarlo.npz"):
            leftovers += self.out.glob(f".{name}.*")
        leftovers += (self.out / "plots").glob(".*.png.tmp")
        for path in leftovers:
            if path.is_file():
                path.unlink(missing_ok=True)
