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

import importlib
import importlib.abc
import importlib.util
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
