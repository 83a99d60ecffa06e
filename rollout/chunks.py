"""Roll a one-step CasADi function out over many steps, a chunk per call.

The step has the signature ``(x, in_1, …, in_m, p) -> (x_next, aux)``: x is carried
from step to step, each ``in_j`` and ``aux`` have one column per step, and p is a
parameter vector that is the same for every step.  A long ``mapaccum`` chunk does
most of the work and a short one finishes the run, so no more than a short
chunk's worth of padded steps is ever computed.
"""

from __future__ import annotations

import hashlib
import os
import threading
from pathlib import Path

import casadi as ca
import numpy as np

from .compiled import CFLAGS, cache_dir, compile_function_path, find_compiler, requested_backend

# Bump when build_chunk's construction changes: the step-keyed cache below does not
# see it.
CHUNK_BUILD_VERSION = "1"


def build_chunk(step: ca.Function, chunk: int) -> ca.Function:
    """``chunk`` steps via ``mapaccum``: ``(x0, IN_1…IN_m, p) -> (X, AUX)``.

    The parameter vector enters once and is repeated symbolically, so a caller
    passes it a single time per chunk.
    """
    n_in = step.n_in()
    acc = step.mapaccum(f"{step.name()}_acc{chunk}", chunk, [0], [0])
    x0 = ca.MX.sym("x0", step.size1_in(0))
    mapped = [ca.MX.sym(step.name_in(i), step.size1_in(i), chunk) for i in range(1, n_in - 1)]
    p = ca.MX.sym("p", step.size1_in(n_in - 1))
    xs, aux = acc(x0, *mapped, ca.repmat(p, 1, chunk))
    return ca.Function(f"{step.name()}_chunk{chunk}", [x0, *mapped, p], [xs, aux],
                       ["x0", *(step.name_in(i) for i in range(1, n_in - 1)), "p"],
                       ["X", "AUX"])


def _step_key_path(step: ca.Function, chunk: int, cc: str) -> Path:
    key = hashlib.sha256("\n".join([step.serialize(), str(chunk), CHUNK_BUILD_VERSION, cc,
                                    *CFLAGS, ca.__version__]).encode()).hexdigest()[:20]
    return cache_dir() / f"{step.name()}_chunk{chunk}_step_{key}.so"


def _chunk_function(step: ca.Function, chunk: int, backend: str) -> tuple[ca.Function, str]:
    """The compiled ``chunk``-step function of ``step``.  Building the mapaccum
    function costs 0.1–0.2 s a process, so a library already built for this very
    step (keyed by its serialisation) is loaded without building it; otherwise it is
    built, compiled (``compile_function``'s source-keyed cache) and linked under the
    step's key for the next process."""
    cc = find_compiler() if backend != "vm" else None
    fast = _step_key_path(step, chunk, cc) if cc else None
    if fast is not None and fast.exists():
        try:
            return ca.external(f"{step.name()}_chunk{chunk}", str(fast)), "compiled"
        except RuntimeError:
            pass   # unreadable: build it again below
    function, used, so_path = compile_function_path(build_chunk(step, chunk), backend)
    if fast is not None and so_path is not None:
        try:
            os.link(so_path, fast)
        except OSError:
            pass   # another process linked it first, or links are not allowed: slow path
    return function, used


class ChunkedRollout:
    """A step function compiled once (main and tail chunk) and rolled out on demand."""

    def __init__(self, step: ca.Function, chunk: int = 4096, tail: int = 256,
                 backend: str | None = None):
        self.step = step
        self.chunk = chunk
        self.tail_chunk = min(tail, chunk)
        self.function, self.backend = _chunk_function(step, chunk,
                                                      backend or requested_backend())
        # Function.buffer() costs ~2 ms (a day of truth in 16384-sample pieces made
        # eleven): one per function and thread, its arguments bound again each call.
        self._buffers = threading.local()
        # The tail always uses the backend the main chunk ended up with, so a run
        # never mixes compiled and VM arithmetic.
        self.tail_function, _ = _chunk_function(step, self.tail_chunk, self.backend)
        self.n_aux = step.size1_out(1)

    def _buffer(self, function):
        """This thread's buffer of ``function`` (every argument is bound again by
        ``_chunks`` before each evaluation, so nothing of a previous call remains)."""
        return _buffer_of(self._buffers, function)

    def run(self, x0: np.ndarray, inputs: list[np.ndarray], p: np.ndarray,
            out: tuple[np.ndarray, np.ndarray] | None = None
            ) -> tuple[np.ndarray, np.ndarray]:
        """One step per row of the (N, k_j) ``inputs``.  Returns the carried states
        (N+1, n_x) including x0, and the aux outputs (N, n_aux): new arrays, or
        ``out``'s (``allocate``), which may be views into a longer run's arrays."""
        arrays = _as_rows(inputs)
        n_steps = len(arrays[0]) if arrays else 0
        states, aux = out if out is not None else self.allocate(n_steps, np.size(x0))
        states[0] = x0
        for start, stop, x_out, a_out in self._chunks(x0, arrays, p, states, aux):
            if not np.may_share_memory(x_out, states):  # a short chunk ran in scratch
                states[start + 1:stop + 1] = x_out[:stop - start]
                aux[start:stop] = a_out[:stop - start]
        return states, aux

    def allocate(self, n_steps: int, n_x: int) -> tuple[np.ndarray, np.ndarray]:
        """Empty (states, aux) for ``run(..., out=)`` of ``n_steps`` steps."""
        return np.empty((n_steps + 1, n_x)), np.empty((n_steps, self.n_aux))

    def run_final(self, x0: np.ndarray, inputs: list[np.ndarray], p: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
        """Like ``run``, but the carried states go through one reused scratch block:
        returns only the final carried state, and the aux outputs (N, n_aux), bit for
        bit ``run``'s (a long filter's state history is as large as its outputs and
        only its end is used)."""
        arrays = _as_rows(inputs)
        n_steps = len(arrays[0]) if arrays else 0
        aux = np.empty((n_steps, self.n_aux))
        x = np.array(x0, dtype=float).reshape(-1)
        for start, stop, x_out, a_out in self._chunks(x0, arrays, p, None, aux):
            if not np.may_share_memory(a_out, aux):  # a short chunk ran in scratch
                aux[start:stop] = a_out[:stop - start]
            x = x_out[stop - start - 1].copy()
        return x, aux

    def run_kept(self, x0: np.ndarray, inputs: list[np.ndarray], p: np.ndarray,
                 rows: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The final carried state and the aux outputs: of every step (``run_final``),
        or of the steps ``rows`` only (``run_rows``)."""
        if rows is None:
            return self.run_final(x0, inputs, p)
        return self.run_rows(x0, inputs, p, rows)

    def run_rows(self, x0: np.ndarray, inputs: list[np.ndarray], p: np.ndarray,
                 rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Like ``run``, but keep only the aux outputs of the steps ``rows`` (sorted)
        and the final carried state.  Every chunk is written into one reused scratch
        block, so a long rollout's memory traffic stays in cache; the kept values
        equal ``run``'s bit for bit (same compiled functions, same chunking)."""
        x, _, kept = self.run_columns(x0, inputs, p, np.arange(0), rows, np.arange(self.n_aux))
        return x, kept

    def run_columns(self, x0: np.ndarray, inputs: list[np.ndarray], p: np.ndarray,
                    columns: np.ndarray, rows: np.ndarray, row_columns: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The final carried state, the aux ``columns`` of every step, and the aux
        ``row_columns`` of the steps ``rows`` (sorted) only: a filter's estimates at
        every sample and its covariance on chosen ones, bit for bit ``run``'s,
        through one reused scratch block, without writing the whole aux history."""
        arrays = _as_rows(inputs)
        n_steps = len(arrays[0]) if arrays else 0
        rows = np.asarray(rows, dtype=np.int64)
        if rows.size and (rows[0] < 0 or rows[-1] >= n_steps or np.any(np.diff(rows) <= 0)):
            raise ValueError("rows must be increasing step indices within the rollout")
        every = np.empty((n_steps, len(columns)))
        kept = np.empty((len(rows), len(row_columns)))
        x = np.array(x0, dtype=float).reshape(-1)
        for start, stop, x_out, a_out in self._chunks(x0, arrays, p):
            every[start:stop] = a_out[:stop - start, columns]
            lo, hi = np.searchsorted(rows, [start, stop])
            kept[lo:hi] = a_out[rows[lo:hi] - start][:, row_columns]
            x = x_out[stop - start - 1].copy()
        return x, every, kept

    def _chunks(self, x0, arrays, p, states=None, aux=None):
        """Roll out every chunk, yielding (start, stop, x_out, a_out): the chunk's
        carried states and aux outputs, rows 0 … stop−start−1 valid.  Full chunks
        write straight into ``states[start+1:]`` and ``aux[start:]`` when given;
        otherwise (and for a short, padded final chunk) into a reused scratch block."""
        n_steps = len(arrays[0]) if arrays else 0
        p = np.ascontiguousarray(p, dtype=float)
        x = np.array(x0, dtype=float).reshape(-1)
        n_main = n_steps - n_steps % self.chunk
        for function, c, begin, end in ((self.function, self.chunk, 0, n_main),
                                        (self.tail_function, self.tail_chunk, n_main,
                                         n_steps)):
            if begin == end:
                continue
            # One buffer per function: binding pointers per chunk is cheap, making
            # a buffer is not.  It keeps raw pointers, so everything bound must stay
            # alive until run(), and outputs must be views, not silent copies.
            buf, run = self._buffer(function)
            x_in = np.empty(x.size)
            scratch_x, scratch_a = np.empty((c, x.size)), np.empty((c, self.n_aux))
            padded = [np.empty((c, a.shape[1])) for a in arrays]
            buf.set_arg(0, memoryview(x_in))
            buf.set_arg(len(arrays) + 1, memoryview(p))
            for start in range(begin, end, c):
                stop = min(start + c, end)
                n = stop - start
                for i, (a, blk) in enumerate(zip(arrays, padded, strict=True), start=1):
                    if n < c:  # pad by repeating the last row: computed and discarded
                        blk[:n] = a[start:stop]
                        blk[n:] = a[stop - 1]
                    elif a.flags.c_contiguous:
                        blk = a[start:stop]
                    else:  # a strided view (the smoother's reversed history): copied
                        # a chunk at a time, in cache, not the whole array up front
                        np.copyto(blk, a[start:stop])
                    buf.set_arg(i, memoryview(blk.reshape(-1)))
                full = n == c
                x_out = states[start + 1:stop + 1] if full and states is not None \
                    else scratch_x
                a_out = aux[start:stop] if full and aux is not None else scratch_a
                x_flat, a_flat = x_out.reshape(-1), a_out.reshape(-1)
                assert np.shares_memory(x_flat, x_out) and np.shares_memory(a_flat, a_out)
                buf.set_res(0, memoryview(x_flat))
                buf.set_res(1, memoryview(a_flat))
                x_in[:] = x
                run()
                if buf.ret() != 0:
                    raise RuntimeError(f"{function.name()} failed in the chunk starting at "
                                       f"step {start}")
                x = x_out[n - 1].copy()
                yield start, stop, x_out, a_out


def _buffer_of(cache, function):
    key = id(function)
    made = getattr(cache, "made", None)
    if made is None:
        made = cache.made = {}
    if key not in made:
        made[key] = function.buffer()
    return made[key]


def _as_rows(inputs: list[np.ndarray]) -> list[np.ndarray]:
    """Each input as (N, k) float rows; a strided view stays a view (``_chunks``
    copies it a chunk at a time)."""
    return [np.asarray(a, dtype=float).reshape(len(a), -1) for a in inputs]
