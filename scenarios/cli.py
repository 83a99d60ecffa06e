"""The ``dynprop`` command line (DESIGN.md section 6).

Exit status: 0 on success, 2 for bad input (one line naming the problem, no
traceback), 1 for an internal error.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from . import __version__

# A truth day holds ~70 MB of arrays; 30 days stays well inside this machine class.
MAX_DURATION_S = 30 * 86400.0


class InputError(ValueError):
    """Bad user input: reported as one line with exit status 2."""


class _Parser(argparse.ArgumentParser):
    """argparse that reports bad arguments as one line (no usage block), exit 2."""

    def error(self, message: str):
        self.exit(2, f"dynprop: error: {message}\n")


def _duration(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not (np.isfinite(value) and 0 <= value <= MAX_DURATION_S):
        raise argparse.ArgumentTypeError(
            f"must be between 0 and {MAX_DURATION_S:.0f} s, got {text!r}")
    return value


def _seed(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a non-negative integer, got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be a non-negative integer, got {text!r}")
    return value


def _build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="dynprop",
        description="Dynamic attitude propagation for momentum-biased Earth-pointing "
                    "spacecraft (GOES-Next): nonlinear truth vs the paper's linear filter.")
    parser.add_argument("--version", action="version", version=f"dynprop {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    truth = sub.add_parser(
        "truth", help="simulate the nonlinear truth with GOES-Next defaults; write CSV + plot")
    truth.add_argument("--out", required=True, type=Path, help="new run directory")
    truth.add_argument("--duration-s", type=_duration, default=86400.0)
    truth.add_argument("--seed", type=_seed, default=20260320)
    truth.add_argument("--epoch", default="2026-03-20T12:00:00Z", help="UTC, ISO 8601")
    truth.add_argument("--force", action="store_true", help="replace a non-empty --out")
    return parser


def _cmd_truth(args) -> int:
    from plots.truth import plot_truth
    from sim import ephemeris
    from sim.control import Control
    from sim.environment import Environment
    from sim.frames import GeoOrbit
    from sim.spacecraft import goes_next
    from sim.truth import InitialState, simulate_truth

    from . import __version__
    from .rundir import check_out_dir, staged_run_dir
    from .truth_io import RAD2DEG, write_truth_csv

    try:
        epoch = ephemeris.parse_epoch(args.epoch)
    except ValueError as exc:
        raise InputError(f"--epoch: {exc}") from None
    if not 1950 <= epoch.year < 2050:
        raise InputError(f"--epoch: {args.epoch} is outside 1950-2049, where the solar "
                         "ephemeris holds 0.01 deg")
    check_out_dir(args.out, args.force)
    rng = np.random.default_rng(np.random.SeedSequence(args.seed))
    init = InitialState(yaw_rad=np.deg2rad(0.05), roll_rad=np.deg2rad(0.02))
    start = time.perf_counter()
    res = simulate_truth(goes_next(), GeoOrbit(), Environment(), Control(), init, epoch,
                         args.duration_s, rng=rng)
    elapsed = time.perf_counter() - start
    with staged_run_dir(args.out, force=args.force) as stage:
        write_truth_csv(stage / "truth.csv", res)
        (stage / "plots").mkdir()
        fig = plot_truth(
            res.t_s,
            {"yaw": res.yaw_rad * RAD2DEG, "roll": res.roll_rad * RAD2DEG,
             "pitch": res.pitch_rad * RAD2DEG},
            res.h_Nms,
            {k: res.torques[k] for k in ("gravity_gradient", "solar", "magnetic",
                                         "magnetic_control", "wheel_control")},
            res.eclipse,
            f"GOES-Next truth, epoch {args.epoch}, seed {args.seed}")
        fig.savefig(stage / "plots" / "truth.png", dpi=120)
        run_info = {"dynprop_version": __version__, "command": "truth", "seed": args.seed,
                    "epoch_utc": args.epoch, "duration_s": args.duration_s,
                    "sample_interval_s": 0.512, "backend": res.backend}
        (stage / "run.json").write_text(json.dumps(run_info, indent=2) + "\n")
    days = args.duration_s / 86400.0
    print(f"simulated {days:.2f} d in {elapsed:.2f} s ({res.backend}); "
          f"wrote {args.out}/truth.csv and {args.out}/plots/truth.png")
    return 0


COMMANDS = {"truth": _cmd_truth}


def main(argv: list[str] | None = None) -> int:
    args = _build_parser().parse_args(argv)
    from .rundir import RunDirError
    try:
        return COMMANDS[args.command](args)
    except (InputError, RunDirError) as exc:
        print(f"dynprop: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        # Files the user named (or their directories) could not be written or read.
        print(f"dynprop: error: {exc.filename or ''}: {exc.strerror or exc}", file=sys.stderr)
        return 2
    except Exception as exc:
        if os.environ.get("DYNPROP_DEBUG"):
            raise
        print(f"dynprop: internal error: {type(exc).__name__}: {exc} "
              "(set DYNPROP_DEBUG=1 for a traceback)", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
