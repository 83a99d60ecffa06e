"""The paper filter's likelihood of its own telemetry, and its derivatives in the
noise parameters: what noise tuning (``estimator.tune``) maximises.

Prediction-error decomposition (Schweppe 1965): the filter (``kalman``) updates
with roll, yaw and h in turn, and each present scalar measurement has an
innovation ν with variance S, independent of the earlier ones if the model is
right, so

    ln L(θ) = −½ Σ (ln 2πS + ν²/S).

Q_d is linear in the spectral densities (Eq. 32 is linear in Q, Eq. 34 in q), so
Q_d(θ) = Q_fixed + Σ_j θ_j U_j with U_j the Q_d of a unit θ_j: the closed forms are
evaluated once per parameter, and each θ is one pass of a compiled step built once,
with θ in its parameter vector.  θ may also hold a scale on the roll variance R.

The score pass carries, besides x and P, their forward sensitivities ∂x/∂θ_j and
∂P/∂θ_j (CasADi ``jtimes`` on the step's own expressions, so they differentiate
exactly what the filter computes) and accumulates the score ∂ln L/∂θ and the
expected (Fisher) information of the innovations (Gupta & Mehra 1974, IEEE TAC
19(6), Eq. 27)

    I_jk = Σ ½ ∂_j S ∂_k S / S² + ∂_j ν ∂_k ν / S,

so one pass gives ln L, its gradient and a Newton-type curvature.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import casadi as ca
import numpy as np
from dynprop.rollout.chunks import ChunkedRollout

from .kalman import Measurements, _inputs
from .kalman_steps import (
    MEAS_STATES,
    N_UT,
    _pack_sym,
    _sparse_sym,
    _symmetric,
    _unpack_sym,
    pack,
    propagation,
    sequential_update,
    unpack,
)
from .model import N_STATES, ModelParams, ProcessNoise
from .transition import process_noise_integral

N_BASE = N_STATES + N_UT          # x and packed P
N_ACC = 6                         # Σ ln S and Σ ν²/S per measurement kind
LOG_2PI = float(np.log(2 * np.pi))
NOISE_KEYS = ("q_x", "q_z", "q_w", "q_px", "q_pz", "q_cx", "q_cz")


@dataclass(frozen=True, eq=False)
class NoiseModel:
    """Which noise parameters θ a likelihood varies, and how Q_d and R follow them.

    ``groups[j]`` maps the ``ProcessNoise`` keys that θ_j sets to their factor
    (q_x = q_z = θ_j for a tied pair); keys in no group keep ``fixed``'s value.
    ``units[j]`` is Q_d for θ_j = 1, ``Qd_fixed`` the held keys' Q_d.  With
    ``roll``, θ has one more element: a factor on the roll variance R_roll."""

    names: tuple[str, ...]
    groups: tuple[dict[str, float], ...]
    fixed: ProcessNoise
    units: np.ndarray        # (n_q, 9, 9)
    Qd_fixed: np.ndarray     # (9, 9)
    unit_w: np.ndarray       # (9, 9): Q_d of q_w = 1, what a bridged dropout adds per unit
    roll: bool

    @property
    def n_q(self) -> int:
        return len(self.groups)

    @property
    def n(self) -> int:
        return self.n_q + int(self.roll)

    def q_w(self, theta) -> float:
        """The wheel-torque density q_w at θ."""
        theta = np.asarray(theta, dtype=float)
        return self.fixed.q_w * (1 - self._tuned("q_w")) + sum(
            g.get("q_w", 0.0) * theta[j] for j, g in enumerate(self.groups))

    def _tuned(self, key: str) -> bool:
        return any(key in g for g in self.groups)

    def Qd(self, theta) -> np.ndarray:
        """Q_d(θ) = Q_fixed + Σ θ_j U_j."""
        theta = np.asarray(theta, dtype=float)[:self.n_q]
        return self.Qd_fixed + np.tensordot(theta, self.units, axes=1)

    def process_noise(self, theta) -> ProcessNoise:
        """The ``ProcessNoise`` at θ (the roll factor, if any, is not part of it)."""
        theta = np.asarray(theta, dtype=float)
        values = {k: getattr(self.fixed, k) for k in NOISE_KEYS}
        for j, g in enumerate(self.groups):
            for k, c in g.items():
                values[k] = c * float(theta[j])
        return ProcessNoise(**values)

    def theta_of(self, q: ProcessNoise, roll_factor: float = 1.0) -> np.ndarray:
        """θ that reproduces ``q`` on the tuned keys (a group takes its first key)."""
        theta = [getattr(q, next(iter(g))) / next(iter(g.values())) for g in self.groups]
        return np.array(theta + ([roll_factor] if self.roll else []), dtype=float)


def noise_model(params: ModelParams, dt: float, groups: dict[str, dict[str, float]],
                fixed: ProcessNoise, roll: bool = False) -> NoiseModel:
    """The ``NoiseModel`` of named parameter ``groups`` (θ_name sets each key of its
    group times its factor), the other keys held at ``fixed``'s values."""
    seen = [k for g in groups.values() for k in g]
    unknown = sorted(set(seen) - set(NOISE_KEYS))
    if unknown or len(seen) != len(set(seen)):
        raise ValueError(f"each process-noise key may be tuned once; got {seen}")
    zero = dict.fromkeys(NOISE_KEYS, 0.0)
    units = np.array([process_noise_integral(params, ProcessNoise(**{**zero, **g}), dt)
                      for g in groups.values()]).reshape(len(groups), N_STATES, N_STATES)
    held = {k: (0.0 if k in seen else getattr(fixed, k)) for k in NOISE_KEYS}
    unit_w = process_noise_integral(params, ProcessNoise(**{**zero, "q_w": 1.0}), dt)
    return NoiseModel(tuple(groups), tuple(dict(g) for g in groups.values()), fixed, units,
                      process_noise_integral(params, ProcessNoise(**held), dt), unit_w, roll)


def _params_sym(n_q: int, roll: bool):
    """Φ (81), Γ (81), Q_d(θ) (45), the unit extra noise Q_e (45), U_j (45 each, which
    only the score step reads), the q_w map [q_w fixed, coefficients (n_q)], then θ
    (n_q + roll)."""
    n2 = N_STATES**2
    n_theta = n_q + int(roll)
    p = ca.SX.sym("p", 2 * n2 + 2 * N_UT + n_q * N_UT + 1 + n_q + n_theta)
    i = 2 * n2
    phi, gam = _sparse_sym(p[:n2]), _sparse_sym(p[n2:i])
    qfix, qe = _unpack_sym(p[i:i + N_UT]), _unpack_sym(p[i + N_UT:i + 2 * N_UT])
    i += 2 * N_UT
    units = [_unpack_sym(p[i + j * N_UT:i + (j + 1) * N_UT]) for j in range(n_q)]
    i += n_q * N_UT
    qw_fixed, qw_coef = p[i], p[i + 1:i + 1 + n_q]
    theta = p[i + 1 + n_q:]
    return p, phi, gam, qfix, qe, units, qw_fixed, qw_coef, theta


def _step_expressions(n_q: int, roll: bool, trace: list | None = None,
                      qd_of_theta: bool = False):
    """The symbols and expressions of one filter step as a function of θ; with
    ``trace``, also the parameters' pieces and each update's P and K (for
    ``score_step``); ``qd_of_theta`` forms Q_d from θ inside the step (the passed Q_d
    is then Q_fixed), for differentiating the step as a whole (``score_step_ad``)."""
    s = ca.SX.sym("s", N_BASE)
    z, m = ca.SX.sym("z", 3), ca.SX.sym("m", 3)
    r, u, e = ca.SX.sym("r", 3), ca.SX.sym("u", N_STATES), ca.SX.sym("e")
    p, phi, gam, qfix, qe, units, qw_fixed, qw_coef, theta = _params_sym(n_q, roll)
    # Q_d(θ) = Q_fixed + Σ θ_j U_j is formed once per pass, outside (``Likelihood._p``):
    # in the step it would cost 2·45·n operations every sample.
    qd = qfix
    if qd_of_theta:   # symbolic in θ, for differentiating the step as a whole
        qd = qd + sum((theta[j] * units[j] for j in range(n_q)), ca.SX(N_STATES, N_STATES))
    # A bridged dropout's wheel noise (``kalman.ExtraNoise``): the input e is the
    # bridge's measured q_w, of which the filter's own q_w already carries a part.
    q_w = qw_fixed
    for j in range(n_q):
        q_w = q_w + qw_coef[j] * theta[j]
    e_eff = ca.fmax(e - q_w, 0)
    r_eff = ca.vertcat(r[0] * theta[n_q], r[1], r[2]) if roll else r
    x, P = s[:N_STATES], _unpack_sym(s[N_STATES:])
    updates: list = []
    x, P, nus, ss = sequential_update(x, P, z, m, r_eff, updates)
    x_next, P_next = propagation(x, P, u, e_eff, phi, gam, qd, qe)
    if trace is not None:
        trace += [updates, phi, qe, units, qw_coef, q_w, e]
    return (s, z, m, r, u, e, p, theta), ca.vertcat(x_next, _pack_sym(P_next)), nus, ss


def _accumulated(acc, m, nus, ss):
    return acc + ca.vertcat(*(m[i] * ca.log(ss[i]) for i in range(3)),
                            *(m[i] * nus[i] ** 2 / ss[i] for i in range(3)))


@lru_cache(maxsize=4)
def likelihood_step(n_q: int, roll: bool) -> ca.Function:
    """``(s, z, m, r, u, e, p) -> (s_next, aux)``: the filter's step (the same
    expressions as ``kalman_steps.filter_step``) with s = [x⁻, P⁻ (45), Σ m ln S (3),
    Σ m ν²/S (3)] and aux = [ν (3), S (3)]; e is the step's raw bridge noise."""
    (s0, z, m, r, u, e, p, _), base_next, nus, ss = _step_expressions(n_q, roll)
    acc = ca.SX.sym("acc", N_ACC)
    s = ca.vertcat(s0, acc)
    out = ca.cse(ca.vertcat(base_next, _accumulated(acc, m, nus, ss), *nus, *ss))
    n_s = N_BASE + N_ACC
    return ca.Function(f"dynprop_ll{n_q}{'r' if roll else ''}", [s, z, m, r, u, e, p],
                       [out[:n_s], out[n_s:]], ["s", "z", "m", "r", "u", "e", "p"],
                       ["s_next", "aux"])


def _n_fisher(n: int) -> int:
    return n * (n + 1) // 2


def _sym_update(dP, K, w) -> ca.SX:
    """dP − K wᵀ − w Kᵀ on the upper triangle only, mirrored."""
    out = ca.SX(N_STATES, N_STATES)
    for a, b in zip(*np.triu_indices(N_STATES), strict=True):
        out[a, b] = dP[a, b] - K[a] * w[b] - w[a] * K[b]
        out[b, a] = out[a, b]
    return out


def _fisher_terms(m, nu, S, dnu, dS, n):
    """The score and information increments of one scalar update: ℓ = −½ m (ln S + ν²/S),
    ∂ℓ = −½ m (∂S (1/S − ν²/S²) + 2ν ∂ν/S), and m (½ ∂S ∂Sᵀ/S² + ∂ν ∂νᵀ/S) as its
    upper triangle, row-major."""
    g = [-0.5 * m * (dS[j] * (1 / S - nu**2 / S**2) + dnu[j] * (2 * nu / S)) for j in range(n)]
    f = [m * (0.5 * dS[a] * dS[b] / S**2 + dnu[a] * dnu[b] / S)
         for a, b in zip(*np.triu_indices(n), strict=True)]
    return g, f


N_DIR = N_UT + 2    # a direction's parameters: U_v (45), its q_w and roll-factor rates


@lru_cache(maxsize=16)
def score_step(n_q: int, roll: bool, k: int) -> ca.Function:
    """``likelihood_step`` carrying the sensitivities along k directions v of θ too:
    s = [x, P (45), the six sums, ∂[x, P]/∂v (54·k, column by direction), the score
    ∂ln L/∂v (k), the Fisher information's upper triangle (k(k+1)/2, row-major)];
    aux = [ν (3), S (3)].  The parameter vector is ``likelihood_step``'s followed, per
    direction, by U_v = Σ v_j U_j (45), ∂q_w/∂v and ∂θ_R/∂v: with the unit vectors as
    directions, the gradient and information of every parameter; with a few, those
    of a few, at the cost of a few (``Likelihood.score``).

    The sensitivity recursion is derived by hand at the optimal gain, where the
    Joseph form's gain terms drop out: for a scalar update with a = P gᵀ,
    K = m a/S, ∂a = ∂P gᵀ, ∂S = ∂a_i + ∂r, ∂ν = −∂x_i, ∂K = m (∂a − K ∂S)/S,

        ∂x⁺ = ∂x + ∂K ν + K ∂ν,   ∂P⁺ = ∂P − ∂a Kᵀ − K ∂aᵀ + ∂S K Kᵀ,

    then ∂x⁻ = Φ ∂x⁺ and ∂P⁻ = Φ ∂P⁺ Φᵀ + U_v + ∂e_eff Q_e (the bridge noise less
    q_w, ``_step_expressions``).  Half the operations of differentiating the Joseph
    form itself (``score_step_ad``, which the tests hold it to)."""
    trace: list = []
    (s0, z, m, r, u, e, p0, theta), base_next, nus, ss = _step_expressions(n_q, roll, trace)
    updates, phi, qe, _, _, q_w, e_raw = trace
    dirs = ca.SX.sym("dirs", N_DIR * k)
    p = ca.vertcat(p0, dirs)
    units = [_unpack_sym(dirs[v * N_DIR:v * N_DIR + N_UT]) for v in range(k)]
    dqw = [dirs[v * N_DIR + N_UT] for v in range(k)]
    droll = [dirs[v * N_DIR + N_UT + 1] for v in range(k)]
    acc = ca.SX.sym("acc", N_ACC)
    D = ca.SX.sym("D", N_BASE, k)
    g = ca.SX.sym("g", k)
    fisher = ca.SX.sym("F", _n_fisher(k))
    dxs = [D[:N_STATES, j] for j in range(k)]
    dPs = [_unpack_sym(D[N_STATES:, j]) for j in range(k)]
    g_next = [g[j] for j in range(k)]
    f_next = [fisher[i] for i in range(_n_fisher(k))]
    for i, (idx, (_, K)) in enumerate(zip(MEAS_STATES, updates, strict=True)):
        S, nu = ss[i], nus[i]
        dnu, dS = [], []
        for j in range(k):
            da = dPs[j][:, idx]
            # The roll variance is r·θ_R: a direction that moves θ_R moves S by r.
            dSj = da[idx] + (r[0] * droll[j] if roll and i == 0 else 0)
            dnu_j = -dxs[j][idx]
            dK = m[i] * (da - K * dSj) / S
            dxs[j] = dxs[j] + dK * nu + K * dnu_j
            # −∂a Kᵀ − K ∂aᵀ + ∂S K Kᵀ = −w Kᵀ − K wᵀ with w = ∂a − ½ ∂S K.
            w = da - (0.5 * dSj) * K
            dPs[j] = _sym_update(dPs[j], K, w)
            dnu.append(dnu_j)
            dS.append(dSj)
        gi, fi = _fisher_terms(m[i], nu, S, dnu, dS, k)
        g_next = [a + b for a, b in zip(g_next, gi, strict=True)]
        f_next = [a + b for a, b in zip(f_next, fi, strict=True)]
    # e_eff = max(e − q_w, 0): where the bridge noise exceeds q_w it falls as q_w rises.
    bridged = e_raw > q_w
    D_next = [ca.vertcat(phi @ dxs[j], _pack_sym(_symmetric(
        phi @ dPs[j] @ phi.T + units[j] - (bridged * dqw[j]) * qe))) for j in range(k)]
    s = ca.vertcat(s0, acc, ca.vec(D), g, fisher)
    out = ca.cse(ca.vertcat(base_next, _accumulated(acc, m, nus, ss), *D_next, *g_next,
                            *f_next, *nus, *ss))
    n_s = s.numel()
    return ca.Function(f"dynprop_score{n_q}{'r' if roll else ''}_{k}",
                       [s, z, m, r, u, e, p], [out[:n_s], out[n_s:]],
                       ["s", "z", "m", "r", "u", "e", "p"], ["s_next", "aux"])


@lru_cache(maxsize=4)
def score_step_ad(n_q: int, roll: bool) -> ca.Function:
    """``score_step`` for every parameter (the unit directions) by CasADi's forward mode
    (``jtimes``) through the step's own expressions, Joseph form and all, Q_d formed
    from θ inside: the tests' reference for the derived recursion.  Its parameter
    vector is ``likelihood_step``'s with Q_fixed in Q_d's place."""
    (s0, z, m, r, u, e, p, theta), base_next, nus, ss = _step_expressions(
        n_q, roll, qd_of_theta=True)
    n = n_q + int(roll)
    acc = ca.SX.sym("acc", N_ACC)
    D = ca.SX.sym("D", N_BASE, n)
    g = ca.SX.sym("g", n)
    fisher = ca.SX.sym("F", _n_fisher(n))
    wrt = ca.vertcat(s0, theta)
    seeds = ca.vertcat(D, ca.SX.eye(n))
    exprs = ca.vertcat(base_next, *nus, *ss)
    d = ca.jtimes(exprs, wrt, seeds)               # (54 + 6, n): forward mode
    D_next, dnu, dS = d[:N_BASE, :], d[N_BASE:N_BASE + 3, :], d[N_BASE + 3:, :]
    g_next, f_next = g, fisher
    iu = np.triu_indices(n)
    for i in range(3):
        S, nu = ss[i], nus[i]
        # ∂ℓ/∂θ of ℓ = −½(ln S + ν²/S), and the expected information of (ν, S).
        g_next = g_next - 0.5 * m[i] * (dS[i, :].T * (1 / S - nu**2 / S**2)
                                        + dnu[i, :].T * (2 * nu / S))
        outer = 0.5 * dS[i, :].T @ dS[i, :] / S**2 + dnu[i, :].T @ dnu[i, :] / S
        f_next = f_next + m[i] * ca.vertcat(*(outer[a, b] for a, b in zip(*iu, strict=True)))
    s = ca.vertcat(s0, acc, ca.vec(D), g, fisher)
    out = ca.cse(ca.vertcat(base_next, _accumulated(acc, m, nus, ss), ca.vec(D_next), g_next,
                            f_next, *nus, *ss))
    n_s = s.numel()
    return ca.Function(f"dynprop_score_ad{n_q}{'r' if roll else ''}", [s, z, m, r, u, e, p],
                       [out[:n_s], out[n_s:]], ["s", "z", "m", "r", "u", "e", "p"],
                       ["s_next", "aux"])


@lru_cache(maxsize=16)
def _engine(kind: str, n_q: int, roll: bool, backend: str | None, k: int = 0
            ) -> ChunkedRollout:
    if kind == "score":
        step = score_step(n_q, roll, k)
    else:
        step = {"ll": likelihood_step, "score_ad": score_step_ad}[kind](n_q, roll)
    return ChunkedRollout(step, 4096, 256, backend)


@dataclass(frozen=True)
class Evaluation:
    """ln L at θ, with the sums it is made of per measurement kind (roll, yaw, h):
    the count of updates, Σ ln S and the normalised innovation squares Σ ν²/S; and,
    from a score pass, the gradient ∂ln L/∂θ and the Fisher information."""

    theta: np.ndarray
    loglik: float
    counts: np.ndarray
    sum_log_S: np.ndarray
    sum_nis: np.ndarray
    score: np.ndarray | None = None
    fisher: np.ndarray | None = None
    subset: np.ndarray | None = None    # the parameters ``score`` and ``fisher`` are of


class Likelihood:
    """The telemetry, prior and model of one filter run, ready to be evaluated at any
    θ: ``evaluate`` (one pass), ``score`` (one pass with sensitivities) and
    ``innovations`` (ν and S at every sample).  Nothing is rebuilt per θ."""

    def __init__(self, meas: Measurements, disc, x0, P0, model: NoiseModel, u=None,
                 bridge_noise: np.ndarray | None = None, backend: str | None = None):
        z, r = meas.z(), meas.r()
        n = len(z)
        self.model, self.n_samples = model, n
        self.present = np.isfinite(z)
        self.counts = self.present.sum(axis=0).astype(float)
        e = np.zeros(n) if bridge_noise is None else np.asarray(bridge_noise, dtype=float)
        if e.shape != (n,) or not np.all(np.isfinite(e) & (e >= 0)):
            raise ValueError(f"bridge noise must be ({n},), finite and non-negative")
        self.inputs = [np.where(self.present, z, 0.0), self.present.astype(float), r,
                       _inputs(u, n), e]
        x0, P0 = np.asarray(x0, dtype=float), np.asarray(P0, dtype=float)
        self.s0 = np.concatenate([x0, pack(0.5 * (P0 + P0.T))])
        qw_coef = [g.get("q_w", 0.0) for g in model.groups]
        qw_fixed = 0.0 if any(qw_coef) else model.fixed.q_w
        self._p_head = np.concatenate([
            np.asarray(disc.Phi, float).ravel(order="F"),
            np.asarray(disc.Gamma, float).ravel(order="F"),
            np.zeros(N_UT), pack(model.unit_w),
            *(pack(U) for U in model.units), [qw_fixed], qw_coef])
        self.backend = backend
        n2 = 2 * N_STATES**2
        self._qd = slice(n2, n2 + N_UT)

    def _p(self, theta) -> np.ndarray:
        theta = np.asarray(theta, dtype=float)
        if theta.shape != (self.model.n,) or not np.all(np.isfinite(theta) & (theta >= 0)):
            raise ValueError(f"θ must be {self.model.n} finite non-negative numbers")
        p = np.concatenate([self._p_head, theta])
        p[self._qd] = pack(self.model.Qd(theta))
        return p

    def _finish(self, theta, acc) -> Evaluation:
        log_s, nis = acc[:3], acc[3:]
        ll = -0.5 * float(np.sum(log_s + nis) + LOG_2PI * self.counts.sum())
        return Evaluation(np.array(theta, float), ll, self.counts.copy(), log_s.copy(),
                          nis.copy())

    def evaluate(self, theta) -> Evaluation:
        """ln L at θ: one filter pass, no history kept."""
        eng = _engine("ll", self.model.n_q, self.model.roll, self.backend)
        s0 = np.concatenate([self.s0, np.zeros(N_ACC)])
        last, _, _ = eng.run_columns(s0, self.inputs, self._p(theta), np.arange(0),
                                     np.arange(0), np.arange(0))
        return self._finish(theta, last[N_BASE:N_BASE + N_ACC])

    def score(self, theta, subset=None, derived: bool = True) -> Evaluation:
        """ln L, its gradient in θ and the Fisher information: one pass.  With
        ``subset`` (indices into θ) only those parameters' gradient and information
        (``Evaluation.subset``), at the cost of that many directions.
        ``derived=False`` takes all of them by differentiating the step itself
        (``score_step_ad``: the tests' reference, slower)."""
        n = self.model.n
        idx = np.arange(n) if subset is None else np.asarray(subset, dtype=np.int64)
        k = len(idx) if derived else n
        p = self._p(theta)
        if derived:
            eng = _engine("score", self.model.n_q, self.model.roll, self.backend, k)
            p = np.concatenate([p, self._directions(idx)])
        else:     # the step forms Q_d(θ) itself from Q_fixed
            eng = _engine("score_ad", self.model.n_q, self.model.roll, self.backend)
            p[self._qd] = pack(self.model.Qd_fixed)
        s0 = np.concatenate([self.s0, np.zeros(N_ACC + N_BASE * k + k + _n_fisher(k))])
        last, _, _ = eng.run_columns(s0, self.inputs, p, np.arange(0), np.arange(0),
                                     np.arange(0))
        ev = self._finish(theta, last[N_BASE:N_BASE + N_ACC])
        i = N_BASE + N_ACC + N_BASE * k
        F = np.zeros((k, k))
        F[np.triu_indices(k)] = last[i + k:]
        F = F + np.triu(F, 1).T
        return Evaluation(ev.theta, ev.loglik, ev.counts, ev.sum_log_S, ev.sum_nis,
                          last[i:i + k].copy(), F, idx if derived else np.arange(n))

    def _directions(self, idx) -> np.ndarray:
        """The parameters of unit directions ``idx``: U_j, ∂q_w/∂θ_j, ∂θ_R/∂θ_j."""
        m = self.model
        out = []
        for j in idx:
            if j < m.n_q:
                out += [pack(m.units[j]), [m.groups[j].get("q_w", 0.0)], [0.0]]
            else:
                out += [np.zeros(N_UT), [0.0], [1.0]]
        return np.concatenate(out) if out else np.zeros(0)

    def innovations(self, theta) -> tuple[np.ndarray, np.ndarray]:
        """ν and S (N, 3: roll, yaw, h) at θ, NaN where no update."""
        eng = _engine("ll", self.model.n_q, self.model.roll, self.backend)
        s0 = np.concatenate([self.s0, np.zeros(N_ACC)])
        _, aux = eng.run_final(s0, self.inputs, self._p(theta))
        nu, S = aux[:, :3].copy(), aux[:, 3:].copy()
        nu[~self.present] = np.nan
        S[~self.present] = np.nan
        return nu, S


def dense_loglik(meas: Measurements, Phi, Gamma, Qd, x0, P0, u=None,
                 extra_Qd: np.ndarray | None = None) -> float:
    """ln L of the filter in plain numpy, one Python iteration per step, with the
    textbook (non-Joseph) update and ``extra_Qd`` (N, 9, 9) added per step: the
    independent reference the tests hold the compiled passes to."""
    z, r = meas.z(), meas.r()
    n = len(z)
    u = _inputs(u, n)
    x, P = np.array(x0, dtype=float), np.array(P0, dtype=float)
    total = 0.0
    for k in range(n):
        for i, idx in enumerate(MEAS_STATES):
            if np.isnan(z[k, i]):
                continue
            S = P[idx, idx] + r[k, i]
            nu = z[k, i] - x[idx]
            total += np.log(2 * np.pi * S) + nu * nu / S
            K = P[:, idx] / S
            x = x + K * nu
            P = P - np.outer(K, P[idx])
            P = 0.5 * (P + P.T)
        x = Phi @ x + Gamma @ u[k]
        P = Phi @ P @ Phi.T + Qd + (0.0 if extra_Qd is None else extra_Qd[k])
    return -0.5 * total


__all__ = ["Evaluation", "Likelihood", "NoiseModel", "dense_loglik", "likelihood_step",
           "noise_model", "score_step", "unpack"]
