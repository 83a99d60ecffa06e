"""comparison.npz and the figure set drawn from it (``scenarios.files.comparison``,
``scenarios.figures.run``): the keys written for each producer (`run` with its linear
twin, `estimate` with or without a truth), the set of figures they give, and
`dynprop plot` redrawing exactly what `dynprop run` drew."""

from __future__ import annotations

import contextlib
import io
import shutil
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from scenarios.cli import main
from scenarios.config.loader import load_scenario
from scenarios.config.schema import resolved_yaml
from scenarios.figures.run import RUN_FIGURES, figure_set, plot_run
from scenarios.files.comparison import ComparisonInputs, comparison_arrays

N = 4000
DT = 0.512
ALWAYS = {"t_s", "yaw_present", "x_real", "sigma", "nis_real"}
TRUTH = {"truth_model", "err_real", "err_smoothed", "nees_real", "true_euler_deg"}
TWIN = {"err_linear", "nees_linear", "err_real_minus_linear"}
TELEMETRY = {"tel_roll_deg", "tel_pitch_deg", "tel_yaw_deg", "tel_yaw_sigma_deg",
             "tel_sun_head", "tel_wheel1_rpm", "tel_wheel2_rpm"}


def _filter_result(rng, n=N):
    innov = rng.standard_normal((n, 3)) * 1e-4
    innov[n // 2:, 1] = np.nan                       # no yaw in the second half
    return SimpleNamespace(x=rng.standard_normal((n, 9)) * 1e-4,
                           sigma=np.full((n, 9), 2e-4), innovations=innov,
                           innovation_var=np.full((n, 3), 1e-8))


def fake_runs(truth: bool, twin: bool, seed: int = 0):
    """What `run` (truth and twin) and `estimate` (no twin; truth optional) hand to
    ``comparison_arrays``, with plausible sizes."""
    rng = np.random.default_rng(seed)
    real = _filter_result(rng)
    truth_model = real.x + rng.standard_normal((N, 9)) * 1e-4 if truth else None
    linear = _filter_result(rng) if twin else None
    twin_model = linear.x + rng.standard_normal((N, 9)) * 1e-4 if twin else None
    euler = rng.standard_normal((N, 3)) * 1e-3 if truth else None
    return ComparisonInputs(-7.3e-5, real, truth_model=truth_model, smoothed_x=real.x * 0.5,
                            linear_x=None if linear is None else linear.x,
                            twin_model=twin_model, true_euler_rad=euler)


def fake_telemetry(n=N, rng=None):
    rng = rng or np.random.default_rng(1)
    head = np.where(np.arange(n) < n // 4, 0.0, np.where(np.arange(n) < n // 2, 1.0, np.nan))
    return {"t_s": np.arange(n) * DT, "roll_deg": rng.normal(0, 0.01, n),
            "pitch_deg": rng.normal(0, 0.01, n),
            "yaw_deg": np.where(np.isnan(head), np.nan, rng.normal(0, 0.5, n)),
            "yaw_sigma_deg": np.where(head == 0, 0.037, 1.0), "sun_head": head,
            "wheel1_rpm": 5485 + rng.normal(0, 0.1, n), "wheel2_rpm": 5485 + rng.normal(0, 0.1, n),
            "dss_alpha_deg": np.zeros(n)}


def arrays(truth: bool, twin: bool, telemetry: bool = True):
    runs = fake_runs(truth, twin)
    t = np.arange(N) * DT
    present = np.arange(N) < N // 2
    idx = np.arange(0, N, 10)
    nees_real = np.full(idx.size, 3.0) if truth else None
    nees_lin = np.full(idx.size, 3.1) if twin else None
    return runs, comparison_arrays(runs, t, present, (idx, nees_real, nees_lin),
                                   fake_telemetry() if telemetry else None)


@pytest.mark.parametrize("truth, twin, expected", [
    (True, True, ALWAYS | TRUTH | TWIN | TELEMETRY),       # dynprop run
    (True, False, ALWAYS | TRUTH | TELEMETRY),             # estimate --truth
    (False, False, ALWAYS | TELEMETRY),                    # estimate
])
def test_comparison_writes_only_the_keys_that_exist(truth, twin, expected):
    _, c = arrays(truth, twin)
    assert set(c) == expected
    assert c["t_s"].dtype == np.float64
    for k, v in c.items():
        assert len(v) == N, k
        assert k == "t_s" or v.dtype == np.float32, k
    assert set(arrays(truth, twin, telemetry=False)[1]) == expected - TELEMETRY


def test_comparison_real_minus_linear_is_differenced_before_rounding():
    """err_real_minus_linear is (x − truth) − (x_lin − twin) in float64, then rounded
    once, in deg (roll, yaw) and N m s (h); err_real − err_linear from the float32
    arrays would round each error first."""
    runs, c = arrays(True, True)
    exact = (runs.real.x - runs.truth_model) - (runs.linear_x - runs.twin_model)
    deg = 180.0 / np.pi
    expected = np.column_stack([exact[:, 0] * deg, exact[:, 2] * deg, exact[:, 4]])
    np.testing.assert_array_equal(c["err_real_minus_linear"], expected.astype(np.float32))


def test_comparison_telemetry_columns_and_length_check():
    _, c = arrays(True, True)
    tel = fake_telemetry()
    np.testing.assert_array_equal(c["tel_sun_head"], tel["sun_head"].astype(np.float32))
    assert "tel_dss_alpha_deg" not in c and "tel_t_s" not in c
    runs = fake_runs(True, True)
    short = {k: v[:-1] for k, v in tel.items()}
    with pytest.raises(ValueError, match="telemetry column"):
        comparison_arrays(runs, np.arange(N) * DT, np.ones(N, bool),
                          (np.arange(0, N, 10), None, None), short)


def test_figure_set_follows_the_keys():
    assert figure_set(ALWAYS | TRUTH | TWIN | TELEMETRY) == [
        "errors.png", "consistency.png", "torques.png", "telemetry_overview.png"]
    assert figure_set(ALWAYS | TRUTH) == ["errors.png", "consistency.png", "torques.png"]
    assert figure_set(ALWAYS | TELEMETRY) == ["estimates.png", "consistency.png",
                                              "torques.png", "telemetry_overview.png"]
    assert set(figure_set(ALWAYS)) <= set(RUN_FIGURES)


def _run_dir(tmp_path: Path, c: dict) -> Path:
    d = tmp_path / "run"
    d.mkdir()
    (d / "scenario.yaml").write_text(resolved_yaml(load_scenario("goes_next_equinox")))
    np.savez(d / "comparison.npz", **c)
    return d


@pytest.mark.parametrize("truth, twin", [(True, True), (True, False), (False, False)])
def test_plot_draws_the_figure_set_of_each_subset(tmp_path, truth, twin):
    """Every subset draws (no key assumed that the producer may not write), and the
    files are exactly ``figure_set`` of the keys; a figure of another set left in
    plots/ (an earlier drawing) is removed."""
    _, c = arrays(truth, twin)
    d = _run_dir(tmp_path, c)
    (d / "plots").mkdir()
    (d / "plots" / "truth.png").write_bytes(b"old")
    written = plot_run(d)
    names = figure_set(c)
    assert sorted(p.name for p in written) == sorted(names)
    assert sorted(p.name for p in (d / "plots").iterdir()) == sorted(names)
    for p in written:
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def run_cli(*argv: str) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = main(list(argv))
    return rc, out.getvalue(), err.getvalue()


def test_plot_redraws_exactly_what_run_drew(tmp_path):
    """`dynprop plot` on a `dynprop run` directory gives the same figure names and
    the same bytes: both go through ``plot_run_figures`` and comparison.npz alone."""
    run = tmp_path / "run"
    rc, _, err = run_cli("run", "goes_next_equinox", "--duration-s", "20000", "--out", str(run))
    assert rc == 0, err
    drawn = {p.name: p.read_bytes() for p in (run / "plots").iterdir()}
    with np.load(run / "comparison.npz") as npz:
        assert sorted(drawn) == sorted(figure_set(npz.files))
    shutil.rmtree(run / "plots")
    rc, stdout, err = run_cli("plot", str(run))
    assert rc == 0, err
    assert sorted(Path(line).name for line in stdout.splitlines()) == sorted(drawn)
    redrawn = {p.name: p.read_bytes() for p in (run / "plots").iterdir()}
    assert redrawn.keys() == drawn.keys()
    for name in drawn:
        assert redrawn[name] == drawn[name], name
