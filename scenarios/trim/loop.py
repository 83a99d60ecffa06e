"""The trim loop (``trim.every_days``): a `dynprop run` that estimates κ from its
own telemetry every N days and moves the tab as `dynprop trim` recommends, from
the next sample on (issue 15, item 4; docs/trim.md).

It lives in the producer, beside the truth it steers: ``TrimSteering`` is the
run engine's steering (``run.stream.producer``), which the command layer hands the run.
At the end of each span of N whole days (N day windows) the span's telemetry goes
through ``batch.estimate_kappa``: the same batch filter, known torques, fit and 3σ rule as
`dynprop trim`, knowing the tab it commanded last.  A significant κ̂ moves the
truth's tab (``TruthStream.retrim``); the run's own filters see only the
telemetry, as before, and the linear twin follows the truth's torques.  Memory is
the span's telemetry columns (about 27 MB a day), not the run's.

trim_loop.csv has one row per day: the tab flown and its true κ, the torquers'
activity, the true wheel momentum h and attitude (what a mistrim builds up: the
torquers, at most ~1e-6 N m, cannot unload 1e-5 N m), and on each span's last
day κ̂, σ and the tab commanded next (the last span's recommendation is
reported, not flown).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..config import build
from ..config.schema import Scenario
from ..files.csvio import CsvAppender, read_csv
from ..units import RAD2DEG
from .batch import TrimError, choose_batch, estimate_kappa, true_kappa_Nm

LOOP_COLUMNS = ("day", "trim_tab_deg", "kappa_true_Nm", "torquer_dipole_rms_Am2",
                "torquer_saturated_fraction", "h_rms_Nms", "roll_rms_deg", "yaw_rms_deg",
                "kappa_Nm", "kappa_sigma_Nm", "trim_tab_deg_new")


def with_tab(s: Scenario, trim_tab_deg: float) -> Scenario:
    """``s`` flying the tab at ``trim_tab_deg``."""
    solar = s.environment.solar.model_copy(update={"trim_tab_deg": float(trim_tab_deg)})
    env = s.environment.model_copy(update={"solar": solar})
    return s.model_copy(update={"environment": env})


def _rms(v: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(v))))


def torquer_activity(s: Scenario, dipole_Am2: np.ndarray) -> tuple[float, float]:
    """RMS of the torquer dipole's magnitude (A m²) and the share of samples with a
    torquer at its limit: how hard the unloading works against the external torque."""
    m = np.asarray(dipole_Am2, dtype=float)
    limit = s.control.torquer_max_Am2
    saturated = np.any(np.abs(m) >= limit * (1.0 - 1e-9), axis=1)
    return float(np.sqrt(np.mean(np.sum(m * m, axis=1)))), float(np.mean(saturated))


def loop_summary(s: Scenario, path: Path) -> dict:
    """summary.json's ``trim_loop``: the file, the span, the tab moves flown and the
    true κ at the start and the end."""
    c = read_csv(path)
    tab, kappa = c["trim_tab_deg"], c["kappa_true_Nm"]
    return {"file": path.name, "every_days": s.trim.every_days,
            "moves": int(np.count_nonzero(np.diff(tab))),
            "trim_tab_deg_start": float(tab[0]), "trim_tab_deg_end": float(tab[-1]),
            "kappa_true_start_Nm": float(kappa[0]), "kappa_true_end_Nm": float(kappa[-1])}


class TrimLoop:
    """Called once per day window, after its truth and telemetry (``add``)."""

    def __init__(self, s: Scenario, stream, out: Path | None):
        self.s, self.stream = s, stream
        self.every = int(s.trim.every_days)
        self.span: list[dict[str, np.ndarray]] = []
        self.file = None if out is None else CsvAppender(Path(out) / "trim_loop.csv")
        self.day = 0

    def add(self, truth, tel_cols: dict[str, np.ndarray], last: bool) -> None:
        rms, sat = torquer_activity(self.s, truth.torquer_dipole_Am2)
        row = {"day": self.day, "trim_tab_deg": self.s.environment.solar.trim_tab_deg,
               "kappa_true_Nm": true_kappa_Nm(self.s), "torquer_dipole_rms_Am2": rms,
               "torquer_saturated_fraction": sat, "h_rms_Nms": _rms(truth.h_Nms),
               "roll_rms_deg": _rms(truth.roll_rad) * RAD2DEG,
               "yaw_rms_deg": _rms(truth.yaw_rad) * RAD2DEG, "kappa_Nm": np.nan,
               "kappa_sigma_Nm": np.nan, "trim_tab_deg_new": np.nan}
        self.span.append(tel_cols)
        self.day += 1
        if len(self.span) == self.every or last:
            self._close_span(row, last)
        if self.file is not None:
            self.file.append({k: np.array([row[k]], dtype=float) for k in LOOP_COLUMNS})

    def _close_span(self, row: dict, last: bool) -> None:
        cols = {k: np.concatenate([c[k] for c in self.span]) for k in self.span[0]}
        self.span = []
        dt = self.s.sample_interval_s
        try:
            r = estimate_kappa(self.s, cols, choose_batch(cols["t_s"], dt, None, None))
        except TrimError:
            return   # a span the fit cannot use (no sunlit time): the tab stays
        row.update(kappa_Nm=r.fit.kappa_Nm, kappa_sigma_Nm=r.fit.sigma_Nm,
                   trim_tab_deg_new=r.rec.trim_tab_deg_new)
        if r.rec.move and not last:
            self.s = with_tab(self.s, r.rec.trim_tab_deg_new)
            self.stream.retrim(build.build_environment(self.s).solar)

    def close(self) -> None:
        if self.file is not None:
            self.file.close()


class TrimSteering:
    """The trim loop as a streamed run's steering (``run.stream.producer``'s module doc):
    a ``TrimLoop`` in the producer, and summary.json's ``trim_loop`` section."""

    def __init__(self, s: Scenario):
        self.s = s

    def start(self, s: Scenario, stream, out: Path | None) -> TrimLoop:
        return TrimLoop(s, stream, out)

    def summary(self, stage: Path) -> dict:
        return {"trim_loop": loop_summary(self.s, Path(stage) / "trim_loop.csv")}
