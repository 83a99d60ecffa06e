"""Autonomous solar torque management: the daily loop that trims the momentum bias's
direction with the solar array's own torque (issue 45; docs/conventions.md).

GOES I-M manages momentum with the solar torque itself (Space Systems/Loral, US
patent 5,996,942, *Autonomous solar torque management*): once a day the spacecraft
records its momentum, estimates the mean external torque of the last day, and moves
the trim tab and the array's offset angle.  In an Earth-pointing GEO spacecraft the
solar torque is nearly fixed in inertial space, in the orbit plane, so the loop works
in the inertial transverse plane (ECI x, y; the orbit normal is ECI z):

* **measure** at the end of day k the transverse inertial momentum H_k (body and
  wheels, from the attitude and the wheel speeds), and the day's mean external torque
  apart from the torquers', ``N̄_k = (H_k − H_{k−1})/T − mean(T_torquers)``;
* **command** a change of the solar torque towards a target that also unloads:
  ``ΔN = g (−H_k/τ − N̄_k)``, split over the two actuators' directions, the tab's
  d̂ × ŝ and the offset's ŝ⊥ (``sim.environment.SolarTorque``), taken at Earth
  pointing with the Sun's direction at the day's end.

With N_{k+1} = N̄_k + ΔN the loop is, per transverse axis,
``[H; N]_{k+1} = [[1 − gT/τ, T(1 − g)], [−g/τ, 1 − g]] [H; N]_k``, whose eigenvalues are
the roots of ``z² − (2 − g − gT/τ) z + (1 − g) = 0``: with the default g = 1 and
τ = 2 T, z = 0 (the torque cancelled in one day) and z = 1 − T/τ = 0.5 (the
momentum halved each day).  The shadow and the Sun's distance only scale the torque
a command buys; the integral action (the angles accumulate) absorbs that.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from .frames import dcm_from_quat
from .spacecraft import Spacecraft
from .sun_inputs import sun_on_grid

DAY_S = 86400.0
ABSORB_EVERY = 8   # steps between the torquer-impulse samples (SolarManager.absorb)


@dataclass(frozen=True)
class SolarManagement:
    """The daily loop's law and the actuators' ranges (deg)."""

    period_s: float = DAY_S
    torque_gain: float = 1.0              # g
    momentum_time_constant_s: float = 2 * DAY_S   # τ
    tab_limits_deg: tuple[float, float] = (0.0, 40.0)
    offset_limits_deg: tuple[float, float] = (-10.0, 10.0)

    def __post_init__(self) -> None:
        if not (self.period_s > 0 and self.momentum_time_constant_s > 0
                and 0 < self.torque_gain <= 1):
            raise ValueError("solar management: period and τ must be positive, 0 < g ≤ 1")

    def transition(self) -> np.ndarray:
        """The loop's matrix on one transverse axis, [H; N] from day to day (module doc)."""
        g, T, tau = self.torque_gain, self.period_s, self.momentum_time_constant_s
        return np.array([[1 - g * T / tau, T * (1 - g)], [-g / tau, 1 - g]])


def inertial_momentum(spacecraft: Spacecraft, x: np.ndarray, c_rn: np.ndarray) -> np.ndarray:
    """Total angular momentum (body and wheels) in inertial axes from the truth state
    x = [q_BR, ω_BN, Ω] (``sim.step``) and C_RN at that time."""
    n = spacecraft.n_wheels
    w, wheels = x[4:7], x[7:7 + n]
    h_b = spacecraft.J @ w + spacecraft.wheel_axes.T @ (spacecraft.wheel_inertias * wheels)
    return c_rn.T @ (dcm_from_quat(x[0:4]).T @ h_b)


def body_to_inertial(q_br: np.ndarray, c_rn: np.ndarray, v_b: np.ndarray) -> np.ndarray:
    """Body vectors (N, 3) to inertial axes, given q_BR (N, 4) and C_RN (N, 3, 3)."""
    v_r = np.einsum("nji,nj->ni", dcm_from_quat(q_br), v_b)
    return np.einsum("nji,nj->ni", c_rn, v_r)


def actuator_directions(sun_n: np.ndarray, lever_n: np.ndarray) -> np.ndarray:
    """The torque of a unit κ (tab) and a unit κ_o (offset), inertial, transverse
    components (2 × 2, columns tab and offset), at Earth pointing: d̂ × ŝ and
    ŝ − (d̂·ŝ) d̂ with the lever d̂ and the Sun ŝ in inertial axes."""
    tab = np.cross(lever_n, sun_n)
    offset = sun_n - (lever_n @ sun_n) * lever_n
    return np.column_stack([tab[:2], offset[:2]])


def command(law: SolarManagement, h_now: np.ndarray, mean_torque: np.ndarray,
            directions: np.ndarray) -> np.ndarray:
    """The changes (Δκ, Δκ_o) in N m that move the day's mean transverse torque
    ``mean_torque`` towards −H/τ by the gain g (the module doc), least squares
    over the two directions."""
    target = -np.asarray(h_now[:2]) / law.momentum_time_constant_s
    wanted = law.torque_gain * (target - np.asarray(mean_torque[:2]))
    return np.linalg.lstsq(directions, wanted, rcond=None)[0]


class SolarManager:
    """The loop on board a ``sim.truth.TruthStream``: ``absorb`` each rolled-out piece,
    ``at_break`` at each period's end (the stream splits its rollout there) gives the
    solar torque to fly next.  ``history`` keeps one row per command."""

    def __init__(self, law: SolarManagement, spacecraft: Spacecraft, orbit, gmst0: float,
                 dt_s: float, sun_nodes, mtq_columns: slice, x0: np.ndarray):
        self.law, self.spacecraft, self.orbit, self.gmst0 = law, spacecraft, orbit, gmst0
        self.dt_s, self.sun_nodes, self.mtq = dt_s, sun_nodes, mtq_columns
        self.period = max(1, int(round(law.period_s / dt_s)))
        self.h_prev = inertial_momentum(spacecraft, x0, self._c_rn(np.array([0.0]))[0])
        self.torquer_impulse = np.zeros(3)
        self.history: list[dict[str, float]] = []

    def _c_rn(self, t_s: np.ndarray) -> np.ndarray:
        return self.orbit.orbit_frame(t_s, self.gmst0)

    def breaks(self, a: int, b: int) -> list[int]:
        """The samples in (a, b] where a period ends (a command applies from there)."""
        first = (a // self.period + 1) * self.period
        return list(range(first, b + 1, self.period))

    def absorb(self, a: int, states: np.ndarray, aux: np.ndarray) -> None:
        """Steps a … a+len(aux)−1: add the torquers' inertial impulse (their torque is
        known on board: the commanded dipoles and the field model), sampled every
        ``ABSORB_EVERY`` steps of the run: the torque turns at the orbit rate, so a
        4 s rectangle rule is exact to ~1e-8 of the day's impulse, at an eighth of the
        cost in the rollout's thread."""
        k = np.arange(-a % ABSORB_EVERY, len(aux), ABSORB_EVERY)
        t = np.round((a + k) * self.dt_s, 9)
        t_n = body_to_inertial(states[k, 0:4], self._c_rn(t), aux[k, self.mtq])
        self.torquer_impulse += t_n.sum(axis=0) * (ABSORB_EVERY * self.dt_s)

    def at_break(self, k: int, x: np.ndarray, solar):
        """The solar torque (``SolarTorque``) to fly from sample k, state x there."""
        t = np.round(k * self.dt_s, 9)
        c_rn = self._c_rn(np.array([t]))[0]
        h_now = inertial_momentum(self.spacecraft, x, c_rn)
        span = self.period * self.dt_s
        mean = (h_now - self.h_prev - self.torquer_impulse) / span
        sun = sun_on_grid(np.array([t]), self.sun_nodes)
        sun_n = np.array([sun["cos_dec"][0] * np.cos(sun["ra"][0]),
                          sun["cos_dec"][0] * np.sin(sun["ra"][0]), sun["sin_dec"][0]])
        lever_n = c_rn.T @ np.asarray(solar.lever_axis, dtype=float)
        d_kappa, d_offset = command(self.law, h_now, mean, actuator_directions(sun_n, lever_n))
        law = self.law
        tab = float(np.clip(solar.trim_tab_deg - d_kappa / solar.tab_effectiveness_Nm_per_deg,
                            *law.tab_limits_deg))
        offset = float(np.clip(
            solar.array_offset_deg - d_offset / solar.offset_effectiveness_Nm_per_deg,
            *law.offset_limits_deg))
        self.history.append({"t_s": t, "H_x_Nms": h_now[0], "H_y_Nms": h_now[1],
                             "torque_x_Nm": mean[0], "torque_y_Nm": mean[1],
                             "trim_tab_deg": tab, "array_offset_deg": offset})
        self.h_prev, self.torquer_impulse = h_now, np.zeros(3)
        return dataclasses.replace(solar, trim_tab_deg=tab, array_offset_deg=offset)
