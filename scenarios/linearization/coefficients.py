"""Section 1 of the linearization report: the truth model's Jacobian against the paper.

Three sets of roll/yaw/pitch coefficients are compared, each named by its place
in Eqs. 3a–3c (row: the angular acceleration; column: the state or input):

- the CasADi Jacobian of the simulator's own symbolic gyrostat
  (``sim.linearize``), which keeps the full inertia tensor;
- the paper's unapproximated Eqs. 3a–3c (diagonal J, signed H);
- the approximated Eqs. 7a–7b, i.e. Eq. 11c in model units, which use
  I_x = I_z = I (Eq. 5) and drop the ω0(I_y − I) terms (Eq. 6).

Constant H and the pitch decoupling are *exact* to first order (the partial
derivatives they neglect vanish at the nominal state); their effect is second
order and is measured by the propagation runs (Section 2 of the report).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from dynprop.eom.linear import (
    COEFFICIENT_INDEX,
    H_COL,
    PHI,
    PHI_D,
    PITCH_ROW,
    PSI,
    PSI_D,
    ROLL_ROW,
    THETA,
    THETA_D,
    YAW_ROW,
    eq3_coefficients,
    eq5_inertia,
    eq5_only,
    eq6_only,
    eq7_coefficients,
    jacobian_of,
    model_matrices,
)
from dynprop.estimator.linear.model import roll_yaw_blocks, torque_input_matrix
from dynprop.sim.frames import GeoOrbit
from dynprop.sim.linearize import linearize_about_nominal
from dynprop.sim.spacecraft import Spacecraft

PRODUCTS_KGM2 = 30.0
EQUATION = {"roll": "3a / 7a", "yaw": "3c / 7b", "pitch": "3b"}


def jacobian_coefficients(sc: Spacecraft, orbit: GeoOrbit) -> tuple[dict[str, float], dict]:
    """The named coefficients from the CasADi Jacobian, and the raw matrices."""
    lin = linearize_about_nominal(sc, orbit)
    mats = {"x": lin.wrt_state, "u": lin.wrt_input}
    named = {k: float(mats[m][r, c]) for k, (r, m, c) in COEFFICIENT_INDEX.items()}
    return named, {"wrt_state": lin.wrt_state, "wrt_input": lin.wrt_input, "H_Nms": lin.H_Nms}


def omitted_terms(wrt_state: np.ndarray, wrt_input: np.ndarray) -> dict[str, float]:
    """Largest |entry| of each group of Jacobian terms the paper sets to zero."""
    mask_x = np.ones_like(wrt_state, dtype=bool)
    mask_u = np.ones_like(wrt_input, dtype=bool)
    for r, m, c in COEFFICIENT_INDEX.values():
        (mask_x if m == "x" else mask_u)[r, c] = False
    pitch_into_rollyaw = np.abs(wrt_state[[YAW_ROW, ROLL_ROW]][:, [THETA, THETA_D]]).max()
    rollyaw_into_pitch = np.abs(wrt_state[PITCH_ROW, [PSI, PHI, PSI_D, PHI_D, H_COL]]).max()
    other_x = np.abs(np.where(mask_x, wrt_state, 0.0))
    other_x[[YAW_ROW, ROLL_ROW], THETA] = other_x[[YAW_ROW, ROLL_ROW], THETA_D] = 0.0
    other_x[PITCH_ROW, [PSI, PHI, PSI_D, PHI_D, H_COL]] = 0.0
    return {"pitch_into_roll_yaw": float(pitch_into_rollyaw),
            "roll_yaw_into_pitch": float(rollyaw_into_pitch),
            "other_state_terms": float(other_x.max()),
            "other_input_terms": float(np.abs(np.where(mask_u, wrt_input, 0.0)).max())}


def eq11_matrices(omega0: float, omega_n: float, H: float) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 11's roll/yaw/h block (A of Eq. 11c plus the h column of B) and its input
    matrix for [N_x, N_z, N_w] (Eq. 12a), in the same layout as ``model_matrices``."""
    A, B = roll_yaw_blocks(omega0, omega_n, H)
    F = np.zeros((5, 5))
    F[:4, :4] = A
    F[1, 4] = B[1, 0]    # h drives roll only (Eq. 11d: ω0/H)
    return F, torque_input_matrix(H)[:5]


def roll_yaw_frequencies(F: np.ndarray) -> tuple[float, float]:
    """(slow, fast) undamped frequencies (rad/s) of the 4×4 roll/yaw block: the orbit
    mode (≈ ω0) and the nutation (≈ |ω_n|)."""
    lam = np.linalg.eigvals(F[:4, :4])
    mags = np.sort(np.abs(lam))
    return float(mags[0]), float(mags[-1])


def _rel(a: float, b: float) -> float:
    return float(abs(a - b) / abs(b)) if b != 0 else float(abs(a - b))


def with_products(sc: Spacecraft, value: float) -> Spacecraft:
    """The spacecraft with every product of inertia set to ``value`` (kg m²); the tensor's
    off-diagonal elements are the negatives of the products."""
    J = np.array(sc.J, dtype=float)
    off = ~np.eye(3, dtype=bool)
    J[off] = -value
    return replace(sc, inertia_kgm2=tuple(map(tuple, J)))


def coefficient_section(sc: Spacecraft, orbit: GeoOrbit, H_range_Nms: float | None = None
                        ) -> dict:
    """Everything Section 1 of the report shows, as plain numbers (SI)."""
    J = sc.J
    Ix, Iy, Iz = np.diag(J)
    w0 = orbit.rate_radps
    jac, raw = jacobian_coefficients(sc, orbit)
    H = raw["H_Nms"]
    eq3, eq7 = eq3_coefficients(Ix, Iy, Iz, H, w0), eq7_coefficients(Ix, Iy, Iz, H, w0)
    only5, only6 = eq5_only(Ix, Iy, Iz, H, w0), eq6_only(Ix, Iy, Iz, H, w0)
    prod, prod_raw = {}, {}
    for sign in (+1, -1):  # one Jacobian per sign, used by the table and the frequencies
        prod[sign], prod_raw[sign] = jacobian_coefficients(
            with_products(sc, sign * PRODUCTS_KGM2), orbit)
    rows = []
    for name in COEFFICIENT_INDEX:
        rows.append({
            "coefficient": name, "equation": EQUATION[name.split("/")[0]],
            "jacobian": jac[name], "eq3": eq3[name], "rel_jacobian_vs_eq3": _rel(jac[name],
                                                                                eq3[name]),
            "eq7": eq7[name], "rel_eq7_vs_jacobian": _rel(eq7[name], jac[name]),
            "rel_eq5_only": _rel(only5[name], jac[name]),
            "rel_eq6_only": _rel(only6[name], jac[name]),
            "rel_products": max(_rel(prod[s][name], jac[name]) for s in prod),
        })
    I_ = eq5_inertia(Ix, Iz)
    wn = H / I_
    F_jac, G_jac = model_matrices(raw["wrt_state"], raw["wrt_input"], wn)
    F_11, _ = eq11_matrices(w0, wn, H)
    prod_omitted = {}
    freqs = {"jacobian": roll_yaw_frequencies(F_jac), "eq11c": roll_yaw_frequencies(F_11)}
    for sign in (+1, -1):
        raw_p = prod_raw[sign]
        prod_omitted[f"{sign * PRODUCTS_KGM2:+g}"] = omitted_terms(raw_p["wrt_state"],
                                                                  raw_p["wrt_input"])
        freqs[f"products_{sign * PRODUCTS_KGM2:+g}"] = roll_yaw_frequencies(
            model_matrices(raw_p["wrt_state"], raw_p["wrt_input"], wn)[0])
    for label, coeffs in (("eq5_only", only5), ("eq6_only", only6)):
        freqs[label] = roll_yaw_frequencies(_matrix_from_named(coeffs, wn))
    if H_range_Nms is not None:
        for sign, label in ((+1, "H_plus"), (-1, "H_minus")):
            Hs = H + sign * H_range_Nms
            freqs[label] = roll_yaw_frequencies(
                _matrix_from_named(eq3_coefficients(Ix, Iy, Iz, Hs, w0), wn))
    ref = freqs["jacobian"]
    eig = {k: {"omega_slow_radps": v[0], "omega_fast_radps": v[1],
               "rel_slow": _rel(v[0], ref[0]), "rel_fast": _rel(v[1], ref[1])}
           for k, v in freqs.items()}
    return {
        "inputs": {"Ix_kgm2": float(Ix), "Iy_kgm2": float(Iy), "Iz_kgm2": float(Iz),
                   "products_kgm2": [float(-J[0, 1]) + 0.0, float(-J[0, 2]) + 0.0,
                                     float(-J[1, 2]) + 0.0],
                   "I_kgm2": I_, "H_Nms": float(H), "omega0_radps": float(w0),
                   "omega_n_radps": float(wn),
                   "eq6_ratio": float(w0 * (Iy - I_) / H),
                   "H_range_Nms": None if H_range_Nms is None else float(H_range_Nms)},
        "rows": rows,
        "omitted": omitted_terms(raw["wrt_state"], raw["wrt_input"]),
        "omitted_with_products": prod_omitted,
        "model_matrix": {"jacobian": F_jac.tolist(), "eq11": F_11.tolist(),
                         "max_rel_difference": _max_rel(F_jac, F_11)},
        "eigenfrequencies": eig,
    }


def _matrix_from_named(c: dict[str, float], omega_n: float) -> np.ndarray:
    """The 5×5 model-unit matrix of a set of named coefficients (diagonal J)."""
    return model_matrices(*jacobian_of(c), omega_n)[0]


def _max_rel(a: np.ndarray, b: np.ndarray) -> float:
    """Largest relative difference over the nonzero entries of ``b``, and the largest
    absolute one (relative to max|b|) where ``b`` is zero."""
    nz = b != 0
    rel = np.abs(a[nz] - b[nz]) / np.abs(b[nz])
    zero = np.abs(a[~nz]).max() / np.abs(b).max() if np.any(~nz) else 0.0
    return float(max(rel.max(), zero))
