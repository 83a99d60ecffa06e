"""An unmodelled random body torque for the truth (roll x, pitch y, yaw z, N m): the
"environmental torque errors" the paper's filter carries only as process noise
(Section 6, Eq. 45), flown so that the filter meets torques its model lacks.

Two kinds, independent between axes:

* ``white``, of intensity q per axis in the paper's Eq. 35 convention (two-sided):
  E[w(t) w(t')] = q δ(t − t'), q in (N m)² s.  Held constant over each step Δt, the
  step's value is drawn N(0, q/Δt): its integral over the step then has variance
  q Δt, the momentum random walk q·t of the continuous process (the convention of
  ``environment.WheelRipple``).
* ``gauss_markov``, first order: autocorrelation R(t) = σ² exp(−|t|/τ), whose
  two-sided power spectral density is S(ω) = 2σ²τ / (1 + ω²τ²).  Below 1/τ it acts
  as white noise of intensity S(0) = 2σ²τ, its zero-frequency white equivalent.
  (Eq. 45 takes q = σ²τ = (5e-6 N m)² · 21541 s = 5.4e-7 (N m)² s, half of 2σ²τ.)
  It is sampled exactly at Δt, x_{k+1} = φ x_k + σ √(1 − φ²) n_k with
  φ = exp(−Δt/τ) and n_k ~ N(0, 1), from a stationary start x_0 ~ N(0, σ²); x_k is
  held over step k (zero-order hold, as the RK4 step holds every per-step input).

The defaults are Eq. 45's assumption: σ = 5e-6 N m on roll and yaw (about 10% of the
equinox solar torque), none on pitch, τ = 21541 s (a quarter orbit), and its
q = 5.4e-7 (N m)² s for the white kind; they act only when ``kind`` selects them.

``DisturbanceDraw`` is the one place the torque is drawn: a run's draws, a piece at a
time, from the run's own generator, with the Gauss–Markov state carried, so pieces
drawn in order give the whole draw bit for bit.  Every axis is drawn whatever its
σ or q (a zero scales to zero), so changing one axis's level never moves another's.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

KINDS = ("none", "white", "gauss_markov")

# Eq. 45: 10% of the equinox torque amplitude, correlated over a quarter orbit.
PAPER_SIGMA_NM = (5e-6, 0.0, 5e-6)
PAPER_CORRELATION_TIME_S = 21541.0
PAPER_Q_NM2S = (5.4e-7, 0.0, 5.4e-7)


def _non_negative_vector(v, name: str) -> None:
    a = np.asarray(v, dtype=float)
    if a.shape != (3,) or not np.all(np.isfinite(a)) or np.any(a < 0):
        raise ValueError(f"disturbance {name} must be 3 finite numbers, none negative")


@dataclass(frozen=True)
class Disturbance:
    """The random body torque's kind and levels (module doc): ``q_Nm2s`` for
    ``white``, ``sigma_Nm`` and ``correlation_time_s`` for ``gauss_markov``."""

    kind: str = "none"
    q_Nm2s: tuple[float, float, float] = PAPER_Q_NM2S
    sigma_Nm: tuple[float, float, float] = PAPER_SIGMA_NM
    correlation_time_s: float = PAPER_CORRELATION_TIME_S

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"disturbance kind must be one of {', '.join(KINDS)}")
        _non_negative_vector(self.q_Nm2s, "q_Nm2s")
        _non_negative_vector(self.sigma_Nm, "sigma_Nm")
        tau = self.correlation_time_s
        if not (np.isfinite(tau) and tau > 0):
            raise ValueError("disturbance correlation_time_s must be finite and positive")

    @property
    def enabled(self) -> bool:
        return self.kind != "none"

    def white_step_sigma_Nm(self, dt_s: float) -> np.ndarray:
        """1σ per axis of a white step's held value, √(q/Δt) (N m)."""
        return np.sqrt(np.asarray(self.q_Nm2s, dtype=float) / dt_s)

    def markov_coefficients(self, dt_s: float) -> tuple[float, float]:
        """φ = exp(−Δt/τ) and √(1 − φ²), the latter by expm1: for Δt ≪ τ, 1 − φ²
        formed from φ would lose the digits that matter."""
        r = dt_s / self.correlation_time_s
        return float(np.exp(-r)), float(np.sqrt(-np.expm1(-2.0 * r)))


class DisturbanceDraw:
    """One run's disturbance torque, drawn a piece at a time from ``rng`` (module doc).

    ``fill(out)`` writes the next ``len(out)`` samples (rows of an (m, 3) array, N m).
    For ``gauss_markov`` it draws the unit-variance process u (x = σ u) and carries
    u's filter state from piece to piece, so that any split of a run into pieces gives
    the very numbers of one piece: the normals continue the generator's one stream,
    and the recursion (scipy's lfilter, its state passed on) is the same element by
    element."""

    def __init__(self, params: Disturbance, dt_s: float, rng: np.random.Generator):
        if not params.enabled:
            raise ValueError("a disturbance of kind 'none' draws nothing")
        if not (np.isfinite(dt_s) and dt_s > 0):
            raise ValueError("dt_s must be positive")
        self.params, self.dt_s, self.rng = params, dt_s, rng
        self.phi, self.gain = params.markov_coefficients(dt_s)
        self._z: np.ndarray | None = None   # lfilter's state (1, 3); None before sample 0

    def fill(self, out: np.ndarray) -> None:
        if len(out) == 0:
            return
        self.rng.standard_normal(out=out)
        if self.params.kind == "white":
            out *= self.params.white_step_sigma_Nm(self.dt_s)
            return
        # Imported here: only a Gauss–Markov run pays for scipy.signal's import.
        from scipy.signal import lfilter
        first = 0
        if self._z is None:
            # Stationary start: u_0 = n_0 ~ N(0, 1); the recursion takes over from u_0.
            self._z = self.phi * out[:1]
            first = 1
        if first < len(out):
            out[first:], self._z = lfilter([self.gain], [1.0, -self.phi], out[first:],
                                           axis=0, zi=self._z)
        out *= np.asarray(self.params.sigma_Nm, dtype=float)


def draw(params: Disturbance, dt_s: float, n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` samples (n, 3) of the disturbance, in one piece (N m)."""
    out = np.empty((n, 3))
    DisturbanceDraw(params, dt_s, rng).fill(out)
    return out
