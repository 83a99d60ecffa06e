"""Suite-wide markers.

CI runs the reference-comparison tests a second time with ``DYNPROP_BACKEND=vm``:
the CasADi VM gives other last bits than the compiled C, as another CPU or
compiler would, so a tolerance that only holds on the machine the test was
written on shows up there.  Tests whose requirement *is* compiled code (that the
compiled backend was used, or bit identity with a compiled result) carry
``@pytest.mark.compiled_only`` and are skipped in that pass; so are those marked
``slow_in_vm``: statistical checks over days of telemetry (noise recovered within 2σ)
whose tolerances are orders above any last-bit difference and which take minutes in
the VM; and those marked ``surface``: whole commands run to check their wiring (the
verdicts and messages they print, the API's processes, the notebook), which compare
with no reference number, so the backend cannot change what they check.
"""

import contextlib
import importlib
import importlib.abc
import importlib.util
import io
import os
import sys

import pytest

# The repository's folders install as dynprop.sim, dynprop.scenarios, ... (no generic
# top-level names in a user's environment).  The tests keep their short imports
# (``from scenarios.config.loader import ...``): each is the installed dynprop module itself,
# never a second copy of it (which would make two ScenarioError classes, two caches).
ALIASED = ("sim", "estimator", "scenarios", "plots", "rollout", "eom")


class _DynpropAlias(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in ALIASED:
            return importlib.util.spec_from_loader(name, self)
        return None

    def __init__(self):
        self.specs = {}

    def create_module(self, spec):
        module = importlib.import_module(f"dynprop.{spec.name}")
        self.specs[spec.name] = module.__spec__
        return module

    def exec_module(self, module):
        # The import system has just stamped the alias spec on the real module; give
        # it back its own, so that __spec__.parent agrees with __package__.
        module.__spec__ = self.specs.pop(module.__spec__.name)


sys.meta_path.insert(0, _DynpropAlias())


def pytest_collection_modifyitems(config, items):
    if os.environ.get("DYNPROP_BACKEND", "").lower() != "vm":
        return
    skip = pytest.mark.skip(reason="requires compiled code; this is the DYNPROP_BACKEND=vm pass")
    slow = pytest.mark.skip(reason="a statistical check over days of telemetry, its tolerance "
                            "far above last-bit differences: the compiled pass runs it")
    surface = pytest.mark.skip(reason="checks a command's wiring, no reference number: "
                               "the compiled pass runs it")
    for item in items:
        if "compiled_only" in item.keywords:
            item.add_marker(skip)
        elif "slow_in_vm" in item.keywords:
            item.add_marker(slow)
        elif "surface" in item.keywords:
            item.add_marker(surface)


# --------------------------------------------------------------------------- shared runs
# Runs that several test modules read, made once for the whole session.  The tests only
# read them: one that changes a file copies the directory first.


GAP_EPOCH = "epoch_utc=2026-03-20T22:00:00Z"   # 17:00 local: the night Sun gap 3.25–11.1 h in


def _run_once(tmp_path_factory, name: str, *argv: str, command: str = "run"):
    from dynprop.scenarios.cli import main
    out = tmp_path_factory.mktemp(name) / "run"
    err = io.StringIO()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
        rc = main([command, "goes_next_equinox", *argv, "--out", str(out)])
    assert rc == 0, err.getvalue()
    return out


@pytest.fixture(scope="session")
def run6(tmp_path_factory):
    """`dynprop run goes_next_equinox --duration-s 21600`: 6 h at the default output
    (64 s rows, telemetry.csv written), no Sun gap.  Read by test_api, test_messages,
    test_estimate_run_fit and test_cli_run (its rerun's bytes)."""
    return _run_once(tmp_path_factory, "run6", "--duration-s", "21600")


@pytest.fixture(scope="session")
def gap_run(tmp_path_factory):
    """13 h from 17:00 local on the equinox, every sample written
    (output.interval_s = 0.512): one whole night Sun gap (3.25–11.1 h in) and its end.
    Read by test_cli_run, test_estimate, test_irregular_telemetry, test_stream (the
    run in one window) and test_ekf_stream (the paper filter alone)."""
    return _run_once(tmp_path_factory, "gap", "--duration-s", "46800", "--set",
                     "output.interval_s=0.512", "--set", GAP_EPOCH)


@pytest.fixture(scope="session")
def linearization_13h(tmp_path_factory):
    """`dynprop linearization goes_next_equinox` over the same 13 h (one whole Sun gap
    and its end, which the sweep, the budget and the estimation tables need).  Read by
    test_linearization and, on a copy, the report's browser test."""
    return _run_once(tmp_path_factory, "lin", "--duration-s", "46800", "--set", GAP_EPOCH,
                     command="linearization")
