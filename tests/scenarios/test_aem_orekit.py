"""dynprop's AEM and APM read by Orekit's own parsers: orekit_checks.py, run in a pytest
process of its own.

The checks start a JVM (``orekit-jpype``), and a JVM in the suite's own process would
hang every later test that forks a worker: the child inherits the JVM's locks held by
threads it does not have (seen: ``dynprop batch``'s pool stuck after this test).  So
the checks run in a child pytest, which must pass them all; here they are one test.
Without ``orekit-jpype`` or a JVM this skips, naming what is missing, unless
DYNPROP_OREKIT_REQUIRED is set (CI), where it fails.
"""

from __future__ import annotations

import importlib.util
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

CHECKS = Path(__file__).with_name("orekit_checks.py")


def test_orekit_reads_dynprops_aem_and_apm(tmp_path):
    missing = None
    if importlib.util.find_spec("orekit_jpype") is None:
        missing = "orekit-jpype is not installed (pip install orekit-jpype)"
    elif not (shutil.which("java") or os.environ.get("JAVA_HOME")):
        missing = "no JVM: install Debian's default-jre-headless"
    if missing is not None:
        if os.environ.get("DYNPROP_OREKIT_REQUIRED"):
            pytest.fail(missing + " -- DYNPROP_OREKIT_REQUIRED is set", pytrace=False)
        pytest.skip(missing)
    # The child fails, not skips, on anything missing: here it was all found.
    env = {**os.environ, "DYNPROP_OREKIT_REQUIRED": "1"}
    done = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                           "--basetemp", str(tmp_path / "child"), str(CHECKS)],
                          capture_output=True, text=True, timeout=600, env=env,
                          cwd=CHECKS.parents[2])
    assert done.returncode == 0, done.stdout[-4000:] + done.stderr[-2000:]
    assert " passed" in done.stdout and "skipped" not in done.stdout, done.stdout[-2000:]
