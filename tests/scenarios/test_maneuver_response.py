"""The scenario's response to the telemetry's maneuver flag (``estimator.maneuver``)
through the bridge, the run's filters and their windows, on run6's telemetry.csv with a
flag column added.  The filter's own response is tested against independent
references in tests/estimator/test_maneuver.py; here: the flag reaches every filter
and window of a run as the scenario says, and without it (or ignored) nothing moves."""

from __future__ import annotations

import numpy as np
import pytest

from estimator.linear.transition import discretize
from scenarios.bridge.inputs import (
    filter_inputs,
    initial_prior,
    padded_filter_inputs,
    telemetry_inputs,
)
from scenarios.config import build
from scenarios.config.loader import load_scenario
from scenarios.files.telemetry_file import read_telemetry
from scenarios.run.ekf import other_filters
from scenarios.run.filtering import design_of, paper_filter, paper_smoother
from scenarios.run.whole import filter_telemetry

FLAGGED = slice(12_000, 12_600)      # 5 min 7 s of firing at 0.512 s, 1.7 h in
N = 24_000                           # the first 3.4 h of run6


def _scenario(*sets: str):
    return load_scenario("goes_next_equinox", list(sets))


@pytest.fixture(scope="module")
def columns(run6):
    s = _scenario()
    cols = read_telemetry(run6 / "telemetry.csv", s)
    cols = {k: v[:N] for k, v in cols.items()}
    flag = np.zeros(N)
    flag[FLAGGED] = 1.0
    return cols, flag


def _filter(s, cols, flag):
    params, noise = build.estimator_model(s)
    disc = discretize(params, noise, s.sample_interval_s)
    tel = telemetry_inputs(s, cols | ({} if flag is None else {"maneuver": flag}))
    result, args = filter_telemetry(s, params, disc, *tel)
    return result, paper_smoother(design_of(s), result, disc, **args)


BIASES = "estimator.bias_states.earth_roll.model=constant"


@pytest.mark.parametrize("sets", [(), (BIASES,)], ids=["paper", "bias states"])
def test_a_flag_ignored_or_never_set_changes_no_bit_and_one_honoured_does(columns, sets):
    """With ``ignore``, or a flag that is never set, the filter and smoother are those
    of the telemetry without the column, bit for bit; with ``inflate`` and ``reset``
    the yaw σ right after the stretch is larger than without (the paper's filter and
    the one with bias states alike)."""
    cols, flag = columns
    plain = _filter(_scenario(*sets), cols, None)
    for response, f in (("ignore", flag), ("inflate", np.zeros(N))):
        got = _filter(_scenario(*sets, f"estimator.maneuver.response={response}"), cols, f)
        for a, b in zip(got, plain, strict=True):
            assert np.array_equal(a.x, b.x) and np.array_equal(a.P_packed, b.P_packed)
    after = FLAGGED.stop + 1
    for response in ("inflate", "reset"):
        f, sm = _filter(_scenario(*sets, f"estimator.maneuver.response={response}"), cols,
                        flag)
        assert f.sigma[after, 2] > 1.5 * plain[0].sigma[after, 2], response
        assert np.all(np.isfinite(sm.x)) and np.all(np.isfinite(sm.sigma))
        assert np.array_equal(f.x[:FLAGGED.start], plain[0].x[:FLAGGED.start])


def test_streamed_windows_carry_the_reset_across_a_cut(columns):
    """A window cut right after the flagged stretch: each window's inputs formed from
    its telemetry padded with its neighbours' (as a streamed run and the twin's filter
    form them) carry the reset into the next window, and the windows' filter, each
    from the prior the one before ended with, is the whole run's."""
    cols, flag = columns
    s = _scenario("estimator.maneuver.response=reset")
    params, noise = build.estimator_model(s)
    disc = discretize(params, noise, s.sample_interval_s)
    tel = telemetry_inputs(s, cols | {"maneuver": flag})
    meas, u, extra = filter_inputs(s, params, *tel)
    design = design_of(s)
    whole = paper_filter(design, meas, disc, *initial_prior(s, params), u=u, extra=extra)
    pad, cut = 200, FLAGGED.stop
    first = padded_filter_inputs(s, params, None, tel.cut(slice(0, cut)),
                                 tel.cut(slice(cut, N)), pad)
    second = padded_filter_inputs(s, params, tel.cut(slice(cut - pad, cut)),
                                  tel.cut(slice(cut, N)), None, pad)
    assert first[2].maneuver.reset[-1]          # the reset, known from the padding
    prior, xs = initial_prior(s, params), []
    for m, uu, ex in (first, second):
        r = paper_filter(design, m, disc, *prior, u=uu, extra=ex)
        prior = (r.x_next, r.P_next)
        xs.append(r.x)
    assert np.array_equal(np.vstack(xs), whole.x)


def test_the_ekf_reads_the_flag_from_the_columns(columns):
    """`estimate`'s other filters (the EKF) take the flag from the file's column: ignored,
    their bits are those without it; reset, the roll and yaw σ after the stretch grow."""
    cols, flag = columns
    sets = ("estimator.filters=[paper, ekf]",)
    plain = other_filters(_scenario(*sets), cols)["ekf"]
    ignored = other_filters(_scenario(*sets, "estimator.maneuver.response=ignore"),
                            cols | {"maneuver": flag})["ekf"]
    assert np.array_equal(ignored.x, plain.x)
    reset = other_filters(_scenario(*sets, "estimator.maneuver.response=reset"),
                          cols | {"maneuver": flag})["ekf"]
    after = FLAGGED.stop + 1
    assert reset.sigma[after, 2] > 1.5 * plain.sigma[after, 2]
    assert np.array_equal(reset.x[:FLAGGED.start], plain.x[:FLAGGED.start])
