"""The package as a user installs it (issue 17): a wheel that puts only the dynprop
namespace into site-packages, so that neither another distribution's ``sim`` nor a
user's own ``sim.py`` or ``plots.py`` beside their notebook can shadow it."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
import venv
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
QUICKSTART = ("import dynprop; r = dynprop.run(dynprop.load_scenario('goes_next_equinox', "
              "duration_s=3600)); print(r.summary['yaw_error_rms_deg']); print(dynprop.__file__)")


def _run(args, cwd):
    # The build backend's own deprecation notices are not this package's warnings.
    env = {k: v for k, v in os.environ.items() if k != "PYTHONWARNINGS"}
    return subprocess.run(args, cwd=cwd, capture_output=True, text=True, timeout=600, env=env)


def test_the_wheel_installs_only_the_dynprop_namespace_and_resists_shadowing(tmp_path):
    # `python -m build`: the sdist, then the wheel built from that sdist, from a copy of
    # the source: setuptools writes its release tree into the project's folder, and a
    # second build there at the same time (make test and make test-vm side by side)
    # removed it under the first ("No such file or directory: dynprop-0.1.0/…").
    src = shutil.copytree(ROOT, tmp_path / "src", ignore=shutil.ignore_patterns(
        ".git", ".venv", "*.egg-info", "__pycache__", "build", "dist", "runs"))
    done = _run([sys.executable, "-m", "build", "--outdir", str(tmp_path / "dist"), str(src)],
                tmp_path)
    assert done.returncode == 0, done.stderr
    # No setuptools warning (build shows the backend's as "WARNING ...", pip as
    # "...Warning: ..."): a data folder left out of the package list printed ~40
    # lines each at every build and install (issue 43).
    warned = [line for line in (done.stdout + done.stderr).splitlines()
              if line.startswith("WARNING ") or "Warning: " in line
              or "absent from the `packages`" in line]
    assert warned == [], "\n".join(warned)
    assert len(list((tmp_path / "dist").glob("dynprop-*.tar.gz"))) == 1
    wheel = next((tmp_path / "dist").glob("dynprop-*.whl"))
    tops = {n.split("/")[0] for n in zipfile.ZipFile(wheel).namelist()}
    assert tops == {"dynprop", wheel.name.split("-py3")[0] + ".dist-info"}
    names = zipfile.ZipFile(wheel).namelist()
    assert "dynprop/py.typed" in names
    # Every package of the source tree is in the wheel (a room left out of pyproject's
    # list imports in the editable checkout and fails in a user's install).
    packages = {str(p.parent.relative_to(ROOT)) for folder in ("sim", "estimator", "scenarios",
                "plots", "rollout", "eom") for p in (ROOT / folder).rglob("__init__.py")}
    assert {f"dynprop/{p}/__init__.py" for p in packages} <= set(names), \
        sorted({f"dynprop/{p}/__init__.py" for p in packages} - set(names))
    # The data folders, every file of them (read here from the source tree).
    for folder, pattern in (("scenarios/bundled", "*.yaml"),
                            ("scenarios/review/templates", "*.html.j2")):
        files = {f"dynprop/{folder}/{p.name}" for p in (ROOT / folder).glob(pattern)}
        assert files and files <= set(names), sorted(files - set(names))
    assert any(n.endswith("dist-info/licenses/LICENSE") or n.endswith("dist-info/LICENSE")
               for n in names)

    # A fresh venv with the wheel; its dependencies from this environment's
    # site-packages (a path, not a site dir: nothing of ours is installed through it).
    env = tmp_path / "venv"
    venv.create(env, with_pip=False)
    py = env / "bin" / "python"
    site = Path(_run([str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                     tmp_path).stdout.strip())
    (site / "deps.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    done = _run([sys.executable, "-m", "pip", "--python", str(py), "install", "-q",
                 "--no-deps", str(wheel)], tmp_path)
    assert done.returncode == 0, done.stderr

    # The user's folder has its own sim.py and plots.py, first on sys.path.
    work = tmp_path / "notebook"
    work.mkdir()
    for name in ("sim.py", "plots.py"):
        (work / name).write_text("raise RuntimeError('the user module was imported')\n")
    done = _run([str(py), "-c", QUICKSTART], work)
    assert done.returncode == 0, done.stderr
    value, where = done.stdout.split()
    assert float(value) > 0 and where.startswith(str(site))
    done = _run([str(py), "-c", "import sim"], tmp_path)
    assert done.returncode != 0 and "No module named 'sim'" in done.stderr
    done = _run([str(py), "-c", "import dynprop.sim.truth, dynprop.estimator.kalman"], tmp_path)
    assert done.returncode == 0, done.stderr
