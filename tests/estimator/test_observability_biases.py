"""Observability of the state augmented with sensor biases (estimator.analysis.observability,
``format_bias_table``; `dynprop observability --biases`).

Independent references:

* F_a = blockdiag(F, 0) and the rows roll = e_r + e_b_roll, yaw = e_y + e_b_head,
  h = e_h are typed here by index, not built by the module.
* Ranks: numpy's ``matrix_rank`` of the stacked [G; GF; …; GF^k] after a *physical*
  change of units, not the module's equilibration: time in units of 1/|ω_n| (F/|ω_n|),
  h in units of |H| and torques in units of |H ω_n| (Eq. 11 then has entries ω0/|ω_n|
  ≈ 2e-3, 1 and 0), biases in rad.  Tolerance 1e-12 · σ_max: the smallest singular value
  the ranks need is 4.7e-11 (G'' with biases, ~ (ω0/|ω_n|)^3.5), asserted > 10 · tol,
  and rounding in forming 52 × 13 products of O(1) entries is ≲ rows · eps ≈ 1e-14,
  asserted (the largest dropped, measured 5e-19) < 1e-3 · tol.
* Null vectors by hand: a constant roll offset δ held by N_cx = −ω0 H δ (Eq. 11: the
  roll-rate row reads ω0 r + N_cx/H = 0) and hidden by b_roll = −δ is an equilibrium
  (F_a v = 0) that no measurement sees (G_a v = 0); likewise yaw with N_cz and a yaw
  bias (the yaw-rate row reads ω0 y + N_cz/H = 0).
"""

from __future__ import annotations

import numpy as np
import pytest

from estimator.analysis.observability import (
    bias_configurations,
    bias_observability_results,
    format_bias_table,
    format_rank_table,
    rank_progression,
)
from estimator.augmented.model import BIAS_NAMES
from estimator.linear.model import (
    H_WHEEL,
    N_STATES,
    NCX,
    NCZ,
    ModelParams,
    R,
    Y,
    dynamics_matrix,
    pitch_bias_Nms,
)
from scenarios.cli import main

H = pitch_bias_Nms(0.1082, [5485 * 2 * np.pi / 60] * 2, np.deg2rad(1.656))
P = ModelParams(3364.376, 954.936, 3461.393, H, 2 * np.pi / 86164.0905)
W0, WN = P.omega0_radps, abs(P.omega_n_radps)
TOL = 1e-12
NB = 4
B_ROLL, B_DSS, B_CASS1, B_CASS2 = range(N_STATES, N_STATES + NB)

# What each configuration is, by hand: (yaw heads, keep N_cz).
HAND = {"G+b dss": (["dss"], True), "G+b cass1": (["cass1"], True),
        "G+b cass2": (["cass2"], True), "G+b dss|cass1": (["dss", "cass1"], True),
        "G''+b": ([], True), "G'+b": ([], False)}
# Ranks found (of 13; G'+b of 12), checked below against the independent rank.
RANKS = {"G+b dss": 9, "G+b cass1": 9, "G+b cass2": 9, "G+b dss|cass1": 10,
         "G''+b": 8, "G'+b": 8}


def hand_system(heads, keep_ncz: bool):
    """F_a and G_a typed by index on [x (9), b_roll, b_dss, b_cass1, b_cass2]."""
    n = N_STATES + NB
    F = np.zeros((n, n))
    F[:N_STATES, :N_STATES] = dynamics_matrix(P)
    rows = []
    roll = np.zeros(n)
    roll[[R, B_ROLL]] = 1.0
    rows.append(roll)
    for head in heads:
        yaw = np.zeros(n)
        yaw[[Y, {"dss": B_DSS, "cass1": B_CASS1, "cass2": B_CASS2}[head]]] = 1.0
        rows.append(yaw)
    h = np.zeros(n)
    h[H_WHEEL] = 1.0
    rows.append(h)
    G = np.array(rows)
    keep = [i for i in range(n) if keep_ncz or i != NCZ]
    return F[np.ix_(keep, keep)], G[:, keep], keep


def physical_units(keep) -> np.ndarray:
    """The unit of each kept state: rad (angles, rates ṙ/ω_n, biases), |H| for h, |H ω_n|
    for the four torques."""
    unit = np.ones(N_STATES + NB)
    unit[H_WHEEL] = abs(H)
    unit[5:N_STATES] = abs(H) * WN
    return unit[keep]


def physical_stack(F, G, unit, k):
    Fd = F * unit[None, :] / unit[:, None] / WN
    blocks = [G * unit[None, :]]
    for _ in range(k):
        blocks.append(blocks[-1] @ Fd)
    return np.vstack(blocks)


@pytest.fixture(scope="module")
def configs():
    return {c.name: c for c in bias_configurations(P, BIAS_NAMES)}


def test_the_augmented_systems_are_the_hand_typed_ones(configs):
    assert list(configs) == list(HAND)
    for name, (heads, keep_ncz) in HAND.items():
        F, G, _ = hand_system(heads, keep_ncz)
        np.testing.assert_array_equal(configs[name].F, F, err_msg=name)
        # The module orders rows roll, yaw..., h as typed here.
        np.testing.assert_array_equal(configs[name].G, G, err_msg=name)


@pytest.mark.parametrize("name", list(HAND))
def test_ranks_match_an_independent_rank(configs, name):
    """The module's scaled rank progression equals numpy's matrix_rank in physical
    units at every power k, with the margins of the module docstring above."""
    F, G, keep = hand_system(*HAND[name])
    unit = physical_units(keep)
    n = F.shape[0]
    want = []
    for k in range(n):
        M = physical_stack(F, G, unit, k)
        sv = np.linalg.svd(M, compute_uv=False)
        rank = int(np.linalg.matrix_rank(M, tol=TOL * sv[0]))
        want.append(rank)
        rel = sv / sv[0]
        if rank:
            assert rel[rank - 1] > 10 * TOL, (name, k, rel[rank - 1])
        if rank < len(rel):
            assert rel[rank] < 1e-3 * TOL, (name, k, rel[rank])
    assert rank_progression(configs[name].F, configs[name].G).tolist() == want
    assert want[-1] == RANKS[name]


@pytest.mark.parametrize("name", list(HAND))
def test_every_unobservable_direction_is_annihilated_by_every_row(configs, name):
    """n − rank directions, each in the null space of the whole observability matrix:
    in physical units every row r of [G; GF; …; GF^(n−1)] gives |r·z| ≤ 1e-10 ‖r‖ ‖z‖.
    Bound: a computed null vector is accurate to about eps/σ_min (Wedin), σ_min the
    smallest kept relative singular value of the module's scaled matrix: 2e-16/2e-4
    ≈ 1e-12 with yaw measured, 2e-16/1.2e-9 ≈ 2e-7 at worst for the Sun gap's ε³
    directions; measured 7e-15 and 1.1e-11 (G'' with biases).  A wrong vector (a sign,
    a unit) gives ≥ 1e-4."""
    res = {r["name"]: r for r in bias_observability_results(P, BIAS_NAMES)}[name]
    c = configs[name]
    F, G, keep = hand_system(*HAND[name])
    unit = physical_units(keep)
    M = physical_stack(F, G, unit, F.shape[0] - 1)
    assert len(res["directions"]) == F.shape[0] - RANKS[name]
    Z = []
    for d in res["directions"]:
        v = np.zeros(len(c.names))
        for state, coef in d.items():
            v[c.names.index(state)] = coef
        z = v / unit
        Z.append(z)
        bound = 1e-10 * np.linalg.norm(M, axis=1) * np.linalg.norm(z)
        assert np.all(np.abs(M @ z) <= bound + 1e-300), (name, d)
    # ... and they are independent: they span the whole unobservable subspace.
    assert np.linalg.matrix_rank(np.array(Z)) == len(Z)


def test_the_hand_null_vectors_are_the_ones_found(configs):
    """A held roll offset hidden by the roll bias: F_a v = 0, G_a v = 0 (to rounding), in
    every configuration, and the module reports exactly it (to its 1e-6 rounding).
    The held yaw offset hidden by the DSS bias, likewise with yaw from the DSS."""
    n = N_STATES + NB
    roll = np.zeros(n)
    roll[[R, NCX, B_ROLL]] = 1.0, -W0 * H, -1.0
    yaw = np.zeros(n)
    yaw[[Y, NCZ, B_DSS]] = 1.0, -W0 * H, -1.0
    res = {r["name"]: r for r in bias_observability_results(P, BIAS_NAMES)}
    for name, (heads, keep_ncz) in HAND.items():
        F, G, keep = hand_system(heads, keep_ncz)
        for v, applies in ((roll, True), (yaw, heads == ["dss"])):
            if not applies:
                continue
            x = v[keep]
            assert np.max(np.abs(F @ x)) < 1e-18 and np.max(np.abs(G @ x)) == 0.0, name
            pivot = "earth_roll" if v is roll else "dss_yaw"
            got = next(d for d in res[name]["directions"] if pivot in d)
            want = {configs[name].names[i]: -x[i] for i in np.flatnonzero(x)}
            assert set(got) == set(want), (name, got)
            for state, coef in want.items():
                assert got[state] == pytest.approx(coef, rel=1e-6), (name, state)


def test_what_each_bias_can_and_cannot_be_told_from():
    """The findings, as states: the roll bias is never observable alone (always with a
    held roll offset); a head's yaw bias is unobservable outright when that head gives
    no yaw, and only in combination when it alone does; two heads make their
    difference observable (the common part stays with the held yaw offset)."""
    res = {r["name"]: r["status"] for r in bias_observability_results(P, BIAS_NAMES)}
    assert all(st["earth_roll"] == "combined" for st in res.values())
    assert res["G+b dss"] == {"earth_roll": "combined", "dss_yaw": "combined",
                              "cass1_yaw": "unobservable", "cass2_yaw": "unobservable"}
    for gap in ("G''+b", "G'+b"):
        assert [res[gap][b] for b in BIAS_NAMES[1:]] == ["unobservable"] * 3
    assert res["G+b dss|cass1"]["cass2_yaw"] == "unobservable"
    both = next(r for r in bias_observability_results(P, BIAS_NAMES)
                if r["name"] == "G+b dss|cass1")
    common = next(d for d in both["directions"] if "dss_yaw" in d)
    assert common["dss_yaw"] == pytest.approx(common["cass1_yaw"], rel=1e-9)
    # With only the DSS bias a state, yaw from the DSS and (unbiased) CASS1: full rank.
    only = {r["name"]: r for r in bias_observability_results(P, ("dss_yaw",))}
    assert only["G+b dss|cass1"]["full_rank_power"] == 3
    assert only["G+b dss|cass1"]["status"] == {"dss_yaw": "observable"}


def test_the_printed_table_names_the_unobservable_biases(capsys):
    assert main(["observability", "goes_next_equinox", "--biases", "all"]) == 0
    out = capsys.readouterr().out
    # The paper's tables first, unchanged.
    assert out.startswith(format_rank_table(ModelParams(*_scenario_params())))
    blocks = {b.split(" (")[0]: b for b in out.split("\n\n") if b.startswith("G")}
    dss = blocks["G+b dss"]
    assert "cass1_yaw alone: no measurement sees it" in dss
    assert "cass2_yaw alone: no measurement sees it" in dss
    assert "hidden from the measured yaw by dss_yaw = -yaw" in dss
    assert "hidden from the measured roll by earth_roll = -roll" in dss
    gap = blocks["G''+b"]
    for b in ("dss_yaw", "cass1_yaw", "cass2_yaw"):
        assert f"{b} alone: no measurement sees it" in gap
    assert "their differences are observable" in blocks["G+b dss|cass1"]
    assert "never (9/13)" in out and "never (8/13)" in out


def _scenario_params():
    from scenarios.config.build import estimator_model
    from scenarios.config.loader import load_scenario
    p, _ = estimator_model(load_scenario("goes_next_equinox"))
    return (p.Ix_kgm2, p.Iy_kgm2, p.Iz_kgm2, p.H_Nms, p.omega0_radps)


def test_the_scenarios_own_biases_by_default(capsys):
    """Without --biases, the states the scenario switches on; none: the paper's
    tables alone (what the API prints)."""
    main(["observability", "goes_next_equinox", "--set",
          "estimator.bias_states.dss_yaw={model: constant}"])
    out = capsys.readouterr().out
    assert "With sensor-bias states dss_yaw (" in out
    assert "earth_roll" not in out and "cass1_yaw" not in out
    main(["observability", "goes_next_equinox"])
    plain = capsys.readouterr().out
    assert "sensor-bias" not in plain
    p = ModelParams(*_scenario_params())
    assert plain == format_rank_table(p) + "\n"
    assert out == format_rank_table(p, biases=("dss_yaw",)) + "\n"
    assert format_bias_table(p, ("dss_yaw",)) in out


def test_the_augmented_filters_model_is_the_same():
    """``estimator.augmented`` (the filter) builds the same F_a and rows."""
    augmented = pytest.importorskip("estimator.augmented.filter")
    bias = augmented.BiasModel(BIAS_NAMES, (1e-4,) * 4, (0.0,) * 4)
    F, G, _ = hand_system(["dss"], True)
    np.testing.assert_array_equal(augmented.augmented_model(P, bias), F)
    rows = [augmented.measurement_row(bias, "roll"), augmented.measurement_row(bias, "yaw", 0),
            augmented.measurement_row(bias, "h")]
    np.testing.assert_array_equal(np.array(rows), G)
