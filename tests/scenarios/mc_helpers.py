"""Shared helpers of the Monte Carlo tests."""

from __future__ import annotations

import contextlib
import io
import json
import math
import re
import sys
from pathlib import Path

import numpy as np
from scipy import stats

from scenarios.cli import main
from scenarios.loader import load_scenario

DYNPROP = Path(sys.executable).with_name("dynprop")
DT = 0.512
STATES = ("roll_deg", "roll_rate_degps", "yaw_deg", "yaw_rate_degps", "h_Nms",
          "N_px_Nm", "N_pz_Nm", "N_cx_Nm", "N_cz_Nm")
YAW = STATES.index("yaw_deg")
FIGURES = ("mc_errors.png", "mc_nees.png", "mc_gap_yaw.png")
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
RAN = re.compile(r": (new|resumed) set, ran (\d+) of (\d+) cases")

# 19:00 local at 75° W the day after the equinox: the night Sun gap (~20:15–04:05
# local) falls ~1.3–9.1 h into the run, so 10 h hold one whole gap and its end.
# Epoch dispersions move whole days, so every case has its gap at the same hours.
GAP_SET = ("--duration-s", "36000", "--set", "epoch_utc=2026-03-21T00:00:00Z",
           "--set", "montecarlo.converged_after_h=1")
TWIN_SET = (*GAP_SET, "--set", "montecarlo.linear_twin=true")


def scenario_of(args):
    """The nominal scenario that CLI arguments ``args`` (--duration-s, --seed, --set) name."""
    overrides, it = [], iter(args)
    for a in it:
        if a == "--set":
            overrides.append(next(it))
        elif a in ("--duration-s", "--seed"):
            overrides.append(f"{a[2:].replace('-', '_')}={next(it)}")
    return load_scenario("goes_next_equinox", overrides)


def run_cli(*argv: str) -> tuple[int, str, str]:
    """``main(argv)`` in-process with stdout and stderr captured; argparse exits too."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            rc = main([str(a) for a in argv])
        except SystemExit as exc:
            rc = exc.code
    return rc, out.getvalue(), err.getvalue()


def montecarlo(out: Path, runs: int, *extra: str, workers: int = 2) -> tuple[int, str, str]:
    return run_cli("montecarlo", "goes_next_equinox", "--runs", runs, "--workers", workers,
                   "--out", out, *extra)


def ran(stdout: str) -> tuple[str, int, int]:
    """("ran" for a new set | "resumed", cases run now, cases in the set) from the
    summary line, which also says how many were already stored."""
    m = RAN.search(stdout)
    assert m, f"no 'new/resumed set, ran N of M cases' in {stdout!r}"
    n, total = int(m.group(2)), int(m.group(3))
    assert f"({total - n} already stored)" in stdout
    return ("ran" if m.group(1) == "new" else "resumed"), n, total


def assert_one_line(err: str) -> str:
    assert err.endswith("\n") and err.count("\n") == 1, f"stderr is not one line: {err!r}"
    assert "Traceback" not in err
    return err


def dispersions_override(d: dict) -> str:
    return f"montecarlo.dispersions={json.dumps(d)}"   # JSON is YAML


def case_files(cases: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(cases.iterdir())}


def snapshot(paths) -> dict[str, tuple[bytes, int]]:
    return {p.name: (p.read_bytes(), p.stat().st_mtime_ns) for p in paths}


def load_npz(path: Path) -> dict[str, np.ndarray]:
    with np.load(path) as data:
        return {k: data[k] for k in data.files}


def assert_same_arrays(a: dict, b: dict) -> None:
    assert set(a) == set(b)
    for k in a:
        assert a[k].dtype == b[k].dtype, k
        assert np.array_equal(a[k], b[k]), k


def chi2_var_interval(n: int, sigma, p: float = 0.999) -> tuple:
    """Where the sample variance (ddof=1) of n draws of N(·, σ²) lies with probability p."""
    lo, hi = stats.chi2.ppf([(1 - p) / 2, (1 + p) / 2], n - 1)
    s2 = np.square(sigma)
    return s2 * lo / (n - 1), s2 * hi / (n - 1)


def binomial_tol(p: float, n: int, k: float = 4.0) -> float:
    return k * math.sqrt(p * (1 - p) / n)


