"""A compiled step function rolled out by a C loop of its own.

CasADi's ``mapaccum`` of a step, generated as C, unrolls the chunk into one call
per step and copies around every call: each step's inputs into work memory, its
carried state and outputs into the chunk's results and then into the caller's, and
the parameter vector ``repmat``-ed once per step (8 MB a 4096-step chunk of the
filter).  Those copies took a third of the filter's time.  Here the step is
generated alone and a short loop calls it with pointers straight into the
caller's arrays: row k of each input, the parameters once, the state the previous
step wrote.  The step's own C code is the same, so every result is the same bit
for bit; only the copies are gone.

Inputs may be strided views (a reversed history for the smoother, a column block
of a wider array): the loop takes each one's row stride, so nothing is copied up
front either.
"""

from __future__ import annotations

import ctypes

import casadi as ca
import numpy as np

from .compiled import cached_library

_LOOP = r"""
#include <stdlib.h>

/* Steps 0 … n-1: step k reads its state from x0 (k = 0) or the row the step before
   wrote, row k of each mapped input (ins[j] + k·in_strides[j]: any row stride, so
   reversed or strided views) and the parameters p; it writes the next state to row
   k mod xs_rows of xs and its outputs to row k of aux.  xs_rows = n keeps every
   state, 2 only the last two (the final state is row (n-1) mod 2). */
CASADI_SYMBOL_EXPORT int dynprop_loop(const casadi_real* x0, const casadi_real* const* ins,
                                      const long long* in_strides, const casadi_real* p,
                                      long long n, casadi_real* xs, long long xs_rows,
                                      casadi_real* aux, long long aux_stride) {
  const casadi_real* arg[SZ_ARG];
  casadi_real* res[SZ_RES];
  casadi_int iw[SZ_IW];
  casadi_real* w = (casadi_real*) malloc(sizeof(casadi_real) * SZ_W);
  const casadi_real* x = x0;
  long long k;
  int j, flag = 0;
  if (!w) return 2;
  for (k = 0; k < SZ_ARG; ++k) arg[k] = 0;
  for (k = 0; k < SZ_RES; ++k) res[k] = 0;
  arg[N_MAPPED + 1] = p;
  for (k = 0; k < n; ++k) {
    arg[0] = x;
    for (j = 0; j < N_MAPPED; ++j) arg[1 + j] = ins[j] + k * in_strides[j];
    res[0] = xs + (k % xs_rows) * N_X;
    res[1] = aux + k * aux_stride;
    if (STEP(arg, res, iw, w, 0)) { flag = 1; break; }
    x = res[0];
  }
  free(w);
  return flag;
}
"""


def loop_source(step: ca.Function) -> str:
    """The step's generated C and the loop over it, one translation unit."""
    gen = ca.CodeGenerator(f"{step.name()}.c", {"with_header": False})
    gen.add(step)
    sizes = {"SZ_ARG": step.sz_arg(), "SZ_RES": step.sz_res(), "SZ_IW": max(step.sz_iw(), 1),
             "SZ_W": max(step.sz_w(), 1), "N_MAPPED": step.n_in() - 2,
             "N_X": step.size1_out(0), "STEP": step.name()}
    defines = "".join(f"#define {k} {v}\n" for k, v in sizes.items())
    return gen.dump() + "\n" + defines + _LOOP


class CompiledLoop:
    """``step`` compiled with its loop (``compiled.cached_library``) and called through
    ctypes, which lets go of the GIL for the call."""

    def __init__(self, step: ca.Function, cc: str):
        self.n_x, self.n_aux = step.size1_out(0), step.size1_out(1)
        self.n_mapped = step.n_in() - 2
        self.widths = [step.size1_in(i) for i in range(1, step.n_in() - 1)]
        self.n_p = step.size1_in(step.n_in() - 1)
        lib = ctypes.CDLL(str(cached_library(f"{step.name()}_loop", loop_source(step), cc)))
        self._loop = lib.dynprop_loop
        self._loop.restype = ctypes.c_int
        self._loop.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p,
                               ctypes.c_void_p, ctypes.c_longlong, ctypes.c_void_p,
                               ctypes.c_longlong, ctypes.c_void_p, ctypes.c_longlong]

    def __call__(self, x0: np.ndarray, arrays: list[np.ndarray], p: np.ndarray,
                 aux: np.ndarray, xs: np.ndarray | None = None) -> np.ndarray:
        """Steps 0 … len(aux)−1 from the state ``x0``: row k of each (n, width)
        ``arrays`` view in, row k of ``aux`` out, and the state after it in row k of
        ``xs`` if given.  Returns the final state (a new array)."""
        n = len(aux)
        x0 = np.ascontiguousarray(x0, dtype=float).reshape(-1)
        p = np.ascontiguousarray(p, dtype=float).reshape(-1)
        if x0.size != self.n_x or p.size != self.n_p or len(arrays) != self.n_mapped:
            raise ValueError("the state, inputs or parameters do not fit the step")
        if n == 0:
            return x0.copy()
        _check_rows(aux, n, self.n_aux, "aux")
        if xs is None:
            # Two rows, used in turn: the final state without the state history.
            xs, xs_rows = np.empty((2, self.n_x)), 2
        else:
            _check_rows(xs, n, self.n_x, "xs")
            if xs.strides[0] != 8 * self.n_x:
                raise ValueError("xs must be contiguous")
            xs_rows = n
        views = []
        for a, width in zip(arrays, self.widths, strict=True):
            a = np.asarray(a, dtype=float).reshape(len(a), -1)
            if a.shape != (n, width):
                raise ValueError(f"an input is {a.shape}, the step wants ({n}, {width})")
            if width > 1 and a.strides[1] != 8:
                a = np.ascontiguousarray(a)   # a row that is not contiguous: copied
            views.append(a)
        ins = (ctypes.c_void_p * max(len(views), 1))(*(v.ctypes.data for v in views))
        strides = (ctypes.c_longlong * max(len(views), 1))(*(v.strides[0] // 8 for v in views))
        flag = self._loop(x0.ctypes.data, ins, strides, p.ctypes.data, n, xs.ctypes.data,
                          xs_rows, aux.ctypes.data, aux.strides[0] // 8)
        if flag:
            raise RuntimeError("the compiled step failed" if flag == 1 else "out of memory")
        return xs[(n - 1) % xs_rows].copy()


def _check_rows(a: np.ndarray, n: int, width: int, name: str) -> None:
    if a.dtype != np.float64 or a.shape != (n, width) or a.strides[1] != 8 or \
            not a.flags.writeable or a.strides[0] % 8:
        raise ValueError(f"{name} must be a writable ({n}, {width}) float64 array with "
                         "contiguous rows")
