"""Compile CasADi functions with the system C compiler, cached on disk.

The cache key is a hash of the generated C source plus the compiler command, so
an unchanged model is compiled once per machine and reused by every process
(Monte Carlo workers included).  Without a working compiler, or with
``DYNPROP_BACKEND=vm``, the function runs in CasADi's virtual machine instead:
slower, never wrong.
"""

from __future__ import annotations

import hashlib
import logging
import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import casadi as ca

log = logging.getLogger(__name__)

# -ffp-contract=off: no fused multiply-adds, so results do not depend on whether
# the target has FMA (bit-identical runs across machines of one architecture).
CFLAGS = ("-O3", "-ffp-contract=off", "-fPIC", "-shared")


def cache_dir() -> Path:
    root = os.environ.get("DYNPROP_CACHE_DIR")
    if root:
        return Path(root)
    return Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "dynprop"


def find_compiler() -> str | None:
    for cc in (os.environ.get("CC"), "cc", "gcc", "clang"):
        if cc and shutil.which(cc):
            return shutil.which(cc)
    return None


def requested_backend() -> str:
    backend = os.environ.get("DYNPROP_BACKEND", "auto").lower()
    if backend not in ("auto", "compiled", "vm"):
        raise ValueError("DYNPROP_BACKEND must be 'auto', 'compiled' or 'vm'")
    return backend


def compiler_for(backend: str, name: str) -> str | None:
    """The C compiler to build ``name`` with, or None for the VM: asked for, or no
    compiler found under ``auto`` (said in a warning; under ``compiled``, an error)."""
    if backend == "vm":
        return None
    cc = find_compiler()
    if cc is None:
        if backend == "compiled":
            raise RuntimeError("no C compiler found for DYNPROP_BACKEND=compiled")
        log.warning("no C compiler found; %s runs in the CasADi VM (slower, and its "
                    "results differ from compiled ones in the last bits)", name)
    return cc


def compile_function(f: ca.Function, backend: str | None = None) -> tuple[ca.Function, str]:
    """Return ``(function, backend_used)`` where backend_used is 'compiled' or 'vm'."""
    function, used, _ = compile_function_path(f, backend)
    return function, used


def compile_function_path(f: ca.Function, backend: str | None = None
                          ) -> tuple[ca.Function, str, Path | None]:
    """``compile_function``, and the library's path (None in the VM)."""
    backend = backend or requested_backend()
    cc = compiler_for(backend, f.name())
    if cc is None:
        return f, "vm", None
    gen = ca.CodeGenerator(f"{f.name()}.c", {"with_header": False})
    gen.add(f)
    try:
        so_path = cached_library(f.name(), gen.dump(), cc)
        return ca.external(f.name(), str(so_path)), "compiled", so_path
    except (OSError, RuntimeError, subprocess.SubprocessError) as exc:
        if backend == "compiled":
            raise
        log.warning("compiling %s failed (%s); falling back to the CasADi VM", f.name(), exc)
        return f, "vm", None


def cached_library(name: str, source: str, cc: str) -> Path:
    """The shared library of C ``source``, compiled once per machine: its path in
    the cache, keyed by the source, the compiler and its flags."""
    key = hashlib.sha256("\n".join([source, cc, *CFLAGS, ca.__version__]).encode())
    so_path = cache_dir() / f"{name}_{key.hexdigest()[:20]}.so"
    if not so_path.exists():
        _build(source, cc, so_path)
    return so_path


def _build(source: str, cc: str, so_path: Path) -> None:
    so_path.parent.mkdir(parents=True, exist_ok=True)
    # Build in a private temporary directory and rename into place, so that
    # concurrent processes never load a half-written library.
    with tempfile.TemporaryDirectory(dir=so_path.parent) as tmp:
        c_file = Path(tmp) / "model.c"
        c_file.write_text(source)
        out = Path(tmp) / "model.so"
        proc = subprocess.run([cc, *CFLAGS, str(c_file), "-o", str(out), "-lm"],
                              capture_output=True, text=True, timeout=600)
        if proc.returncode != 0:
            raise RuntimeError(f"{cc} failed: {proc.stderr.strip()[:500]}")
        os.replace(out, so_path)
