"""The linear model propagated exactly: x_{k+1} = Φ x_k + Γ u_k, compiled.

The paper's model (Eq. 11) with its closed-form Φ and Γ (``transition``) is exact
for inputs held over each step; the linear twin of a run and the linearization
report propagate it (or another linear model, discretised by ``zoh``) over a whole
run.
The step is one CasADi function per shape with Φ and Γ as parameters, rolled out by
``rollout`` (compiled C when a compiler is present): no Python loop per step.
"""

from __future__ import annotations

from functools import lru_cache

import casadi as ca
import numpy as np
from dynprop.rollout.chunks import ChunkedRollout
from scipy.linalg import expm

from .model import N_STATES


def zoh(F: np.ndarray, G: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Φ and Γ of ẋ = F x + G u with u held over each step of ``dt``, exactly, from
    one matrix exponential (Van Loan): for a linear model whose closed form is not
    known (a Jacobian)."""
    n, m = G.shape
    aug = np.zeros((n + m, n + m))
    aug[:n, :n], aug[:n, n:] = F, G
    e = expm(aug * dt)
    return e[:n, :n], e[:n, n:]


@lru_cache(maxsize=4)
def _linear_engine(n_x: int = N_STATES, n_u: int = N_STATES) -> ChunkedRollout:
    """x_{k+1} = Φ x_k + Γ u_k compiled once per shape (Φ, Γ as parameters)."""
    x, u = ca.SX.sym("x", n_x), ca.SX.sym("u", n_u)
    p = ca.SX.sym("p", n_x * n_x + n_x * n_u)
    n2 = n_x * n_x
    phi = ca.reshape(p[:n2], n_x, n_x)
    gam = ca.reshape(p[n2:], n_x, n_u)
    name = "dynprop_linear" if (n_x, n_u) == (N_STATES, N_STATES) \
        else f"dynprop_linear_{n_x}x{n_u}"
    step = ca.Function(name, [x, u, p], [phi @ x + gam @ u, x])
    return ChunkedRollout(step)


def _parameters(Phi, Gamma) -> tuple[np.ndarray, tuple[int, int]]:
    Phi, Gamma = np.asarray(Phi, float), np.asarray(Gamma, float)
    return np.concatenate([Phi.ravel(order="F"), Gamma.ravel(order="F")]), Gamma.shape


def propagate_lti(Phi, Gamma, x0, u) -> np.ndarray:
    """x_{k+1} = Φ x_k + Γ u_k from x_0 = x0 for each row of u (N, m); returns the
    states at every sample (N, n), x0 first."""
    p, shape = _parameters(Phi, Gamma)
    _, aux = _linear_engine(*shape).run(np.asarray(x0, float), [np.asarray(u, float)], p)
    return aux


def propagate_lti_final(Phi, Gamma, x0, u) -> tuple[np.ndarray, np.ndarray]:
    """``propagate_lti``'s states at every sample, and the state one step after the
    last (where a following window starts)."""
    p, shape = _parameters(Phi, Gamma)
    last, aux = _linear_engine(*shape).run_final(np.asarray(x0, float),
                                                 [np.asarray(u, float)], p)
    return aux, last
