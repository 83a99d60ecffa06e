"""`dynprop estimate --truth` with a truth that has rows at only some of the filter's
samples (a `dynprop run`'s truth.csv, every ``output.interval_s``): the errors,
NEES and gap-end verdicts at the rows both have, and nowhere else.

The filter's own figures (Sun gaps, its σ at their ends, NIS) need no truth and
stay at every sample.  The error figures are those `run` computes, on the common
rows: RMS over them, (e/σ)² and NEES at each of them (a truth at every sample is
``statistics.whole_run_statistics``'s, NEES every ``NEES_STRIDE``-th sample as in
`run`).

A Sun-gap end (sample b, the first with a Sun-sensor yaw again) is judged at b
when the truth has a row there.  Otherwise at the last common row r before b,
only if r lies inside the gap (no yaw update from r up to b) and the filter's yaw
σ at r is within ``END_SIGMA_MATCH`` of its σ at b: then the yaw uncertainty has
changed by at most ~2% in variance from r to b, both by the process noise between
them and by the update at b, so the error at r stands for the one at b to about
0.2 σ (1σ of their difference), small beside the 3σ it is judged against (at r,
against the σ at r).  Otherwise (a Sun-sensor update at b that collapses σ, e.g.
the digital Sun sensor's; or no common row inside the gap) that end is not tested:
its error is null and the verdict does not count it.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from dynprop.estimator.kalman.consistency import chi2_bounds, fraction_inside, nees
from dynprop.estimator.kalman.filter import unpack
from dynprop.estimator.linear.model import H_WHEEL, N_STATES, R, Y

from ..files.comparison import ComparisonInputs
from ..files.summary import RunStatistics
from ..records import FilterHistory
from ..samples import END_SIGMA_MATCH
from ..units import RAD2DEG
from .filter_tally import FilterTally


def gap_end_rows(gaps, rows: np.ndarray, sigma_yaw: np.ndarray, n: int
                 ) -> list[tuple[int, int | None]]:
    """For each Sun gap (a, b) that ends inside the grid's ``n`` samples: b and the
    common row (grid sample) its gap-end error is judged at, or None (module doc)."""
    out = []
    for a, b in gaps:
        if b >= n:
            continue
        i = int(np.searchsorted(rows, b, side="right")) - 1
        r = int(rows[i]) if i >= 0 else -1
        ok = r >= a and abs(sigma_yaw[r] / sigma_yaw[b] - 1.0) <= END_SIGMA_MATCH
        out.append((int(b), r if ok else None))
    return out


def at_rows(h, rows: np.ndarray, P_nees=None) -> FilterHistory:
    """A filter history (``FilterResult`` or ``FilterHistory``) at the grid samples
    ``rows``."""
    return FilterHistory(h.x[rows], h.sigma[rows], h.innovations[rows], h.innovation_var[rows],
                         h.backend, P_nees)


def _rms(a) -> float:
    return float(np.sqrt(np.mean(np.square(a))))


def row_statistics(base: RunStatistics, real, smoothed, truth_model: np.ndarray,
                   rows: np.ndarray, t_s: np.ndarray
                   ) -> tuple[RunStatistics, list[tuple[int, int | None]], np.ndarray]:
    """``base`` (the filter's own figures, every sample, computed without the truth)
    with the error figures at the common ``rows`` against ``truth_model`` (there).
    Also returns each gap end with the row it was judged at (``gap_end_rows``) and
    the NEES at each common row."""
    from .statistics import SETTLED_S, mean_or_none, truth_extremes
    x, sig = real.x[rows], real.sigma[rows]
    err = x - truth_model
    n_real = nees(x, unpack(real.P_packed[rows]), truth_model)
    ends = gap_end_rows(base.gaps, rows, real.sigma[:, Y], len(real.x))
    pos = {int(r): i for i, r in enumerate(rows)}
    tested = [pos[r] for _, r in ends if r is not None]
    stats = dataclasses.replace(
        base, yaw_rms=_rms(err[:, Y]) * RAD2DEG, roll_rms=_rms(err[:, R]) * RAD2DEG,
        h_rms=_rms(err[:, H_WHEEL]),
        per_state=np.mean((err / np.maximum(sig, 1e-300)) ** 2, axis=0),
        yaw_rms_smoothed=None if smoothed is None else
        _rms(smoothed.x[rows, Y] - truth_model[:, Y]) * RAD2DEG,
        end_err=[None if r is None else float(err[pos[r], Y] * RAD2DEG) for _, r in ends],
        # No gap end judged, no verdict: None, never a vacuous True.
        ends_within=bool(all(abs(err[i, Y]) <= 3 * sig[i, Y] for i in tested))
        if tested else None,
        nees_mean=float(np.mean(n_real)),
        nees_mean_settled=mean_or_none(n_real[t_s[rows] >= t_s[0] + SETTLED_S]),
        nees_inside=fraction_inside(n_real, chi2_bounds(N_STATES, 1)),
        truth_max=truth_extremes(truth_model, t_s[rows]))
    return stats, ends, n_real


def filter_row_summary(name: str, result, truth_model, rows, ends, t_s) -> dict:
    """summary.json's section of a filter besides the paper's: its errors at the
    common ``rows`` and at the gap ends judged there (``ends`` from
    ``gap_end_rows``; null where not tested), its σ at the gap ends themselves; its
    NEES on every 10th common row (``FilterTally``'s NEES samples)."""
    from ..samples import nees_rows
    pos = {int(r): i for i, r in enumerate(rows)}
    tested = [(0, pos[r]) for _, r in ends if r is not None]
    tally = FilterTally(name)
    tally.add(at_rows(result, rows, result.P_packed[rows][nees_rows(0, len(rows))]), 0,
              truth_model, tested, t_s[rows] - t_s[0])
    out = tally.summary()
    judged = iter(out["yaw_error_at_gap_end_deg"])
    out["yaw_error_at_gap_end_deg"] = [None if r is None else next(judged) for _, r in ends]
    out["yaw_sigma_at_gap_end_deg"] = [float(result.sigma[b, Y] * RAD2DEG) for b, _ in ends]
    if not tested:
        out["yaw_within_3sigma_at_gap_ends"] = None
    return out


def comparison_at_rows(runs, rows: np.ndarray, filters: dict, pitch=None
                       ) -> ComparisonInputs:
    """What comparison.npz is drawn from, at the common rows (a truth that is not at
    every sample: the error series exist there only); ``pitch`` the pitch filter's
    ``PitchRows`` there."""
    return ComparisonInputs(
        runs.params.omega_n_radps, at_rows(runs.real, rows), runs.truth_model,
        None if runs.smoothed is None else runs.smoothed.x[rows], None, None,
        runs.true_euler_rad, {k: at_rows(v, rows) for k, v in filters.items()}, pitch)
