"""A run's telemetry.csv resampled as a ground system with a jittery clock would have
delivered it: the tests of `tune`, `trim` and `batch` on telemetry off the grid.

How: rows at 1.0 s ± 20 ms (uniform jitter, tags to the millisecond), inside the
file's span, less the rows in ``gap`` (a telemetry gap); each row holds the file's
sample nearest its tag (zero-order interpolation), empty where that sample is, so a
dropout or a Sun gap stays one.  The tag is then up to 0.27 s off the sample's time,
which moves roll and yaw by ~1e-5°, a thousandth of their noise.  ``linear=True``
interpolates linearly between the two bracketing samples instead (empty if either
is), except ``sun_head`` and ``yaw_sigma_deg`` (which head, and its σ): that averages
two samples' independent noise, a quieter sensor than the scenario's (roll NIS 0.67),
which biases a noise fit.  The text time_utc column is dropped (t_s counts from the
scenario's epoch)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from scenarios.files.csvio import read_csv, write_csv

NEAREST = ("sun_head", "yaw_sigma_deg")


def resample(src: Path, out: Path, cadence_s: float = 1.0, jitter_s: float = 0.02,
             gap: tuple[float, float] | None = None, seed: int = 43,
             linear: bool = False) -> dict[str, np.ndarray]:
    """Write ``src`` resampled (module doc) to ``out``; returns the columns written."""
    cols = read_csv(src)
    t = cols["t_s"]
    rng = np.random.default_rng(seed)
    k = np.arange(1, int((t[-1] - t[0]) / cadence_s))
    tn = np.round(t[0] + k * cadence_s + rng.uniform(-jitter_s, jitter_s, len(k)), 3)
    if gap is not None:
        tn = tn[(tn < gap[0]) | (tn >= gap[1])]
    i = np.clip(np.searchsorted(t, tn, side="right") - 1, 0, len(t) - 2)
    w = (tn - t[i]) / (t[i + 1] - t[i])
    nearest = np.where(w < 0.5, i, i + 1)
    out_cols = {"t_s": tn}
    for name, v in cols.items():
        if name == "t_s" or v.dtype.kind not in "fi":
            continue
        v = np.asarray(v, dtype=float)
        out_cols[name] = (v[nearest] if not linear or name in NEAREST
                          else (1 - w) * v[i] + w * v[i + 1])
    write_csv(out, out_cols, exact=True)
    return out_cols
