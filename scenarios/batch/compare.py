"""The batch, the filter and the filter plus smoother against the truth, at the
samples the truth has (a run's truth.csv: every ``output.interval_s``).

A Sun gap's end is judged by the one rule every command uses (docs/outputs.md, "Where
a Sun-gap end is judged"; ``run.estimate_truth.gap_end_rows``): at the sample where the
Sun sensor's yaw returns, or, with a coarser truth, at the last truth sample inside the
gap while the filter's σ there is within 1% of its σ at the end.  Every estimator is
judged at that same sample, and batch.json says which it was.
"""

from __future__ import annotations

import numpy as np

from ..units import RAD2DEG


def _rms(e) -> float | None:
    e = np.asarray(e)[np.isfinite(e)]
    return float(np.sqrt(np.mean(e**2))) if e.size else None


def compare(t_s, rows: np.ndarray, truth_model: np.ndarray, estimators: dict, ends,
            consider_sigma: np.ndarray | None = None) -> dict:
    """batch.json's ``truth`` section: per estimator (name → (x, σ) at ``rows``), the
    roll and yaw RMS errors and each gap end's yaw error, σ and whether it is within
    3σ, judged at the row ``ends`` gives (``gap_end_rows``: (b, row or None)); for the
    batch also its consider σ there (``consider_sigma`` at ``rows``)."""
    pos = {int(r): i for i, r in enumerate(rows)}
    out = {"compared_rows": int(len(rows)),
           "gap_end_t_s": [float(t_s[b]) for b, _ in ends],
           "gap_end_judged_at_t_s": [None if r is None else float(t_s[r]) for _, r in ends]}
    for name, (x, sig) in estimators.items():
        err = x - truth_model
        judged = []
        for _, r in ends:
            if r is None or not np.isfinite(err[pos[r], 2]):
                judged.append({"error_deg": None, "sigma_deg": None, "within_3sigma": None})
                continue
            e, s = float(err[pos[r], 2]), float(sig[pos[r], 2])
            entry = {"error_deg": e * RAD2DEG, "sigma_deg": s * RAD2DEG,
                     "within_3sigma": bool(abs(e) <= 3 * s)}
            if name == "batch" and consider_sigma is not None:
                sc = float(consider_sigma[pos[r], 2])
                entry["sigma_consider_deg"] = sc * RAD2DEG
                entry["within_3sigma_consider"] = bool(abs(e) <= 3 * sc)
            judged.append(entry)
        tested = [j["within_3sigma"] for j in judged if j["within_3sigma"] is not None]
        yaw, roll = _rms(err[:, 2]), _rms(err[:, 0])
        out[name] = {
            "yaw_rms_deg": None if yaw is None else yaw * RAD2DEG,
            "roll_rms_deg": None if roll is None else roll * RAD2DEG,
            "gap_ends": judged,
            # Nothing judged: not tested (None), never a vacuous pass.
            "gap_ends_within_3sigma": all(tested) if tested else None}
    return out
