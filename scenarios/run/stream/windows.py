"""`dynprop run` in windows: truth → telemetry → the paper's filter and the linear
twin, a window at a time, so that memory does not grow with the duration.

A run of at most ``plan.SINGLE_WINDOW_S`` (two days) is one window, and every
array is the one the whole-array run (``whole.run_scenario``) computes, bit for
bit.  A longer run is cut into whole days (the remainder joins the last day).
Across a window boundary the truth, its telemetry and both filters continue
exactly as in one long array: the rollout state and every random generator are
carried (``sim.truth.TruthStream``), the wheel-torque derivative is taken on the
window padded with its neighbours' samples, and each filter starts from the
prior the previous window ended with.  Three things are per window by design:

- the "true" torque states (``bridge.coordinates.truth_torques``): the model's constant +
  orbit-rate form (Eqs. 9, 18) is fitted per window, as the torques change with
  the season and one fit over a year would describe none of its days;
- the linear twin's torque states are set to the new window's fit at its first
  sample (its attitude states carry on), so its total torque stays the truth's;
- the RTS smoother runs backwards over the window and ``SMOOTHER_OVERLAP_S`` of
  the next one, starting there from the filtered estimate.

The pieces: ``plan`` cuts the run; ``producer`` (truth, telemetry, the twin and
its filter, ``twin_filter``) yields typed records (``records``) and can run in a
second process (``process``); ``stages`` filter and smooth the truth windows;
``windows_of`` here chains them and joins each window with its twin record;
``run.stream.directory`` accumulates and writes what comes out.
"""

from __future__ import annotations

from ...config import build
from ...config.schema import Scenario
from ...records import TruthWindow, TwinWindow, Window
from .producer import producer
from .stages import filtered, smoothed


class Demux:
    """The producer's tagged records as two streams: ``reals()`` yields the plan and
    the truth windows in order; ``twin(index)`` returns that window's twin record,
    reading ahead (and keeping the truth windows it passes) as far as needed."""

    def __init__(self, items):
        self.items = iter(items)
        self.plan = next(self.items)
        self.real_queue: list[TruthWindow] = []
        self.twins: dict[int, TwinWindow] = {}

    def _pull(self) -> bool:
        item = next(self.items, None)
        if item is None:
            return False
        kind, rec = item
        (self.real_queue.append(rec) if kind == "real" else
         self.twins.__setitem__(rec.index, rec))
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

    def twin(self, index: int) -> TwinWindow:
        while index not in self.twins:
            if not self._pull():
                raise RuntimeError(f"the producer ended without the twin of window {index}")
        return self.twins.pop(index)


def windows_of(s: Scenario, run: int = 0, window_samples: int | None = None,
               items=None, smooth: bool = True):
    """The chained stages: the plan, then one ``records.Window`` per window (the real
    filter and smoother, and the window's twin record joined in)."""
    demux = Demux(items if items is not None else producer(s, run, window_samples))
    records = smoothed(s, filtered(s, demux.reals()), smooth)
    yield next(records)
    params, _ = build.estimator_model(s)
    for rec in records:
        yield Window.join(rec.window, demux.twin(rec.window.index), params=params,
                          real=rec.real, nees_real=rec.nees_real, smoothed_x=rec.smoothed_x,
                          filters=rec.filters, pitch=rec.pitch)
    demux.drain()
