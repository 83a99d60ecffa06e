"""The Python API in a plain script (issue 29, item 3).

The README's example, saved as a file and run with ``python script.py``, has no
``if __name__ == "__main__":`` guard.  Worker processes started by spawn or
forkserver run the parent's ``__main__`` again, so such a script ran once per
Monte Carlo worker, each copy failing on the run directory the first had saved.
The API's workers must not, and it must leave nothing in the temporary directory.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

import dynprop

# Whole commands checked for their wiring: the compiled pass runs them (conftest).
pytestmark = pytest.mark.surface

REPO = Path(__file__).resolve().parents[1]
MARK = "dynprop-example-script-started"


def _readme_python_block() -> str:
    """The README's one ```python block, verbatim: this test follows the README."""
    blocks = re.findall(r"^```python\n(.*?)^```", (REPO / "README.md").read_text(),
                        re.MULTILINE | re.DOTALL)
    assert len(blocks) == 1, "the README should have exactly one ```python example"
    return blocks[0]


def test_the_readme_example_runs_once_as_a_script_and_leaves_no_temporary_files(tmp_path):
    work, tmp = tmp_path / "cwd", tmp_path / "tmp"
    work.mkdir()
    tmp.mkdir()
    # A line printed before the example counts how often the script is executed:
    # a worker that ran __main__ again would print it again (workers share stdout).
    script = work / "example.py"
    script.write_text(f"print({MARK!r}, flush=True)\n" + _readme_python_block())
    env = {**os.environ, "TMPDIR": str(tmp), "MPLBACKEND": "Agg"}
    proc = subprocess.run([sys.executable, script.name], cwd=work, env=env,
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "Traceback" not in proc.stderr, proc.stderr[-3000:]
    assert proc.stdout.count(MARK) == 1, proc.stdout
    assert sorted(p.name for p in work.iterdir()) == ["example.py", "runs"]
    assert sorted(p.name for p in (work / "runs").iterdir()) == ["eq"]
    saved = work / "runs" / "eq"
    # r.report(), called after r.save(), put the page into the saved folder.
    assert (saved / "report.html").is_file()
    assert sorted(p.name for p in tmp.iterdir()) == []
    # The gap-end line prints the run's own figure: one Sun-gap end, judged within the
    # filter's 3σ there (summary.json's own numbers).
    summary = json.loads((saved / "summary.json").read_text())
    errors, sigmas = summary["yaw_error_at_gap_end_deg"], summary["yaw_sigma_at_gap_end_deg"]
    assert len(errors) == 1 and abs(errors[0]) < 3 * sigmas[0]
    assert str(errors) in proc.stdout.splitlines()


@pytest.mark.parametrize("call", [
    lambda missing: dynprop.tune(missing),
    # Fails after the set directory was opened inside the temporary one.
    lambda missing: dynprop.montecarlo(dynprop.load_scenario("goes_next_equinox",
                                                             duration_s=3600.0),
                                       runs=2, workers=-1),
], ids=["tune", "montecarlo"])
def test_a_command_that_fails_leaves_no_temporary_directory(tmp_path, monkeypatch, call):
    # No result object exists to own the directory made for it: the API removes it.
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(tmp))
    with pytest.raises(Exception):  # noqa: B017, PT011 - which error is the command's business
        call(tmp_path / "no-such-run")
    assert sorted(p.name for p in tmp.iterdir()) == []


def test_montecarlo_leaves_no_process_behind():
    """The forkserver and resource tracker a set starts stop with it.  Left running,
    they are children of a notebook kernel, which then takes 29 s to shut down and
    is killed before it removes its temporary directories (test_notebook.py)."""
    psutil = pytest.importorskip("psutil")
    before = {p.pid for p in psutil.Process().children(recursive=True)}
    s = dynprop.load_scenario("goes_next_equinox", duration_s=3600.0)
    mc = dynprop.montecarlo(s, runs=2, workers=2)
    assert mc.summary["runs_ok"] == 2
    after = {p.pid for p in psutil.Process().children(recursive=True)}
    assert after - before == set()
