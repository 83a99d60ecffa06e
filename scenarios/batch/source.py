"""The telemetry `dynprop batch` fits, and the truth it is judged against: a run
directory's telemetry.csv (or the file a `dynprop estimate` directory read) and
truth.csv, or a telemetry file with ``--scenario`` (and ``--truth``).

The telemetry is a ``files.telemetry_source.TelemetrySource``, read by range (issue
44: a month of telemetry is never held whole); ``span_data`` forms each batch's data
from the samples of its span alone.  The truth is at the run's output cadence and is
read whole.
"""

from __future__ import annotations

import contextlib
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..bridge.batch import linear_consider, linear_data, nonlinear_data
from ..bridge.inputs import telemetry_inputs
from ..config.loader import load_scenario
from ..config.schema import Scenario
from ..files.rundir import RunDirError
from ..files.telemetry_file import GriddedTelemetry, run_telemetry
from ..files.truth_aem import is_aem
from ..run.windowed import (
    DAYS,
    Windows,
    pad_samples,
    padded_range,
    used_names,
    wheel_names,
    window_bounds,
)
from ..units import DEG
from .spans import Span, cut_span


@dataclass(frozen=True)
class BatchSource:
    scenario: Scenario
    telemetry: Path
    truth_path: Path | None
    run_dir: Path | None
    grid: GriddedTelemetry
    truth: object | None      # files.truth_file.TruthFromFile


@dataclass(frozen=True)
class StreamedSource:
    """``BatchSource`` with the telemetry as a source read by range and its sample
    times ``t`` (one float per sample: the spans are planned on them)."""

    scenario: Scenario
    telemetry: Path
    truth_path: Path | None
    run_dir: Path | None
    source: object            # files.telemetry_source.TelemetrySource
    t: np.ndarray
    truth: object | None


def _locate(source: Path, scenario, overrides, truth):
    """The scenario, the telemetry file, the truth file and the run directory (or
    None) of `dynprop batch SOURCE`; every problem a ``RunDirError``."""
    source = Path(source)
    if not source.exists():
        raise RunDirError(f"{source}: no such telemetry file or run directory")
    if source.is_dir():
        if not (source / "scenario.yaml").is_file():
            raise RunDirError(f"{source}: not a run directory (no scenario.yaml)")
        path = run_telemetry(source)
        if path is None:
            raise RunDirError(f"{source}: no telemetry.csv to fit (a run longer than 2 days "
                              "writes it only with output.telemetry: true: rerun with --set "
                              "output.telemetry=true)")
        s = load_scenario(scenario or source / "scenario.yaml", list(overrides))
        own_truth = source / "truth.csv"
        truth = truth if truth is not None else (own_truth if own_truth.is_file() else None)
        return s, path, truth, source
    if scenario is None:
        raise RunDirError(f"{source}: a telemetry file needs --scenario (the spacecraft "
                          "and sensors it came from)")
    return load_scenario(scenario, list(overrides)), source, truth, None


def read_source(source: Path, scenario: str | Path | None = None, overrides=(),
                truth: Path | None = None) -> BatchSource:
    """The telemetry on the filter's grid (or at its own times), read whole, and the
    truth at its samples; a run directory's truth.csv is used unless ``truth`` names
    another."""
    from ..run.estimate import estimate_inputs
    s, path, truth, run_dir = _locate(source, scenario, overrides, truth)
    grid, truth_rows = estimate_inputs(s, path, truth)
    return BatchSource(s, path, truth, run_dir, grid, truth_rows)


def truth_at(s: Scenario, path: Path, t: np.ndarray, regular: bool):
    """The truth file at the telemetry's samples ``t`` (``run.estimate.estimate_inputs``'
    truth: a truth.csv or an AEM)."""
    if is_aem(path):
        from ..files.aem import AemError
        from ..files.truth_aem import read_truth_aem
        try:
            return read_truth_aem(path, s, t, regular)
        except AemError as exc:
            raise RunDirError(str(exc)) from None
    from ..files.truth_file import read_truth
    return read_truth(path, s, t, regular)


@contextlib.contextmanager
def open_batch_source(source: Path, scenario: str | Path | None = None, overrides=(),
                      truth: Path | None = None, block_rows: int | None = None):
    """``read_source`` with the telemetry read by range (``files.telemetry_source.
    open_source``), its scratch files in a temporary folder removed on leaving; every
    problem of the files reported before this yields."""
    from ..files.telemetry_source import open_source
    s, path, truth, run_dir = _locate(source, scenario, overrides, truth)
    with tempfile.TemporaryDirectory(prefix="dynprop-batch-") as scratch:
        tel = open_source(path, s, Path(scratch), block_rows)
        try:
            t = np.asarray(tel.columns(0, tel.n, ["t_s"])["t_s"], dtype=float)
            truth_rows = None if truth is None else truth_at(s, truth, t, tel.regular)
            yield StreamedSource(s, path, truth, run_dir, tel, t, truth_rows)
        finally:
            tel.close()


def span_data(s: Scenario, source, t: np.ndarray, model: str, windows: Windows = DAYS):
    """``spans.solve_chain``'s ``data_of``: each span's data from ``source``.  A record
    of up to ``windows.whole_s`` (two days) is formed whole and cut, as before; a longer
    one span by span, from the span and the sample past it padded as a window is
    (``run.windowed``): the wheel torque's and the pitch's fits, and any dropout's
    bridge, are the whole record's there, and only the span is held."""
    n = source.n
    regular = source.regular
    pitch = ["pitch_deg"] if "pitch_deg" in source.names else []
    names = used_names(source, s, tuple(pitch))

    def formed(c: int, d: int):
        cols = source.columns(c, d, names)
        tel = telemetry_inputs(s, cols)
        own_t = None if regular else np.asarray(cols["t_s"], dtype=float)
        return (linear_data(s, tel, own_t),
                linear_consider(s, tel, own_t) if model == "linear" else (),
                nonlinear_data(s, tel, cols["pitch_deg"] * DEG, own_t)
                if model == "nonlinear" else None)

    if len(window_bounds(t, 0, n, windows)) == 1:
        whole = []

        def data_of(sp: Span):
            if not whole:
                whole.append(formed(0, n))
            return cut_span(*whole[0], sp)
        return data_of
    pad = pad_samples(s, s.sample_interval_s if regular else source.median_step_s())
    # The columns preprocessing bridges with a straight line (``preprocess.wheel_torque``,
    # ``earth_pitch``).
    needed = wheel_names(s) + (pitch if model == "nonlinear" else [])

    def data_of(sp: Span):
        c, d = padded_range(source, sp.a, sp.stop, 0, n, pad, needed)
        return cut_span(*formed(c, d), Span(sp.index, sp.a - c, sp.b - c, sp.stop - c))
    return data_of
