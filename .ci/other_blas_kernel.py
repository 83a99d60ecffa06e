"""Print an OpenBLAS kernel, other than the one this machine loads, that this CPU can run.

The second test pass (`make test-vm`) sets it as OPENBLAS_CORETYPE, so numpy's matrix
products round as on another CPU.  That is what broke a fresh machine's `make test`
(issue 12): the Haswell kernel leaves 2.2e-19 where the SkylakeX one leaves an exact 0,
in a product numpy hands to BLAS.  CasADi's VM alone does not show such differences.

The kernel is chosen by trying: the first candidate the CPU supports whose product of a
fixed random matrix pair differs in its bits from the native one.  Prints nothing where
numpy does not use OpenBLAS or no candidate differs; the pass then differs in CasADi only.
"""

from __future__ import annotations

import os
import platform
import re
import subprocess
import sys
from pathlib import Path

PROBE = ("import hashlib, numpy as np; r = np.random.default_rng(0); "
         "print(hashlib.sha1((r.standard_normal((200, 64)) @ r.standard_normal((64, 50)))"
         ".tobytes()).hexdigest())")


def probe(coretype: str | None) -> tuple[str | None, str]:
    """(kernel OpenBLAS reports, digest of the product) in this environment, which may
    already set OPENBLAS_CORETYPE, or with ``coretype`` in its place."""
    env = {**os.environ, "OPENBLAS_VERBOSE": "2"}
    if coretype:
        env["OPENBLAS_CORETYPE"] = coretype
    run = subprocess.run([sys.executable, "-c", PROBE], env=env, capture_output=True,
                         text=True, check=True)
    out = run.stdout + run.stderr   # OpenBLAS's line comes from C stdio, in any order
    core = re.search(r"Core: (\w+)", out)
    return (core.group(1) if core else None), re.search(r"\b[0-9a-f]{40}\b", out).group(0)


def candidates() -> list[str]:
    """Kernels this CPU can execute, FMA kernels first: different FMA kernels round
    differently, which is the difference between machines of one kind."""
    machine = platform.machine().lower()
    if machine in ("aarch64", "arm64"):
        return ["ARMV8"]
    if machine not in ("x86_64", "amd64"):
        return []
    try:
        flags = set(re.search(r"^flags\s*:(.*)$", Path("/proc/cpuinfo").read_text(),
                              re.MULTILINE).group(1).split())
    except (OSError, AttributeError):
        return []
    kernels = []
    if {"avx2", "fma"} <= flags:
        kernels.append("Haswell")
    if {"avx512f", "avx512bw", "avx512vl", "avx512dq", "avx512cd"} <= flags:
        kernels.append("SkylakeX")
    if "avx" in flags:
        kernels.append("Sandybridge")
    return [*kernels, "Nehalem"]


def main() -> None:
    native_core, native = probe(None)
    if native_core is None:         # not OpenBLAS (or too old to say): nothing to vary
        return
    for kernel in candidates():
        if kernel == native_core:
            continue
        core, digest = probe(kernel)
        if core == kernel and digest != native:
            print(kernel)
            return


if __name__ == "__main__":
    main()
