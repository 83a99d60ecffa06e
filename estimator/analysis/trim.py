"""The solar imbalance κ from the filter's torque states, and the trim-tab move.

The paper's torque model (Eqs. 9, 18) is a constant N̄_c plus a term N̄_p that
turns at the orbit rate ω0.  Over a batch the filter's torque states at its end,
θ = [N_px, N_pz, N_cx, N_cz] with covariance P_θ, hold what the batch says about
the external torque.  The solar torque of a unit κ over the same batch (given by
the caller from the ephemeris, the shadow and the lever axis) projects onto that
model as a state vector v; κ and the unknown constants c (residual dipole,
gravity-gradient imperfections: constant in the body of an Earth-pointing GEO
satellite) then follow from θ = κ v + [0, 0, c_x, c_z] + e, e ~ N(0, P_θ), by
generalised least squares.  Its one spare degree of freedom is the periodic
torque *out of phase with the Sun*: a χ²(1) that flags an orbit-rate torque the
Sun cannot explain (a magnetic one mistaken for solar, for example).

The recommendation follows the imbalance law of ``sim.environment.SolarTorque``
(κ = untrimmed − effectiveness · tab): tab_new = tab + κ̂ / effectiveness.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

SIGNIFICANCE = 3.0   # a κ̂ within this many σ of zero asks for no move


def torque_basis(t_s: np.ndarray, t_end_s: float, omega0_radps: float) -> np.ndarray:
    """(N, 2, 4): the roll and yaw torque at each t of the torque states θ at
    ``t_end_s``.  N_p turns as the filter propagates it (Eq. 18:
    Ṅ_px = ω0 N_pz, Ṅ_pz = −ω0 N_px)."""
    phase = omega0_radps * (np.asarray(t_s, dtype=float) - t_end_s)
    c, s = np.cos(phase), np.sin(phase)
    B = np.zeros((len(phase), 2, 4))
    B[:, 0, 0], B[:, 0, 1], B[:, 0, 2] = c, s, 1.0
    B[:, 1, 0], B[:, 1, 1], B[:, 1, 3] = -s, c, 1.0
    return B


def equivalent_states(t_s: np.ndarray, torque_xz: np.ndarray, t_end_s: float,
                      omega0_radps: float) -> np.ndarray:
    """The torque states at ``t_end_s`` whose torque (``torque_basis``) fits the roll
    and yaw torques ``torque_xz`` (N, 2) best over the samples ``t_s`` (least squares,
    equal weights).  A torque of the model's own form maps to its states exactly."""
    B = torque_basis(t_s, t_end_s, omega0_radps)
    y = np.asarray(torque_xz, dtype=float)
    # Normal equations from sums (4×4), not a 2N×4 least-squares problem.
    G = np.einsum("nki,nkj->ij", B, B)
    rhs = np.einsum("nki,nk->i", B, y)
    return np.linalg.solve(G, rhs)


@dataclass(frozen=True)
class KappaFit:
    """κ̂ (N m at 1 AU) and its 1σ; the fitted constant roll and yaw torques (N m)
    with their 1σ; the χ²(1) of the periodic torque out of phase with the Sun and
    that torque's amplitude (N m)."""

    kappa_Nm: float
    sigma_Nm: float
    constants_Nm: tuple[float, float]
    constants_sigma_Nm: tuple[float, float]
    out_of_phase_chi2: float
    out_of_phase_Nm: float

    @property
    def significant(self) -> bool:
        return abs(self.kappa_Nm) > SIGNIFICANCE * self.sigma_Nm


def fit_kappa(theta: np.ndarray, P_theta: np.ndarray, v: np.ndarray) -> KappaFit:
    """Generalised least squares of θ = κ v + [0, 0, c_x, c_z] + e, e ~ N(0, P_θ)
    (module doc).  ``v`` is the torque-state vector of a unit κ over the batch."""
    theta, v = np.asarray(theta, dtype=float), np.asarray(v, dtype=float)
    P = np.asarray(P_theta, dtype=float)
    if np.hypot(v[0], v[1]) == 0.0:
        raise ValueError("the solar torque has no periodic part over this batch")
    X = np.column_stack([v, [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]])
    W = np.linalg.inv(0.5 * (P + P.T))
    cov = np.linalg.inv(X.T @ W @ X)
    beta = cov @ (X.T @ W @ theta)
    r = theta - X @ beta
    return KappaFit(float(beta[0]), float(np.sqrt(cov[0, 0])),
                    (float(beta[1]), float(beta[2])),
                    (float(np.sqrt(cov[1, 1])), float(np.sqrt(cov[2, 2]))),
                    float(r @ W @ r), float(np.hypot(r[0], r[1])))


@dataclass(frozen=True)
class Recommendation:
    """The tab move for a fitted κ (degrees at the I/O boundary, as the ground
    commands it).  ``move`` is False when κ̂ is within ``SIGNIFICANCE`` σ of zero:
    then the tab stays where it is."""

    move: bool
    trim_tab_deg: float
    trim_tab_deg_new: float
    sigma_deg: float
    residual_after_Nm: float    # 1σ of the κ left after the move


def recommend(fit: KappaFit, trim_tab_deg: float, effectiveness_Nm_per_deg: float
              ) -> Recommendation:
    """tab_new = tab + κ̂ / effectiveness, σ = σ_κ / effectiveness (the law of
    ``sim.environment.SolarTorque``); the κ left after it is κ − κ̂, of 1σ σ_κ."""
    if not (np.isfinite(effectiveness_Nm_per_deg) and effectiveness_Nm_per_deg != 0):
        raise ValueError("the tab effectiveness must be finite and non-zero")
    move = fit.significant
    new = trim_tab_deg + fit.kappa_Nm / effectiveness_Nm_per_deg if move else trim_tab_deg
    return Recommendation(move, trim_tab_deg, float(new),
                          float(fit.sigma_Nm / abs(effectiveness_Nm_per_deg)),
                          fit.sigma_Nm if move else abs(fit.kappa_Nm))
