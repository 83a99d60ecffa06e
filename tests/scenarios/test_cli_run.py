"""`dynprop run`, `estimate` and `plot` end to end through ``scenarios.cli.main``
(docs/outputs.md: the run directory, summary.json, exit codes), plus the
filter-consistency and real-versus-linear properties the run exists to show.

Runs are kept short (10 min to 13 h) so the module takes well under a minute.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy import stats

from estimator.kalman.consistency import chi2_bounds, fraction_inside, nees
from estimator.kalman.filter import unpack
from scenarios.cli import main
from scenarios.config.loader import load_scenario
from scenarios.files.columns import STATE_COLUMNS
from scenarios.files.csvio import read_csv
from scenarios.run.whole import run_scenario

from .mc_helpers import predicted_sun_gaps_h

DT = 0.512
# Storage precision of the run's files, for numbers recomputed from them:
# truth.csv and estimate.csv hold 10 significant digits (%.10g: each value within
# 5e-10 of itself); comparison.npz holds float32 (round to nearest: within 2⁻²⁴).
CSV_REL = 5e-10
F32_REL = 2.0**-24
RUN_FILES = {"scenario.yaml", "truth.csv", "telemetry.csv", "estimate.csv", "summary.json",
             "comparison.npz", "daily.csv", "plots"}
# The runs here write every sample (the default output.interval_s is 64 s): their
# files are recomputed against the run's summary and re-filtered row for row.
FULL_RATE = ("--set", f"output.interval_s={DT}")
RUN_FIGURES = {"errors.png", "consistency.png", "torques.png", "telemetry_overview.png"}
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
# 17:00 local at 75° W on the equinox: the night Sun gap (~20:08–04:00 local) falls
# 3.25–11.1 h into the run, so a 13 h run holds one whole gap and its end.
GAP_EPOCH = "epoch_utc=2026-03-20T22:00:00Z"

def run_cli(*argv: str) -> tuple[int, str, str]:
    """``main(argv)`` with its stdout and stderr captured (usable in module fixtures)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = main(list(argv))
    return rc, out.getvalue(), err.getvalue()


def run_dir(tmp_path_factory, name: str, scenario: str, duration_s: float,
            *extra: str) -> tuple[Path, str]:
    out = tmp_path_factory.mktemp(name) / "run"
    rc, stdout, stderr = run_cli("run", scenario, "--duration-s", str(duration_s),
                                 "--out", str(out), *FULL_RATE, *extra)
    assert rc == 0, stderr
    return out, stdout


def summary(run: Path) -> dict:
    def non_finite(constant):
        raise AssertionError(f"summary.json holds {constant}")
    return json.loads((run / "summary.json").read_text(), parse_constant=non_finite)


def eq55_sigma_deg(resolved: dict) -> float:
    """σ_yaw ≈ √(q/(ω0 H²)) (Eq. 55) from the run's scenario, computed independently."""
    pn = resolved["estimator"]["process_noise"]
    q = 0.5 * (pn["q_x"] + pn["q_z"])
    w = resolved["spacecraft"]["wheels"]
    H = -w["spin_inertia_kgm2"] * 2 * w["speed_rpm"] * math.pi / 30 \
        * math.cos(math.radians(w["cant_deg"]))
    omega0 = math.sqrt(3.986004418e14 / resolved["orbit"]["radius_m"] ** 3)
    return math.degrees(math.sqrt(q / (omega0 * H**2)))


def assert_one_line(err: str) -> str:
    assert err.endswith("\n") and err.count("\n") == 1, f"stderr is not one line: {err!r}"
    assert "Traceback" not in err
    return err


@pytest.fixture(scope="module")
def short_run(tmp_path_factory) -> tuple[Path, str]:
    """10 minutes of the default scenario (no Sun gap)."""
    return run_dir(tmp_path_factory, "short", "goes_next_equinox", 600)


@pytest.fixture(scope="module")
def hour_run(tmp_path_factory) -> Path:
    return run_dir(tmp_path_factory, "hour", "goes_next_equinox", 3600)[0]


# --------------------------------------------------------------------------- the run directory


def test_run_writes_every_file_of_the_contract(short_run):
    run, stdout = short_run
    assert {p.name for p in run.iterdir()} == RUN_FILES
    assert {p.name for p in (run / "plots").iterdir()} == RUN_FIGURES
    for name in RUN_FIGURES:
        png = (run / "plots" / name).read_bytes()
        assert png.startswith(PNG_MAGIC) and len(png) > 20_000, name
    for name in RUN_FILES - {"plots", "daily.csv"}:
        assert (run / name).stat().st_size > 1_000, name
    assert len(read_csv(run / "daily.csv")["day"]) == 1   # ten minutes: one (partial) day
    # The summary on stdout names the figures directory.
    assert "yaw error RMS" in stdout
    assert f"{run}/plots" in stdout


def test_estimate_csv_has_every_state_with_units_and_sigmas(short_run):
    run, _ = short_run
    header = (run / "estimate.csv").read_text().split("\n", 1)[0].split(",")
    names = ("roll_deg", "roll_rate_degps", "yaw_deg", "yaw_rate_degps", "h_Nms",
             "N_px_Nm", "N_pz_Nm", "N_cx_Nm", "N_cz_Nm")
    assert STATE_COLUMNS == names
    # The pitch filter's states (Eq. 3b) after the paper's 9.
    pitch = ("pitch_deg", "pitch_rate_degps", "N_y_Nm")
    assert header == ["t_s", *names, *(f"sigma_{n}" for n in names),
                      *pitch, *(f"sigma_{n}" for n in pitch)]
    names = names + pitch
    est, tel = read_csv(run / "estimate.csv"), read_csv(run / "telemetry.csv")
    assert len(est["t_s"]) == len(tel["t_s"]) == math.ceil(600 / DT)
    # k·0.512 s has at most 8 significant digits: %.10g and the shortest round-trip
    # text both read back as the same double; the tolerance only allows the last bit.
    np.testing.assert_allclose(est["t_s"], tel["t_s"], rtol=1e-12, atol=1e-9)
    for name in names:
        assert np.isfinite(est[name]).all(), name
        sigma = est[f"sigma_{name}"]
        assert np.isfinite(sigma).all() and (sigma > 0).all(), name


# --------------------------------------------------------------------------- summary.json


def test_summary_has_the_design_keys_and_only_finite_numbers(short_run, gap_run):
    nees_bounds, nis_bounds = chi2_bounds(9), chi2_bounds(1)
    for run in (short_run[0], gap_run):
        s = summary(run)
        resolved = yaml.safe_load((run / "scenario.yaml").read_text())

        def finite(v, where="summary"):
            if isinstance(v, dict):
                for k, x in v.items():
                    finite(x, f"{where}.{k}")
            elif isinstance(v, list):
                for x in v:
                    finite(x, where)
            elif isinstance(v, int | float) and not isinstance(v, bool):
                assert math.isfinite(v), where

        finite(s)
        ends, sigmas = s["yaw_error_at_gap_end_deg"], s["yaw_sigma_at_gap_end_deg"]
        assert isinstance(ends, list) and len(ends) == len(sigmas)
        # Eq. 55 with q = (q_x + q_z)/2, H = −I_w·2Ω·cos(cant), ω0 = √(μ/R³): ≈ 0.0397°.
        assert s["analytic_sigma_yaw_deg"] == pytest.approx(eq55_sigma_deg(resolved), rel=1e-6)
        assert s["analytic_sigma_yaw_deg"] == pytest.approx(0.0397, abs=5e-5)
        assert s["nees_dof"] == 9
        assert s["nees_bounds_95_per_sample"] == pytest.approx(nees_bounds)
        assert s["nees_bounds_95_per_sample"] == pytest.approx([2.700, 19.023], abs=1e-3)
        assert set(s["nis_mean"]) == set(s["nis_mean_linear"]) == {"roll", "yaw", "h"}
        assert s["nis_bounds_95_per_sample"] == pytest.approx(nis_bounds)
        assert set(s["nonlinear_vs_linear"]) == {"roll_deg", "yaw_deg", "h_Nms"}
        # The numbers themselves: test_summary_numbers_are_those_of_the_written_files.
    assert summary(gap_run)["yaw_error_at_gap_end_deg"], "the 13 h run must end a Sun gap"
    assert summary(short_run[0])["yaw_error_at_gap_end_deg"] == []


def test_the_sun_gap_is_where_the_hour_angle_leaves_the_sun_sensors(gap_run):
    """The night gap of 17:00–06:00 local at 75° W on the equinox, against the Sun's
    hour angle computed from first principles (Meeus's equation of time, see
    ``predicted_sun_gaps_h``): the DSS loses the Sun at hour angle 90° + 32° = 122°
    (3.254 h into the run) and CASS1 finds it at −75° − 45° = −120° (11.122 h).

    ±2 min: the prediction is for zero attitude and neglects GEO parallax, nutation
    and UT1 − UTC; measured 0.4 s at the start and 7.9 s at the end (the run's
    attitude, a few hundredths of a degree of pitch: 0.01° is 2.4 s)."""
    s = summary(gap_run)
    scenario = load_scenario(gap_run / "scenario.yaml")
    (predicted,) = predicted_sun_gaps_h(scenario)
    assert predicted == pytest.approx((3.254, 11.12), abs=0.01)     # the numbers
    (gap,) = s["sun_gaps_h"]
    assert gap == pytest.approx(predicted, abs=2 / 60)
    # The gap's edges are the telemetry's: the first sample without yaw, the first with
    # yaw again (t_s is written exactly).
    tel = read_csv(gap_run / "telemetry.csv")
    present = np.isfinite(tel["yaw_deg"])
    a, b = (int(round(h * 3600 / DT)) for h in gap)
    assert present[a - 1] and not present[a:b].any() and present[b]
    # k·dt / 3600 both ways: a product and a quotient, a few ulps.
    assert gap == pytest.approx([tel["t_s"][a] / 3600, tel["t_s"][b] / 3600], rel=1e-12)


def test_yaw_error_is_within_3_sigma_at_the_end_of_a_whole_sun_gap(gap_run):
    s = summary(gap_run)
    duration_h = s["duration_s"] / 3600
    # One whole gap: it starts after the run does and ends before it stops.
    assert len(s["sun_gaps_h"]) == 1
    start_h, end_h = s["sun_gaps_h"][0]
    assert 0 < start_h and end_h < duration_h
    ends, sigmas = s["yaw_error_at_gap_end_deg"], s["yaw_sigma_at_gap_end_deg"]
    assert len(ends) == 1
    assert s["yaw_within_3sigma_at_gap_ends"] is True
    for err, sig in zip(ends, sigmas, strict=True):
        assert abs(err) <= 3 * sig, (err, sig)
        # Within 50% of Eq. 55: the 9-state filter with a daily 8 h gap settles at about
        # 0.041° (periodic solution) against Eq. 55's 0.0397°, and this is the first gap
        # after start-up, where the torque states are still poorly known and σ is larger
        # (measured 0.055°, 1.39 × Eq. 55).
        assert 0.5 <= sig / s["analytic_sigma_yaw_deg"] <= 1.5, sig


def _rms_and_bound(a, b, rel_a, rel_b) -> tuple[float, float]:
    """RMS of a − b and how far it can be from the RMS of the exact values when each
    stored value is within ``rel`` of itself: |rms(x) − rms(y)| ≤ rms(x − y)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    rms = math.sqrt(np.mean((a - b) ** 2))
    bound = math.sqrt(np.mean((rel_a * np.abs(a) + rel_b * np.abs(b)) ** 2))
    return rms, bound + 1e-12 * rms   # + the float64 sums


@pytest.mark.parametrize("which", ["short_run", "gap_run"])
def test_summary_numbers_are_those_of_the_written_files(request, which):
    """summary.json recomputed from estimate.csv, truth.csv, telemetry.csv and
    comparison.npz.  Each tolerance is the storage precision of the file used
    (see CSV_REL, F32_REL) propagated to the figure, plus 1e-12 for float64 sums:
    about 1e-9 relative for the roll and yaw RMS (measured 1e-12–2e-13), 6e-8 for
    the means of float32 NEES and NIS (measured ≤ 5e-10).  The full-precision
    covariance and innovations are not written, so NEES and NIS are recomputed from
    their float32 series; the yaw, roll and h errors from the 10-digit CSVs."""
    run = request.getfixturevalue(which)
    run = run[0] if isinstance(run, tuple) else run
    s = summary(run)
    est, tru = read_csv(run / "estimate.csv"), read_csv(run / "truth.csv")
    tel = read_csv(run / "telemetry.csv")
    with np.load(run / "comparison.npz") as npz:
        c = {k: npz[k].astype(float) for k in npz.files}
    n = len(est["t_s"])
    assert len(tru["t_s"]) == len(tel["t_s"]) == len(c["t_s"]) == n

    # RMS of the filter error, every sample (deg; h in N m s).
    for key, col in (("yaw_error_rms_deg", "yaw_deg"), ("roll_error_rms_deg", "roll_deg"),
                     ("h_error_rms_Nms", "h_Nms")):
        rms, tol = _rms_and_bound(est[col], tru[col], CSV_REL, CSV_REL)
        assert s[key] == pytest.approx(rms, rel=0, abs=tol), (key, tol / rms)
    for key, k, err in (("yaw_error_rms_linear_deg", 2, "err_linear"),
                        ("yaw_error_rms_smoothed_deg", 2, "err_smoothed")):
        rms = math.sqrt(np.mean(c[err][:, k] ** 2))
        assert s[key] == pytest.approx(rms, rel=F32_REL + 1e-12), key
    for name, k in (("roll_deg", 0), ("yaw_deg", 2), ("h_Nms", 4)):
        row, real, lin = s["nonlinear_vs_linear"][name], c["err_real"][:, k], \
            c["err_linear"][:, k]
        assert row["rms_real"] == pytest.approx(math.sqrt(np.mean(real**2)),
                                                rel=F32_REL + 1e-12), name
        assert row["rms_linear"] == pytest.approx(math.sqrt(np.mean(lin**2)),
                                                  rel=F32_REL + 1e-12), name
        # For h the two errors agree to 5e-14 N m s, below the float32 resolution of the
        # errors themselves (1e-12): there this only bounds the summary's number.
        rms, tol = _rms_and_bound(real, lin, F32_REL, F32_REL)
        assert row["rms_difference"] == pytest.approx(rms, rel=0, abs=tol), name
        worst = np.abs(real - lin)
        assert row["max_abs_difference"] == pytest.approx(
            worst.max(), rel=0, abs=F32_REL * (np.abs(real) + np.abs(lin)).max()), name

    # NEES: the stored series holds it on a regular stride from the first sample;
    # the mean and the per-state (e/σ)² are taken on those samples.
    rows = np.flatnonzero(np.isfinite(c["nees_real"]))
    assert rows[0] == 0 and len(set(np.diff(rows))) == 1
    assert np.array_equal(rows, np.flatnonzero(np.isfinite(c["nees_linear"])))
    assert s["nees_mean"] == pytest.approx(c["nees_real"][rows].mean(), rel=F32_REL + 1e-12)
    assert s["nees_mean_linear"] == pytest.approx(c["nees_linear"][rows].mean(),
                                                  rel=F32_REL + 1e-12)
    # (e/σ)² of a float32 e and σ: within 4·2⁻²⁴ of the exact ratio.
    per_state = np.mean((c["err_real"][rows] / c["sigma"][rows]) ** 2, axis=0)
    # Labelled by estimate.csv's columns, in the state order.
    assert list(s["nees_mean_per_state"]) == list(STATE_COLUMNS)
    assert list(s["nees_mean_per_state"].values()) == pytest.approx(per_state.tolist(),
                                                                     rel=4 * F32_REL + 1e-12)
    lo, hi = s["nees_bounds_95_per_sample"]
    for key, series in (("nees_fraction_inside_95", c["nees_real"][rows]),
                        ("nees_fraction_inside_95_linear", c["nees_linear"][rows])):
        inside = np.mean((series >= lo) & (series <= hi))
        # A float32 value within 2⁻²⁴ of a bound may sit on the other side of it.
        edge = np.sum(np.minimum(np.abs(series - lo) / lo, np.abs(series - hi) / hi)
                      <= F32_REL) / rows.size
        assert s[key] == pytest.approx(inside, rel=0, abs=edge + 1e-12), key

    # NIS: ν²/S of every update made (the stored series is NaN where none was).
    for i, m in enumerate(("roll", "yaw", "h")):
        v = c["nis_real"][:, i]
        v = v[np.isfinite(v)]
        assert s["nis_mean"][m] == pytest.approx(v.mean(), rel=F32_REL + 1e-12), m
    # Yaw updates happen exactly where the telemetry has a yaw; roll and h every sample.
    assert np.array_equal(np.isfinite(c["nis_real"][:, 1]), np.isfinite(tel["yaw_deg"]))
    assert np.isfinite(c["nis_real"][:, [0, 2]]).all()

    # The gap ends: the filter's values at b, the first sample with yaw again, the
    # estimate after processing that yaw (it has just lowered σ).
    ends = [int(round(b * 3600 / DT)) for _, b in s["sun_gaps_h"]]
    ends = [b for b in ends if b < n]
    assert len(s["yaw_error_at_gap_end_deg"]) == len(ends)
    for b, err, sig in zip(ends, s["yaw_error_at_gap_end_deg"], s["yaw_sigma_at_gap_end_deg"],
                           strict=True):
        assert np.isnan(c["nis_real"][b - 1, 1]) and np.isfinite(c["nis_real"][b, 1])
        e = est["yaw_deg"][b] - tru["yaw_deg"][b]
        assert err == pytest.approx(e, rel=0, abs=CSV_REL * (abs(est["yaw_deg"][b])
                                                             + abs(tru["yaw_deg"][b])) + 1e-15)
        assert sig == pytest.approx(est["sigma_yaw_deg"][b], rel=CSV_REL)
        assert est["sigma_yaw_deg"][b] < est["sigma_yaw_deg"][b - 1] * (1 - 1e-6)


# --------------------------------------------------------------------------- NEES, linear twin


FINE_HEAD = "{quantum_deg: 0.0001, noise_deg: 0.01}"
MATCHED = [
    "duration_s=14400", "epoch_utc=2026-03-20T12:00:00Z",   # 07:00–11:00 local: Sun all along
    "environment.gravity_gradient.enabled=false", "environment.solar.enabled=false",
    "environment.magnetic.enabled=false", "environment.ripple.enabled=false",
    "control.enabled=false",
    f"sensors.sun.dss={FINE_HEAD}", f"sensors.sun.cass1={FINE_HEAD}",
    f"sensors.sun.cass2={FINE_HEAD}",
    # Small but not zero; q_w covers the Savitzky–Golay N_w* noise from the tachometers.
    "estimator.process_noise={q_x: 1e-12, q_z: 1e-12, q_w: 3e-12, "
    "q_px: 1e-20, q_pz: 1e-20, q_cx: 1e-20, q_cz: 1e-20}",
]
NEES_SEEDS = range(1, 13)


def test_linear_twin_nees_is_consistent_when_the_model_matches():
    """The filter on the linear twin, with nothing unmodelled, is χ²-consistent.

    NEES over the attitude, rate and h states (0–4) only: the torque states 5–8 are
    exactly zero in this torque-free truth and stay prior-dominated, so their errors
    sit far inside their σ and would make the NEES trivially conservative.

    Pooled over 12 seeds (a Monte-Carlo NEES): the errors are correlated over hours,
    so one 3 h window holds few independent samples.  Over 60 seeds the single-run
    mean scatters from 2.4 to 7.2 (5–95 %; the default seed gives 2.9) while the
    pooled mean is 4.5.  Pooling steadies the estimate; the bounds are not widened.
    """
    values, normalized = [], []
    for seed in NEES_SEEDS:
        runs = run_scenario(load_scenario("goes_next_equinox", [*MATCHED, f"seed={seed}"]))
        n = len(runs.linear.x)
        idx = np.arange(n // 4, n, 10)   # after the first hour (convergence), every 5 s
        P = unpack(runs.linear.P_packed[idx])
        x_hat, x_true = runs.linear.x[idx], runs.twin_model[idx]
        values.append(nees(x_hat, P, x_true, states=range(5)))
        sig = np.sqrt(np.diagonal(P, axis1=1, axis2=2))
        normalized.append(((x_hat - x_true) / sig)[:, :5] ** 2)
    v = np.concatenate(values)
    per_state = np.round(np.concatenate(normalized).mean(axis=0), 2)
    lo, hi = stats.chi2.ppf([0.025, 0.975], 5)
    inside = fraction_inside(v, (lo, hi))
    detail = f"mean {v.mean():.2f}, inside {inside:.3f}, e²/σ² per state {per_state}"
    assert inside >= 0.85, detail
    assert 5 / 1.5 <= v.mean() <= 5 * 1.5, detail


# --------------------------------------------------------------------------- dynprop estimate


def _estimate(run: Path, out: Path) -> tuple[int, str, str]:
    return run_cli("estimate", str(run / "telemetry.csv"), "--scenario",
                   str(run / "scenario.yaml"), "--out", str(out))


def test_estimate_reproduces_the_runs_estimate_csv_byte_for_byte(hour_run, tmp_path):
    """Identity is the requirement here: `dynprop estimate` on a run's telemetry.csv
    is the run's filter on the same doubles, on the same machine."""
    rc, _, err = _estimate(hour_run, tmp_path / "est")
    assert rc == 0, err
    assert (tmp_path / "est" / "estimate.csv").read_bytes() \
        == (hour_run / "estimate.csv").read_bytes()


def _telemetry_lines(run: Path) -> list[str]:
    """telemetry.csv's header and rows, without its ``# epoch_utc`` comment line (a file
    without it is read the same)."""
    return [line for line in (run / "telemetry.csv").read_text().splitlines(keepends=True)
            if not line.startswith("#")]


def _drop_column(lines: list[str], name: str) -> str:
    k = lines[0].rstrip("\n").split(",").index(name)
    return "".join(",".join(f for i, f in enumerate(line.rstrip("\n").split(",")) if i != k)
                   + "\n" for line in lines)


def _set_cell(lines: list[str], row: int, name: str, value: str) -> str:
    k = lines[0].rstrip("\n").split(",").index(name)
    out = list(lines)
    fields = out[row].rstrip("\n").split(",")
    fields[k] = value
    out[row] = ",".join(fields) + "\n"
    return "".join(out)


def _swap_rows(lines: list[str], row: int) -> str:
    out = list(lines)
    out[row], out[row + 1] = out[row + 1], out[row]
    return "".join(out)


# name -> (file contents from the telemetry lines, or None for no file; text in the message)
BAD_TELEMETRY = {
    "missing_file": (None, "no such telemetry file"),
    "binary": (lambda lines: bytes(range(256)) * 8, "not a CSV text file"),
    "text": (lambda lines: "hello world\nthis is, not a telemetry file\n",
             "row 2 has 2 values, but the header (row 1) names 1 column"),
    "no_yaw_deg": (lambda lines: _drop_column(lines, "yaw_deg"), "yaw_deg"),
    "no_wheel2_rpm": (lambda lines: _drop_column(lines, "wheel2_rpm"), "wheel2_rpm"),
    "roll_not_a_number": (lambda lines: _set_cell(lines, 5, "roll_deg", "abc"),
                          "row 6, column roll_deg: 'abc' is not a number"),
    "wheel_missing_in_the_first_row": (lambda lines: _set_cell(lines, 1, "wheel1_rpm", ""),
                                       "first and the last row"),
    "t_s_missing": (lambda lines: _set_cell(lines, 7, "t_s", ""), "t_s"),
    "t_s_not_increasing": (lambda lines: _swap_rows(lines, 9), "must increase"),
    "one_row": (lambda lines: "".join(lines[:2]), "at least two"),
}
# These pass the CSV parse and so reach the failing line of read_telemetry.


def _write_bad(tmp_path: Path, run: Path, case: str) -> tuple[Path, str]:
    make, needle = BAD_TELEMETRY[case]
    path = tmp_path / f"{case}.csv"
    if make is not None:
        content = make(_telemetry_lines(run))
        if isinstance(content, bytes):
            path.write_bytes(content)
        else:
            path.write_text(content)
    return path, needle


def _check_bad_telemetry(tmp_path: Path, run: Path, case: str) -> None:
    path, needle = _write_bad(tmp_path, run, case)
    out = tmp_path / "est"
    rc, stdout, err = run_cli("estimate", str(path), "--scenario",
                              str(run / "scenario.yaml"), "--out", str(out))
    assert rc == 2, err
    assert_one_line(err)
    assert err.startswith("dynprop: error: ") and path.name in err and needle in err, err
    assert stdout == ""
    assert not out.exists()


@pytest.mark.parametrize("case", list(BAD_TELEMETRY))
def test_bad_telemetry_exits_2_with_one_line_and_writes_nothing(short_run, tmp_path, case):
    _check_bad_telemetry(tmp_path, short_run[0], case)


# --------------------------------------------------------------------------- dynprop plot


def test_plot_redraws_the_run_figures(short_run, tmp_path):
    """`dynprop plot` on a run directory draws exactly run's set, with its names."""
    run = tmp_path / "run"
    shutil.copytree(short_run[0], run)
    shutil.rmtree(run / "plots")
    rc, stdout, err = run_cli("plot", str(run))
    assert rc == 0, err
    assert {Path(line).name for line in stdout.splitlines()} == RUN_FIGURES
    assert {p.name for p in (run / "plots").iterdir()} == RUN_FIGURES
    for name in RUN_FIGURES:
        png = (run / "plots" / name).read_bytes()
        assert png.startswith(PNG_MAGIC) and len(png) > 20_000, name


# --------------------------------------------------------------------------- real vs linearised


def test_torque_free_without_noise_real_and_linear_agree_within_the_quanta(tmp_path_factory):
    run, _ = run_dir(tmp_path_factory, "torque_free", "torque_free", 7200,
                     "--set", "sensors.noise.enabled=false")
    resolved = yaml.safe_load((run / "scenario.yaml").read_text())
    earth_q = resolved["sensors"]["earth"]["quantum_deg"]      # 0.01°
    dss_q = resolved["sensors"]["sun"]["dss"]["quantum_deg"]   # 0.125°
    diff = summary(run)["nonlinear_vs_linear"]
    assert diff["roll_deg"]["max_abs_difference"] <= earth_q, diff["roll_deg"]
    assert diff["yaw_deg"]["max_abs_difference"] <= dss_q, diff["yaw_deg"]
    c = np.load(run / "comparison.npz")
    gap = np.abs(c["err_real"] - c["err_linear"])
    assert gap[:, 0].max() <= earth_q and gap[:, 2].max() <= dss_q


def test_large_offset_separates_real_from_linear(tmp_path_factory, hour_run):
    """The divergence the tool exists to show: several degrees off the linearisation
    point, real and linearised errors differ far more than at nominal pointing."""
    big = summary(run_dir(tmp_path_factory, "large", "large_offset", 3600)[0])
    nominal = summary(hour_run)
    ratios = {k: big["nonlinear_vs_linear"][k]["rms_difference"]
              / nominal["nonlinear_vs_linear"][k]["rms_difference"]
              for k in ("roll_deg", "yaw_deg")}
    assert max(ratios.values()) > 5, ratios


def test_same_seed_gives_a_byte_identical_run_directory(run6, tmp_path):
    """Every file of a run, figures and summary included, is a function of the
    scenario and seed alone.  Identity is the requirement here: a rerun on the same
    machine gives the same bytes (the session's ``run6``, run again here)."""
    dirs = [run6, tmp_path / "b"]
    # 6 h: more rows than one CSV block, so the multi-process writer is exercised.
    rc, _, err = run_cli("run", "goes_next_equinox", "--duration-s", "21600", "--out",
                         str(dirs[1]))
    assert rc == 0, err
    files = sorted(p.relative_to(dirs[0]) for p in dirs[0].rglob("*") if p.is_file())
    assert files == sorted(p.relative_to(dirs[1]) for p in dirs[1].rglob("*") if p.is_file())
    assert len(files) >= 10
    for f in files:
        assert (dirs[0] / f).read_bytes() == (dirs[1] / f).read_bytes(), f
