"""`dynprop run` in windows: truth → telemetry → the paper's filter and the linear
twin, a window at a time, so that memory does not grow with the duration.

A run of at most ``SINGLE_WINDOW_S`` (two days) is one window, and every array is
the one the whole-array pipeline (``pipeline.run_scenario``) computes, bit for
bit.  A longer run is cut into whole days (the remainder joins the last day).
Across a window boundary the truth, its telemetry and both filters continue
exactly as in one long array: the rollout state and every random generator are
carried (``sim.truth.TruthStream``), the wheel-torque derivative is taken on the
window padded with its neighbours' samples, and each filter starts from the
prior the previous window ended with.  Three things are per window by design:

- the "true" torque states (``pipeline.truth_torques``): the model's constant +
  orbit-rate form (Eqs. 9, 18) is fitted per window, as the torques change with
  the season and one fit over a year would describe none of its days;
- the linear twin's torque states are set to the new window's fit at its first
  sample (its attitude states carry on), so its total torque stays the truth's;
- the RTS smoother runs backwards over the window and ``SMOOTHER_OVERLAP_S`` of
  the next one, starting there from the filtered estimate.

Stages are generators over window records (dicts), chained in ``windows_of``;
``producer`` (truth, telemetry, twin: ``twin_stream``) can run in a second process.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace

from dynprop.estimator.consistency import nees
from dynprop.estimator.kalman import (
    ExtraNoise,
    FilterResult,
    kalman_filter,
    rts_smoother,
    unpack,
)
from dynprop.estimator.transition import discretize
from dynprop.sim.telemetry import sense_window
from dynprop.sim.truth import TruthStream

from ..config import build
from ..config.schema import Scenario, output_stride
from ..files.columns import telemetry_columns, telemetry_lattices, truth_columns
from ..files.csvio import CsvAppender
from ..files.decimate import output_rows
from ..files.summary import NEES_STRIDE
from ..trim.loop import TrimLoop
from .ekf import EkfStream
from .twin_filter import TwinFilter, padded_inputs, twin_window
from .whole import (
    DEG,
    initial_prior,
    model_truth,
    telemetry_inputs,
    truth_torques,
)

DAY_S = 86400.0
SINGLE_WINDOW_S = 2 * DAY_S
SMOOTHER_OVERLAP_S = 12 * 3600.0


def window_bounds(n_samples: int, dt_s: float, window_samples: int | None = None
                  ) -> list[tuple[int, int]]:
    """[start, stop) sample ranges: one window up to two days, else whole days with
    the remainder (if under half a day) joined to the last one."""
    if window_samples is None:
        if (n_samples - 1) * dt_s <= SINGLE_WINDOW_S + 1e-9:
            return [(0, n_samples)]
        window_samples = int(round(DAY_S / dt_s))
    starts = list(range(0, n_samples, window_samples))
    if len(starts) > 1 and n_samples - starts[-1] < window_samples // 2:
        starts.pop()
    return list(zip(starts, starts[1:] + [n_samples], strict=True))


@dataclass(frozen=True)
class Plan:
    """What every stage needs to know of the run, built once from the scenario."""

    n_samples: int
    bounds: list[tuple[int, int]]
    stride: int                 # output rows every ``stride`` samples
    pad: int                    # samples of each neighbour the wheel-torque fit needs
    overlap: int                # samples of the next window the smoother runs over


def make_plan(s: Scenario, n_samples: int, window_samples: int | None = None) -> Plan:
    dt = s.sample_interval_s
    if window_samples is None and s.trim.every_days is not None:
        window_samples = int(round(DAY_S / dt))   # the trim loop decides at day ends
    bounds = window_bounds(n_samples, dt, window_samples)
    stride = output_stride(s)
    pad = int(round(s.estimator.wheel_torque_window_s / dt)) // 2 + 1
    overlap = max(pad, int(round(SMOOTHER_OVERLAP_S / dt)))
    return Plan(n_samples, bounds, stride, pad, overlap)


def _truth_stream(s: Scenario, run: int) -> TruthStream:
    rngs = build.streams(s.seed, run)
    return TruthStream(build.build_spacecraft(s), build.orbit(s), build.build_environment(s),
                       build.build_control(s), build.build_initial(s), build.epoch(s),
                       s.duration_s, s.sample_interval_s, rng=rngs.pop("ripple"))


def producer(s: Scenario, run: int = 0, window_samples: int | None = None,
             out: Path | None = None, telemetry_file: bool = False):
    """Truth, telemetry and the linear twin with its filter, window by window (see
    the module doc).

    Yields the plan first, then tagged records: ``("real", rec)`` as soon as a
    window's truth and telemetry exist (``index``, ``start``, ``stop``, ``t_s``;
    ``meas``, the telemetry in SI as telemetry.csv writes it; ``truth_model``;
    ``shadow``; at the output rows ``tel_rows`` (telemetry.csv's columns) and
    ``euler_rows``), and ``("twin", rec)`` for a window once the twin and its filter
    are through it, two windows later (``index``, ``twin_model``, ``linear`` and
    ``nees_linear``, see ``twin_stream.lighten_twin``).  With ``out`` it writes truth.csv at
    the output rows and, if ``telemetry_file``, telemetry.csv at every sample, a
    window late (after the records that window's twin makes)."""
    stream = _truth_stream(s, run)
    plan = make_plan(s, stream.n_samples, window_samples)
    yield plan
    suite = build.build_sensors(s)
    rngs = build.streams(s.seed, run)
    draws = ThreadPoolExecutor(1)
    params, noise = build.estimator_model(s)
    disc = discretize(params, noise, s.sample_interval_s)
    mt = s.estimator.model_torques
    min_sep = s.sensors.sun.min_sun_separation_deg
    files = {}
    if out is not None:
        files["truth"] = CsvAppender(Path(out) / "truth.csv")
        if telemetry_file:
            files["telemetry"] = CsvAppender(
                Path(out) / "telemetry.csv", exact=True,
                lattices=telemetry_lattices(suite, stream.spacecraft.n_wheels))
    twin_filter = TwinFilter(s, params, disc, plan)
    loop = None if s.trim.every_days is None else TrimLoop(s, stream, out)
    ekf = "ekf" in s.estimator.filters
    pending = None
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
                tt = truth_torques(truth, mt, params.omega0_radps)
                rows = output_rows(a, b, plan.stride) - a
                tel_cols = telemetry_columns(tel, suite)
                if loop is not None:   # may move the tab for the next window
                    loop.add(truth, tel_cols, index == len(plan.bounds) - 1)
                unwritten.append((index, truth_columns(truth, tel.sun_visible, rows),
                                  tel_cols))
                real = {"index": index, "start": a, "stop": b, "t_s": truth.t_s,
                        "meas": telemetry_inputs(s, tel_cols),
                        # The EKF measures pitch as well (the Earth sensor's).
                        "pitch": tel_cols["pitch_deg"] * DEG if ekf else None,
                        "tel_rows": {k: v[rows] for k, v in tel_cols.items()},
                        "truth_model": model_truth(params, truth, tt),
                        "shadow": truth.shadow, "euler_rows": truth.euler_rad[rows]}
                # What the twin needs of the truth, kept until the next window's first h.
                current = {"index": index, "start": a, "stop": b, "t_s": truth.t_s, "tt": tt,
                           "drawn": drawn,
                           "truth": SimpleNamespace(
                               t_s=truth.t_s, h_Nms=truth.h_Nms, shadow=truth.shadow,
                               wheel_speeds_radps=truth.wheel_speeds_radps,
                               pitch_rad=truth.pitch_rad, roll_rad=truth.roll_rad,
                               yaw_rad=truth.yaw_rad, sun_orbit_frame=truth.sun_orbit_frame)}
                del tel, truth
                yield "real", real
            if pending is not None:
                # The twin's last step needs the next window's first h (its wheel torque).
                h_next = None if current is None else current["truth"].h_Nms[0]
                twin_x = twin_window(s, params, disc, pending, h_next, twin_x, pending["drawn"],
                                     suite, mt)
                del pending["truth"], pending["tt"], pending["drawn"]
                for done in twin_filter.push(pending):
                    yield "twin", done
                    # Files once a window's records are all handed on, so the consumer
                    # gets every record as early as it can.
                    write(done["index"])
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


class Demux:
    """The producer's tagged records as two streams: ``reals()`` yields the plan and
    the real records in order; ``twin(index)`` returns that window's twin record,
    reading ahead (and keeping the real records it passes) as far as needed."""

    def __init__(self, items):
        self.items = iter(items)
        self.plan = next(self.items)
        self.real_queue: list[dict] = []
        self.twins: dict[int, dict] = {}

    def _pull(self) -> bool:
        item = next(self.items, None)
        if item is None:
            return False
        kind, rec = item
        (self.real_queue.append(rec) if kind == "real" else
         self.twins.__setitem__(rec["index"], rec))
        return True

    def reals(self):
        yield self.plan
        for _ in self.plan.bounds:
            while not self.real_queue:
                if not self._pull():
                    return
            yield self.real_queue.pop(0)

    def drain(self) -> None:
        """Read the stream to its end (the producer finishes its files there)."""
        while self._pull():
            pass

    def twin(self, index: int) -> dict:
        while index not in self.twins:
            if not self._pull():
                raise RuntimeError(f"the producer ended without the twin of window {index}")
        return self.twins.pop(index)


def filtered(s: Scenario, records):
    """The paper's filter on ``meas`` over each window, continuing from the prior the
    previous window ended with (and the EKF beside it when the scenario asks).  Adds
    the FilterResult as ``real`` and its inputs (u, extra) as ``real_in``.  The twin
    is filtered in its own process (``twin_stream.TwinFilter``)."""
    plan = next(records)
    yield plan
    params, noise = build.estimator_model(s)
    disc = discretize(params, noise, s.sample_interval_s)
    prior = initial_prior(s, params)
    ekf = EkfStream(s, params) if "ekf" in s.estimator.filters else None
    prev, cur = None, next(records, None)
    while cur is not None:
        # The last window needs no look-ahead (and waiting for the stream's end would
        # hold it up until the producer is done with its files).
        nxt = None if cur["index"] == len(plan.bounds) - 1 else next(records, None)
        meas, u, extra = padded_inputs(s, params, plan, prev, cur, nxt, "meas")
        result = kalman_filter(meas, disc, *prior, u=u, extra=extra)
        prior = (result.x_next, result.P_next)
        cur["real"], cur["real_in"] = result, (u, extra)
        if ekf is not None:
            cur["ekf"] = ekf.window(plan, prev, cur, nxt)
        cur["params"] = params
        # The next window's derivative needs only the last samples of this one.
        prev = {"meas": tuple(None if v is None else v[-plan.pad:] for v in cur["meas"])}
        if cur.get("pitch") is not None:
            prev["pitch"] = cur["pitch"][-plan.pad:]
        yield cur
        cur = nxt


def _head(a: FilterResult, n: int) -> FilterResult:
    return FilterResult(a.x[:n], a.P_packed[:n], a.innovations[:n], a.innovation_var[:n],
                        a.x_next, a.P_next, a.backend)


def smoothed(s: Scenario, records, smooth: bool = True):
    """The RTS smoother over each window and ``plan.overlap`` samples of the next
    (one window: the whole run, exactly ``rts_smoother``).  Adds ``smoothed``."""
    plan = next(records)
    yield plan
    params, noise = build.estimator_model(s)
    disc = discretize(params, noise, s.sample_interval_s)
    cur = next(records, None)
    while cur is not None:
        nxt = None if cur["index"] == len(plan.bounds) - 1 else next(records, None)
        if smooth:
            result, (u, extra) = cur["real"], cur["real_in"]
            x_after = None
            if nxt is not None:
                # The overlap first, from its filtered end; then this window from the
                # smoothed state where the overlap begins (no joined copy of the two).
                m = min(plan.overlap, len(nxt["t_s"]))
                u_n, extra_n = nxt["real_in"]
                head = _head(nxt["real"], m)
                x_after = rts_smoother(
                    head, disc, u=u_n[:m], covariance=False,
                    extra=None if extra_n is None else ExtraNoise(extra_n.scale[:m],
                                                                  extra_n.Qd_unit)).x[0]
            sm = rts_smoother(result, disc, u=u, extra=extra, covariance=False,
                              x_after=x_after)
            cur["smoothed"] = SimpleNamespace(x=sm.x)
            del sm
        else:
            cur["smoothed"] = None
        _lighten_real(cur)
        yield cur
        cur = nxt


def _lighten_real(rec: dict) -> None:
    """What the summary and files need of the real filter once the window is smoothed:
    estimate, σ, innovations and its NEES (``nees_real``, on the NEES samples; formed
    here, before the window's twin record comes, which the consumer would otherwise
    wait for idle), not the covariance history."""
    a, n = rec["start"], len(rec["t_s"])
    real, k = rec["real"], output_rows(a, a + n, NEES_STRIDE) - a
    rec["nees_real"] = nees(real.x[k], unpack(real.P_packed[k]), rec["truth_model"][k])
    rec["real"] = SimpleNamespace(
        x=real.x, sigma=real.sigma, innovations=real.innovations,
        innovation_var=real.innovation_var, backend=real.backend)
    rec.pop("real_in", None)
    if rec.get("ekf") is not None:
        e = rec["ekf"]
        rec["ekf"] = SimpleNamespace(
            x=e.x, sigma=e.sigma, innovations=e.innovations, innovation_var=e.innovation_var,
            backend=e.backend, P_nees=e.P_packed[output_rows(a, a + n, NEES_STRIDE) - a])


def windows_of(s: Scenario, run: int = 0, window_samples: int | None = None,
               items=None, smooth: bool = True):
    """The chained stages: the plan, then one fully processed record per window (the
    real filter and smoother, and the window's twin record merged in)."""
    demux = Demux(items if items is not None else producer(s, run, window_samples))
    records = smoothed(s, filtered(s, demux.reals()), smooth)
    yield next(records)
    for rec in records:
        rec.update(demux.twin(rec["index"]))
        yield rec
    demux.drain()

