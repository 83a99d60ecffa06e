"""Sun gaps (``scenarios.samples.sun_gaps``) on synthetic yaw-presence masks, and
what ``summarize`` reports at their ends.

A gap is a run of consecutive samples without a ground yaw, reported as
(a, b): a the first sample without yaw, b the first sample with yaw again (b = N
when the run ends inside the gap), kept when (b − a)·dt ≥ ``min_hours``.  The
summary's "gap end" values are the filter's at sample b: the a-posteriori
estimate after that first yaw update.  Gaps still open at the end of the run have
no end and so no gap-end values.

The Sun-gap edges of a real run are checked against the Sun's hour angle in
tests/scenarios/test_cli_run.py and test_montecarlo_sets.py.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from estimator.linear.model import N_STATES, Y
from scenarios.config import build
from scenarios.config.loader import load_scenario
from scenarios.files.summary import assemble_summary
from scenarios.run.statistics import whole_run_statistics
from scenarios.samples import sun_gaps

DT = 0.512
RAD2DEG = 180.0 / np.pi


def mask(n: int, *missing: tuple[int, int]) -> np.ndarray:
    """Yaw presence of ``n`` samples, absent on each half-open range of ``missing``."""
    present = np.ones(n, dtype=bool)
    for a, b in missing:
        present[a:b] = False
    return present


def brute_force_gaps(present, dt: float, min_hours: float) -> list[tuple[int, int]]:
    """The definition, one sample at a time: the reference for random masks."""
    out, start = [], None
    for k, p in enumerate(list(present) + [True]):     # a sentinel closes an open gap
        if not p and start is None:
            start = k
        elif p and start is not None:
            if (k - start) * dt >= min_hours * 3600:
                out.append((start, k))
            start = None
    return out


# --------------------------------------------------------------------------- sun_gaps


def test_no_gap_when_yaw_is_always_present():
    assert sun_gaps(np.ones(50_000, dtype=bool), DT, 4.0) == []


def test_all_missing_is_one_gap_from_0_to_n_when_long_enough():
    n = 30_000                                 # 4.27 h at 0.512 s
    assert sun_gaps(np.zeros(n, dtype=bool), DT, 4.0) == [(0, n)]
    assert sun_gaps(np.zeros(n, dtype=bool), DT, 4.5) == []


def test_a_run_that_starts_in_a_gap():
    present = mask(40_000, (0, 30_000))
    assert sun_gaps(present, DT, 4.0) == [(0, 30_000)]


def test_a_run_that_ends_in_a_gap_has_end_n():
    present = mask(40_000, (9_000, 40_000))
    assert sun_gaps(present, DT, 4.0) == [(9_000, 40_000)]


def test_min_hours_threshold_is_inclusive():
    """4 h at 0.512 s is exactly 28 125 samples (14 400 / 0.512; the product
    28 125 × 0.512 rounds to 14 400.0 exactly): a gap of that length counts,
    one sample shorter does not."""
    n_4h = 28_125
    for length, counted in ((n_4h - 1, False), (n_4h, True), (n_4h + 1, True)):
        present = mask(40_000, (1_000, 1_000 + length))
        assert sun_gaps(present, DT, 4.0) == ([(1_000, 1_000 + length)] if counted else []), \
            length
    # A threshold that is exact in binary: 1 h of 0.5 s samples is 7 200 of them.
    for length, counted in ((7_199, False), (7_200, True), (7_201, True)):
        present = mask(10_000, (100, 100 + length))
        assert sun_gaps(present, 0.5, 1.0) == ([(100, 100 + length)] if counted else []), \
            length


def test_several_gaps_in_order_short_outages_left_out():
    n = 200_000
    present = mask(n, (0, 29_000),            # starts in a gap: 4.12 h
                   (40_000, 40_500),          # 4 min: not a Sun gap
                   (50_000, 80_000),          # 4.27 h
                   (80_001, 110_000),         # one sample of yaw splits it: 4.27 h again
                   (150_000, 160_000),        # 1.4 h: left out
                   (170_000, n))              # open at the end: 4.27 h
    assert sun_gaps(present, DT, 4.0) == [(0, 29_000), (50_000, 80_000), (80_001, 110_000),
                                          (170_000, n)]


@pytest.mark.parametrize("seed", range(10))
def test_gaps_of_random_masks_match_the_definition(seed):
    """Random outages, some longer than min_hours, starting and ending anywhere."""
    rng = np.random.default_rng(seed)
    n = 20_000
    # Alternating runs of presence and absence with lengths up to ~2× the threshold.
    lengths = rng.integers(1, 1_500, size=60)
    present = np.repeat(np.arange(lengths.size) % 2 == int(rng.integers(2)), lengths)[:n]
    min_hours = 700 * DT / 3600              # 700 samples
    got = sun_gaps(present, DT, min_hours)
    assert got == brute_force_gaps(present, DT, min_hours)
    for a, b in got:
        assert not present[a:b].any()
        assert a == 0 or present[a - 1]        # a: the first sample without yaw
        assert b == len(present) or present[b]  # b: the first sample with yaw again


# --------------------------------------------------------------------------- summarize


def summarize(s, runs, t_s, present, nees_data) -> dict:
    """summary.json's dict of a run held whole, as `dynprop estimate` assembles it."""
    return assemble_summary(s, runs.params, runs.real.backend, runs.truth_model is not None,
                            runs.linear is not None,
                            whole_run_statistics(s, runs, t_s, present, nees_data))


def synthetic_runs(s, n: int, seed: int = 0):
    """A stand-in for ``pipeline.TwoRuns``: every sample's yaw error and σ distinct, so
    that picking the sample before or after a gap end gives another number."""
    rng = np.random.default_rng(seed)
    params, _ = build.estimator_model(s)
    truth = rng.normal(0, 1e-3, (n, N_STATES))
    twin = truth + rng.normal(0, 1e-4, (n, N_STATES))
    sig = rng.uniform(1e-4, 1e-3, (n, N_STATES))

    def filt(reference):
        innov = rng.normal(0, 1e-3, (n, 3))
        var = rng.uniform(1e-6, 2e-6, (n, 3))
        return SimpleNamespace(x=reference + rng.normal(0, 1e-3, (n, N_STATES)), sigma=sig,
                               innovations=innov, innovation_var=var, backend="synthetic")
    real, linear = filt(truth), filt(twin)
    smoothed = SimpleNamespace(x=truth + rng.normal(0, 1e-4, (n, N_STATES)))
    runs = SimpleNamespace(params=params, real=real, linear=linear, smoothed=smoothed,
                           truth_model=truth, twin_model=twin)
    idx = np.arange(0, n, 10)
    nees_data = (idx, rng.chisquare(9, idx.size), rng.chisquare(9, idx.size))
    return runs, nees_data


@pytest.fixture(scope="module")
def short_gaps_scenario():
    # Gaps of ≥ 0.1 h (704 samples) keep the synthetic arrays small.
    return load_scenario("goes_next_equinox", ["estimator.sun_gap_min_h=0.1"])


def test_summary_gap_ends_are_the_filter_values_at_the_first_yaw_sample(short_gaps_scenario):
    """Gap-end error and σ are taken at b, the first sample with yaw again (where the
    filter has just processed that yaw), not at b − 1; the gap open at the end of the
    run has no end and adds nothing to the gap-end lists."""
    s = short_gaps_scenario
    n = 4_000
    gaps = [(0, 800), (1_200, 2_000), (3_000, n)]
    present = mask(n, *gaps, (2_300, 2_400))     # plus a 51 s outage: not a Sun gap
    runs, nees_data = synthetic_runs(s, n)
    out = summarize(s, runs, np.arange(n) * DT, present, nees_data)
    assert out["sun_gaps_h"] == [[a * DT / 3600, b * DT / 3600] for a, b in gaps]
    closed = [800, 2_000]
    err = runs.real.x[:, Y] - runs.truth_model[:, Y]
    err_lin = runs.linear.x[:, Y] - runs.twin_model[:, Y]
    sig = runs.real.sigma[:, Y]
    # A difference and a scaling, a few roundings: 1e-12 still tells every sample from
    # its neighbours, whose values differ at O(1).
    assert out["yaw_error_at_gap_end_deg"] == pytest.approx([err[b] * RAD2DEG for b in closed],
                                                            rel=1e-12)
    assert out["yaw_error_linear_at_gap_end_deg"] == pytest.approx(
        [err_lin[b] * RAD2DEG for b in closed], rel=1e-12)
    assert out["yaw_sigma_at_gap_end_deg"] == pytest.approx([sig[b] * RAD2DEG for b in closed],
                                                            rel=1e-12)
    assert out["yaw_within_3sigma_at_gap_ends"] == all(abs(err[b]) <= 3 * sig[b]
                                                       for b in closed)
    assert out["last_gap_end_sigma_over_eq55"] == pytest.approx(
        sig[2_000] * RAD2DEG / out["analytic_sigma_yaw_deg"], rel=1e-12)


def test_summary_of_a_run_inside_one_gap_has_no_gap_end(short_gaps_scenario):
    s = short_gaps_scenario
    n = 1_000
    runs, nees_data = synthetic_runs(s, n, seed=1)
    out = summarize(s, runs, np.arange(n) * DT, np.zeros(n, dtype=bool), nees_data)
    assert out["sun_gaps_h"] == [[0.0, n * DT / 3600]]
    assert out["yaw_error_at_gap_end_deg"] == []
    assert out["yaw_error_linear_at_gap_end_deg"] == []
    assert out["yaw_sigma_at_gap_end_deg"] == []
    assert out["last_gap_end_sigma_over_eq55"] is None
