"""The paper's linear roll/yaw model (Section 3, Eqs. 10–12 and 33–35).

State (Eq. 10), with index constants below::

    x = [r, ṙ/ω_n, y, ẏ/ω_n, h, N_px, N_pz, N_cx, N_cz]

H is *signed*: it is the body-y wheel momentum, negative for GOES-Next (Eq. 1),
so ω_n = H/I is negative too (the paper prints |ω_n|; docs/paper-errata.md
entry 1).  The estimator never imports ``sim``: every number comes in through
``ModelParams`` and ``ProcessNoise``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from dynprop.eom.linear import eq5_inertia

R, RDOT, Y, YDOT, H_WHEEL, NPX, NPZ, NCX, NCZ = range(9)
STATE_NAMES = ("roll", "roll_rate_scaled", "yaw", "yaw_rate_scaled", "h", "N_px", "N_pz",
               "N_cx", "N_cz")
N_STATES = 9


@dataclass(frozen=True)
class ModelParams:
    """Inertias (kg m²), signed pitch wheel momentum H (N m s), orbit rate ω0 (rad/s).

    The model uses I = √(I_x I_z) (Eq. 5) and ω_n = H/I (Eq. 8); I_y enters only
    through the omitted terms of Eq. 6.
    """

    Ix_kgm2: float
    Iy_kgm2: float
    Iz_kgm2: float
    H_Nms: float
    omega0_radps: float

    def __post_init__(self) -> None:
        for name in ("Ix_kgm2", "Iy_kgm2", "Iz_kgm2", "omega0_radps"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be positive and finite")
        if not (np.isfinite(self.H_Nms) and self.H_Nms != 0):
            raise ValueError("H_Nms must be finite and non-zero")
        if abs(self.H_Nms / self.I_kgm2) <= 2 * self.omega0_radps:
            raise ValueError("the model needs |ω_n| = |H|/I well above ω0 (momentum bias)")

    @property
    def I_kgm2(self) -> float:
        """I = √(I_x I_z) (Eq. 5)."""
        return eq5_inertia(self.Ix_kgm2, self.Iz_kgm2)

    @property
    def omega_n_radps(self) -> float:
        """Signed nutation frequency ω_n = H/I (Eq. 8)."""
        return self.H_Nms / self.I_kgm2


@dataclass(frozen=True)
class ProcessNoise:
    """White-noise intensities of Eq. 35 (E[w(t)w(t')] = q δ(t−t')).

    q_x, q_z, q_w in (N m)² s; q_px … q_cz, which drive the torque states as
    random walks, in (N m)²/s.
    """

    q_x: float
    q_z: float
    q_w: float
    q_px: float = 0.0
    q_pz: float = 0.0
    q_cx: float = 0.0
    q_cz: float = 0.0

    def __post_init__(self) -> None:
        for name, v in self.__dict__.items():
            if not (np.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be finite and non-negative")


def pitch_bias_Nms(wheel_inertia_kgm2: float, speeds_radps, cant_rad: float) -> float:
    """H = −I_w (ω1 + ω2) cos(cant) (Eq. 1)."""
    return float(-wheel_inertia_kgm2 * np.sum(speeds_radps) * np.cos(cant_rad))


def yaw_momentum_Nms(wheel_inertia_kgm2: float, speed1_radps, speed2_radps, cant_rad: float):
    """h = I_w (ω1 − ω2) sin(cant) (Eq. 2); works on arrays."""
    return wheel_inertia_kgm2 * (np.asarray(speed1_radps) - np.asarray(speed2_radps)) \
        * np.sin(cant_rad)


def roll_yaw_blocks(w0: float, wn: float, H: float) -> tuple[np.ndarray, np.ndarray]:
    """A (4×4, Eq. 11c) and B (4×5, Eq. 11d) from ω0, the signed ω_n and H."""
    A = np.array([[0.0, wn, 0.0, 0.0],
                  [w0, 0.0, 0.0, wn + w0],
                  [0.0, 0.0, 0.0, wn],
                  [0.0, -(wn + w0), w0, 0.0]])
    B = np.array([[0.0, 0.0, 0.0, 0.0, 0.0],
                  [w0, 1.0, 0.0, 1.0, 0.0],
                  [0.0, 0.0, 0.0, 0.0, 0.0],
                  [0.0, 0.0, 1.0, 0.0, 1.0]]) / H
    return A, B


def blocks(p: ModelParams) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A (4×4, Eq. 11c), B (4×5, Eq. 11d) and C (5×5, Eq. 11e)."""
    w0 = p.omega0_radps
    A, B = roll_yaw_blocks(w0, p.omega_n_radps, p.H_Nms)
    C = np.zeros((5, 5))
    C[1, 2] = w0
    C[2, 1] = -w0
    return A, B, C


def dynamics_matrix(p: ModelParams) -> np.ndarray:
    """F of Eq. 11b: [[A, B], [0, C]]."""
    A, B, C = blocks(p)
    F = np.zeros((N_STATES, N_STATES))
    F[:4, :4] = A
    F[:4, 4:] = B
    F[4:, 4:] = C
    return F


def input_vector(p: ModelParams, Nx_Nm=0.0, Nz_Nm=0.0, Nw_Nm=0.0) -> np.ndarray:
    """ū of Eq. 12a from the modelled torques N_x*, N_z*, N_w*; broadcasts to (..., 9)."""
    Nx, Nz, Nw = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (Nx_Nm, Nz_Nm,
                                                                            Nw_Nm)))
    u = np.zeros(Nx.shape + (N_STATES,))
    u[..., RDOT] = Nx / p.H_Nms
    u[..., YDOT] = (Nz - Nw) / p.H_Nms
    u[..., H_WHEEL] = Nw
    return u


def torque_input_matrix(H_Nms: float) -> np.ndarray:
    """∂ū/∂(N_x*, N_z*, N_w*) of Eq. 12a, (9, 3): the continuous input matrix of the
    modelled torques."""
    G = np.zeros((N_STATES, 3))
    G[RDOT, 0] = 1 / H_Nms
    G[YDOT, 1] = 1 / H_Nms
    G[YDOT, 2] = -1 / H_Nms
    G[H_WHEEL, 2] = 1.0
    return G


def input_torques(p: ModelParams, u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(N_x*, N_z*, N_w*) back from inputs ū (..., 9) of Eq. 12a."""
    Nw = u[..., H_WHEEL]
    return u[..., RDOT] * p.H_Nms, u[..., YDOT] * p.H_Nms + Nw, Nw


def project_torques(t_s, nx, nz, w0):
    """Least-squares fit of torques to the model's form, N_x = N_cx + c0 a + s0 b,
    N_z = N_cz − s0 a + c0 b (Eqs. 9, 18), c0 = cos ω0t, s0 = sin ω0t.  Returns the
    torque-state histories (N, 4) [N_px, N_pz, N_cx, N_cz] and the residuals."""
    c, s = np.cos(w0 * t_s), np.sin(w0 * t_s)
    one = np.ones_like(c)
    # Unknowns (a, b, N_cx, N_cz).  The normal equations need only a few sums over
    # the run (no 2N×4 matrix): with c² + s² = 1 they are well conditioned once the
    # run covers a fair part of an orbit; shorter runs go to lstsq (minimum norm).
    n, sc, ss = len(c), c.sum(), s.sum()
    G = np.array([[n, 0.0, sc, -ss], [0.0, n, ss, sc], [sc, ss, n, 0.0], [-ss, sc, 0.0, n]])
    # np.sum, not BLAS dot: a threaded BLAS sums in an order that depends on the
    # thread count, and a Monte Carlo case must give the same bits in any process.
    rhs = np.array([np.sum(c * nx - s * nz), np.sum(s * nx + c * nz), nx.sum(), nz.sum()])
    if n and np.linalg.cond(G) < 1e4:
        a, b, ncx, ncz = np.linalg.solve(G, rhs)
    else:
        zero = np.zeros_like(c)
        A = np.vstack([np.column_stack([c, s, one, zero]), np.column_stack([-s, c, zero, one])])
        a, b, ncx, ncz = np.linalg.lstsq(A, np.concatenate([nx, nz]), rcond=None)[0]
    states = np.column_stack([c * a + s * b, -s * a + c * b, ncx * one, ncz * one])
    return states, nx - states[:, 0] - ncx, nz - states[:, 1] - ncz


def noise_density(p: ModelParams, q: ProcessNoise) -> np.ndarray:
    """Q of Eq. 34 for the noise w̄ of Eq. 12b."""
    H = p.H_Nms
    Q = np.zeros((N_STATES, N_STATES))
    Q[RDOT, RDOT] = q.q_x / H**2
    Q[YDOT, YDOT] = (q.q_z + q.q_w) / H**2
    Q[YDOT, H_WHEEL] = Q[H_WHEEL, YDOT] = -q.q_w / H
    Q[H_WHEEL, H_WHEEL] = q.q_w
    Q[NPX, NPX], Q[NPZ, NPZ], Q[NCX, NCX], Q[NCZ, NCZ] = q.q_px, q.q_pz, q.q_cx, q.q_cz
    return Q


def measurement_rows() -> dict[str, np.ndarray]:
    """G rows (Eq. 26) of the three measurement kinds: roll, yaw, and h."""
    eye = np.eye(N_STATES)
    return {"roll": eye[R], "yaw": eye[Y], "h": eye[H_WHEEL]}
