"""`dynprop tune` on telemetry of any length (issue 44): the file read into a few
numbers per sample (``tune.store``) and each likelihood pass stepping through them a
block at a time (``tune.streamed``), held to the whole-file reference
(``tune.source.read_source``, the arrays `dynprop estimate`'s filter reads) with
blocks small enough to cut the files everywhere: inside the Sun gap, inside
dropouts, on jittered tags, through the coarse likelihood's groups of samples and the
hours of the NIS.

Two files from the session's 13 h run (``gap_run``: every sample, a whole night Sun
gap): its telemetry with 40 dropouts of 1 to 60 rows cut out (on the grid: NaN
samples, a bridged wheel torque and its noise), and the same resampled at 1 s ± 20 ms
with a 2 h hole (off the grid: each sample its own interval).  A few seconds.

Planted off-by-ones these were seen failing on: a store block's interval to the next
block's first sample taken one row short; a pass block's state carried from one
sample before its end; an hour's partial NIS sum not carried into the next block."""

from __future__ import annotations

import json
import math
from contextlib import ExitStack
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from scenarios.tune.fit import COARSE, TuneOptions, _likelihood, diagnostics, tune
from scenarios.tune.report import report_dict, run_tune
from scenarios.tune.source import read_source
from scenarios.tune.streamed import open_streamed

from .resample import resample

ROWS = 3_001        # rows per block: no multiple of the grid's hour, COARSE or 4096
PARAMS = ("q_x", "q_z", "q_w")
TIED = {"params": PARAMS, "tie_xz": True}      # two parameters: a quicker fit


@pytest.fixture(scope="module")
def files(gap_run, tmp_path_factory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("tune_blocks")
    lines = (gap_run / "telemetry.csv").read_text().splitlines(keepends=True)
    head = [x for x in lines if x.startswith("#")]
    body = [x for x in lines if not x.startswith("#")]
    rng = np.random.default_rng(44)
    keep = np.ones(len(body) - 1, bool)
    for start in rng.integers(1000, len(keep) - 1000, 40):
        keep[start:start + rng.integers(1, 61)] = False
    grid = folder / "dropouts.csv"
    grid.write_text("".join(head + body[:1] + [r for r, k in zip(body[1:], keep,
                                                                  strict=True) if k]))
    jittered = folder / "jittered.csv"
    resample(gap_run / "telemetry.csv", jittered, gap=(20_000.0, 27_200.0))
    return {"grid": grid, "jittered": jittered}


@pytest.fixture(scope="module")
def opened(files, gap_run, tmp_path_factory):
    """Per file, the whole-file source and the streamed one in blocks of ``ROWS``."""
    scenario = gap_run / "scenario.yaml"
    out, folders = {}, []
    with ExitStack() as stack:
        for kind, path in files.items():
            folder = tmp_path_factory.mktemp("scratch") / kind
            folders.append(folder)
            out[kind] = (read_source(path, scenario),
                         stack.enter_context(open_streamed(path, scenario, folder=folder,
                                                           block_rows=ROWS)))
        yield out
    assert not any(f.exists() for f in folders)    # the scratch files go with the source


@pytest.fixture(params=["grid", "jittered"])
def sources(request, opened):
    return (request.param, *opened[request.param])


def _cat(samples, n: int) -> tuple[list[np.ndarray], np.ndarray | None]:
    """Every sample of ``samples``, read in blocks of ``ROWS`` and joined."""
    parts = [samples.block(a, min(a + ROWS, n)) for a in range(0, n, ROWS)]
    inputs = [np.concatenate(col) for col in zip(*(p[0] for p in parts), strict=True)]
    return inputs, None if parts[0][1] is None else np.concatenate([p[1] for p in parts])


@pytest.mark.parametrize("every", [1, COARSE])
def test_the_streamed_samples_are_the_whole_files_bit_for_bit(sources, every):
    """Each input of the likelihood's step (z, the update mask, the variances, ū, the
    bridge noise) and, off the grid, each step's interval, of every sample or of the
    coarse filter's every 8th: the whole file's arrays exactly."""
    kind, whole, streamed = sources
    ref, samples = whole.samples(every), streamed.samples(every)
    assert samples.n == ref.n
    got, dt = _cat(samples, ref.n)
    for a, b in zip(got, ref.inputs, strict=True):
        np.testing.assert_array_equal(a, b)
    if kind == "grid":
        assert dt is None and ref.inputs[4].max() > 0     # dropouts bridged, with noise
    else:
        np.testing.assert_array_equal(dt, ref.dt)
        short = dt[dt < 2 * every]
        assert np.ptp(short) > 0.03 and dt.max() > 7000     # jittered, and the hole
    np.testing.assert_array_equal(samples.counts, ref.counts)


@pytest.mark.parametrize("every", [1, COARSE])
def test_passes_in_blocks_equal_one_pass_over_the_whole_file(sources, every):
    """ln L, its score and information, and the innovations at the scenario's noise:
    one pass over the whole file's arrays against passes over the streamed samples in
    blocks of ``ROWS``, the filter's state carried across: equal bit for bit."""
    _, whole, streamed = sources
    opts = TuneOptions(params=PARAMS)
    one = _likelihood(replace(whole, block=whole.n), opts, every)
    blocked = _likelihood(streamed, opts, every)
    assert blocked.block == ROWS < blocked.n_samples and one.block >= one.n_samples
    theta = one.model.theta_of(whole.noise)
    a, b = one.score(theta), blocked.score(theta)
    assert a.loglik == b.loglik and math.isfinite(a.loglik)
    np.testing.assert_array_equal(a.score, b.score)
    np.testing.assert_array_equal(a.fisher, b.fisher)
    for x, y in zip(one.innovations(theta), blocked.innovations(theta), strict=True):
        np.testing.assert_array_equal(x, y)


def _without_timing(d: dict) -> dict:
    d = json.loads(json.dumps(d))
    d["optimizer"].pop("seconds")
    return d


@pytest.fixture(scope="module")
def tuned_grid(opened):
    """``tune`` of the grid file, whole and streamed."""
    whole, streamed = opened["grid"]
    opts = TuneOptions(**TIED)
    return tune(whole, opts), tune(streamed, opts)


def test_the_streamed_tune_is_the_whole_files(tuned_grid):
    """The whole fit (the maximum, σ, limits, profiles, before and after) on the streamed
    source in blocks of ``ROWS`` against the whole file's: tune.json's dictionary equal
    but for the innovations' autocorrelation, which for a series longer than a block
    is summed piece by piece (``LaggedProducts``): ρ within 1e-14 of the whole-series
    FFT's, whose rounding is ~1e-16 of ρ(0) = 1; NIS means, ln L and the NIS per hour
    are the whole series' sums bit for bit.  On the grid file (dropouts in blocks);
    the jittered file's passes and diagnostics are held to the whole file's above and
    below."""
    a, b = tuned_grid
    da, db = _without_timing(report_dict(a)), _without_timing(report_dict(b))
    for side in ("before", "after"):
        for kind in ("roll", "yaw", "h"):
            wa, wb = da[side]["whiteness"].pop(kind), db[side]["whiteness"].pop(kind)
            assert wa["lags"] == wb["lags"] and wa["first_lag"] == wb["first_lag"]
            for key in ("rho_1", "max_abs_rho", "fraction_outside"):
                assert wb[key] == pytest.approx(wa[key], rel=0, abs=1e-14), (side, kind, key)
            np.testing.assert_allclose(getattr(b, side).rho[kind], getattr(a, side).rho[kind],
                                       rtol=0, atol=1e-14)
            ha, hb = getattr(a, side).hourly_nis[kind], getattr(b, side).hourly_nis[kind]
            np.testing.assert_array_equal(ha[0], hb[0])
            np.testing.assert_array_equal(ha[1], hb[1])
            assert len(ha[1]) >= 12     # 13 h: the whole hours
    assert da == db


def test_the_command_leaves_no_scratch_and_writes_what_the_whole_files_tune_does(
        files, gap_run, tuned_grid, tmp_path):
    """`dynprop tune` (``run_tune``) with small blocks writes tune.json as the whole
    file's tune reports it (but the command and the seconds), and its stage's scratch
    files (the store, the telemetry reader's) are gone: the output holds its four
    files only."""
    scenario = gap_run / "scenario.yaml"
    opts = TuneOptions(**TIED)
    out = tmp_path / "tune"
    d, _ = run_tune(files["grid"], scenario, out=out, options=opts, block_rows=ROWS)
    assert sorted(p.name for p in out.iterdir()) == ["tune.json", "tune.md", "tune.png",
                                                     "tuned_noise.yaml"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["tune"]
    ref = _without_timing(report_dict(tuned_grid[0]))
    got = _without_timing(json.loads((out / "tune.json").read_text()))
    for side in ("before", "after"):
        for kind in ("roll", "yaw", "h"):
            for key in ("rho_1", "max_abs_rho"):
                assert got[side]["whiteness"][kind][key] == pytest.approx(
                    ref[side]["whiteness"][kind][key], rel=0, abs=1e-14)
                got[side]["whiteness"][kind][key] = ref[side]["whiteness"][kind][key]
    assert got == json.loads(json.dumps(ref))


def test_diagnostics_of_one_block_are_the_whole_series_bit_for_bit(sources):
    """The innovations in blocks of ``ROWS`` (the hours' sums carried across them) and
    the autocorrelation in one piece, as by default up to 2^19 samples (three days at
    0.512 s): the streamed diagnostics, NIS per hour and autocorrelation included,
    equal the whole file's exactly."""
    _, whole, streamed = sources
    opts = TuneOptions(params=PARAMS)
    lik = _likelihood(whole, opts, 1)
    theta = lik.model.theta_of(whole.noise)
    one = diagnostics(lik, theta, whole, whole.noise, 1.0)
    blocked = diagnostics(_likelihood(streamed, opts, 1), theta,
                          _Span(streamed, lik.n_samples), whole.noise, 1.0)
    assert one.whiteness == blocked.whiteness and one.nis == blocked.nis
    assert one.loglik == blocked.loglik
    for kind in one.rho:
        np.testing.assert_array_equal(one.rho[kind], blocked.rho[kind])
        for x, y in zip(one.hourly_nis[kind], blocked.hourly_nis[kind], strict=True):
            np.testing.assert_array_equal(x, y)


class _Span:
    """``streamed`` with its autocorrelation in one piece of ``span`` samples."""

    def __init__(self, streamed, span: int):
        self._s, self.span = streamed, span

    def __getattr__(self, name):
        return getattr(self._s, name)
