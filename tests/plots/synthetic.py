"""Synthetic arrays shaped like one two-day estimation run (no physics, just
plausible sizes), for the figure tests."""

from __future__ import annotations

import numpy as np

DT = 0.512
N = 337_501                       # 2 days at 0.512 s
TITLE = "goes_next_equinox — epoch 2026-03-20T12:00:00Z, seed 7"
NEES_DOF = 9
NEES_BOUNDS = (2.700, 19.023)     # χ²(9) 2.5% / 97.5%
NIS_BOUNDS = (0.000982, 5.024)    # χ²(1) 2.5% / 97.5%
TORQUES = ("N_px", "N_pz", "N_cx", "N_cz")
YAW_DIFF_MAX = 7.5e-4             # deg: the default run's largest real − linearized yaw


def colored(rng, n, corr_samples):
    """Unit-variance low-pass noise (moving average of white noise)."""
    w = rng.standard_normal(n + corr_samples)
    c = np.cumsum(np.r_[0.0, w])
    y = (c[corr_samples:] - c[:-corr_samples])[:n]
    return y / np.sqrt(corr_samples)


def make_run(seed: int = 1, n: int = N) -> dict:
    rng = np.random.default_rng(seed)
    t = np.arange(n) * DT
    t_h = t / 3600.0
    hod = t_h % 24.0
    gap = (hod >= 14.0) & (hod < 22.0)               # 8 h daily gap, both end in the record
    into_gap = np.where(gap, hod - 14.0, 0.0)
    since_gap = np.where(~gap & (hod >= 22.0), hod - 22.0, 24.0)
    since_gap = np.where(~gap & (hod < 14.0), hod + 2.0, since_gap)
    start = np.exp(-t / 1800.0)                      # initial convergence, 30 min
    dss = ~gap & (hod >= 10.0) & (hod < 14.0)        # the 4 h before each gap

    sig_yaw = 0.003 + np.where(gap, 0.0378 * (into_gap / 8.0) ** 1.5,
                               0.0378 * np.exp(-since_gap * 60 / 5.0)) + 0.05 * start
    sig_roll = 0.0025 + 0.03 * start
    sig_h = 4e-6 + 2e-6 * gap + 5e-5 * start         # N m s
    series = {}
    for name, sig, unit, style in (("roll", sig_roll, "deg", "envelope"),
                                   ("yaw", sig_yaw, "deg", "trace"),
                                   ("h", sig_h, "N m s", "envelope")):
        lin = sig * colored(rng, n, 400 if style == "trace" else 2)
        diff = 0.02 * sig * colored(rng, n, 2000)
        real = lin + diff
        smoothed = 0.4 * sig * colored(rng, n, 800)
        series[name] = {"unit": unit, "real": real, "linear": lin, "sigma": sig,
                        "smoothed": smoothed, "style": style, "difference": diff}
    # The yaw difference peaks at the default run's value, far below the paper's σ.
    d = series["yaw"]["difference"]
    d *= YAW_DIFF_MAX / np.max(np.abs(d))
    series["yaw"]["real"] = series["yaw"]["linear"] + d
    series["yaw"]["reference"] = (0.0397, "σ_yaw, Eq. 55")
    # A start-up transient far outside everything else: it must be said, not hidden.
    series["yaw"]["real"][:20] = series["yaw"]["linear"][:20] = 0.67
    series["h"]["smoothed"] = None

    est, tru, tsig = {}, {}, {}
    for k, name in enumerate(TORQUES):
        truth_val = (0.2 + 0.1 * k) * 1e-6 * (-1) ** k
        tru[name] = truth_val + 3e-7 * np.sin(2 * np.pi * t / 86164.0 + k)
        s = 2e-6 * (1 + gap * (name == "N_cz")) + 3e-6 * start
        tsig[name] = s
        est[name] = tru[name] + 0.3 * s * colored(rng, n, 1000) - truth_val * start

    nees_lin = np.full(n, np.nan)
    nees_lin[::10] = 0.3 * rng.chisquare(NEES_DOF, nees_lin[::10].size)   # conservative
    nees_real = nees_lin * (1 + 0.01 * gap)
    nis = {m: rng.chisquare(1, n) for m in ("roll", "yaw", "h")}
    nis["yaw"][gap] = np.nan
    nis["yaw"][dss] *= 1e-3                          # down-weighted DSS yaw

    orbit = 2 * np.pi * t / 86164.0
    truth_att = {"roll": 0.004 * np.sin(orbit), "pitch": 0.006 * np.cos(orbit) + 0.002,
                 "yaw": 0.02 * np.sin(orbit + 0.5)}
    head = np.where(gap, np.nan, np.where(dss, 0.0, np.where(hod < 5, 1.0, 2.0)))
    yaw_sigma = np.where(head == 0, 0.037, np.where(head == 1, 1.0, 1.5 + 3 * (hod % 1)))
    yaw_sigma = np.where(np.isnan(head), np.nan, yaw_sigma)
    measured = {"roll": truth_att["roll"] + 0.01 * rng.standard_normal(n),
                "pitch": truth_att["pitch"] + 0.01 * rng.standard_normal(n),
                "yaw": truth_att["yaw"] + yaw_sigma * rng.standard_normal(n)}
    wheels = {"wheel1_rpm": 5485.0 + 2.0 * np.sin(orbit) + 0.05 * rng.standard_normal(n),
              "wheel2_rpm": 5470.0 - 1.5 * np.sin(orbit) + 0.05 * rng.standard_normal(n)}
    return {"t_s": t, "gap": gap, "dss": dss, "series": series, "est": est, "tru": tru,
            "tsig": tsig, "nees_real": nees_real, "nees_lin": nees_lin, "nis": nis,
            "measured": measured, "truth_att": truth_att, "wheels": wheels,
            "sun_head": head, "yaw_sigma": yaw_sigma}
