"""The truth's histories (``TruthResult``) and how a rollout's raw output becomes
one (``result``): attitude, rates, wheels, momentum, torques by source (the wheel
motors' reactions formed only when read), the Sun and the shadow."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from .step import split_aux

# TruthResult.torques's sources, in truth.csv's column order.  Those of
# OPTIONAL_TORQUES are there only in runs that fly them: the disturbance
# (``sim.disturbance``) only when a scenario has one, the thrusters (``sim.events``) only
# when it has thruster events, so a run without them records and writes what it always
# did.
TORQUE_SOURCES = ("gravity_gradient", "solar", "magnetic", "magnetic_control", "wheel_control",
                  "wheel_input", "wheel_ripple", "external", "disturbance", "thruster")
OPTIONAL_TORQUES = ("disturbance", "thruster")
# The sources acting on the spacecraft from outside, besides the gravity gradient
# (which the paper's linear model carries in F): the torques its Eq. 9 stands for
# (the disturbance too, which the model meets only as process noise), summed in
# this order.
EXTERNAL_TORQUES = ("solar", "magnetic", "magnetic_control", "external", "disturbance",
                    "thruster")

class Euler312:
    """yaw, roll and pitch (rad) of a history holding ``euler_rad`` (N, 3): the 3-1-2
    angles, in that order."""

    euler_rad: np.ndarray

    @property
    def yaw_rad(self) -> np.ndarray:
        return self.euler_rad[:, 0]

    @property
    def roll_rad(self) -> np.ndarray:
        return self.euler_rad[:, 1]

    @property
    def pitch_rad(self) -> np.ndarray:
        return self.euler_rad[:, 2]


@dataclass(frozen=True)
class TruthResult(Euler312):
    """Truth histories on the output grid (SI units, body axes unless named).

    ``torques`` maps a source name to an (N, 3) body torque in N m:
    gravity_gradient, solar, magnetic (residual and prescribed dipoles),
    magnetic_control (the torquers), wheel_control (the reaction of the control's
    motor torques on the body), wheel_input (of ``wheel_torque``), wheel_ripple,
    external (the caller's ``extra_torque``) and, in runs that fly them, disturbance
    (``sim.disturbance``) and thruster (``sim.events``).  Torques are evaluated at each
    sample, the start of its step; external, disturbance and thruster are held over it.
    """

    t_s: np.ndarray
    q_br: np.ndarray
    w_bn_radps: np.ndarray
    w_br_radps: np.ndarray
    wheel_speeds_radps: np.ndarray
    h_Nms: np.ndarray
    H_Nms: np.ndarray
    torques: Mapping[str, np.ndarray]
    wheel_command_Nm: np.ndarray
    torquer_dipole_Am2: np.ndarray
    sun_body: np.ndarray
    sun_orbit_frame: np.ndarray
    shadow: np.ndarray
    final_state: np.ndarray
    backend: str
    euler_rad: np.ndarray  # (N, 3): yaw, roll, pitch (3-1-2)

    @property
    def eclipse(self) -> np.ndarray:
        return self.shadow < 1.0

    def rows(self, lo: int, hi: int) -> TruthResult:
        """Samples lo … hi−1 of this window, as views (``final_state`` is the state
        after them only for the window's last piece)."""
        cut = slice(lo, hi)
        fields = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        for name, v in fields.items():
            if isinstance(v, np.ndarray) and name != "final_state":
                fields[name] = v[cut]
        fields["torques"] = self.torques.slice(lo, hi) if isinstance(self.torques, Torques) \
            else {k: v[cut] for k, v in self.torques.items()}
        return TruthResult(**fields)


class Torques(Mapping):
    """``TruthResult.torques``: body torques by source, (N, 3) each.  The wheel
    motors' reactions on the body (``_reaction``) are formed when first asked for,
    since only the files read them, and ``rows`` forms them on chosen samples
    alone: a run writing every 125th sample never builds the others."""

    def __init__(self, ready: dict[str, np.ndarray], reactions: dict[str, np.ndarray],
                 axes: np.ndarray, order: tuple[str, ...]):
        self._ready, self._reactions, self._axes, self._order = \
            dict(ready), dict(reactions), axes, order

    def __getitem__(self, name: str) -> np.ndarray:
        if name not in self._ready:
            if name not in self._reactions:
                raise KeyError(name)
            self._ready[name] = _reaction(self._reactions.pop(name), self._axes)
        return self._ready[name]

    def __iter__(self):
        return iter(self._order)

    def __len__(self) -> int:
        return len(self._order)

    def __contains__(self, name) -> bool:
        # Without this, Mapping's would form a reaction just to answer.
        return name in self._order

    def slice(self, lo: int, hi: int) -> Torques:
        """Samples lo … hi−1, still formed only when read."""
        cut = slice(lo, hi)
        return Torques({k: v[cut] for k, v in self._ready.items()},
                       {k: v[cut] for k, v in self._reactions.items()}, self._axes,
                       self._order)

    def rows(self, idx: np.ndarray) -> dict[str, np.ndarray]:
        """Every torque at the samples ``idx``: the rows of the whole arrays, bit for
        bit (a reaction is a per-row sum)."""
        return {name: self._ready[name][idx] if name in self._ready
                else _reaction(self._reactions[name][idx], self._axes)
                for name in self._order}


def _reaction(motor_Nm: np.ndarray, axes: np.ndarray) -> np.ndarray:
    """Body torque −Σ_i u_i a_i of the wheel motor torques (N, n) on axes (n, 3).
    Summed wheel by wheel, not by a BLAS product: BLAS kernels treat the rows of a
    block and of its tail differently (fused or not), so a row's bits would depend on
    how long the window holding it is."""
    out = np.zeros((len(motor_Nm), 3))
    for i in range(axes.shape[0]):
        out -= motor_Nm[:, i:i + 1] * axes[i]
    return out


def truth_result(t_s, states, aux, inputs, shadow, spacecraft, backend) -> TruthResult:
    """The TruthResult of a rolled-out piece: its states, the step's outputs and inputs."""
    n = spacecraft.n_wheels
    a = split_aux(aux, n)
    x = states[:-1]
    axes = spacecraft.wheel_axes
    # With a disturbance or thrusters the step's n_ext is the caller's torque plus
    # them, each kept apart (``TruthStream._window_inputs``); without, the caller's alone.
    ready = {"gravity_gradient": a["t_gg"], "solar": a["t_solar"], "magnetic": a["t_mag"],
             "magnetic_control": a["t_mtq"], "external": inputs.get("external", inputs["n_ext"])}
    for optional in OPTIONAL_TORQUES:
        if optional in inputs:
            ready[optional] = inputs[optional]
    reactions = {"wheel_control": a["u_cmd"], "wheel_input": inputs["u_wheel"],
                 "wheel_ripple": inputs["ripple"]}
    order = tuple(k for k in TORQUE_SOURCES if k in ready or k in reactions)
    torques = Torques(ready, reactions, axes, order)
    return TruthResult(
        t_s=t_s, q_br=x[:, 0:4], w_bn_radps=x[:, 4:7], w_br_radps=a["w_br"],
        wheel_speeds_radps=x[:, 7:], h_Nms=a["h"], H_Nms=a["H"], torques=torques,
        wheel_command_Nm=a["u_cmd"], torquer_dipole_Am2=a["m_cmd"], sun_body=a["sun_b"],
        sun_orbit_frame=inputs["sun_r"], shadow=shadow, final_state=states[-1],
        backend=backend, euler_rad=a["euler"])
