"""Roll a one-step CasADi function out over many steps.

The step has the signature ``(x, in_1, …, in_m, p) -> (x_next, aux)``: x is carried
from step to step, each ``in_j`` and ``aux`` have one column per step, and p is a
parameter vector that is the same for every step.  Compiled, the step runs in a
C loop of its own (``driver``).  In CasADi's VM a long ``mapaccum`` chunk does most
of the work and a short one finishes the run, so no more than a short chunk's
worth of padded steps is ever computed.
"""

from __future__ import annotations

import logging
import subprocess
import threading

import casadi as ca
import numpy as np

from . import compiled
from .driver import CompiledLoop

log = logging.getLogger(__name__)


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


class ChunkedRollout:
    """A step function compiled once and rolled out on demand: by its own C loop
    (``driver``) when compiled; in CasADi's VM by a ``mapaccum`` chunk function
    (main and tail chunk), the last chunk padded."""

    def __init__(self, step: ca.Function, chunk: int = 4096, tail: int = 256,
                 backend: str | None = None):
        self.step = step
        self.chunk = chunk
        self.tail_chunk = min(tail, chunk)
        self.n_aux = step.size1_out(1)
        self.loop = _compiled_loop(step, backend or compiled.requested_backend())
        self.backend = "vm" if self.loop is None else "compiled"
        if self.loop is None:
            self.function = build_chunk(step, chunk)
            self.tail_function = build_chunk(step, self.tail_chunk)
            # Function.buffer() costs ~2 ms: one per function and thread, its
            # arguments bound again each call.
            self._buffers = threading.local()

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
        self._roll(x0, arrays, p, aux, states[1:])
        return states, aux

    def allocate(self, n_steps: int, n_x: int) -> tuple[np.ndarray, np.ndarray]:
        """Empty (states, aux) for ``run(..., out=)`` of ``n_steps`` steps."""
        return np.empty((n_steps + 1, n_x)), np.empty((n_steps, self.n_aux))

    def run_final(self, x0: np.ndarray, inputs: list[np.ndarray], p: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
        """Like ``run``, but without the carried states' history: returns only the
        final carried state, and the aux outputs (N, n_aux), bit for bit ``run``'s
        (a long filter's state history is as large as its outputs and only its end
        is used)."""
        arrays = _as_rows(inputs)
        aux = np.empty((len(arrays[0]) if arrays else 0, self.n_aux))
        return self._roll(x0, arrays, p, aux), aux

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
        and the final carried state, bit for bit ``run``'s."""
        x, _, kept = self.run_columns(x0, inputs, p, np.arange(0), rows, np.arange(self.n_aux))
        return x, kept

    def run_columns(self, x0: np.ndarray, inputs: list[np.ndarray], p: np.ndarray,
                    columns: np.ndarray, rows: np.ndarray, row_columns: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The final carried state, the aux ``columns`` of every step, and the aux
        ``row_columns`` of the steps ``rows`` (sorted) only: a filter's estimates at
        every sample and its covariance on chosen ones, bit for bit ``run``'s.  The
        steps go ``chunk`` at a time through one reused scratch block, so a long
        rollout's outputs stay in cache and its whole aux history is never written."""
        arrays = _as_rows(inputs)
        n_steps = len(arrays[0]) if arrays else 0
        rows = np.asarray(rows, dtype=np.int64)
        if rows.size and (rows[0] < 0 or rows[-1] >= n_steps or np.any(np.diff(rows) <= 0)):
            raise ValueError("rows must be increasing step indices within the rollout")
        every = np.empty((n_steps, len(columns)))
        kept = np.empty((len(rows), len(row_columns)))
        scratch = np.empty((min(self.chunk, n_steps), self.n_aux))
        x = np.array(x0, dtype=float).reshape(-1)
        for start in range(0, n_steps, self.chunk):
            stop = min(start + self.chunk, n_steps)
            block = scratch[:stop - start]
            x = self._roll(x, [a[start:stop] for a in arrays], p, block)
            every[start:stop] = block[:, columns]
            lo, hi = np.searchsorted(rows, [start, stop])
            kept[lo:hi] = block[rows[lo:hi] - start][:, row_columns]
        return x, every, kept

    def _roll(self, x0, arrays, p, aux: np.ndarray, xs: np.ndarray | None = None
              ) -> np.ndarray:
        """Steps 0 … len(aux)−1 from ``x0``: their aux outputs into ``aux`` and, if
        given, the carried state after each into ``xs``.  Returns the final state."""
        if self.loop is not None:
            return self.loop(x0, arrays, p, aux, xs)
        return self._vm_roll(x0, arrays, p, aux, xs)

    def _vm_roll(self, x0, arrays, p, aux, xs):
        """``_roll`` through the VM's chunk functions: full chunks, then tail chunks,
        the last padded by repeating its last row (computed and discarded)."""
        n_steps = len(aux)
        p = np.ascontiguousarray(p, dtype=float)
        x = np.array(x0, dtype=float).reshape(-1)
        n_main = n_steps - n_steps % self.chunk
        for function, c, begin, end in ((self.function, self.chunk, 0, n_main),
                                        (self.tail_function, self.tail_chunk, n_main,
                                         n_steps)):
            if begin == end:
                continue
            # The buffer keeps raw pointers: everything bound stays alive meanwhile.
            buf, run = _buffer_of(self._buffers, function)
            x_in = np.empty(x.size)
            scratch_x, scratch_a = np.empty((c, x.size)), np.empty((c, self.n_aux))
            padded = [np.empty((c, a.shape[1])) for a in arrays]
            buf.set_arg(0, memoryview(x_in))
            for i, blk in enumerate(padded, start=1):
                buf.set_arg(i, memoryview(blk.reshape(-1)))
            buf.set_arg(len(arrays) + 1, memoryview(p))
            buf.set_res(0, memoryview(scratch_x.reshape(-1)))
            buf.set_res(1, memoryview(scratch_a.reshape(-1)))
            for start in range(begin, end, c):
                stop = min(start + c, end)
                n = stop - start
                for a, blk in zip(arrays, padded, strict=True):
                    blk[:n] = a[start:stop]
                    blk[n:] = a[stop - 1]
                x_in[:] = x
                run()
                if buf.ret() != 0:
                    raise RuntimeError(f"{function.name()} failed in the chunk starting at "
                                       f"step {start}")
                aux[start:stop] = scratch_a[:n]
                if xs is not None:
                    xs[start:stop] = scratch_x[:n]
                x = scratch_x[n - 1].copy()
        return x


def _compiled_loop(step: ca.Function, backend: str) -> CompiledLoop | None:
    """The step compiled with its loop, or None for the VM (asked for, or no
    working compiler under ``auto``)."""
    cc = compiled.compiler_for(backend, step.name())
    if cc is None:
        return None
    try:
        return CompiledLoop(step, cc)
    except (OSError, RuntimeError, subprocess.SubprocessError) as exc:
        if backend == "compiled":
            raise
        log.warning("compiling %s failed (%s); falling back to the CasADi VM", step.name(),
                    exc)
        return None


def _buffer_of(cache, function):
    key = id(function)
    made = getattr(cache, "made", None)
    if made is None:
        made = cache.made = {}
    if key not in made:
        made[key] = function.buffer()
    return made[key]


def _as_rows(inputs: list[np.ndarray]) -> list[np.ndarray]:
    """Each input as (N, k) float rows; a strided view stays a view (the compiled
    loop reads it with its stride, the VM copies it a chunk at a time)."""
    arrays = [np.asarray(a, dtype=float) for a in inputs]
    return [a.reshape(len(a), int(np.prod(a.shape[1:]))) for a in arrays]
