"""What `dynprop tune`'s likelihood passes read of a telemetry file of any length
(issue 44): a few numbers per sample in raw scratch files, written once from the
file read a block at a time (``files.telemetry_source``), and read back a block at a
time (``StoreSamples``, the ``estimator.tuning.samples.Samples`` a pass steps
through).  The numbers are exactly those `dynprop estimate`'s filter reads
(``bridge.inputs.prepared_inputs``): each sample's own arrays are formed block by
block (elementwise, the same bits), and the two that depend on the whole record,
the wheel torque N_w* and a dropout's bridge noise, by the same functions on the
whole h (and t off the grid), 8 bytes a sample each.
"""

from __future__ import annotations

import os
import threading
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from dynprop.estimator.kalman.preprocess import (
    dropout_wheel_noise,
    dropout_wheel_noise_at,
    wheel_torque,
    wheel_torque_at,
    yaw_momentum,
)
from dynprop.estimator.linear.model import input_vector
from dynprop.estimator.linear.noise import roll_variance, tach_variance
from dynprop.estimator.tuning.intervals import RESOLUTION_S

from ..bridge.inputs import telemetry_inputs, yaw_correlation_inflation
from ..config import build
from ..config.schema import Scenario

COLUMNS = ("t", "roll", "yaw", "h", "var_yaw", "nw", "e")
BLOCK_ROWS = 1 << 16      # rows per block read or written (~4 MB of the store)


class Store:
    """Raw float64 columns in ``folder``, one file each, appended and read by row range
    (``os.pread``: threads may read at once)."""

    def __init__(self, folder: Path):
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        self._fds: dict[str, int] = {}
        self._lock = threading.Lock()      # the fit and the diagnostics read at once

    def append(self, name: str, values: np.ndarray) -> None:
        with open(self.folder / f"{name}.f8", "ab") as f:
            f.write(np.ascontiguousarray(values, dtype=np.float64).tobytes())

    def read(self, name: str, start: int, stop: int) -> np.ndarray:
        with self._lock:
            if name not in self._fds:
                self._fds[name] = os.open(self.folder / f"{name}.f8", os.O_RDONLY)
            fd = self._fds[name]
        out = np.empty(max(stop - start, 0))
        got = os.preadv(fd, [memoryview(out)], 8 * start)
        if got != out.nbytes:
            raise OSError(f"{self.folder / name}.f8: short read at row {start}")
        return out

    def close(self) -> None:
        with self._lock:
            for fd in self._fds.values():
                os.close(fd)
            self._fds.clear()


@dataclass(frozen=True)
class Written:
    """What the write pass learns of the whole record on the way."""

    n: int
    t_first: float
    t_last: float
    updates: dict              # kind -> present updates
    yaw_present: np.ndarray    # bool per sample (the Sun gaps)
    t_s: np.ndarray | None     # off the grid, the samples' times (the Sun gaps)
    var_roll: float
    var_h: float


def write_store(store: Store, tel, s: Scenario, block_rows: int = BLOCK_ROWS) -> Written:
    """The telemetry source ``tel`` (``TelemetrySource``) into ``store``: each sample's
    t, roll, yaw, h, yaw variance, N_w* and bridge noise, as ``prepared_inputs`` forms
    them (raising its ``ValueError``s)."""
    n, est = tel.n, s.estimator
    k = np.asarray(build.yaw_factors(s), dtype=float)
    sensors = build.estimator_sensor_specs(s)
    var_roll = roll_variance(sensors)
    var_h = float(np.sum(k**2)) * tach_variance(sensors)
    cadence = None if tel.regular else tel.median_step_s()
    h_all, present = np.empty(n), np.zeros(n, dtype=bool)
    t_all = None if tel.regular else np.empty(n)
    counts = np.zeros(3, dtype=np.int64)
    t_first = t_last = np.nan
    for a in range(0, n, block_rows):
        b = min(a + block_rows, n)
        cols = tel.columns(a, b)
        m = telemetry_inputs(s, cols)
        h = yaw_momentum(m.speeds_radps, k)
        sigma = m.yaw_sigma_rad
        if m.sun_head is not None:      # prepared_inputs' inflation of the yaw variance
            sigma = np.asarray(sigma) * np.sqrt(yaw_correlation_inflation(s, m.sun_head,
                                                                          cadence))
        var_yaw = np.where(np.isfinite(m.yaw_rad), np.asarray(sigma, dtype=float) ** 2, 1.0)
        z = np.column_stack([m.roll_rad, m.yaw_rad, h]).astype(float)
        _check_variances(z, var_roll, var_yaw, var_h)
        counts += np.isfinite(z).sum(axis=0)
        t = cols["t_s"]
        for name, v in zip(COLUMNS[:5], (t, m.roll_rad, m.yaw_rad, h, var_yaw), strict=True):
            store.append(name, v)
        h_all[a:b], present[a:b] = h, np.isfinite(m.yaw_rad)
        if t_all is not None:
            t_all[a:b] = t
        t_first = t[0] if a == 0 else t_first
        t_last = t[-1]
    if not (np.isfinite(h_all[0]) and np.isfinite(h_all[-1])):
        raise ValueError("the wheel speeds of the first and last samples must be present")
    # The two numbers of the whole record, by prepare's (or prepare_at_times') own calls.
    if t_all is None:
        nw = wheel_torque(h_all, s.sample_interval_s, est.wheel_torque_window_s)
        e = dropout_wheel_noise(h_all, s.sample_interval_s, var_h)
    else:
        nw = wheel_torque_at(t_all, h_all, est.wheel_torque_window_s)
        e = dropout_wheel_noise_at(t_all, h_all, var_h)
    del h_all
    store.append("nw", nw)
    del nw
    store.append("e", np.zeros(n) if e is None else e)
    return Written(n, float(t_first), float(t_last),
                   dict(zip(("roll", "yaw", "h"), map(int, counts), strict=True)),
                   present, t_all, var_roll, var_h)


def _check_variances(z, var_roll, var_yaw, var_h) -> None:
    """``Measurements.r``'s check, a block at a time."""
    r = np.column_stack([np.broadcast_to(np.asarray(v, dtype=float), (len(z),))
                         for v in (var_roll, var_yaw, var_h)])
    if np.any(~np.isfinite(r) & np.isfinite(z)) or np.any(r[np.isfinite(r)] <= 0):
        raise ValueError("measurement variances must be positive and finite where a "
                         "measurement is present")


def _group_mean(a: np.ndarray, every: int) -> np.ndarray:
    """The mean of each ``every`` rows, the last group padded with the last row (the
    coarse likelihood's ū and bridge noise: ``fit``)."""
    pad = (-len(a)) % every
    a = np.concatenate([a, np.repeat(a[-1:], pad, axis=0)])
    return a.reshape(-1, every, *a.shape[1:]).mean(axis=1)


class StoreSamples:
    """The ``Samples`` of a store: every sample (``every`` = 1), or every ``every``-th
    with the mean of its ``every`` samples' ū and bridge noise (a coarse filter
    stepping ``every`` samples at a time); off the grid each step's interval to the
    next of them (``intervals.intervals`` of their times)."""

    def __init__(self, store: Store, written: Written, s: Scenario, params, regular: bool,
                 every: int = 1, block_rows: int = BLOCK_ROWS):
        self.store, self.w, self.params, self.regular = store, written, params, regular
        self.every = int(every)
        self.nx, self.nz = s.estimator.model_torques.roll_Nm, s.estimator.model_torques.yaw_Nm
        self.n = -(-written.n // self.every)
        counts = np.zeros(3)
        for a in range(0, self.n, block_rows):
            b = min(a + block_rows, self.n)
            counts += np.isfinite(self._z(a, b)).sum(axis=0)
        self.counts = counts

    def _rows(self, name: str, a: int, b: int) -> np.ndarray:
        """Column ``name`` at the fine rows of samples [a, b) (the first of each group)."""
        ev = self.every
        return self.store.read(name, a * ev, min((b - 1) * ev + 1, self.w.n))[::ev]

    def _z(self, a: int, b: int) -> np.ndarray:
        return np.column_stack([self._rows(c, a, b) for c in ("roll", "yaw", "h")])

    def block(self, start: int, stop: int) -> tuple[list[np.ndarray], np.ndarray | None]:
        z = self._z(start, stop)
        present = np.isfinite(z)
        k = len(z)
        r = np.column_stack([np.broadcast_to(self.w.var_roll, (k,)),
                             self._rows("var_yaw", start, stop),
                             np.broadcast_to(self.w.var_h, (k,))])
        r = np.where(np.isfinite(r), r, 1.0)
        ev = self.every
        lo, hi = start * ev, min(stop * ev, self.w.n)
        nw, e = self.store.read("nw", lo, hi), self.store.read("e", lo, hi)
        u = input_vector(self.params, self.nx, self.nz, nw) * np.ones((len(nw), 1))
        if ev > 1:
            u, e = _group_mean(u, ev), _group_mean(e, ev)
        inputs = [np.where(present, z, 0.0), present.astype(float), r, u, e]
        return inputs, None if self.regular else self._intervals(start, stop)

    def _intervals(self, a: int, b: int) -> np.ndarray:
        """``intervals.intervals`` of these samples' times, [a, b) of it."""
        hi = min(b + 1, self.n)
        lo = a - 1 if hi - a < 2 and a > 0 else a
        d = np.diff(self._rows("t", lo, hi))
        if hi == self.n:      # the last sample takes the step before it
            d = np.r_[d, d[-1]]
        d = d[a - lo:a - lo + (b - a)]
        if not np.all(np.isfinite(d) & (d > 0)):
            raise ValueError("sample times must be finite and increasing")
        return np.round(d / RESOLUTION_S) * RESOLUTION_S

    def times(self, start: int, stop: int) -> np.ndarray:
        return self._rows("t", start, stop)
