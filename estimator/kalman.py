"""The paper's 9-state Kalman filter (Section 5) and an RTS smoother.

Each step, at t_k: sequential scalar measurement updates of roll, yaw and h,
each in Joseph form (Eq. 37, with the gain of Eq. 38 and the state update of
Eq. 36); a missing value (NaN) means no update.  Then propagation to t_{k+1}
with Eqs. 31–32: x⁻ = Φ x⁺ + Γ ū_k, P⁻ = Φ P⁺ Φᵀ + Q_d, with ū held over the step.

Joseph form (I − KG) P (I − KG)ᵀ + K R Kᵀ keeps P symmetric and positive
definite in floating point, where the short form (I − KG) P does not; with
scalar updates and G a unit row it costs little.

The step is one CasADi function rolled out by ``rollout`` (compiled once, Φ, Γ
and Q_d entering as parameters), so a day of 0.512 s data takes a fraction of a
second; ``dense_filter`` is a plain-numpy reference used by the tests.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import casadi as ca
import numpy as np
from dynprop.rollout.chunks import ChunkedRollout

from .model import H_WHEEL, N_STATES, R, Y

MEAS_STATES = (R, Y, H_WHEEL)   # roll, yaw, h: each a unit row of G (Eq. 26)
MEAS_NAMES = ("roll", "yaw", "h")
_IU = np.triu_indices(N_STATES)
N_UT = len(_IU[0])  # 45


def pack(P: np.ndarray) -> np.ndarray:
    """Upper triangle (row-major) of symmetric matrices, (..., 9, 9) -> (..., 45)."""
    return P[..., _IU[0], _IU[1]]


def unpack(p: np.ndarray) -> np.ndarray:
    """Inverse of ``pack``: (..., 45) -> symmetric (..., 9, 9)."""
    p = np.asarray(p)
    P = np.zeros(p.shape[:-1] + (N_STATES, N_STATES))
    P[..., _IU[0], _IU[1]] = p
    P[..., _IU[1], _IU[0]] = p
    return P


def _unpack_sym(p) -> ca.SX:
    P = ca.SX(N_STATES, N_STATES)
    for k, (i, j) in enumerate(zip(*_IU, strict=True)):
        P[i, j] = p[k]
        P[j, i] = p[k]
    return P


def _pack_sym(P) -> ca.SX:
    return ca.vertcat(*(P[i, j] for i, j in zip(*_IU, strict=True)))


# Structural nonzeros of Φ and Γ (Eq. 15): the 4×9 attitude rows, and ψ (Eq. 18):
# h and the constant torques on the diagonal, the periodic pair rotating.
PHI_PATTERN = np.zeros((N_STATES, N_STATES), dtype=bool)
PHI_PATTERN[:4, :] = True
PHI_PATTERN[4, 4] = PHI_PATTERN[7, 7] = PHI_PATTERN[8, 8] = True
PHI_PATTERN[5:7, 5:7] = True


def _sparse_sym(flat) -> ca.SX:
    """A 9×9 SX matrix from column-major entries, zero outside PHI_PATTERN, so
    products skip the structural zeros."""
    M = ca.SX(N_STATES, N_STATES)
    for j in range(N_STATES):
        for i in range(N_STATES):
            if PHI_PATTERN[i, j]:
                M[i, j] = flat[j * N_STATES + i]
    return M


def _params_sym():
    """Φ (81), Γ (81), Q_d (45) and the unit extra noise Q_e (45) as one parameter
    vector."""
    p = ca.SX.sym("p", 2 * N_STATES**2 + 2 * N_UT)
    n2 = N_STATES**2
    return (p, _sparse_sym(p[:n2]), _sparse_sym(p[n2:2 * n2]),
            _unpack_sym(p[2 * n2:2 * n2 + N_UT]), _unpack_sym(p[2 * n2 + N_UT:]))


def _symmetric(P) -> ca.SX:
    """P rebuilt from its upper triangle: the lower half's expressions are dropped,
    which halves the work of every update and propagation."""
    return _unpack_sym(_pack_sym(P))


@dataclass(frozen=True)
class ExtraNoise:
    """Process noise added on chosen steps: step k adds ``scale[k] · Qd_unit``.

    For a telemetry dropout the wheel torque N_w* is bridged, not measured, so
    its uncertainty is added as the paper's wheel-torque noise q_w (Eq. 34, which
    drives ẏ and h together) on the bridged steps only: ``Qd_unit`` is Q_d for
    q_w = 1 (N m)² s and ``scale`` the q_w of each step (zero elsewhere, which
    leaves those steps bit for bit as without it)."""

    scale: np.ndarray       # (N,)
    Qd_unit: np.ndarray     # (9, 9)


def _extra(extra: ExtraNoise | None, n: int) -> tuple[np.ndarray, np.ndarray]:
    if extra is None:
        return np.zeros(n), np.zeros((N_STATES, N_STATES))
    scale = np.asarray(extra.scale, dtype=float)
    if scale.shape != (n,) or not np.all(np.isfinite(scale) & (scale >= 0)):
        raise ValueError(f"extra noise scale must be ({n},), finite and non-negative")
    return scale, np.asarray(extra.Qd_unit, dtype=float)


def pack_params(disc, Qd_unit=None) -> np.ndarray:
    Phi, Gam, Qd = (np.asarray(m, dtype=float) for m in (disc.Phi, disc.Gamma, disc.Qd))
    Qe = np.zeros((N_STATES, N_STATES)) if Qd_unit is None else np.asarray(Qd_unit, float)
    for name, M in (("Phi", Phi), ("Gamma", Gam)):
        off = np.abs(M[~PHI_PATTERN]).max(initial=0.0)
        if off > 1e-12 * np.abs(M).max():
            raise ValueError(f"{name} has entries outside the structure of Eq. 15 ({off:g})")
    return np.concatenate([Phi.ravel(order="F"), Gam.ravel(order="F"), pack(Qd), pack(Qe)])


@lru_cache(maxsize=2)
def filter_step() -> ca.Function:
    """``(s, z, m, r, u, e, p) -> (s_next, aux)`` with s = [x⁻, P⁻ (45)] at t_k,
    m the 0/1 presence of each measurement (z is 0 where absent: NaN never enters
    the compiled code, and CasADi would fold a ``z == z`` NaN test to true), and
    aux = [x⁺, P⁺ (45), ν (3), S (3)] (the caller blanks ν, S where m = 0), and e the
    step's extra-noise scale (``ExtraNoise``)."""
    s = ca.SX.sym("s", N_STATES + N_UT)
    z, m = ca.SX.sym("z", 3), ca.SX.sym("m", 3)
    r, u, e = ca.SX.sym("r", 3), ca.SX.sym("u", N_STATES), ca.SX.sym("e")
    p, phi, gam, qd, qe = _params_sym()
    x, P = s[:N_STATES], _unpack_sym(s[N_STATES:])
    eye = ca.SX.eye(N_STATES)
    nus, ss = [], []
    for i, idx in enumerate(MEAS_STATES):
        S = P[idx, idx] + r[i]
        # An absent measurement (m = 0) zeroes the gain, and with K = 0 the Joseph
        # form returns P unchanged bit for bit (I P Iᵀ + r·0): no branches needed.
        K = m[i] * P[:, idx] / S
        nu = z[i] - x[idx]
        G = ca.SX(1, N_STATES)
        G[idx] = 1.0
        ikg = eye - K @ G
        P = _symmetric(ikg @ P @ ikg.T + r[i] * (K @ K.T))  # Joseph form, Eq. 37
        x = x + K * nu
        nus.append(nu)
        ss.append(S)
    x_next = phi @ x + gam @ u
    # + e·Q_e after + Q_d: with e = 0 it adds (±)0 and changes no bit.
    P_next = _symmetric(phi @ P @ phi.T + qd + e * qe)
    out = ca.cse(ca.vertcat(x_next, _pack_sym(P_next), x, _pack_sym(P), *nus, *ss))
    n_s = N_STATES + N_UT
    return ca.Function("dynprop_kf", [s, z, m, r, u, e, p], [out[:n_s], out[n_s:]],
                       ["s", "z", "m", "r", "u", "e", "p"], ["s_next", "aux"])


def _sum(terms, start):
    for term in terms:
        start = start - term
    return start


def _cholesky_solve(A, B) -> ca.SX:
    """X with A X = B for symmetric positive definite A, by A = L Lᵀ written out
    (A's lower triangle is read), with one division per pivot."""
    n, m = A.size1(), B.size2()
    L = [[None] * n for _ in range(n)]
    inv = [None] * n
    for j in range(n):
        inv[j] = 1.0 / ca.sqrt(_sum((L[j][k] * L[j][k] for k in range(j)), A[j, j]))
        for i in range(j + 1, n):
            L[i][j] = _sum((L[i][k] * L[j][k] for k in range(j)), A[i, j]) * inv[j]
    X = ca.SX(n, m)
    for c in range(m):
        y = [None] * n
        for i in range(n):
            y[i] = _sum((L[i][k] * y[k] for k in range(i)), B[i, c]) * inv[i]
        x = [None] * n
        for i in reversed(range(n)):
            x[i] = _sum((L[k][i] * x[k] for k in range(i + 1, n)), y[i]) * inv[i]
        for i in range(n):
            X[i, c] = x[i]
    return X


@lru_cache(maxsize=2)
def smoother_step() -> ca.Function:
    """Backward RTS step ``(s, x⁺_k, P⁺_k, u_k, e_k, p) -> (s_prev, aux)`` with
    s = [x^s_{k+1}, P^s_{k+1}]; aux = [x^s_k, P^s_k]."""
    s = ca.SX.sym("s", N_STATES + N_UT)
    xk, pk, u = ca.SX.sym("x", N_STATES), ca.SX.sym("P", N_UT), ca.SX.sym("u", N_STATES)
    e = ca.SX.sym("e")
    p, phi, gam, qd, qe = _params_sym()
    Pk = _unpack_sym(pk)
    xs1, Ps1 = s[:N_STATES], _unpack_sym(s[N_STATES:])
    x_pred = phi @ xk + gam @ u
    P_pred = _symmetric(phi @ Pk @ phi.T + qd + e * qe)
    # C = P_k Φᵀ P⁻¹_pred, from a Cholesky solve with the symmetric positive definite
    # P_pred: a third of the operations of CasADi's general (QR) solve, which made the
    # smoother the costliest step of a long run.
    C = _cholesky_solve(P_pred, phi @ Pk).T
    xs = xk + C @ (xs1 - x_pred)
    Ps = Pk + C @ (Ps1 - P_pred) @ C.T
    out = ca.cse(ca.vertcat(xs, _pack_sym(Ps)))
    return ca.Function("dynprop_rts", [s, xk, pk, u, e, p], [out, out],
                       ["s", "x", "P", "u", "e", "p"], ["s_prev", "aux"])


@lru_cache(maxsize=2)
def smoother_x_step() -> ca.Function:
    """The RTS step for the smoothed state alone, ``(s, x⁺_k, P⁺_k, u_k, e_k, p) ->
    (s_prev, aux)`` with s = x^s_{k+1}, aux = x^s_k: x^s_k = x⁺_k + P⁺_k Φᵀ P⁻¹_pred
    (x^s_{k+1} − x⁻_{k+1}), one solve with a single right-hand side and no
    smoothed-covariance recursion (which x^s does not need): a quarter of
    ``smoother_step``'s operations, for runs that report the smoothed estimate only."""
    s = ca.SX.sym("s", N_STATES)
    xk, pk, u = ca.SX.sym("x", N_STATES), ca.SX.sym("P", N_UT), ca.SX.sym("u", N_STATES)
    e = ca.SX.sym("e")
    p, phi, gam, qd, qe = _params_sym()
    Pk = _unpack_sym(pk)
    x_pred = phi @ xk + gam @ u
    P_pred = _symmetric(phi @ Pk @ phi.T + qd + e * qe)
    xs = xk + Pk @ (phi.T @ _cholesky_solve(P_pred, s - x_pred))
    out = ca.cse(xs)
    return ca.Function("dynprop_rts_x", [s, xk, pk, u, e, p], [out, out],
                       ["s", "x", "P", "u", "e", "p"], ["s_prev", "aux"])


@lru_cache(maxsize=6)
def _engine(kind: str, chunk: int, backend: str | None) -> ChunkedRollout:
    step = {"filter": filter_step, "smoother": smoother_step,
            "smoother_x": smoother_x_step}[kind]()
    return ChunkedRollout(step, chunk, 256, backend)


@dataclass(frozen=True)
class Measurements:
    """Roll (rad), yaw (rad) and h (N m s) per sample, NaN where missing, and their
    variances (scalars or per-sample arrays; rad², rad², (N m s)²)."""

    roll_rad: np.ndarray
    yaw_rad: np.ndarray
    h_Nms: np.ndarray
    var_roll: float | np.ndarray
    var_yaw: float | np.ndarray
    var_h: float | np.ndarray

    def z(self) -> np.ndarray:
        return np.column_stack([self.roll_rad, self.yaw_rad, self.h_Nms]).astype(float)

    def r(self) -> np.ndarray:
        n = len(self.roll_rad)
        cols = [np.broadcast_to(np.asarray(v, dtype=float), (n,))
                for v in (self.var_roll, self.var_yaw, self.var_h)]
        r = np.column_stack(cols)
        if np.any(~np.isfinite(r) & np.isfinite(self.z())) or np.any(r[np.isfinite(r)] <= 0):
            raise ValueError("measurement variances must be positive and finite where "
                             "a measurement is present")
        return np.where(np.isfinite(r), r, 1.0)


class _PackedHistory:
    """σ and P views of a (N, 45) packed covariance history."""

    P_packed: np.ndarray

    @property
    def sigma(self) -> np.ndarray:
        """1σ of each state, (N, 9)."""
        return np.sqrt(self.P_packed[:, _DIAG])

    @property
    def P(self) -> np.ndarray:
        return unpack(self.P_packed)


_DIAG = [k for k, (i, j) in enumerate(zip(*_IU, strict=True)) if i == j]


@dataclass(frozen=True)
class FilterResult(_PackedHistory):
    """A-posteriori history at each sample, innovations ν and their variances S
    (columns roll, yaw, h; NaN where no update), and the prior after the last step."""

    x: np.ndarray          # (N, 9)
    P_packed: np.ndarray   # (N, 45), see ``unpack``
    innovations: np.ndarray
    innovation_var: np.ndarray
    x_next: np.ndarray
    P_next: np.ndarray
    backend: str


@dataclass(frozen=True)
class SmootherResult(_PackedHistory):
    x: np.ndarray
    P_packed: np.ndarray | None   # None from rts_smoother(covariance=False)


def _inputs(u, n) -> np.ndarray:
    if u is None:
        return np.zeros((n, N_STATES))
    u = np.asarray(u, dtype=float)
    if u.shape != (n, N_STATES) or not np.all(np.isfinite(u)):
        raise ValueError(f"inputs must be a finite ({n}, {N_STATES}) array (Eq. 12a)")
    return u


def kalman_filter(meas: Measurements, disc, x0, P0, u=None, backend: str | None = None,
                  chunk: int = 4096, rows=None, extra: ExtraNoise | None = None,
                  covariance_rows=None) -> FilterResult:
    """Run the filter over every sample.  ``disc`` has Φ, Γ, Q_d for the sample
    interval (``estimator.transition.discretize``); x0, P0 are the prior at the first
    sample; ``u`` the (N, 9) input vectors of Eq. 12a (zero if None).  With ``rows``
    (increasing sample indices) the history holds only those samples, bit for bit
    the full run's, without the full history's memory; with ``covariance_rows``
    instead, only ``P_packed`` is cut to those samples (the estimates, innovations and
    their variances stay at every sample), for a run that needs the covariance only
    where it forms the NEES.  ``extra`` adds process noise on chosen steps
    (``ExtraNoise``: a telemetry dropout)."""
    z, r = meas.z(), meas.r()
    n = len(z)
    x0, P0 = np.asarray(x0, dtype=float), np.asarray(P0, dtype=float)
    if x0.shape != (N_STATES,) or P0.shape != (N_STATES, N_STATES):
        raise ValueError("x0 must have 9 elements and P0 be 9×9")
    engine = _engine("filter", chunk, backend)
    s0 = np.concatenate([x0, pack(0.5 * (P0 + P0.T))])
    present = np.isfinite(z)
    scale, Qd_unit = _extra(extra, n)
    inputs = [np.where(present, z, 0.0), present.astype(float), r, _inputs(u, n), scale]
    p = pack_params(disc, Qd_unit)
    if covariance_rows is not None:
        if rows is not None:
            raise ValueError("rows and covariance_rows exclude each other")
        # x (9), then ν and S (3 each) after the packed covariance: every sample.
        last, aux, P = engine.run_columns(
            s0, inputs, p, np.r_[0:N_STATES, N_STATES + N_UT:engine.n_aux],
            np.asarray(covariance_rows, dtype=np.int64), np.arange(N_STATES, N_STATES + N_UT))
        nu, S = aux[:, N_STATES:N_STATES + 3], aux[:, N_STATES + 3:]
    else:
        rows = None if rows is None else np.asarray(rows, dtype=np.int64)
        last, aux = engine.run_kept(s0, inputs, p, rows)
        if rows is not None:
            present = present[rows]
        P = aux[:, N_STATES:N_STATES + N_UT]
        nu, S = aux[:, N_STATES + N_UT:N_STATES + N_UT + 3], aux[:, -3:]
    nu[~present] = np.nan
    S[~present] = np.nan
    return FilterResult(aux[:, :N_STATES], P, nu, S, last[:N_STATES], unpack(last[N_STATES:]),
                        engine.backend)


def rts_smoother(result: FilterResult, disc, u=None, backend: str | None = None,
                 chunk: int = 4096, extra: ExtraNoise | None = None,
                 covariance: bool = True, x_after: np.ndarray | None = None
                 ) -> SmootherResult:
    """Rauch–Tung–Striebel smoother over a stored filter history (with the
    filter's own ``u`` and ``extra``).  ``covariance=False`` smooths the state alone
    (``smoother_x_step``; ``P_packed`` is None), about four times faster; with it,
    ``x_after`` is the smoothed state one step after the history (where a following
    stretch, smoothed first, begins), from which the recursion goes back over every
    sample: the smoother of the joined history, without joining it.  Without it the
    last filtered state is its own smoothed value."""
    n = len(result.x)
    if x_after is not None and covariance:
        raise ValueError("x_after needs covariance=False")
    if n < 2 and x_after is None:  # nothing to smooth: the last estimate is the smoothed one
        return SmootherResult(result.x.copy(),
                              result.P_packed.copy() if covariance else None)
    u = _inputs(u, n)
    scale, Qd_unit = _extra(extra, n)
    engine = _engine("smoother" if covariance else "smoother_x", chunk, backend)
    # Backwards: step k uses the filter's k-th posterior and input, for k = n−2 … 0
    # (from n−1 when the smoothed state after the history is given).
    rev = slice(n - 2 if x_after is None else n - 1, None, -1)
    if covariance:
        s0 = np.concatenate([result.x[-1], result.P_packed[-1]])
    else:
        s0 = result.x[-1] if x_after is None else np.asarray(x_after, dtype=float)
    _, aux = engine.run_final(s0, [result.x[rev], result.P_packed[rev], u[rev], scale[rev]],
                              pack_params(disc, Qd_unit))
    if x_after is not None:
        return SmootherResult(aux[::-1].copy(), None)
    xs = np.vstack([aux[::-1, :N_STATES], result.x[-1:]])
    if not covariance:
        return SmootherResult(xs, None)
    Ps = np.vstack([aux[::-1, N_STATES:], result.P_packed[-1:]])
    return SmootherResult(xs, Ps)


def dense_filter(meas: Measurements, disc, x0, P0, u=None, extra: ExtraNoise | None = None
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Reference implementation in plain numpy, one Python loop iteration per step
    (slow; for tests).  Returns the a-posteriori x (N, 9) and P (N, 9, 9)."""
    z, r = meas.z(), meas.r()
    n = len(z)
    u = _inputs(u, n)
    scale, Qd_unit = _extra(extra, n)
    Phi, Gam, Qd = (np.asarray(m, dtype=float) for m in (disc.Phi, disc.Gamma, disc.Qd))
    x, P = np.asarray(x0, dtype=float).copy(), np.asarray(P0, dtype=float).copy()
    xs, Ps = np.empty((n, N_STATES)), np.empty((n, N_STATES, N_STATES))
    eye = np.eye(N_STATES)
    for k in range(n):
        for i, idx in enumerate(MEAS_STATES):
            if np.isnan(z[k, i]):
                continue
            G = eye[idx:idx + 1]
            S = (G @ P @ G.T).item() + r[k, i]
            K = P @ G.T / S
            x = x + (K * (z[k, i] - x[idx])).ravel()
            IKG = eye - K @ G
            P = IKG @ P @ IKG.T + r[k, i] * K @ K.T
        xs[k], Ps[k] = x, P
        x = Phi @ x + Gam @ u[k]
        P = Phi @ P @ Phi.T + Qd + scale[k] * Qd_unit
    return xs, Ps
