"""The pitch estimator of Eq. 3b: pitch, pitch rate and a constant pitch torque.

Model.  Eq. 3b, I_y θ̈ + 3ω0²(I_x − I_z) θ = N_y − Ḣ, with θ the 3-1-2 pitch, H the
*signed* body-y wheel momentum (docs/conventions.md, "Wheels and momentum": H =
−I_w cos c (Ω1 + Ω2) < 0) and Ḣ its rate.  With k = 3ω0²(I_x − I_z)/I_y, w a white
torque of intensity q_w ((N m)² s) and N_y a random walk of intensity q_c ((N m)²/s)::

    x = [θ, θ̇, N_y],  ẋ = F x + B Ḣ + [0, w/I_y, w_c]
    F = [[0, 1, 0], [−k, 0, 1/I_y], [0, 0, 0]],   B = [0, −1/I_y, 0]

Sign.  The printed Eq. 3b holds as it stands, with the signed H: the CasADi Jacobian of
the truth's own gyrostat (``sim.linearize.linearize_about_nominal``, the equation
``eom.gyrostat`` integrates) at Earth pointing gives ∂θ̈/∂θ = +1.6207e-9 /s² = −k,
∂θ̈/∂N_y = +1/I_y, ∂θ̈/∂Ḣ = −1/I_y, to 1.2e-15 (``tests/estimator/test_pitch.py``).  For
GOES-Next I_x = 3364.376 < I_z = 3461.393 kg m², so k = −1.62e-9 /s² < 0: the gravity
gradient destabilises pitch (docs/conventions.md, Torques: T_y > 0 for θ > 0), and the
free motion is cosh/sinh, e-folding in 1/√|k| = 6.9 h, held by the pitch loop.

Closed forms.  With z = kτ² and the entire functions c_m(z) = Σ_n (−z)^n/(2n + m)!
(c_0 = cos√z, c_1 = sin√z/√z for z > 0, cosh/sinh for z < 0, c_{m+2} = (1/m! − c_m)/z;
summed as a series for |z| ≤ 8, so k > 0, k < 0 and k → 0 are one formula), the
free solutions are C = c_0(z), S = τc_1(z) = ∫C, V = τ²c_2(z) = ∫S, and::

    Φ(τ) = [[C, S, V/I_y], [−kS, C, S/I_y], [0, 0, 1]],   Γ = ∫Φ B = −[V, S, 0]/I_y
    Q_d = ∫_0^τ Φ Q Φᵀ du,  Q = diag(0, q_w/I_y², q_c):
      q_w/I_y² · [[∫S², ∫SC, 0], [∫SC, ∫C², 0], [0, 0, 0]]
    + q_c · [[∫V²/I_y², ∫VS/I_y², ∫V/I_y], [·, ∫S²/I_y², V/I_y], [·, ·, τ]]
    ∫S² = 2τ³c_3(4z)    ∫C² = τ(1 + c_1(4z))/2    ∫SC = S²/2    ∫VS = V²/2
    ∫V = τ³c_3(z)       ∫V² = τ⁵(8c_5(4z) − 2c_5(z))

(from C² + kS² = 1, C² − kS² = C(2τ), SC = S(2τ)/2 and c_1 = 1 − z/6 + z²c_5).  Each
is exact for either sign of k and cancellation-free as k → 0 (τ³/3, τ, τ⁵/20, ...).

Filter.  Per sample: a scalar Joseph update with the Earth-sensor pitch (NaN: none),
then x⁻ = Φx⁺ + ΓḢ_k, P⁻ = ΦP⁺Φᵀ + Q_d over the interval after the sample (``kalman``'s
order), one CasADi step compiled with its C loop (``rollout``), Φ, Γ, Q_d read per step.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from math import factorial

import casadi as ca
import numpy as np
from dynprop.rollout.chunks import ChunkedRollout
from scipy.linalg import solve_discrete_are

from .steps import step_intervals

THETA, THETA_DOT, N_Y = range(3)
_IU = np.triu_indices(3)        # packed upper triangle: 00 01 02 11 12 22
_ZS, _NT = 8.0, 24              # series for |z| ≤ 8, at most 24 terms (8^24/48! ≈ 4e-40)


@dataclass(frozen=True)
class PitchParams:
    """Diagonal inertias (kg m²) and orbit rate (rad/s); ``estimator.model.ModelParams``
    has the same fields and serves as well."""

    Ix_kgm2: float
    Iy_kgm2: float
    Iz_kgm2: float
    omega0_radps: float


@dataclass(frozen=True)
class PitchNoise:
    """q_w: white torque on Eq. 3b, (N m)² s; q_c: random walk of N_y, (N m)²/s."""

    q_w: float
    q_c: float

    def __post_init__(self):
        if not all(np.isfinite(v) and v >= 0 for v in (self.q_w, self.q_c)):
            raise ValueError("q_w and q_c must be finite and non-negative")


def stiffness(params) -> float:
    """k = 3ω0²(I_x − I_z)/I_y (1/s²), θ̈ = −kθ + (N_y − Ḣ)/I_y; negative for GOES-Next."""
    return 3 * params.omega0_radps**2 * (params.Ix_kgm2 - params.Iz_kgm2) / params.Iy_kgm2


def continuous_model(params, noise: PitchNoise):
    """F, B, Q of the continuous model (for references and tests)."""
    Iy = params.Iy_kgm2
    F = np.array([[0, 1, 0], [-stiffness(params), 0, 1 / Iy], [0, 0, 0]], dtype=float)
    return F, np.array([0, -1 / Iy, 0]), np.diag([0, noise.q_w / Iy**2, noise.q_c])


def c_fun(m: int, z) -> np.ndarray:
    """c_m(z) = Σ (−z)^n/(2n + m)!: Horner series for |z| ≤ 8, else closed form."""
    shape = np.shape(z)
    z = np.asarray(z, dtype=float).reshape(-1)
    big = np.abs(z) > _ZS
    zs, out = np.where(big, 0.0, z), np.zeros(z.shape)
    # Terms up to where |z|^n m!/(2n + m)! < 1e-18 (two at GOES-Next's 0.512 s).
    zmax = float(np.abs(zs).max(initial=0.0))
    nt = next((n for n in range(1, _NT) if zmax**n * factorial(m) < 1e-18 * factorial(2 * n + m)),
              _NT)
    for n in range(nt - 1, -1, -1):
        out = 1.0 / factorial(2 * n + m) - zs * out
    if np.any(big):
        zb = z[big]
        r = np.sqrt(np.abs(zb))
        c = [np.where(zb > 0, np.cos(r), np.cosh(r)),
             np.where(zb > 0, np.sin(r), np.sinh(r)) / r]
        for j in range(2, m + 1):
            c.append((1.0 / factorial(j - 2) - c[j - 2]) / zb)
        out[big] = c[m]
    return out.reshape(shape)


@dataclass(frozen=True)
class PitchDiscretization:
    """Φ (..., 3, 3), Γ (..., 3) for Ḣ held over the step, Q_d (..., 3, 3) at ``dt``."""

    dt: np.ndarray
    Phi: np.ndarray
    Gamma: np.ndarray
    Qd: np.ndarray


def discretize(params, noise: PitchNoise, dt) -> PitchDiscretization:
    """The closed forms of the module docstring, vectorised over ``dt`` (s)."""
    t = np.asarray(dt, dtype=float)
    if not np.all(np.isfinite(t) & (t > 0)):
        raise ValueError("step intervals must be positive and finite")
    k, Iy = stiffness(params), params.Iy_kgm2
    z = k * t * t
    C, S, V = c_fun(0, z), t * c_fun(1, z), t * t * c_fun(2, z)
    Phi = np.zeros(t.shape + (3, 3))
    Phi[..., 0, :] = np.stack([C, S, V / Iy], -1)
    Phi[..., 1, :] = np.stack([-k * S, C, S / Iy], -1)
    Phi[..., 2, 2] = 1.0
    Gamma = np.stack([-V / Iy, -S / Iy, np.zeros(t.shape)], -1)
    iSS, iCC = 2 * t**3 * c_fun(3, 4 * z), 0.5 * t * (1 + c_fun(1, 4 * z))
    iVV = t**5 * (8 * c_fun(5, 4 * z) - 2 * c_fun(5, z))
    a, qc = noise.q_w / Iy**2, noise.q_c
    Qd = np.zeros(t.shape + (3, 3))
    Qd[..., 0, 0] = a * iSS + qc * iVV / Iy**2
    Qd[..., 0, 1] = Qd[..., 1, 0] = a * 0.5 * S * S + qc * 0.5 * V * V / Iy**2
    Qd[..., 1, 1] = a * iCC + qc * iSS / Iy**2
    Qd[..., 0, 2] = Qd[..., 2, 0] = qc * t**3 * c_fun(3, z) / Iy
    Qd[..., 1, 2] = Qd[..., 2, 1] = qc * V / Iy
    Qd[..., 2, 2] = qc * t
    return PitchDiscretization(t, Phi, Gamma, Qd)


@dataclass(frozen=True)
class SteadyState:
    """Steady-state a-priori and a-posteriori covariances and the gain, fixed Δt."""

    P_prior: np.ndarray
    P_post: np.ndarray
    gain: np.ndarray


def steady_state(params, noise: PitchNoise, dt: float, R: float) -> SteadyState:
    """From ``scipy.linalg.solve_discrete_are`` (needs q_c > 0: with q_c = 0 the N_y
    mode is a pure constant and its variance only tends to zero)."""
    d = discretize(params, noise, float(dt))
    G = np.array([[1.0, 0.0, 0.0]])
    P = solve_discrete_are(d.Phi.T, G.T, d.Qd, np.array([[float(R)]]))
    P = 0.5 * (P + P.T)
    K = P[:, 0] / (P[0, 0] + R)
    return SteadyState(P, P - np.outer(K, P[0, :]), K)


def pack(P: np.ndarray) -> np.ndarray:
    return P[..., _IU[0], _IU[1]]


def unpack(p: np.ndarray) -> np.ndarray:
    p = np.asarray(p)
    P = np.zeros(p.shape[:-1] + (3, 3))
    P[..., _IU[0], _IU[1]] = p
    P[..., _IU[1], _IU[0]] = p
    return P


def _sym(p) -> ca.SX:
    P = ca.SX(3, 3)
    for n, (i, j) in enumerate(zip(*_IU, strict=True)):
        P[i, j] = P[j, i] = p[n]
    return P


def _psym(P) -> ca.SX:
    return ca.vertcat(*(P[i, j] for i, j in zip(*_IU, strict=True)))


def _step_params():
    """Φ rows 0–1 (6), Γ[0:2] (2), Q_d packed (6): Φ's last row is (0, 0, 1), Γ[2] = 0."""
    prm = ca.SX.sym("prm", 14)
    Phi = ca.vertcat(ca.reshape(prm[:6], 3, 2).T, ca.horzcat(0, 0, 1))
    return prm, Phi, ca.vertcat(prm[6], prm[7], 0), _sym(prm[8:])


def _param_rows(d: PitchDiscretization) -> np.ndarray:
    return np.concatenate([d.Phi[..., :2, :].reshape(d.dt.shape + (6,)),
                           d.Gamma[..., :2], pack(d.Qd)], axis=-1)


@lru_cache(maxsize=1)
def filter_step() -> ca.Function:
    """``(s, z, m, r, u, prm, unused) -> (s_next, aux)``: s = [x⁻, P⁻ packed] at t_k,
    m = 1 with a measurement z (z = 0, m = 0 without: K = 0 leaves x, P bit for bit),
    aux = [x⁺, P⁺ packed, ν, S]."""
    s, z, m, r, u = (ca.SX.sym(n, w) for n, w in (("s", 9), ("z", 1), ("m", 1), ("r", 1),
                                                   ("u", 1)))
    prm, Phi, Gam, Qd = _step_params()
    x, P = s[:3], _sym(s[3:])
    S = P[0, 0] + r
    K = m * P[:, 0] / S
    nu = z - x[0]
    ikg = ca.SX.eye(3) - ca.horzcat(K, ca.SX(3, 2))
    P = _sym(_psym(ikg @ P @ ikg.T + r * (K @ K.T)))          # Joseph form
    x = x + K * nu
    xn, Pn = Phi @ x + Gam * u, Phi @ P @ Phi.T + Qd
    out = ca.cse(ca.vertcat(xn, _psym(Pn), x, _psym(P), nu, S))
    return ca.Function("dynprop_pitch_kf", [s, z, m, r, u, prm, ca.SX.sym("unused")],
                       [out[:9], out[9:]])


@lru_cache(maxsize=1)
def smoother_step() -> ca.Function:
    """Backward RTS step ``(s, x⁺_k, P⁺_k, u_k, prm_k, unused) -> (s_prev, aux)`` with
    s = [x^s_{k+1}, P^s_{k+1} packed]; aux = [x^s_k, P^s_k packed]."""
    s, xk, pk, u = ca.SX.sym("s", 9), ca.SX.sym("x", 3), ca.SX.sym("P", 6), ca.SX.sym("u")
    prm, Phi, Gam, Qd = _step_params()
    Pk = _sym(pk)
    x_pred, P_pred = Phi @ xk + Gam * u, _sym(_psym(Phi @ Pk @ Phi.T + Qd))
    Cg = ca.solve(P_pred, Phi @ Pk).T
    xs = xk + Cg @ (s[:3] - x_pred)
    Ps = Pk + Cg @ (_sym(s[3:]) - P_pred) @ Cg.T
    out = ca.cse(ca.vertcat(xs, _psym(Ps)))
    return ca.Function("dynprop_pitch_rts", [s, xk, pk, u, prm, ca.SX.sym("unused")],
                       [out, out])


@lru_cache(maxsize=4)
def _engine(kind: str, backend: str | None) -> ChunkedRollout:
    return ChunkedRollout({"filter": filter_step, "smoother": smoother_step}[kind](),
                          4096, 256, backend)


@dataclass(frozen=True)
class PitchResult:
    """A-posteriori x (N, 3) = [θ rad, θ̇ rad/s, N_y N m] and packed P (N, 6) at each
    sample; innovations ν, their variances S and NIS ν²/S (NaN where no measurement);
    the prior after the last step; the per-step parameter rows (for the smoother)."""

    x: np.ndarray
    P_packed: np.ndarray
    innovations: np.ndarray
    innovation_var: np.ndarray
    nis: np.ndarray
    x_next: np.ndarray
    P_next: np.ndarray
    rows: np.ndarray
    u: np.ndarray
    backend: str

    @property
    def P(self) -> np.ndarray:
        return unpack(self.P_packed)

    @property
    def sigma(self) -> np.ndarray:
        return np.sqrt(self.P_packed[:, [0, 3, 5]])


def _rows(params, noise, dt_or_times, n: int) -> np.ndarray:
    """Per-step parameter rows (n, 14): a stride-0 view for one fixed Δt, else each
    distinct interval after sample k (``steps.step_intervals``) evaluated once."""
    if np.ndim(dt_or_times) == 0:
        return np.broadcast_to(_param_rows(discretize(params, noise, float(dt_or_times))),
                               (n, 14))
    t = np.asarray(dt_or_times, dtype=float)
    if t.shape != (n,):
        raise ValueError(f"times must be ({n},), one per sample")
    distinct, index = np.unique(step_intervals(t), return_inverse=True)
    return _param_rows(discretize(params, noise, distinct))[index]


def pitch_filter(z, u, dt_or_times, params, noise: PitchNoise, x0, P0, R,
                 backend: str | None = None) -> PitchResult:
    """Kalman filter over a record: Earth-sensor pitch ``z`` (rad, NaN where missing),
    Ḣ ``u`` (N m, rate of the signed H; scalar or (N,)), a fixed Δt (s) or the sample
    times (N,), the prior x0, P0 at the first sample and the pitch variance R (rad²,
    scalar or (N,))."""
    z = np.asarray(z, dtype=float)
    n = len(z)
    u = np.broadcast_to(np.asarray(u, dtype=float), (n,))
    r = np.broadcast_to(np.asarray(R, dtype=float), (n,))
    present = np.isfinite(z)
    if not np.all(np.isfinite(u)) or np.any(~(r[present] > 0) | ~np.isfinite(r[present])):
        raise ValueError("Ḣ must be finite, R positive and finite where z is present")
    x0, P0 = np.asarray(x0, dtype=float), np.asarray(P0, dtype=float)
    if x0.shape != (3,) or P0.shape != (3, 3):
        raise ValueError("x0 must have 3 elements and P0 be 3×3")
    rows = _rows(params, noise, dt_or_times, n)
    engine = _engine("filter", backend)
    s0 = np.concatenate([x0, pack(0.5 * (P0 + P0.T))])
    inputs = [np.where(present, z, 0.0), present.astype(float), np.where(present, r, 1.0),
              u, rows]
    last, aux = engine.run_final(s0, inputs, np.zeros(1))
    nu, S = aux[:, 9], aux[:, 10]
    nu[~present] = np.nan
    S[~present] = np.nan
    return PitchResult(aux[:, :3], aux[:, 3:9], nu, S, nu * nu / S, last[:3],
                       unpack(last[3:]), rows, u, engine.backend)


def rts_smoother(res: PitchResult, backend: str | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Rauch–Tung–Striebel smoothed x (N, 3) and packed P (N, 6) of a filter run."""
    n = len(res.x)
    if n < 2:
        return res.x.copy(), res.P_packed.copy()
    rev = slice(n - 2, None, -1)
    engine = _engine("smoother", backend)
    s0 = np.concatenate([res.x[-1], res.P_packed[-1]])
    _, aux = engine.run_final(s0, [res.x[rev], res.P_packed[rev], res.u[rev], res.rows[rev]],
                              np.zeros(1))
    out = np.vstack([aux[::-1], s0[None, :]])
    return out[:, :3], out[:, 3:]
