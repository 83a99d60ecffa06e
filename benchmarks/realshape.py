"""A real-shaped 30-day telemetry file from a run's telemetry.csv: ISO UTC tags only
(ms), ±50 ms jitter on every tag, 10% of rows dropped at random, a 6 h hole."""
import sys

import numpy as np
import pandas as pd

HOLE = (12.3 * 86400, 12.3 * 86400 + 6 * 3600)     # 6 h from day 12.3


def real_shaped(src: str, dst: str, epoch_utc: str = "2026-03-20T12:00:00") -> None:
    """``src`` (a run's telemetry.csv, t_s from ``epoch_utc``) as ``dst``, a chunk at a
    time; the seed is fixed, so the file repeats."""
    rng = np.random.default_rng(2026)
    epoch = np.datetime64(epoch_utc, "ns")
    first = True
    with open(dst, "w") as out:
        for chunk in pd.read_csv(src, comment="#", chunksize=500_000):
            t = chunk["t_s"].to_numpy()
            jit = rng.uniform(-0.05, 0.05, len(t))
            jit[t == 0] = 0.0
            keep = rng.random(len(t)) > 0.1
            keep[t == 0] = True
            keep &= ~((t > HOLE[0]) & (t < HOLE[1]))
            tj = t + jit
            ns = epoch + (np.rint(tj * 1000).astype(np.int64) * 1_000_000).astype("timedelta64[ns]")
            tags = np.datetime_as_string(ns.astype("datetime64[ms]"), unit="ms")
            df = chunk.drop(columns=["t_s", "time_utc"])
            df.insert(0, "time_utc", [s + "Z" for s in tags])
            df = df[keep]
            df.to_csv(out, header=first, index=False)
            first = False


if __name__ == "__main__":
    real_shaped(sys.argv[1], sys.argv[2])
