"""The paper's linearised roll/yaw/pitch equations (Eqs. 3a–3c) and their
approximations (Eqs. 5–7), as named coefficients and as Jacobian matrices.

Each coefficient is named by its place in Eqs. 3a–3c (row: the angular
acceleration; column: the state or input) and sits in the Jacobian layout of
``sim.linearize``, which differentiates the truth's own gyrostat: state columns
ψ φ θ ψ̇ φ̇ θ̇ h, input columns N_x N_y N_z Ḣ ḣ, rows ψ̈ φ̈ θ̈ (SI).  H is the signed
body-y wheel momentum (docs/paper-errata.md entry 1).  Eq. 11c, the roll/yaw block
in the filter's model units, is ``estimator.model.roll_yaw_blocks``.
"""

from __future__ import annotations

import numpy as np

# Jacobian columns: state ψ φ θ ψ̇ φ̇ θ̇ h, inputs N_x N_y N_z Ḣ ḣ; rows ψ̈ φ̈ θ̈.
PSI, PHI, THETA, PSI_D, PHI_D, THETA_D, H_COL = range(7)
NX, NY, NZ, HDOT_BIG, HDOT = range(5)
YAW_ROW, ROLL_ROW, PITCH_ROW = range(3)

# Where each named coefficient sits in the Jacobian: (row, "x" or "u", column).
COEFFICIENT_INDEX = {
    "roll/roll": (ROLL_ROW, "x", PHI), "roll/yaw_rate": (ROLL_ROW, "x", PSI_D),
    "roll/h": (ROLL_ROW, "x", H_COL), "roll/N_x": (ROLL_ROW, "u", NX),
    "yaw/yaw": (YAW_ROW, "x", PSI), "yaw/roll_rate": (YAW_ROW, "x", PHI_D),
    "yaw/N_z": (YAW_ROW, "u", NZ), "yaw/N_w": (YAW_ROW, "u", HDOT),
    "pitch/pitch": (PITCH_ROW, "x", THETA), "pitch/N_y": (PITCH_ROW, "u", NY),
    "pitch/H_dot": (PITCH_ROW, "u", HDOT_BIG),
}


def eq5_inertia(Ix: float, Iz: float) -> float:
    """The model's single transverse inertia, I = √(I_x I_z) (Eq. 5)."""
    return float(np.sqrt(Ix * Iz))


def eq3_coefficients(Ix, Iy, Iz, H, w0) -> dict[str, float]:
    """Eqs. 3a–3c solved for the accelerations, by coefficient name:
    Ix r̈ = ω0[H − 4(Iy − Iz)ω0] r + [H + (Ix − Iy + Iz)ω0] ẏ + Nx + ω0 h,
    Iz ÿ = ω0[H − (Iy − Ix)ω0] y − [H + (Ix − Iy + Iz)ω0] ṙ + Nz − Nw,
    Iy p̈ = −3ω0²(Ix − Iz) p + Ny − Ḣ."""
    g = H + (Ix - Iy + Iz) * w0
    return {
        "roll/roll": w0 * (H - 4 * (Iy - Iz) * w0) / Ix,
        "roll/yaw_rate": g / Ix,
        "roll/h": w0 / Ix,
        "roll/N_x": 1 / Ix,
        "yaw/yaw": w0 * (H - (Iy - Ix) * w0) / Iz,
        "yaw/roll_rate": -g / Iz,
        "yaw/N_z": 1 / Iz,
        "yaw/N_w": -1 / Iz,
        "pitch/pitch": -3 * w0**2 * (Ix - Iz) / Iy,
        "pitch/N_y": 1 / Iy,
        "pitch/H_dot": -1 / Iy,
    }


def eq7_coefficients(Ix, Iy, Iz, H, w0) -> dict[str, float]:
    """Eqs. 7a–7b (= Eq. 11c in model units): I_x = I_z = I = √(I_x I_z) (Eq. 5),
    ω0(I_y − I) dropped (Eq. 6).  Pitch is not part of the paper's model; its
    Eq. 3b entries are carried over."""
    I_ = eq5_inertia(Ix, Iz)
    wn = H / I_
    out = eq3_coefficients(Ix, Iy, Iz, H, w0)
    out.update({"roll/roll": w0 * wn, "roll/yaw_rate": wn + w0, "roll/h": w0 / I_,
                "roll/N_x": 1 / I_, "yaw/yaw": w0 * wn, "yaw/roll_rate": -(wn + w0),
                "yaw/N_z": 1 / I_, "yaw/N_w": -1 / I_})
    return out


def eq5_only(Ix, Iy, Iz, H, w0) -> dict[str, float]:
    """Eqs. 3a–3c with only Eq. 5 applied (I_x = I_z = I, the ω0(I_y − I) terms kept)."""
    I_ = eq5_inertia(Ix, Iz)
    return eq3_coefficients(I_, Iy, I_, H, w0)


def eq6_only(Ix, Iy, Iz, H, w0) -> dict[str, float]:
    """Eqs. 3a–3c with only Eq. 6 applied: the ω0·(inertia difference) terms in the
    H coefficients dropped, I_x and I_z kept apart."""
    out = eq3_coefficients(Ix, Iy, Iz, H, w0)
    out.update({"roll/roll": w0 * H / Ix, "roll/yaw_rate": (H + Iz * w0) / Ix,
                "yaw/yaw": w0 * H / Iz, "yaw/roll_rate": -(H + Ix * w0) / Iz})
    return out


def jacobian_of(named: dict[str, float]) -> tuple[np.ndarray, np.ndarray]:
    """The Jacobians (3×7 state, 3×5 input) holding a set of named coefficients, zero
    elsewhere."""
    wrt_state, wrt_input = np.zeros((3, 7)), np.zeros((3, 5))
    for name, (r, m, col) in COEFFICIENT_INDEX.items():
        (wrt_state if m == "x" else wrt_input)[r, col] = named[name]
    return wrt_state, wrt_input


def model_matrices(wrt_state: np.ndarray, wrt_input: np.ndarray, omega_n: float
                   ) -> tuple[np.ndarray, np.ndarray]:
    """A Jacobian in the paper's model units: F (5×5) on [r, ṙ/ω_n, y, ẏ/ω_n, h]
    and G (5×3) on the inputs [N_x, N_z, N_w].  Pitch is left out (Eq. 3b decouples)."""
    F, G = np.zeros((5, 5)), np.zeros((5, 3))
    F[0, 1] = F[2, 3] = omega_n
    for row, jrow in ((1, ROLL_ROW), (3, YAW_ROW)):
        F[row] = [wrt_state[jrow, PHI] / omega_n, wrt_state[jrow, PHI_D],
                  wrt_state[jrow, PSI] / omega_n, wrt_state[jrow, PSI_D],
                  wrt_state[jrow, H_COL] / omega_n]
        G[row] = [wrt_input[jrow, NX] / omega_n, wrt_input[jrow, NZ] / omega_n,
                  wrt_input[jrow, HDOT] / omega_n]
    G[4, 2] = 1.0
    return F, G
