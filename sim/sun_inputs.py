"""The Sun-driven inputs of the truth's step, on the run's sample grid: the Sun's
direction and distance from the spacecraft, the Earth's shadow and the magnetic
profile (``step.input_layout``).

The ephemeris is evaluated every ``SUN_EVERY`` samples and interpolated between
(``sun_nodes``, ``sun_on_grid``); the shadow is exact only where a coarse pass finds
the penumbra within reach (``near_shadow``, ``shadow_fine``).  ``TruthStream``
(``truth``) fills a window's inputs from these.
"""

from __future__ import annotations

from datetime import datetime

import numpy as np

from . import ephemeris
from .environment import Environment
from .frames import GeoOrbit


def step_inputs(t_s: np.ndarray, epoch: datetime, orbit: GeoOrbit, env: Environment,
                sun: dict[str, np.ndarray], shadow: np.ndarray, out: dict[str, np.ndarray]
                ) -> None:
    """The Sun-driven step inputs of ``step.input_layout`` at the samples ``t_s``, from
    the Sun there (``sun_on_grid``) and the shadow (``TruthStream._shadow``), written
    into ``out``'s arrays of those samples: ``sun_r``, ``sun_scale`` and, when the
    magnetic profile is on, ``m_prof`` (``TruthStream._window_inputs`` sets the rest)."""
    jd0 = ephemeris.julian_date(epoch)
    alpha = orbit.right_ascension(t_s, ephemeris.gmst_rad(jd0))
    # Satellite-to-Sun direction in the orbit frame.  The geocentric Sun, at right
    # ascension λ and declination δ, is (ρ sin(λ−α), −sin δ, −ρ cos(λ−α)) in the frame
    # of GeoOrbit.orbit_frame (ρ = cos δ); the satellite sits at −R ẑ_R, so d ŝ − r
    # adds R to the z component (a parallax of up to R/AU = 0.016°).
    phase = sun["ra"] - alpha
    d, radius = sun["dist"], orbit.radius_m
    d_cos_dec, cos_phase = d * sun["cos_dec"], np.cos(phase)   # each formed once
    sun_r = out["sun_r"]
    sun_r[:, 0] = d_cos_dec * np.sin(phase)
    sun_r[:, 1] = -d * sun["sin_dec"]
    sun_r[:, 2] = radius - d_cos_dec * cos_phase
    # |d ŝ + R ẑ|² = d² + 2 d R ŝ_z + R²
    sat_sun_dist = np.sqrt(d * (d - 2.0 * radius * sun["cos_dec"] * cos_phase) + radius**2)
    sun_r /= sat_sun_dist[:, None]
    np.multiply(shadow, (ephemeris.AU_M / sat_sun_dist) ** 2, out=out["sun_scale"])
    if profiled(env):
        out["m_prof"][:] = env.magnetic.profile(t_s)


def profiled(env: Environment) -> bool:
    mag = env.magnetic
    return bool(mag.enabled and np.any(mag.profile_amplitude_Am2))


def _sun_inertial(sun: dict[str, np.ndarray], idx) -> np.ndarray:
    """Geocentric Sun unit vectors (inertial) at the given sample indices."""
    ra, cd = sun["ra"][idx], sun["cos_dec"][idx]
    return np.stack([cd * np.cos(ra), cd * np.sin(ra), sun["sin_dec"][idx]], axis=-1)


def near_shadow(alpha_c, sun, idx_c, radius, step_len) -> np.ndarray:
    """The coarse pass: which coarse samples come within the penumbra's reach."""
    r = radius * np.stack([np.cos(alpha_c), np.sin(alpha_c), np.zeros(len(alpha_c))], -1)
    along = np.einsum("ij,ij->i", r, _sun_inertial(sun, idx_c))
    perp = np.sqrt(np.maximum(radius**2 - along**2, 0.0))
    reach = ephemeris.R_EARTH_M + 2.0 * radius * ephemeris.R_SUN_M / sun["dist"][idx_c] \
        + step_len
    return (along < step_len) & (perp < reach)


def shadow_fine(coarse, near, start, alpha, sun, radius, model, every) -> np.ndarray:
    """Shadow of the samples ``start`` … ``start + len(alpha) − 1`` (``alpha`` and
    ``sun`` hold those): the exact model within ``every`` samples of each flagged
    coarse sample (global indices ``coarse``), 1 elsewhere."""
    n = len(alpha)
    out = np.ones(n)
    if not np.any(near):
        return out
    fine = np.zeros(n, dtype=bool)
    for g in coarse[near]:
        fine[max(g - every - start, 0):max(g + every + 1 - start, 0)] = True
    fine = np.flatnonzero(fine)
    r_sat = radius * np.stack([np.cos(alpha[fine]), np.sin(alpha[fine]),
                               np.zeros(len(fine))], -1)
    out[fine] = ephemeris.shadow_factor(r_sat, _sun_inertial(sun, fine), sun["dist"][fine],
                                        model=model)
    return out


SUN_EVERY = 128   # samples between ephemeris nodes (about a minute)


def sun_nodes(n: int, dt_s: float, jd0: float, every: int = SUN_EVERY):
    """The ephemeris nodes of a run of ``n`` samples: their times and the Sun's right
    ascension (unwrapped over the run), cos and sin of declination, and distance."""
    idx = np.arange(0, n + every - 1, every)
    idx[-1] = min(idx[-1], n - 1)
    idx = np.unique(idx)
    t_nodes = np.round(idx * dt_s, 9)   # the run's sample times there (simulate_truth)
    unit, dist = ephemeris.sun_position_eci(jd0 + t_nodes / 86400.0)
    return t_nodes, {"ra": np.unwrap(np.arctan2(unit[:, 1], unit[:, 0])),
                     "cos_dec": np.hypot(unit[:, 0], unit[:, 1]), "sin_dec": unit[:, 2],
                     "dist": dist}


def sun_on_grid(t_s: np.ndarray, nodes) -> dict[str, np.ndarray]:
    """The Sun's right ascension, cos and sin of declination, and distance (m) at the
    samples ``t_s``, interpolated linearly between the run's ephemeris ``nodes``
    (``sun_nodes``).

    These slowly varying quantities need the ephemeris only every ``SUN_EVERY``
    samples (about a minute): the Sun moves about 1e-5 rad a minute, so the error
    (≈ angle²/8 ≈ 2e-11 rad) is far below the ephemeris's own 0.01°, and the
    day-long evaluation costs almost nothing.  np.interp at a sample depends only on
    the nodes either side, so a window gets the values the whole run has.
    """
    t_nodes, values = nodes
    return {k: np.interp(t_s, t_nodes, v) for k, v in values.items()}
