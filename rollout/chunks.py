"""Roll a one-step CasADi function out over many steps, a chunk per call.

The step has the signature ``(x, in_1, …, in_m, p) -> (x_next, aux)``: x is carried
from step to step, each ``in_j`` and ``aux`` have one column per step, and p is a
parameter vector that is the same for every step.  A long ``mapaccum`` chunk does
most of the work and a short one finishes the run, so no more than a short
chunk's worth of padded steps is ever computed.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from .compiled import compile_function, requested_backend


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
    """A step function compiled once (main and tail chunk) and rolled out on demand."""

    def __init__(self, step: ca.Function, chunk: int = 4096, tail: int = 256,
                 backend: str | None = None):
        self.step = step
        self.chunk = chunk
        self.tail_chunk = min(tail, chunk)
        self.function, self.backend = compile_function(build_chunk(step, chunk),
                                                       backend or requested_backend())
        # The tail always uses the backend the main chunk ended up with, so a run
        # never mixes compiled and VM arithmetic.
        self.tail_function, _ = compile_function(build_chunk(step, self.tail_chunk),
                                                 self.backend)
        self.n_aux = step.size1_out(1)

    def run(self, x0: np.ndarray, inputs: list[np.ndarray], p: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray]:
        """One step per row of the (N, k_j) ``inputs``.  Returns the carried states
        (N+1, n_x) including x0, and the aux outputs (N, n_aux)."""
        arrays = [np.ascontiguousarray(a, dtype=float).reshape(len(a), -1) for a in inputs]
        n_steps = len(arrays[0]) if arrays else 0
        states = np.empty((n_steps + 1, np.size(x0)))
        states[0] = x0
        aux = np.empty((n_steps, self.n_aux))
        p = np.ascontiguousarray(p, dtype=float)
        n_main = n_steps - n_steps % self.chunk
        _run(self.function, self.chunk, 0, n_main, states, aux, arrays, p)
        _run(self.tail_function, self.tail_chunk, n_main, n_steps, states, aux, arrays, p)
        return states, aux


    def run_rows(self, x0: np.ndarray, inputs: list[np.ndarray], p: np.ndarray,
                 rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Like ``run``, but keep only the aux outputs of the steps ``rows`` (sorted)
        and the final carried state.  Each chunk is written into one reused scratch
        block, so a long rollout's memory traffic stays in cache; the kept values
        equal ``run``'s bit for bit (same compiled functions, same chunking)."""
        arrays = [np.ascontiguousarray(a, dtype=float).reshape(len(a), -1) for a in inputs]
        n_steps = len(arrays[0]) if arrays else 0
        rows = np.asarray(rows, dtype=np.int64)
        if rows.size and (rows[0] < 0 or rows[-1] >= n_steps or np.any(np.diff(rows) <= 0)):
            raise ValueError("rows must be increasing step indices within the rollout")
        p = np.ascontiguousarray(p, dtype=float)
        kept = np.empty((len(rows), self.n_aux))
        x = np.array(x0, dtype=float).reshape(-1)
        n_main = n_steps - n_steps % self.chunk
        for function, c, begin, end in ((self.function, self.chunk, 0, n_main),
                                        (self.tail_function, self.tail_chunk, n_main,
                                         n_steps)):
            if begin == end:
                continue
            x_in = np.empty(x.size)
            states = np.empty((c, x.size))
            aux = np.empty((c, self.n_aux))
            blocks = [np.empty((c, a.shape[1])) for a in arrays]
            # One buffer per function, bound once to the scratch arrays: only their
            # contents change from chunk to chunk.
            buf, run = function.buffer()
            buf.set_arg(0, memoryview(x_in))
            for i, blk in enumerate(blocks, start=1):
                buf.set_arg(i, memoryview(blk.reshape(-1)))
            buf.set_arg(len(blocks) + 1, memoryview(p))
            buf.set_res(0, memoryview(states.reshape(-1)))
            buf.set_res(1, memoryview(aux.reshape(-1)))
            for start in range(begin, end, c):
                stop = min(start + c, end)
                x_in[:] = x
                for blk, a in zip(blocks, arrays, strict=True):
                    blk[:stop - start] = a[start:stop]
                    blk[stop - start:] = a[stop - 1]  # padding, computed and discarded
                run()
                if buf.ret() != 0:
                    raise RuntimeError(f"{function.name()} failed in the chunk starting at "
                                       f"step {start}")
                x = states[stop - start - 1].copy()
                lo, hi = np.searchsorted(rows, [start, stop])
                kept[lo:hi] = aux[rows[lo:hi] - start]
        return x, kept


def _run(function, c, begin, end, states, aux, arrays, p) -> None:
    buf, run = function.buffer()
    nx = states.shape[1]
    for start in range(begin, end, c):
        stop = min(start + c, end)
        full = stop - start == c
        blocks = [a[start:stop] if full else _pad(a[start:stop], c) for a in arrays]
        x_out = states[start + 1:stop + 1] if full else np.empty((c, nx))
        a_out = aux[start:stop] if full else np.empty((c, aux.shape[1]))
        x_in = states[start].copy()
        # The buffer keeps raw pointers: every array must stay alive until run(),
        # and outputs must be views into states/aux, not silent copies.
        x_flat, a_flat = x_out.reshape(-1), a_out.reshape(-1)
        assert np.shares_memory(x_flat, x_out) and np.shares_memory(a_flat, a_out)
        buf.set_arg(0, memoryview(x_in))
        for i, blk in enumerate(blocks, start=1):
            buf.set_arg(i, memoryview(blk.reshape(-1)))
        buf.set_arg(len(blocks) + 1, memoryview(p))
        buf.set_res(0, memoryview(x_flat))
        buf.set_res(1, memoryview(a_flat))
        run()
        if buf.ret() != 0:
            raise RuntimeError(f"{function.name()} failed in the chunk starting at step {start}")
        if not full:
            states[start + 1:stop + 1] = x_out[:stop - start]
            aux[start:stop] = a_out[:stop - start]


def _pad(block: np.ndarray, rows: int) -> np.ndarray:
    """Pad a short final chunk by repeating its last row (the extra steps are
    computed and discarded)."""
    out = np.empty((rows, block.shape[1]))
    out[:len(block)] = block
    out[len(block):] = block[-1]
    return out
