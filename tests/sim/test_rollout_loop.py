"""The compiled step's own C loop (``rollout.driver``): the values of CasADi's
compiled ``mapaccum`` chunk, inputs read in place whatever their row stride, and the
final state without the state history.

Bit identity here is the requirement (the same compiled step code on one machine,
called by another loop), so the tests that compare compiled results carry
``compiled_only``."""

import casadi as ca
import numpy as np
import pytest

from estimator.kalman.steps import N_STATES, N_UT, PHI_PATTERN, filter_step, pack
from rollout import compiled
from rollout.chunks import ChunkedRollout, build_chunk

needs_cc = pytest.mark.skipif(compiled.find_compiler() is None, reason="no C compiler")


def _filter_inputs(n: int, seed: int = 3):
    """A state, inputs and parameters of the paper's filter step: some measurements
    missing, some steps with extra noise, Φ with the structure of Eq. 15."""
    rng = np.random.default_rng(seed)
    phi = np.where(PHI_PATTERN, 0.1 * rng.standard_normal((N_STATES, N_STATES)), 0.0)
    phi += np.eye(N_STATES)
    gam = np.where(PHI_PATTERN, 0.01 * rng.standard_normal((N_STATES, N_STATES)), 0.0)
    a = rng.standard_normal((N_STATES, N_STATES))
    qd, qe = pack(1e-3 * a @ a.T), pack(1e-4 * np.eye(N_STATES))
    p = np.concatenate([phi.ravel(order="F"), gam.ravel(order="F"), qd, qe])
    x0 = np.concatenate([rng.standard_normal(N_STATES), pack(np.eye(N_STATES))])
    m = (rng.random((n, 3)) < 0.7).astype(float)
    ins = [rng.standard_normal((n, 3)) * m, m, 0.1 + rng.random((n, 3)),
           rng.standard_normal((n, N_STATES)), np.where(rng.random(n) < 0.1, 2.0, 0.0)]
    return x0, ins, p


@pytest.mark.compiled_only
@needs_cc
def test_loop_gives_the_compiled_mapaccum_chunk_bit_for_bit():
    """200 steps of the filter: the loop's states and outputs are those of the
    mapaccum chunk it replaced (compiled with the same flags), every bit.  A step
    lost, repeated or fed another row's input would change them."""
    n = 200
    x0, ins, p = _filter_inputs(n)
    states, aux = ChunkedRollout(filter_step(), backend="compiled").run(x0, ins, p)
    chunk, used = compiled.compile_function(build_chunk(filter_step(), n), "compiled")
    assert used == "compiled"
    X, AUX = chunk(x0, *(a.reshape(n, -1).T for a in ins), p)
    assert np.array_equal(states[1:], np.asarray(X).T)
    assert np.array_equal(aux, np.asarray(AUX).T)
    assert np.array_equal(states[0], x0)


@needs_cc
def test_inputs_are_read_with_their_strides():
    """Reversed views, a column block of a wider array and a broadcast row give what
    their contiguous copies give (the same compiled code either way: ==)."""
    n = 300
    x0, ins, p = _filter_inputs(n)
    engine = ChunkedRollout(filter_step(), backend="compiled")
    reference = engine.run_final(x0, [np.ascontiguousarray(a[::-1]) for a in ins], p)
    wide = np.hstack([np.zeros((n, 2)), ins[3], np.zeros((n, 1))])
    strided = [a[::-1] for a in ins[:3]] + [wide[::-1, 2:2 + N_STATES], ins[4][::-1]]
    got = engine.run_final(x0, strided, p)
    assert np.array_equal(got[0], reference[0]) and np.array_equal(got[1], reference[1])
    same_r = np.broadcast_to(ins[2][0], (n, 3))
    a = engine.run_final(x0, ins[:2] + [same_r] + ins[3:], p)
    b = engine.run_final(x0, ins[:2] + [np.ascontiguousarray(same_r)] + ins[3:], p)
    assert np.array_equal(a[1], b[1]) and np.array_equal(a[0], b[0])


@pytest.mark.parametrize("n", [0, 1, 2, 3, 257])
def test_final_state_without_history_is_runs_last(n):
    """run_final's two alternating state rows end where run's history ends (odd and
    even step counts), and no step leaves x0 as it was."""
    x0, ins, p = _filter_inputs(max(n, 1))
    ins = [a[:n] for a in ins]
    engine = ChunkedRollout(filter_step())
    states, aux = engine.run(x0, ins, p)
    x, aux_final = engine.run_final(x0, ins, p)
    assert np.array_equal(x, states[-1]) and np.array_equal(aux_final, aux)
    assert aux.shape == (n, N_STATES + N_UT + 6)
    assert np.array_equal(states[0], x0) and (n == 0 or not np.array_equal(x, x0))


@needs_cc
def test_inputs_that_do_not_fit_the_step_are_refused():
    x0, ins, p = _filter_inputs(10)
    loop = ChunkedRollout(filter_step(), backend="compiled").loop
    aux = np.empty((10, loop.n_aux))
    with pytest.raises(ValueError, match="wants"):
        loop(x0, ins[:3] + [ins[3][:, :8]] + ins[4:], p, aux)
    with pytest.raises(ValueError, match="do not fit"):
        loop(x0[:-1], ins, p, aux)
    with pytest.raises(ValueError, match="aux"):
        loop(x0, ins, p, aux[:, :-1])


def test_no_compiler_means_the_vm(monkeypatch):
    """Under ``auto`` a machine without a compiler rolls out in the VM; asking for
    compiled code there is an error."""
    monkeypatch.setattr(compiled, "find_compiler", lambda: None)
    x, u, q = ca.SX.sym("x"), ca.SX.sym("u"), ca.SX.sym("p")
    step = ca.Function("halve_loop", [x, u, q], [0.5 * x + u, x])
    engine = ChunkedRollout(step, chunk=4, tail=2, backend="auto")
    assert engine.backend == "vm" and engine.loop is None
    states, aux = engine.run(np.array([8.0]), [np.ones(5)], np.zeros(1))
    # Halving and adding 1 is exact in binary: 8, 5, 3.5, 2.75, 2.375, 2.1875.
    assert np.array_equal(states[:, 0], [8.0, 5.0, 3.5, 2.75, 2.375, 2.1875])
    assert np.array_equal(aux[:, 0], states[:-1, 0])
    with pytest.raises(RuntimeError, match="compiler"):
        ChunkedRollout(step, backend="compiled")


def test_a_compiler_that_fails_means_the_vm(monkeypatch, tmp_path, caplog):
    """Under ``auto`` a compiler that fails leaves the step in the VM, says so, and
    leaves no library behind; under ``compiled`` it is an error."""
    monkeypatch.setenv("DYNPROP_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(compiled, "find_compiler", lambda: "/bin/false")
    x, u, q = ca.SX.sym("x"), ca.SX.sym("u"), ca.SX.sym("p")
    step = ca.Function("halve_bad_cc", [x, u, q], [0.5 * x + u, x])
    with caplog.at_level("WARNING"):
        engine = ChunkedRollout(step, chunk=4, tail=2, backend="auto")
    assert engine.backend == "vm" and "falling back to the CasADi VM" in caplog.text
    assert not list(tmp_path.glob("*.so"))
    states, _ = engine.run(np.array([8.0]), [np.ones(3)], np.zeros(1))
    assert np.array_equal(states[:, 0], [8.0, 5.0, 3.5, 2.75])
    with pytest.raises(RuntimeError):
        ChunkedRollout(step, backend="compiled")
