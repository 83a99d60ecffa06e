"""Section 4: rank progressions of the observability matrix (Eqs. 24–30)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from estimator.analysis.observability import (
    default_tol,
    format_rank_table,
    full_rank_power,
    paper_configurations,
    rank_margins,
    rank_progression,
    scaled_observability,
    unobservable_direction,
    unobservable_subspace,
    unscaled_rank_progression,
)
from estimator.linear.model import (
    N_STATES,
    NCZ,
    ModelParams,
    Y,
    dynamics_matrix,
    measurement_rows,
    pitch_bias_Nms,
)


def goes_next(sign: float = 1.0) -> ModelParams:
    """The paper's inputs: inertias (Sec. 2), Eq. 1 wheels, ω0 of one sidereal day."""
    H = pitch_bias_Nms(0.1082, [5485 * 2 * np.pi / 60] * 2, np.deg2rad(1.656))
    return ModelParams(3364.376, 954.936, 3461.393, sign * H, 2 * np.pi / 86164.0905)


@pytest.fixture(scope="module")
def configs():
    return {c.name: c for c in paper_configurations(goes_next())}


def test_full_measurements_reach_full_rank_at_F3(configs):
    """Eq. 26: G, GF, GF², GF³ achieve full rank (Section 4)."""
    c = configs["G"]
    ranks = rank_progression(c.F, c.G)
    assert ranks.tolist() == [3, 5, 7, 9, 9, 9, 9, 9, 9]
    assert full_rank_power(ranks) == 3 == c.paper_full_rank_power


def test_roll_and_tach_only_give_rank_eight(configs):
    """Eq. 27: with G″ the observability matrix has rank eight."""
    c = configs["G''"]
    ranks = rank_progression(c.F, c.G)
    assert ranks.tolist() == [2, 3, 4, 5, 6, 7, 8, 8, 8]
    assert full_rank_power(ranks) is None


def test_reduced_state_is_observable_at_power_six(configs):
    """Eqs. 28–30: G′(F′)^k for k up to six gives full rank, not before."""
    c = configs["G'"]
    ranks = rank_progression(c.F, c.G)
    assert ranks.tolist() == [2, 3, 4, 5, 6, 7, 8, 8]
    assert full_rank_power(ranks) == 6 == c.paper_full_rank_power


def test_reduced_model_is_eq29_as_printed(configs):
    """F′ from deleting N_cz equals Eqs. 29b–d typed from the paper.  Compared exactly:
    each entry is one IEEE operation (ω0/H, 1/H, ω0) on the same inputs, or a structural
    0 or 1, which no CPU rounds differently."""
    p = goes_next()
    w0, H = p.omega0_radps, p.H_Nms
    Bp = np.array([[0, 0, 0, 0], [w0, 1, 0, 1], [0, 0, 0, 0], [0, 0, 1, 0]]) / H
    Cp = w0 * np.array([[0, 0, 0, 0], [0, 0, 1, 0], [0, -1, 0, 0], [0, 0, 0, 0]])
    Fp = np.zeros((8, 8))
    Fp[:4, :4] = dynamics_matrix(p)[:4, :4]
    Fp[:4, 4:], Fp[4:, 4:] = Bp, Cp
    np.testing.assert_array_equal(configs["G'"].F, Fp)
    np.testing.assert_array_equal(configs["G'"].G, np.eye(8)[[0, 4]])   # Eq. 30


def test_unobservable_direction_is_Ncz_with_the_yaw_it_balances(configs):
    """The null direction of G″ is N_cz together with y = −N_cz/(ω0 H), nothing else.

    A constant yaw torque N_cz is balanced by gravity-gradient/gyroscopic yaw
    stiffness at y = −N_cz/(ω0 H) (Eq. 39b with ṙ = 0): that pair leaves roll and
    h untouched.  So "the constant yaw torque is unobservable" (paper) means this
    combination; N_cz with y held fixed is not a null vector.
    """
    p = goes_next()
    c = configs["G''"]
    eps = np.finfo(float).eps
    # The analytic direction is an exact equilibrium of Eq. 11, F v = 0, so G″ F^k v = 0
    # for every k.  Each row of F v is a sum of at most two products whose factors carry a
    # few roundings each (1/(ω0 H), the normalisation, 1/H in F): ≤ ~2.5 eps of |F||v|
    # (measured 0.5 eps; 8 eps allowed).
    v_exact = np.zeros(N_STATES)
    v_exact[Y], v_exact[NCZ] = -1.0 / (p.omega0_radps * p.H_Nms), 1.0
    v_exact /= np.linalg.norm(v_exact)
    assert np.all(np.abs(c.F @ v_exact) <= 8 * eps * (np.abs(c.F) @ np.abs(v_exact)))

    v = unobservable_direction(c.F, c.G)
    assert v.shape == (N_STATES,)
    assert np.linalg.norm(v) == pytest.approx(1.0)
    # Compare in the scaled coordinates z = x / s in which the code takes the SVD: there
    # the computed null vector of M (σ_max = 1 relative) is perturbed along each right
    # singular vector V_j by about ‖E‖/σ_j, with ‖E‖ ≈ k eps ‖M‖ the rounding of forming M
    # and of the SVD.  So state i is good to k eps Σ_j |V_ji| σ_max/σ_j: ~1e-10 for y, N_cz
    # and N_pz, ~1e-7 for ẏ, N_px, N_cx (they make up V_7, σ_7/σ_max = 1.4e-9 ≈ (ω0/ω_n)³),
    # ~1e-15 for the rest.  k = rows of M (18); measured ≤ 0.26 of the bound with k = 1,
    # so 70 times under it at worst (and 1000 for y, N_cz, N_pz).
    M, s = scaled_observability(c.F, c.G)
    _, sv, Vt = np.linalg.svd(M)
    rank = N_STATES - 1
    bound = M.shape[0] * eps * (np.abs(Vt[:rank]).T @ (sv[0] / sv[:rank]))
    z, z_exact = v / s, v_exact / s
    z, z_exact = z / np.linalg.norm(z), z_exact / np.linalg.norm(z_exact) * np.sign(z @ z_exact)
    assert np.all(np.abs(z - z_exact) <= bound)      # nothing but y and N_cz, in ratio:
    ratio_tol = (bound[Y] / abs(z_exact[Y]) + bound[NCZ] / abs(z_exact[NCZ])) + 8 * eps
    assert ratio_tol < 1e-8
    assert v[Y] / v[NCZ] == pytest.approx(-1.0 / (p.omega0_radps * p.H_Nms), rel=ratio_tol)
    e_ncz = np.eye(N_STATES)[NCZ]
    assert np.abs(c.G @ c.F @ c.F @ c.F @ e_ncz).max() > 0       # N_cz alone is seen
    assert unobservable_direction(configs["G"].F, configs["G"].G) is None


def test_unscaled_matrix_rank_gives_wrong_answers(configs):
    """numpy.linalg.matrix_rank on the raw M loses the small-but-structural directions."""
    for name, paper_rank in (("G''", 8), ("G'", 8)):
        c = configs[name]
        assert rank_progression(c.F, c.G)[-1] == paper_rank
        assert unscaled_rank_progression(c.F, c.G)[-1] < paper_rank     # 7 and 6
    assert unscaled_rank_progression(configs["G''"].F, configs["G''"].G)[-1] == 7
    assert unscaled_rank_progression(configs["G'"].F, configs["G'"].G)[-1] == 6


@pytest.mark.parametrize("name", ["G", "G''", "G'"])
def test_tolerance_sits_in_a_wide_gap(configs, name):
    """Kept singular values ≥ 1e-9 ≈ (ω0/ω_n)³, four decades above the tolerance; the
    dropped ones are rounding, below the level LAPACK promises for values that are zero in
    exact arithmetic."""
    c = configs[name]
    tol = default_tol(c.G.shape[0] * c.F.shape[0], c.F.shape[0])
    kept, dropped = rank_margins(c.F, c.G)
    # Structural values set by the frequency ratio, computed to ~eps absolute: not
    # sensitive to rounding (measured 3.0e4 tol for G″, 4.4e4 for G′).
    assert kept > 1e4 * tol
    # numpy's own rank tolerance max(rows, n) eps σ_max (= tol/10) is the rounding level
    # a backward-stable SVD promises; measured ≤ 1.3e-16, 27 times below it (G′).
    assert dropped < tol / 10
    # and any tolerance within the gap gives the same ranks
    for other in (1e-10, 1e-12, 1e-14):
        assert rank_progression(c.F, c.G, other).tolist() == rank_progression(c.F, c.G).tolist()


def test_signed_and_unsigned_H_give_the_same_ranks():
    for sign in (1.0, -1.0):
        configs = paper_configurations(goes_next(sign))
        res = {c.name: rank_progression(c.F, c.G)[-1] for c in configs}
        assert res == {"G": 9, "G''": 8, "G'": 8}


@settings(max_examples=25, deadline=None)
@given(st.lists(st.floats(-6, 6), min_size=N_STATES, max_size=N_STATES))
def test_ranks_do_not_depend_on_state_units(log_scales):
    """x = S z for any diagonal S (units of each state) leaves every rank unchanged."""
    s = 10.0 ** np.array(log_scales)
    for c in paper_configurations(goes_next()):
        n = c.F.shape[0]
        Fs = c.F * s[None, :n] / s[:n, None]
        Gs = c.G * s[None, :n]
        assert rank_progression(Fs, Gs).tolist() == rank_progression(c.F, c.G).tolist()


def test_small_textbook_cases():
    """Double integrator: position sees everything at k=1; velocity never sees position."""
    F = np.array([[0.0, 1.0], [0.0, 0.0]])
    assert rank_progression(F, [[1.0, 0.0]]).tolist() == [1, 2]
    assert rank_progression(F, [[0.0, 1.0]]).tolist() == [1, 1]
    np.testing.assert_allclose(np.abs(unobservable_direction(F, [[0.0, 1.0]])), [1.0, 0.0])
    # two unobservable directions: a basis, and unobservable_direction refuses
    F3 = np.zeros((3, 3))
    basis = unobservable_subspace(F3, [[1.0, 0.0, 0.0]])
    assert basis.shape == (3, 2)
    with pytest.raises(ValueError):
        unobservable_direction(F3, [[1.0, 0.0, 0.0]])


def test_measurement_rows_match_eq26():
    """Structural 0/1 rows: identity is the requirement."""
    rows = measurement_rows()
    G = np.vstack([rows["roll"], rows["yaw"], rows["h"]])
    expected = np.zeros((3, 9))
    expected[0, 0] = expected[1, 2] = expected[2, 4] = 1.0
    np.testing.assert_array_equal(G, expected)


def test_format_rank_table():
    text = format_rank_table(goes_next())
    rows = {ln.split(":")[0]: ln.split(")", 1)[1].split() for ln in text.splitlines()
            if ln.startswith(("G:", "G'':", "G':"))}
    assert rows["G"] == ["3", "5", "7", "9", "9", "9", "9", "9", "9", "k=3", "full", "at", "k=3"]
    assert rows["G''"][:9] == ["2", "3", "4", "5", "6", "7", "8", "8", "8"]
    assert rows["G''"][9:] == ["never", "(8/9)", "rank", "8"]
    assert rows["G'"] == ["2", "3", "4", "5", "6", "7", "8", "8", "k=6", "full", "at", "k=6"]
    assert "numpy matrix_rank unscaled: 7" in text
    assert "y/N_cz = 110.37" in text
