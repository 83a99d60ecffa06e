"""The producer of a streamed run: truth → telemetry → the linear twin and its
filter, window by window (``stream``'s module doc), in a process of its own
(``process``) or in the caller's.

It yields the ``Plan`` first, then tagged records: ``("real", TruthWindow)`` as
soon as a window's truth and telemetry exist, and ``("twin", TwinWindow)`` once
the twin and its filter are through it, two windows later.  With ``out`` it
writes truth.csv at the output rows and, if ``telemetry_file``, telemetry.csv at
every sample, a window late (after the records that window's twin makes).

A ``steering`` (the trim loop, ``trim.loop.TrimSteering``) may steer the truth from
the run's own telemetry: its ``start(s, stream, out)`` is called here, in the
producer, and returns what is told each window's truth and telemetry columns
(``add(truth, tel_cols, last)``) before the next window flies, and closed at the
end.  The run engine knows nothing else of it.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import numpy as np
from dynprop.estimator.linear.transition import discretize
from dynprop.sim.telemetry import sense_window

from ...bridge.coordinates import TruthTorques, model_truth, pitch_truth, truth_torques
from ...bridge.inputs import telemetry_inputs
from ...bridge.twin import TwinTruth, twin_window
from ...config import build
from ...config.management import telemeters_torquers, torquer_columns
from ...config.schema import Scenario
from ...files.columns import (
    UtcTags,
    telemetry_columns,
    telemetry_lattices,
    truth_columns,
)
from ...files.csvio import CsvAppender
from ...records import TruthWindow
from ...samples import output_rows
from ...units import DEG
from .plan import make_plan
from .twin_filter import TwinFilter, TwinTelemetry

MANAGEMENT_FILE = "momentum_management.csv"   # solar management's daily commands


class Steering(Protocol):
    def start(self, s: Scenario, stream, out: Path | None): ...


@dataclass(frozen=True)
class _TwinPending:
    """What the twin needs of a window, kept until the next window's first h."""

    index: int
    start: int
    truth: TwinTruth
    tt: TruthTorques
    drawn: dict


def producer(s: Scenario, run: int = 0, window_samples: int | None = None,
             out: Path | None = None, telemetry_file: bool = False,
             steering: Steering | None = None):
    """Truth, telemetry and the linear twin with its filter, window by window (see
    the module doc)."""
    rngs = build.streams(s.seed, run)
    stream = build.truth_stream(s, rngs.pop("ripple"),
                                disturbance_rng=build.disturbance_generator(s, run))
    plan = make_plan(s, stream.n_samples, window_samples)
    yield plan
    suite = build.build_sensors(s)
    rngs = build.streams(s.seed, run)
    draws = ThreadPoolExecutor(1)
    params, noise = build.estimator_model(s)
    disc = discretize(params, noise, s.sample_interval_s)
    min_sep = s.sensors.sun.min_sun_separation_deg
    files = {}
    if out is not None:
        files["truth"] = CsvAppender(Path(out) / "truth.csv")
        if telemetry_file:
            files["telemetry"] = CsvAppender(
                Path(out) / "telemetry.csv", exact=True,
                lattices=telemetry_lattices(suite, stream.spacecraft.n_wheels),
                tags=UtcTags.of(s.epoch_utc, s.sample_interval_s))
    twin_filter = TwinFilter(s, params, disc, plan)
    torquers = telemeters_torquers(s)
    loop = None if steering is None else steering.start(s, stream, out)
    if out is not None and stream.manager is not None:
        files["management"] = CsvAppender(Path(out) / MANAGEMENT_FILE)
    logged = 0    # solar management's commands already in its file
    pending: _TwinPending | None = None
    twin_x = None
    unwritten: list = []     # file rows of windows whose twin is not yet handed on

    def write(upto: int) -> None:
        while unwritten and unwritten[0][0] <= upto:
            _, truth_rows, tel_rows = unwritten.pop(0)
            if "truth" in files:
                files["truth"].append(truth_rows)
            if "telemetry" in files:
                files["telemetry"].append(tel_rows)
    try:
        for index in range(len(plan.bounds) + 1):
            current = None
            if index < len(plan.bounds):
                a, b = plan.bounds[index]
                # The sensors' draws are made in a thread while the truth rolls out in
                # another and this one senses it behind the rollout, a piece at a
                # time; the twin's sensors read the same draws again (its generators
                # would repeat them: the same seeds).
                truth, tel, drawn = sense_window(stream, a, b, suite, rngs, draws, min_sep)
                rows = output_rows(a, b, plan.stride) - a
                tel_cols = telemetry_columns(tel, suite)
                if torquers:
                    tel_cols.update(torquer_columns(truth.torquer_dipole_Am2))
                seen = telemetry_inputs(s, tel_cols)
                tt = truth_torques(truth, s.estimator.model_torques, params.omega0_radps,
                                   seen.known_Nm)
                if loop is not None:   # may move the truth's tab for the next window
                    loop.add(truth, tel_cols, plan.is_last(index))
                if "management" in files and len(stream.manager.history) > logged:
                    new = stream.manager.history[logged:]
                    files["management"].append({k: np.array([r[k] for r in new])
                                                for k in new[0]})
                    logged = len(stream.manager.history)
                unwritten.append((index, truth_columns(truth, tel.sun_visible, rows),
                                  tel_cols))
                real = TruthWindow(
                    index, a, b, truth.t_s, seen,
                    # The pitch filter and the EKF measure the Earth sensor's pitch.
                    tel_cols["pitch_deg"] * DEG,
                    {k: v[rows] for k, v in tel_cols.items()}, model_truth(params, truth, tt),
                    pitch_truth(truth, tt), truth.shadow, truth.euler_rad[rows])
                current = _TwinPending(index, a, TwinTruth.of(truth), tt, drawn)
                del tel, truth
                yield "real", real
            if pending is not None:
                # The twin's last step needs the next window's first h (its wheel torque).
                h_next = None if current is None else current.truth.h_Nms[0]
                twin, measured, twin_x = twin_window(s, params, disc, pending.truth, pending.tt,
                                                     h_next, twin_x, pending.drawn, suite)
                # The twin's filter knows the torques the real one does.
                measured = measured._replace(known_Nm=pending.tt.known)
                twin_rec = TwinTelemetry(pending.index, pending.start, len(pending.truth.t_s),
                                         twin, measured)
                pending = None   # what it kept of the truth is not needed any more
                for done in twin_filter.push(twin_rec):
                    yield "twin", done
                    # Files once a window's records are all handed on, so the consumer
                    # gets every record as early as it can.
                    write(done.index)
            pending = current
        for done in twin_filter.finish():
            yield "twin", done
        write(len(plan.bounds))
    finally:
        draws.shutdown()
        for f in files.values():
            f.close()
        if loop is not None:
            loop.close()
