"""`--force` knows dynprop's files by their names, figures included: a user's own
picture beside a run is never taken for one of its figures (issue 29)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from scenarios.files.rundir import OWN_FIGURES, RunDirError, check_out_dir, foreign_files

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"


def test_every_figure_name_the_commands_write_is_dynprops_own():
    """Every `NAME.png` literal in the commands' code is in the list (a new figure
    not added there would make `--force` refuse its own run)."""
    written = set()
    for path in SCENARIOS.rglob("*.py"):
        written |= set(re.findall(r"[\"']([a-z0-9_]+\.png)[\"']", path.read_text()))
    assert written and written <= OWN_FIGURES, sorted(written - OWN_FIGURES)


def test_a_users_picture_stops_force_and_is_named(tmp_path):
    out = tmp_path / "run"
    (out / "plots").mkdir(parents=True)
    for name in ("summary.json", "plots/errors.png", "holiday.png", "plots/sketch.png"):
        (out / name).write_text("x")
    assert foreign_files(out) == ["holiday.png", "plots/sketch.png"]
    with pytest.raises(RunDirError, match="holds holiday.png, plots/sketch.png, which "
                                          "dynprop did not write"):
        check_out_dir(out, 1)
    assert (out / "holiday.png").exists()
    check_out_dir(out, 2)          # --force --force: whatever it holds
