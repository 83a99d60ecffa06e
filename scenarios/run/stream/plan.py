"""How a streamed run is cut into windows, built once from the scenario.

A run of at most ``SINGLE_WINDOW_S`` (two days) is one window; a longer one is
cut into whole days, the remainder joining the last day (a trim loop always cuts
days: it decides at day ends).  Each window is filtered padded with ``pad``
samples of each neighbour (the wheel-torque derivative's half window) and
smoothed over ``overlap`` samples of the next one (``stream``'s module doc).
"""

from __future__ import annotations

from dataclasses import dataclass

from ...config.schema import Scenario, output_stride
from ...units import DAY_S, HOUR_S

SINGLE_WINDOW_S = 2 * DAY_S
SMOOTHER_OVERLAP_S = 12 * HOUR_S


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
    # A telemetry file off the scenario's grid: its median step and first time, which
    # every window's wheel torque is resampled on (``bridge.inputs.prepared_inputs``).
    record: tuple[float, float] | None = None

    def is_last(self, index: int) -> bool:
        return index == len(self.bounds) - 1


def make_plan(s: Scenario, n_samples: int, window_samples: int | None = None) -> Plan:
    dt = s.sample_interval_s
    if window_samples is None and s.trim.every_days is not None:
        window_samples = int(round(DAY_S / dt))   # the trim loop decides at day ends
    bounds = window_bounds(n_samples, dt, window_samples)
    stride = output_stride(s)
    pad = int(round(s.estimator.wheel_torque_window_s / dt)) // 2 + 1
    overlap = max(pad, int(round(SMOOTHER_OVERLAP_S / dt)))
    return Plan(n_samples, bounds, stride, pad, overlap)
