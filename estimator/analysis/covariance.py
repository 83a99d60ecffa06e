"""Steady-state yaw accuracy (Section 6, Eqs. 39–56), from the measurement variances
of ``linear.noise``.

Four routes to σ_yaw, from the paper's closed form to the discrete filter:

1. Eq. 54 (p11, p22, p12 with α of Eq. 54d) and Eq. 55 (p22 ≈ q/(ω0 H²)) for the
   nutation-averaged state x̃ = [r + h/H, y] (Eq. 40);
2. the continuous Riccati equation 49 with F̃ (Eq. 41b), Q̃ = (q/H²) I₂ (Eq. 43;
   optionally + q_w/2, as the text after Eq. 43 says), G̃ = [1 0] and
   R = R_k Δt (Eq. 51), solved by ``scipy.linalg.solve_continuous_are``;
3. the discrete filter on the 5-state model [r, ṙ/ω_n, y, ẏ/ω_n, h] at Δt with
   roll and h measured every step: ``scipy.linalg.solve_discrete_are`` on the
   Van Loan discretisation (``scipy.linalg.expm``);
4. the full 9-state filter with a daily yaw gap (``periodic_gap_covariance``).

Eqs. 41b, 53 and 54 hold as printed with the signed H: x̃ obeys Eq. 41 for either
sign of H (Eq. 39 divides Eq. 7 by ω_n = H/I), and the stabilising root of
Eq. 53b, p12 = ω0 R (α − 1) > 0, is the CARE solution.  In the limit
|ω_n| → ∞ (H, R fixed) the 5-state filter's P̃ tends to Eq. 54's p22 and p12,
but its p11 to p11 + √((q_x + q_z) R)/|H|: the nutation-band roll error, which
averaging drops, is as large as p11 itself.  At the GOES-Next numbers the
filter's bandwidth on the nutation states, of order √(q/(H² R)) ≈ 0.045 rad/s,
is not small against |ω_n| = 0.036 rad/s, so Eq. 54's p11 and p12 do not
describe the filter (p12 even changes sign); p22, set at orbit rate, agrees to
0.2 %.

The discrete recursions run in scaled coordinates z = S⁻¹x, S = diag(1, 1, 1, 1,
|H|, |H|ω0 …): h/|H| is the roll it offsets, N/(|H|ω0) the yaw a constant
torque balances, so every state is an angle and P is well conditioned.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import expm, solve_continuous_are, solve_discrete_are

from ..linear.model import (
    H_WHEEL,
    ModelParams,
    ProcessNoise,
    R,
    Y,
    dynamics_matrix,
    noise_density,
)
from ..linear.noise import (
    PAPER_SENSORS,
    SensorSpecs,
    continuous_R,
    h_variance,
    ripple_noise_density,
    roll_variance,
    yaw_variance,
)

PAPER_SIGMA_YAW_DEG = 0.040          # Eq. 56
PAPER_SIGMA_YAW_RAD = 6.9e-4         # Eq. 56

# --- the nutation-averaged 2-state model (Eqs. 40–55) ---------------------------------

def alpha(q, H_Nms: float, omega0: float, R_c: float):
    """α of Eq. 54d; broadcasts over q."""
    return np.sqrt(1.0 + np.asarray(q, dtype=float) / (omega0**2 * H_Nms**2 * R_c))


def closed_form_steady_state(q, H_Nms: float, omega0: float, R_c: float):
    """(p11, p22, p12) of Eq. 54; broadcasts over q."""
    a = alpha(q, H_Nms, omega0, R_c)
    root = np.sqrt((a + 3.0) * (a - 1.0))
    return omega0 * R_c * root, omega0 * R_c * a * root, omega0 * R_c * (a - 1.0)


def approx_yaw_variance(q, H_Nms: float, omega0: float):
    """p22 ≈ q/(ω0 H²) of Eq. 55."""
    return np.asarray(q, dtype=float) / (omega0 * H_Nms**2)


def riccati_rates(P, q: float, H_Nms: float, omega0: float, R_c: float):
    """(ṗ11, ṗ22, ṗ12) of Eqs. 53a–c."""
    p11, p22, p12, qh = P[0, 0], P[1, 1], P[0, 1], q / H_Nms**2
    return (2 * omega0 * p12 + qh - p11**2 / R_c, -2 * omega0 * p12 + qh - p12**2 / R_c,
            omega0 * (p22 - p11) - p11 * p12 / R_c)


def care_steady_state(omega0: float, H_Nms: float, R_c: float, q_x: float, q_z: float,
                      q_w: float = 0.0, sign: float = 1.0) -> np.ndarray:
    """Steady state of Eq. 49 (P̃ of Eq. 52) by ``solve_continuous_are``.

    F̃ = sign · ω0 [[0, 1], [−1, 0]] (Eq. 41b for sign = +1; −1 only to test it),
    Q̃ = diag(q_z, q_x)/H² (Eq. 43, W̃ = [w_z, −w_x]/H), plus q_w/2 on both if given.
    """
    F = sign * omega0 * np.array([[0.0, 1.0], [-1.0, 0.0]])
    Q = np.diag([q_z + q_w / 2, q_x + q_w / 2]) / H_Nms**2
    return solve_continuous_are(F.T, np.array([[1.0], [0.0]]), Q, np.array([[R_c]]))


# --- discrete filters -----------------------------------------------------------------

def van_loan(F: np.ndarray, Q: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Φ = e^{FΔt} and Q_d = ∫ Φ(s) Q Φ(s)ᵀ ds (Van Loan, one ``expm``)."""
    n = F.shape[0]
    M = np.zeros((2 * n, 2 * n))
    M[:n, :n], M[:n, n:], M[n:, n:] = -F, Q, F.T
    E = expm(M * dt)
    Phi = E[n:, n:].T
    return Phi, _sym(Phi @ E[:n, n:])


def _sym(X: np.ndarray) -> np.ndarray:
    return (X + X.T) / 2


def _discrete_model(p: ModelParams, noise: ProcessNoise, dt: float, n: int):
    """Scaled Φ, Q_d of the first n states, and the scale S."""
    H = abs(p.H_Nms)
    s = np.array([1.0, 1.0, 1.0, 1.0, H] + [H * p.omega0_radps] * 4)[:n]
    F = dynamics_matrix(p)[:n, :n] * s[None, :] / s[:, None]
    Q = noise_density(p, noise)[:n, :n] / np.outer(s, s)
    return (*van_loan(F, Q, dt), s)


def _rows(n: int, s: np.ndarray, states) -> np.ndarray:
    """Unit measurement rows of ``states`` in the scaled coordinates."""
    return np.eye(n)[list(states)] * s[None, :]


def reduced(P: np.ndarray, p: ModelParams) -> np.ndarray:
    """P̃ of x̃ = [r + h/H, y] (Eq. 40) from a full covariance."""
    T = np.zeros((2, P.shape[0]))
    T[0, R], T[0, H_WHEEL], T[1, Y] = 1.0, 1.0 / p.H_Nms, 1.0
    return T @ P @ T.T


def roll_tach_steady_state(p: ModelParams, noise: ProcessNoise,
                           sensors: SensorSpecs = PAPER_SENSORS, method: str = "dare") -> dict:
    """Discrete steady state of the 5-state model with roll and h every Δt.

    ``method="dare"``: ``solve_discrete_are``; ``"doubling"``: the limit of the
    covariance recursion itself (``_fixed_point``), which also works where the
    DARE's symplectic pencil has eigenvalues on the unit circle (q_w = 0 leaves h
    without process noise).  Returns the a-priori and a-posteriori 5×5
    covariances (original units) and σ_yaw of each; q_px … q_cz play no part
    (the torque states are dropped, as in Section 6).
    """
    Phi, Qd, s = _discrete_model(p, noise, sensors.dt_s, 5)
    Hm = _rows(5, s, (R, H_WHEEL))
    Rm = np.diag([roll_variance(sensors), h_variance(sensors)])
    if method == "dare":
        Pz = solve_discrete_are(Phi.T, Hm.T, Qd, Rm)
    elif method == "doubling":
        Pz = _fixed_point((Phi, Hm.T @ np.linalg.solve(Rm, Hm), Qd), np.eye(5) * 1e-2)[0]
    else:
        raise ValueError(f"unknown method {method!r}")
    K = np.linalg.solve(Hm @ Pz @ Hm.T + Rm, Hm @ Pz).T
    Pz_post = Pz - K @ Hm @ Pz
    prior, post = (np.outer(s, s) * _sym(X) for X in (Pz, Pz_post))
    return {"P_prior": prior, "P_post": post, "sigma_yaw_prior_rad": float(np.sqrt(prior[Y, Y])),
            "sigma_yaw_post_rad": float(np.sqrt(post[Y, Y]))}


# The Riccati step "update with information G = Hᵀ R⁻¹ H, then propagate" maps the
# a-priori P to Q + A P (I + G P)⁻¹ Aᵀ (A = Φ, Q = Q_d).  N steps compose to a map
# of the same form, so 2^k steps cost k compositions (the doubling algorithm):
# a day of 0.512 s steps is exact, with no batching of measurements.

def _compose(m1, m2):
    """The map m2 ∘ m1 (m1 first), each m = (A, G, Q)."""
    A1, G1, Q1 = m1
    A2, G2, Q2 = m2
    W = np.eye(A1.shape[0]) + Q1 @ G2
    WA1 = np.linalg.solve(W, A1)
    return (A2 @ WA1, _sym(G1 + A1.T @ G2 @ WA1),
            _sym(Q2 + A2 @ np.linalg.solve(W, Q1) @ A2.T))


def _power(m, steps: int):
    """The map of ``steps`` >= 1 identical steps (binary powering)."""
    out, base = None, m
    while steps:
        if steps & 1:
            out = base if out is None else _compose(out, base)
        steps >>= 1
        if steps:
            base = _compose(base, base)
    return out


def _apply(m, P: np.ndarray) -> np.ndarray:
    A, G, Q = m
    return _sym(Q + A @ P @ np.linalg.solve(np.eye(P.shape[0]) + G @ P, A.T))


def _fixed_point(m, P0: np.ndarray, tol: float = 1e-12, max_doublings: int = 64):
    """(lim P_k, k) of the recursion P_k = m(P_{k-1}): P_k = m^k(P0) for k = 2^j, until
    P_2k and P_k agree to ``tol`` (relative, max-norm)."""
    P, k = _apply(m, P0), 1
    for _ in range(max_doublings):
        m = _compose(m, m)
        P_next, k = _apply(m, P0), 2 * k
        if np.abs(P_next - P).max() <= tol * np.abs(P_next).max():
            return P_next, k
        P = P_next
    raise RuntimeError("the covariance recursion did not settle")


@dataclass(frozen=True)
class GapResult:
    """Periodic steady state of the 9-state filter with a daily yaw gap.

    t = 0 is the end of the gap (the first yaw measurement); yaw is measured on
    [0, period − gap), roll and h throughout.  Covariances are a priori.
    """

    times_s: np.ndarray
    sigma_yaw_rad: np.ndarray
    P_gap_end: np.ndarray
    days: int


def periodic_gap_covariance(p: ModelParams, noise: ProcessNoise,
                            sensors: SensorSpecs = PAPER_SENSORS, *, gap_s: float = 28800.0,
                            period_s: float = 86400.0, sample_s: float = 600.0,
                            tol: float = 1e-10) -> GapResult:
    """σ_yaw over a day of the 9-state filter: roll and h every Δt, yaw 16 h of 24 h.

    Without yaw, (y, N_cz) ∝ (−1/(ω0 H), 1) is unobservable (``observability``):
    there is no steady state, only a periodic one.  The exact covariance
    recursion (update every Δt, propagate with the Van Loan Φ, Q_d of Eq. 32)
    runs from a broad prior for 2, 4, 8, … days until the gap-end covariance
    after 2k days agrees with that after k days to ``tol`` (relative, max-norm);
    one more day gives the profile, sampled about every ``sample_s``.  Steps and
    days are composed by doubling (above ``_compose``): milliseconds, and it
    settles even when the decay is only algebraic (q_cz = 0).
    """
    dt = sensors.dt_s
    n_day, n_gap = round(period_s / dt), round(gap_s / dt)
    if not 0 <= n_gap < n_day:
        raise ValueError("need 0 <= gap < period")
    Phi, Qd, s = _discrete_model(p, noise, dt, 9)
    Rs = {R: roll_variance(sensors), Y: yaw_variance(sensors), H_WHEEL: h_variance(sensors)}
    maps, cache = [], {}
    for with_yaw, steps in [(True, n_day - n_gap), (False, n_gap)][:2 if n_gap else 1]:
        states = (R, Y, H_WHEEL) if with_yaw else (R, H_WHEEL)
        Hm = _rows(9, s, states)
        G = Hm.T @ np.diag([1.0 / Rs[i] for i in states]) @ Hm
        for size in np.diff(np.linspace(0, steps, max(1, round(steps * dt / sample_s)) + 1)
                            .round().astype(int)):
            key = (with_yaw, int(size))
            if key not in cache:
                cache[key] = _power((Phi, G, Qd), int(size))
            maps.append((int(size), cache[key]))
    day = maps[0][1]
    for _, m in maps[1:]:
        day = _compose(day, m)
    P, days = _fixed_point(day, np.eye(9) * 1e-2, tol)
    times, sig, X, k = [0.0], [np.sqrt(P[Y, Y])], P, 0
    for size, m in maps:
        X, k = _apply(m, X), k + size
        times.append(k * dt)
        sig.append(np.sqrt(X[Y, Y]))
    return GapResult(np.array(times), np.array(sig), np.outer(s, s) * P, days)


def sigma_yaw_sweep(q_values, p: ModelParams, sensors: SensorSpecs = PAPER_SENSORS,
                    q_w: float | None = None) -> dict:
    """σ_yaw (rad) against q = q_x = q_z: Eq. 55, Eq. 54, and the discrete filter (a priori).

    q_w defaults to ``ripple_noise_density()``; the discrete filter falls back to
    the doubling recursion where the DARE solver gives up.
    """
    q_w = ripple_noise_density() if q_w is None else q_w

    def discrete(v):
        noise = ProcessNoise(v, v, q_w)
        try:
            return roll_tach_steady_state(p, noise, sensors)["sigma_yaw_prior_rad"]
        except np.linalg.LinAlgError:
            return roll_tach_steady_state(p, noise, sensors, "doubling")["sigma_yaw_prior_rad"]

    q = np.atleast_1d(np.asarray(q_values, dtype=float))
    H, w0 = p.H_Nms, p.omega0_radps
    return {"q": q, "eq55": np.sqrt(approx_yaw_variance(q, H, w0)),
            "eq54": np.sqrt(closed_form_steady_state(q, H, w0, continuous_R(H, sensors))[1]),
            "discrete": np.array([discrete(v) for v in q])}
