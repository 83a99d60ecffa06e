"""Observability of the paper's roll/yaw model (Section 4, Eqs. 24–30).

The observability matrix M_k = [G; GF; …; GF^k] of the GOES-Next model has
entries spanning more than ten orders of magnitude (ω0 ≈ 7.3e-5 rad/s,
|ω_n| ≈ 0.036 rad/s, 1/|H| ≈ 8e-3, torques in N m next to angles in rad), so
``numpy.linalg.matrix_rank`` on the raw matrix compares singular values that
differ only because of units: it reports rank 7 instead of 8 with G″ (Eq. 27)
and 6 instead of 8 with G′ (Eq. 30).  Rank is invariant under

* a change of time unit, t = τ/ω_ref, which multiplies the block G F^k by
  ω_ref^-k (a row scaling of M), and
* a change of state units x = S z, S diagonal (a column scaling of M),

so ``rank_progression`` computes the rank of a scaled matrix instead:

1. F is divided by ω_ref, the spectral radius of F (|ω_n| here), so the scaled
   F has norm ≈ 1 and its powers neither overflow nor vanish through units;
2. each state column of the full stacked matrix M_{n−1} is scaled to unit
   2-norm (this choice of S removes the state units), and the same S is used
   for every prefix M_k;
3. the rank is the number of singular values above ``tol`` · σ_max.

Tolerance.  The default tol = 10 · max(rows, n) · eps (≈ 6e-14 for the 9-state
case) is ten times numpy's own default.  After scaling, the error in a computed
singular value is of the order of the rounding error of forming and stacking
the products, eps · k · ‖M‖, and the computed values that are zero in exact
arithmetic come out ≤ 1e-16.  The smallest *structural* singular values are
set by powers of the frequency ratio ε = ω0/|ω_n| ≈ 2e-3: the deepest needed
(G″ and G′, seventh block row) is ≈ 1.2e-9, of order ε³.  The default sits more than
four decades below that and more than two above the rounding level; the
margins are in ``rank_margins`` and are tested.

The same test on the state augmented with sensor biases (not in the paper) is at the
end of the module (``format_bias_table``): a constant sensor bias is, with the
paper's constant torque states, indistinguishable from an attitude offset that the
torque holds, so the roll bias is never observable alone and a head's yaw bias only
against another head's yaw.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..augmented.model import BIAS_NAMES, augmented_dynamics, augmented_rows
from ..linear.model import NCZ, STATE_NAMES, ModelParams, Y, dynamics_matrix, measurement_rows


def default_tol(n_rows: int, n_states: int) -> float:
    """Relative tolerance 10 · max(rows, n) · eps (on σ/σ_max): see the module docstring."""
    return 10.0 * max(n_rows, n_states) * np.finfo(float).eps


def _stack(F: np.ndarray, G: np.ndarray, k: int) -> np.ndarray:
    blocks = [G]
    for _ in range(k):
        blocks.append(blocks[-1] @ F)
    return np.vstack(blocks)


def scaled_observability(F, G, k: int | None = None):
    """(M_k scaled, state scales s): M_scaled = diag(ω_ref^-j) M_k diag(s).

    A null vector z of the scaled matrix is the state x = s ∘ z.
    """
    F = np.atleast_2d(np.asarray(F, dtype=float))
    G = np.atleast_2d(np.asarray(G, dtype=float))
    n = F.shape[0]
    if F.shape != (n, n) or G.shape[1] != n:
        raise ValueError("F must be n×n and G m×n")
    k = n - 1 if k is None else k
    omega_ref = float(np.max(np.abs(np.linalg.eigvals(F))))
    if omega_ref == 0.0:
        omega_ref = float(np.linalg.norm(F, 2)) or 1.0
    Ft = F / omega_ref
    col = np.linalg.norm(_stack(Ft, G, n - 1), axis=0)
    s = np.where(col > 0, 1.0 / np.where(col > 0, col, 1.0), 1.0)
    Fs = Ft * s[None, :] / s[:, None]
    return _stack(Fs, G * s[None, :], k), s


def _singular_values(F, G, k: int) -> np.ndarray:
    M, _ = scaled_observability(F, G, k)
    sv = np.linalg.svd(M, compute_uv=False)
    return sv / sv[0] if sv[0] > 0 else sv


def rank_progression(F, G, tol: float | None = None) -> np.ndarray:
    """Numerical rank of [G; GF; …; GF^k] for k = 0 … n−1 (scaled SVD, see module)."""
    n = np.shape(F)[0]
    m = np.atleast_2d(G).shape[0]
    tol = default_tol(m * n, n) if tol is None else tol
    return np.array([int(np.sum(_singular_values(F, G, k) > tol)) for k in range(n)])


def rank_margins(F, G, tol: float | None = None) -> tuple[float, float]:
    """(smallest kept, largest dropped) relative singular value over all k.

    The smallest singular value counted in any rank and the largest one
    discarded: the tolerance is safe when it sits well between them.
    """
    n = np.shape(F)[0]
    m = np.atleast_2d(G).shape[0]
    tol = default_tol(m * n, n) if tol is None else tol
    kept, dropped = 1.0, 0.0
    for k in range(n):
        sv = _singular_values(F, G, k)
        if np.any(sv > tol):
            kept = min(kept, float(sv[sv > tol].min()))
        if np.any(sv <= tol):
            dropped = max(dropped, float(sv[sv <= tol].max()))
    return kept, dropped


def unscaled_rank_progression(F, G) -> np.ndarray:
    """What plain ``numpy.linalg.matrix_rank`` says (wrong here: module docstring)."""
    F = np.asarray(F, dtype=float)
    G = np.atleast_2d(np.asarray(G, dtype=float))
    return np.array([int(np.linalg.matrix_rank(_stack(F, G, k))) for k in range(F.shape[0])])


def full_rank_power(ranks) -> int | None:
    """The first power k with rank n (n = len(ranks)), or None if never."""
    ranks = np.asarray(ranks)
    hits = np.flatnonzero(ranks == len(ranks))
    return int(hits[0]) if hits.size else None


def unobservable_subspace(F, G, tol: float | None = None) -> np.ndarray:
    """n×d basis of the unobservable subspace, unit columns in the original coordinates."""
    n = np.shape(F)[0]
    M, s = scaled_observability(F, G)
    tol = default_tol(M.shape[0], n) if tol is None else tol
    _, sv, Vt = np.linalg.svd(M)
    sv = sv / sv[0]
    rank = int(np.sum(sv > tol))
    basis = Vt[rank:].T * s[:, None]
    if basis.shape[1] == 1:
        basis = basis / np.linalg.norm(basis)
        i = int(np.argmax(np.abs(basis[:, 0])))
        return basis * np.sign(basis[i, 0])
    q, _ = np.linalg.qr(basis) if basis.size else (basis, None)
    return q


def unobservable_direction(F, G, tol: float | None = None) -> np.ndarray | None:
    """The unit null vector (original coordinates) when the nullity is one, else None.

    The unit vector depends on the state units: with G″ it is mostly yaw, because
    one N m of constant yaw torque is balanced by 1/(ω0|H|) ≈ 110 rad of yaw.
    Raises ValueError for a nullity above one (use ``unobservable_subspace``).
    """
    basis = unobservable_subspace(F, G, tol)
    if basis.shape[1] == 0:
        return None
    if basis.shape[1] > 1:
        raise ValueError(f"the unobservable subspace has dimension {basis.shape[1]}")
    return basis[:, 0]


@dataclass(frozen=True)
class Configuration:
    """A (F, G) pair of Section 4 and what the paper says about it."""

    name: str
    description: str
    F: np.ndarray
    G: np.ndarray
    paper: str
    paper_full_rank_power: int | None


def paper_configurations(p: ModelParams) -> list[Configuration]:
    """G (Eq. 26), G″ (Eq. 27) on the 9-state F, and G′ (Eq. 30) on F′ (Eqs. 28–29)."""
    F = dynamics_matrix(p)
    rows = measurement_rows()
    G = np.vstack([rows["roll"], rows["yaw"], rows["h"]])
    G2 = np.vstack([rows["roll"], rows["h"]])
    keep = [i for i in range(F.shape[0]) if i != NCZ]     # Eq. 28: drop N_cz
    return [
        Configuration("G", "roll, yaw, h; 9 states (Eq. 26)", F, G, "full at k=3", 3),
        Configuration("G''", "roll, h; 9 states (Eq. 27)", F, G2, "rank 8", None),
        Configuration("G'", "roll, h; 8 states, no N_cz (Eqs. 28-30)", F[np.ix_(keep, keep)],
                      G2[:, keep], "full at k=6", 6),
    ]


def observability_results(p: ModelParams, tol: float | None = None) -> list[dict]:
    """Per configuration: ranks, full-rank power, unscaled ranks, margins, null vector."""
    out = []
    for c in paper_configurations(p):
        ranks = rank_progression(c.F, c.G, tol)
        out.append({"name": c.name, "description": c.description, "ranks": ranks.tolist(),
                    "full_rank_power": full_rank_power(ranks), "paper": c.paper,
                    "paper_full_rank_power": c.paper_full_rank_power,
                    "unscaled_ranks": unscaled_rank_progression(c.F, c.G).tolist(),
                    "margins": rank_margins(c.F, c.G, tol),
                    "null": None if ranks[-1] == len(ranks) else
                    unobservable_direction(c.F, c.G, tol)})
    return out


def format_rank_table(p: ModelParams, tol: float | None = None, biases=()) -> str:
    """The text of ``dynprop observability``: rank after each power k, full-rank power;
    with ``biases`` (of ``BIAS_NAMES``), the same on the augmented state after it
    (``format_bias_table``)."""
    if biases:
        return format_rank_table(p, tol) + "\n\n" + format_bias_table(p, biases, tol)
    res = observability_results(p, tol)
    kmax = max(len(r["ranks"]) for r in res)
    head = f"{'configuration':<44}" + "".join(f"{f'k={k}':>5}" for k in range(kmax))
    head += f"{'full at':>14}  paper"
    lines = ["Observability (Section 4): numerical rank of [G; GF; ...; GF^k]",
             "(time scaled by the spectral radius of F, state columns equilibrated, SVD)", "",
             head, "-" * len(head)]
    for r in res:
        cells = "".join(f"{v:>5d}" for v in r["ranks"]) + " " * 5 * (kmax - len(r["ranks"]))
        n = len(r["ranks"])
        full = f"never ({r['ranks'][-1]}/{n})" if r["full_rank_power"] is None \
            else f"k={r['full_rank_power']}"
        lines.append(f"{r['name'] + ': ' + r['description']:<44}{cells}{full:>14}  {r['paper']}")
    lines.append("")
    for r in res:
        kept, dropped = r["margins"]
        lines.append(f"{r['name']:<4} smallest kept σ/σmax {kept:.1e}, largest dropped "
                     f"{dropped:.1e}; numpy matrix_rank unscaled: {r['unscaled_ranks'][-1]}")
    for r in res:
        v = r["null"]
        if v is None:
            continue
        nz = [f"{STATE_NAMES[i]} {v[i]:+.5f}" for i in np.flatnonzero(np.abs(v) > 1e-9)]
        lines.append(f"unobservable with {r['name']}: " + ", ".join(nz))
        if len(v) > NCZ and abs(v[NCZ]) > 0 and abs(v[Y]) > 0:
            lines.append(f"  = a constant yaw torque N_cz with the yaw offset it balances, "
                         f"y/N_cz = {v[Y] / v[NCZ]:.2f} rad/(N m) "
                         f"(-1/(ω0 H) = {-1 / (p.omega0_radps * p.H_Nms):.2f})")
    return "\n".join(lines)


# ------------------------------------------------------------------ sensor-bias states
#
# Not in the paper: the state augmented with sensor biases b (``augmented``'s filter;
# its F_a and rows are ``augmented.model``'s),
# x_a = [x (Eq. 10), b].  A bias has no dynamics (a constant, or a random walk whose
# noise does not enter observability), so F_a = blockdiag(F, 0); it adds to its
# sensor's measurement row: roll = e_r + e_earth_roll, yaw from a head = e_y + e_<head>_yaw,
# h = e_h.  The same scaled rank test applies.  Yaw from two heads at different times
# is the pair's rows stacked: F_a is the same in both spans and each span's
# unobservable subspace is F_a-invariant (so e^{F_a t}-invariant), hence what neither
# span sees is the intersection, the null space of the stacked rows' matrix.

_CLEAN = 1e-6   # entries of a scaled null vector below this are rounding (see _directions)


@dataclass(frozen=True)
class BiasConfiguration:
    """A measurement configuration of the augmented state: (F_a, G_a) and state names."""

    name: str
    description: str
    F: np.ndarray
    G: np.ndarray
    names: tuple[str, ...]


def bias_configurations(p: ModelParams, biases) -> list[BiasConfiguration]:
    """The paper's configurations (G, G″, G′) on the state augmented with ``biases``;
    G once per head giving the yaw, and once with yaw from the DSS and, at other
    times, CASS1 (the day's order: a CASS in the morning, the DSS before the gap)."""
    biases = tuple(b for b in BIAS_NAMES if b in biases)
    F = dynamics_matrix(p)
    every = list(range(F.shape[0]))
    no_ncz = [i for i in every if i != NCZ]
    specs = [
        ("G+b dss", "roll, yaw from the DSS, h", ("roll", "yaw:dss", "h"), every),
        ("G+b cass1", "roll, yaw from CASS1, h", ("roll", "yaw:cass1", "h"), every),
        ("G+b cass2", "roll, yaw from CASS2, h", ("roll", "yaw:cass2", "h"), every),
        ("G+b dss|cass1", "roll, h, yaw from the DSS, at other times CASS1",
         ("roll", "yaw:dss", "yaw:cass1", "h"), every),
        ("G''+b", "roll, h: the Sun gap (Eq. 27)", ("roll", "h"), every),
        ("G'+b", "roll, h; no N_cz (Eqs. 28-30)", ("roll", "h"), no_ncz),
    ]
    return [BiasConfiguration(name, text, augmented_dynamics(F[np.ix_(keep, keep)],
                                                             len(biases)),
                              augmented_rows(kinds, biases, keep),
                              tuple(STATE_NAMES[i] for i in keep) + biases)
            for name, text, kinds, keep in specs]


def _directions(F, G, names, tol: float | None = None) -> list[dict[str, float]]:
    """A basis of the unobservable subspace as readable vectors: each has one pivot
    state with coefficient 1 and 0 on the other vectors' pivots (pivots chosen among
    the biases first, then the attitude, then the rest), in the original units.  The
    reduction is done on the scaled null vectors (``scaled_observability``), whose
    entries are unit-free: their rounding is ≈ eps/σ_min ≲ 1e-7 (σ_min ≈ 1e-9, the
    deepest structural singular value), so entries below 1e-6 are dropped."""
    n = np.shape(F)[0]
    M, s = scaled_observability(F, G)
    tol = default_tol(M.shape[0], n) if tol is None else tol
    _, sv, Vt = np.linalg.svd(M)
    rank = int(np.sum(sv / sv[0] > tol))
    Z = Vt[rank:].T.copy()
    order = [i for i, nm in enumerate(names) if nm in BIAS_NAMES] + \
        [names.index(nm) for nm in ("roll", "yaw", "h") if nm in names] + list(range(n))
    pivots: list[int] = []
    for i in dict.fromkeys(order):
        free = [j for j in range(Z.shape[1]) if j not in [c for _, c in pivots]]
        if not free:
            break
        j = max(free, key=lambda c: abs(Z[i, c]))
        if abs(Z[i, j]) < _CLEAN:
            continue
        Z[:, j] /= Z[i, j]
        for c in range(Z.shape[1]):
            if c != j:
                Z[:, c] -= Z[i, c] * Z[:, j]
        pivots.append((i, j))
    out = []
    for i, j in pivots:
        z = np.where(np.abs(Z[:, j]) < _CLEAN, 0.0, Z[:, j])
        x = s * z / s[i]
        out.append({names[k]: float(x[k]) for k in [i, *(k for k in np.flatnonzero(z) if k != i)]})
    return out


def _words(v: dict[str, float], G, names, p: ModelParams) -> str:
    """One unobservable direction in words."""
    states = list(v)
    pivot = states[0]
    if len(states) == 1:
        seen = np.any(G[:, names.index(pivot)] != 0)
        return f"{pivot} alone" + ("" if seen else ": no measurement sees it")
    terms = ", ".join(f"{k} {c:+.4g}" for k, c in v.items())
    why = []
    hold = -p.omega0_radps * p.H_Nms          # N_c/offset of a held offset (Eq. 11)
    for angle, torque in (("roll", "N_cx"), ("yaw", "N_cz")):
        if angle in v and torque in v and np.isclose(v[torque] / v[angle], hold, rtol=1e-6):
            text = f"a constant {angle} offset held by the constant torque {torque} = " \
                   f"-ω0 H·{angle} ({hold:.4g} N m/rad)"
            hidden = [b for b in v if b in BIAS_NAMES and np.isclose(v[b], -v[angle])]
            if hidden:
                text += f", hidden from the measured {angle} by " + \
                    (f"{hidden[0]} = -{angle}" if len(hidden) == 1 else
                     " = ".join(hidden) + f" = -{angle}: their common part only, their "
                     "differences are observable")
            why.append(text)
    return f"together {terms}" + (f" ({'; '.join(why)})" if why else "")


def bias_observability_results(p: ModelParams, biases, tol: float | None = None
                               ) -> list[dict]:
    """Per augmented configuration: ranks, full-rank power, margins, the unobservable
    directions (pivot-1 vectors, ``_directions``) and each bias's status: 'observable',
    'unobservable' (alone) or 'combined' (only together with other states)."""
    out = []
    for c in bias_configurations(p, biases):
        ranks = rank_progression(c.F, c.G, tol)
        dirs = _directions(c.F, c.G, c.names, tol)
        status = {}
        for b in c.names[len(c.names) - sum(nm in BIAS_NAMES for nm in c.names):]:
            hit = [d for d in dirs if b in d]
            status[b] = "observable" if not hit else \
                "unobservable" if any(list(d) == [b] for d in hit) else "combined"
        out.append({"name": c.name, "description": c.description, "ranks": ranks.tolist(),
                    "n": len(c.names), "full_rank_power": full_rank_power(ranks),
                    "margins": rank_margins(c.F, c.G, tol), "directions": dirs,
                    "words": [_words(d, c.G, list(c.names), p) for d in dirs],
                    "status": status})
    return out


def format_bias_table(p: ModelParams, biases, tol: float | None = None) -> str:
    """Section 4's method on the state augmented with ``biases``: rank after each
    power k and the unobservable directions, in words."""
    biases = tuple(b for b in BIAS_NAMES if b in biases)
    res = bias_observability_results(p, biases, tol)
    kmax = max(r["n"] for r in res)
    width = max(len(r["name"] + r["description"]) for r in res) + 4
    head = f"{'configuration':<{width}}" + "".join(f"{f'k={k}':>5}" for k in range(kmax))
    head += f"{'full at':>14}"
    lines = [f"With sensor-bias states {', '.join(biases)} (not in the paper): F_a = "
             "blockdiag(F, 0), roll = r + b_roll, yaw = y + b_head", "",
             head, "-" * len(head)]
    for r in res:
        cells = "".join(f"{v:>5d}" for v in r["ranks"]) + " " * 5 * (kmax - len(r["ranks"]))
        full = f"never ({r['ranks'][-1]}/{r['n']})" if r["full_rank_power"] is None \
            else f"k={r['full_rank_power']}"
        lines.append(f"{r['name'] + ': ' + r['description']:<{width}}{cells}{full:>14}")
    for r in res:
        kept, dropped = r["margins"]
        lines += ["", f"{r['name']} (smallest kept σ/σmax {kept:.1e}, largest dropped "
                  f"{dropped:.1e}): " + ", ".join(f"{b} {st}" for b, st in r["status"].items())]
        lines += [f"  unobservable: {w}" for w in r["words"]]
    return "\n".join(lines)
