"""Suite-wide markers.

CI runs the reference-comparison tests a second time with ``DYNPROP_BACKEND=vm``:
the CasADi VM gives other last bits than the compiled C, as another CPU or
compiler would, so a tolerance that only holds on the machine the test was
written on shows up there.  Tests whose requirement *is* compiled code (that the
compiled backend was used, or bit identity with a compiled result) carry
``@pytest.mark.compiled_only`` and are skipped in that pass.
"""

import os

import pytest


def pytest_collection_modifyitems(config, items):
    if os.environ.get("DYNPROP_BACKEND", "").lower() != "vm":
        return
    skip = pytest.mark.skip(reason="requires compiled code; this is the DYNPROP_BACKEND=vm pass")
    for item in items:
        if "compiled_only" in item.keywords:
            item.add_marker(skip)
