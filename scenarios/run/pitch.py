"""The pitch filter (Eq. 3b, ``estimator.pitch``) beside the roll/yaw filter: on a
whole telemetry record, through a streamed run's windows, and its statistics.

Pitch decouples from roll and yaw (Eq. 3b), so its filter is its own 3-state one and
its figures are kept apart from the 9-state filter's: summary.json's ``pitch``
section, estimate.csv's ``pitch_*`` columns, comparison.npz's ``*_pitch`` keys.
Its inputs and design are ``bridge.pitch``'s.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from dynprop.estimator.kalman.consistency import chi2_bounds, nees
from dynprop.estimator.pitch.filter import PitchResult, pitch_filter, unpack
from dynprop.estimator.pitch.model import steady_state

from ..bridge.pitch import padded_pitch_wheel_rate, pitch_design, pitch_wheel_rate
from ..config.schema import Scenario
from ..samples import nees_rows
from ..units import RAD2DEG
from .statistics import SETTLED_S
from .tally import Mean, Rms

N_PITCH = 3


def run_pitch(s: Scenario, pitch_rad, speeds, t_s=None) -> PitchResult:
    """The pitch filter over a whole record (``t_s``: the samples' own times, for
    telemetry off the grid; None on the scenario's grid)."""
    d = pitch_design(s)
    u = pitch_wheel_rate(s, speeds, t_s)
    return pitch_filter(pitch_rad, u, s.sample_interval_s if t_s is None else t_s,
                        d.params, d.noise, d.x0, d.P0, d.R)


class PitchStream:
    """The pitch filter through a streamed run's windows, each continuing from the
    prior the previous one ended with; Ḣ from the window's speeds padded with its
    neighbours' (``bridge.pitch.padded_pitch_wheel_rate``), so it equals the whole
    run's."""

    def __init__(self, s: Scenario):
        self.s, self.design = s, pitch_design(s)
        self.x, self.P = self.design.x0, self.design.P0
        self.prev_tail: np.ndarray | None = None

    def window(self, pitch_rad: np.ndarray, speeds: np.ndarray, next_speeds, pad: int,
               lead: np.ndarray | None = None, t_s=None, steps=None, record=None
               ) -> PitchResult:
        """One window; ``lead`` (a file's window: its own padding before it, in place
        of the previous window's last ``pad`` samples, and ``next_speeds`` its padding
        after), ``t_s`` the padded samples' times and ``steps`` the window's intervals
        off the grid."""
        d = self.design
        u = padded_pitch_wheel_rate(self.s, self.prev_tail if lead is None else lead, speeds,
                                    next_speeds, pad, t_s, record)
        r = pitch_filter(pitch_rad, u, self.s.sample_interval_s if steps is None else None,
                         d.params, d.noise, self.x, self.P, d.R, steps=steps)
        self.x, self.P = r.x_next, r.P_next
        self.prev_tail = speeds[-pad:]
        return r


@dataclass(frozen=True)
class PitchHistory:
    """What the files and the summary keep of a window's pitch filter: x and σ (N, 3:
    θ rad, θ̇ rad/s, N_y N m), innovations and their variances, the backend, and the
    NEES on the window's NEES samples (None without a truth); the packed covariance
    only when kept (a record held whole, for NEES on other samples)."""

    x: np.ndarray
    sigma: np.ndarray
    innovations: np.ndarray
    innovation_var: np.ndarray
    backend: str
    nees: np.ndarray | None = None
    P_packed: np.ndarray | None = None

    @classmethod
    def of(cls, r: PitchResult, truth: np.ndarray | None, nees_k, keep_P: bool = False
           ) -> PitchHistory:
        """``truth``: the pitch states (N, 3) at the window's samples; ``nees_k`` the
        window's NEES samples (local indices)."""
        values = None if truth is None else nees(r.x[nees_k], unpack(r.P_packed[nees_k]),
                                                 truth[nees_k])
        if keep_P:
            return cls(r.x, r.sigma, r.innovations, r.innovation_var, r.backend, values,
                       r.P_packed)
        # Copies: the result's columns are views of one (N, 11) block, which a view kept
        # here would hold whole through a streamed window's life.
        return cls(r.x.copy(), r.sigma, r.innovations.copy(), r.innovation_var.copy(),
                   r.backend, values)


def history_at(r: PitchResult, rows: np.ndarray, truth: np.ndarray | None, first: int = 0
               ) -> PitchHistory:
    """The pitch filter at the samples ``rows`` only, with ``truth`` there (or None):
    its NEES on every ``samples.NEES_STRIDE``-th of those rows, as ``run`` forms it
    (``first``: how many rows came before, in a streamed file's earlier windows)."""
    sub = PitchResult(r.x[rows], r.P_packed[rows], r.innovations[rows],
                      r.innovation_var[rows], r.nis[rows], r.x_next, r.P_next, r.rows[:0],
                      r.u[:0], r.backend)
    return PitchHistory.of(sub, truth, nees_rows(first, first + len(rows)) - first,
                           keep_P=True)


def steady_sigma_deg(s: Scenario) -> float | None:
    """The pitch 1σ (deg) the filter settles to with a measurement every sample: the
    a-posteriori steady state of its own model (``estimator.pitch.steady_state``);
    None when q_c = 0 (the N_y variance then only tends to zero)."""
    d = pitch_design(s)
    if not d.noise.q_c > 0:
        return None
    ss = steady_state(d.params, d.noise, s.sample_interval_s, d.R)
    return float(np.sqrt(ss.P_post[0, 0]) * RAD2DEG)


class PitchTally:
    """summary.json's ``pitch`` section, tallied window by window (or once, for a
    record held whole).  NEES is the 3-state one, against χ²(3), on the NEES samples
    (``samples.nees_rows``); "settled" means after the first ``SETTLED_S``."""

    def __init__(self, s: Scenario):
        self.s = s
        self.rms, self.rms_settled = Rms(), Rms()
        self.max_abs = 0.0
        self.within = [0, 0]
        self.nees, self.nees_settled = Mean(), Mean()
        self.inside = [0, 0]
        self.nis = Mean()
        self.sigma_settled = Mean()
        self.backend = None
        self.truth = False
        self.bounds = chi2_bounds(N_PITCH, 1)

    def add(self, h: PitchHistory, start: int, t_s: np.ndarray, truth: np.ndarray | None
            ) -> None:
        """One window from sample ``start`` on; ``t_s`` its times since the run's start,
        ``truth`` its pitch states (N, 3) or None."""
        self.add_own(h, t_s)
        if truth is not None:
            self.add_errors(h, start, t_s, truth)

    def add_own(self, h: PitchHistory, t_s: np.ndarray) -> None:
        """The figures that need no truth: NIS and the settled σ."""
        self.backend = h.backend
        self.nis.add(h.innovations**2 / h.innovation_var)
        self.sigma_settled.add(h.sigma[t_s >= SETTLED_S, 0])

    def add_errors(self, h: PitchHistory, start: int, t_s: np.ndarray, truth: np.ndarray
                   ) -> None:
        """The figures against the truth (``h`` and ``truth`` on the same samples,
        which may be only some of the filter's: a truth file's rows)."""
        self.truth = True
        settled = t_s >= SETTLED_S
        e = h.x[:, 0] - truth[:, 0]
        self.rms.add(e)
        self.rms_settled.add(e[settled])
        self.max_abs = max(self.max_abs, float(np.max(np.abs(e[settled]), initial=0.0)))
        ok = np.abs(e[settled]) <= 3 * h.sigma[settled, 0]
        self.within[0] += int(np.sum(ok))
        self.within[1] += ok.size
        k = nees_rows(start, start + len(t_s)) - start
        values = h.nees
        self.nees.add(values)
        self.nees_settled.add(values[settled[k]])
        finite = values[np.isfinite(values)]
        self.inside[0] += int(np.sum((finite >= self.bounds[0]) & (finite <= self.bounds[1])))
        self.inside[1] += finite.size

    def summary(self) -> dict:
        """summary.json's ``pitch`` section (docs/outputs.md)."""
        t = self.truth
        sig = self.sigma_settled.value()
        return {
            "backend": self.backend,
            "pitch_error_rms_deg": self.rms.value() * RAD2DEG if t else None,
            "pitch_error_rms_after_1h_deg": (self.rms_settled.value() * RAD2DEG
                                             if t and self.rms_settled.count else None),
            "pitch_error_max_abs_after_1h_deg": (self.max_abs * RAD2DEG
                                                 if t and self.within[1] else None),
            "pitch_within_3sigma_fraction_after_1h": (self.within[0] / self.within[1]
                                                      if t and self.within[1] else None),
            "sigma_pitch_mean_after_1h_deg": None if sig is None else sig * RAD2DEG,
            "sigma_pitch_steady_state_deg": steady_sigma_deg(self.s),
            "nees_mean": self.nees.value() if t else None,
            "nees_mean_after_1h": self.nees_settled.value() if t else None,
            "nees_fraction_inside_95": (self.inside[0] / self.inside[1]
                                        if t and self.inside[1] else None),
            "nees_bounds_95": list(self.bounds),
            "nis_mean": self.nis.value(),
        }


def pitch_summary(s: Scenario, h: PitchHistory | None, t_s: np.ndarray,
                  truth: np.ndarray | None) -> dict | None:
    """summary.json's ``pitch`` of a record held whole (every sample; ``t_s`` since
    its start), or None without a pitch filter."""
    if h is None:
        return None
    tally = PitchTally(s)
    tally.add(h, 0, t_s, truth)
    return tally.summary()
