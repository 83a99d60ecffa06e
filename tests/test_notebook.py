"""examples/quickstart.ipynb runs headless, top to bottom, in the test suite (issue 17),
and is committed without outputs.

It runs as the README opens it (issue 29): by the venv's `jupyter nbconvert --execute`,
called by its path, with the venv's bin directory not on PATH.  A `dynprop` found on
PATH would hide a notebook that shells out to it, so PATH leads with a decoy that fails
loudly."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import nbformat
import pytest

# Whole commands checked for their wiring: the compiled pass runs them (conftest).
pytestmark = pytest.mark.surface

NOTEBOOK = Path(__file__).resolve().parents[1] / "examples" / "quickstart.ipynb"
DECOY = "#!/bin/sh\necho 'dynprop from PATH: the notebook must not rely on PATH' >&2\nexit 3\n"


def _path_without(bin_dir: Path, decoys: Path) -> str:
    kept = [p for p in os.environ.get("PATH", os.defpath).split(os.pathsep)
            if p and Path(p).resolve() != bin_dir.resolve()]
    return os.pathsep.join([str(decoys), *kept])


def test_quickstart_notebook_runs_without_the_venv_on_path(tmp_path):
    nb = nbformat.read(NOTEBOOK, as_version=4)
    assert all(not c.get("outputs") and not c.get("execution_count")
               for c in nb.cells if c.cell_type == "code"), "commit the notebook without outputs"
    work, tmp, decoys = tmp_path / "nb", tmp_path / "tmp", tmp_path / "decoys"
    for d in (work, tmp, decoys):
        d.mkdir()
    (decoys / "dynprop").write_text(DECOY)
    (decoys / "dynprop").chmod(0o755)
    nbformat.write(nb, work / "quickstart.ipynb")
    bin_dir = Path(sys.executable).parent
    env = {**os.environ, "PATH": _path_without(bin_dir, decoys), "TMPDIR": str(tmp)}
    if env.get("PYTHONWARNINGS"):
        # `make test` turns warnings into errors, the kernel's too; ipykernel's own
        # warning in its shutdown handler would then stop the kernel from exiting.
        env["PYTHONWARNINGS"] += ",ignore::PendingDeprecationWarning:ipykernel.kernelbase"
    proc = subprocess.run([str(bin_dir / "jupyter"), "nbconvert", "--to", "notebook",
                           "--execute", "--output", "executed", "quickstart.ipynb"],
                          cwd=work, env=env, capture_output=True, text=True, timeout=1800)
    assert proc.returncode == 0, proc.stderr[-4000:]
    done = nbformat.read(work / "executed.ipynb", as_version=4)
    outputs = [o for c in done.cells if c.cell_type == "code" for o in c.outputs]
    assert not [o for o in outputs if o.output_type == "error"]
    images = [o for o in outputs if "image/png" in o.get("data", {})]
    assert len(images) >= 3     # the errors figure, the two yaw errors, the NEES figure
    # The kernel stopped in time to remove every temporary directory the API made
    # (a Monte Carlo's helper processes used to hold its shutdown past Jupyter's 5 s).
    assert sorted(p.name for p in tmp.iterdir()) == []
