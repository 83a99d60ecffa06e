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

The filter on this model is ``filter``'s.
"""

from __future__ import annotations

from dataclasses import dataclass
from math import factorial

import numpy as np
from scipy.linalg import solve_discrete_are

THETA, THETA_DOT, N_Y = range(3)
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
