"""Truth simulation: the compiled rollout of the RK4 step over a run, window by window.

``TruthStream`` is what every run flies: a window at a time, it evaluates the
slowly varying inputs (Sun, shadow, field: ``sun_inputs``) on the window's grid
with vectorised numpy, draws the wheel ripple from the caller's generator (and a
disturbance torque, ``disturbance``, from its own), and rolls the compiled step out
(``rollout``: a C loop over the step, or ``mapaccum`` chunks in the VM), one Python
call per piece of thousands of steps, none per step, carrying its state and
generators to the next window.  ``simulate_truth`` rolls a whole run
out at once (the tests and benchmarks).  The result is ``history.TruthResult``.
"""

from __future__ import annotations

import dataclasses
import queue
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from datetime import datetime
from functools import lru_cache

import numpy as np
from dynprop.rollout.chunks import ChunkedRollout
from dynprop.rollout.compiled import requested_backend

from . import ephemeris
from .control import Control
from .disturbance import Disturbance, DisturbanceDraw
from .environment import Environment
from .events import Schedule
from .frames import GeoOrbit, dcm_from_quat, quat_from_euler312
from .history import TruthResult, truth_result
from .momentum import SolarManagement, SolarManager
from .spacecraft import Spacecraft
from .step import aux_slice, build_step, input_layout, is_managed, pack_params
from .sun_inputs import near_shadow, profiled, shadow_fine, step_inputs, sun_nodes, sun_on_grid

DEFAULT_CHUNK = 4096
TAIL_CHUNK = 256  # a short run's or a long run's last steps, without 4096-step padding
SENSE_PIECE = 4 * DEFAULT_CHUNK   # samples per sensing call while the rollout runs
# The solar torque's setting each command kind of ``sim.events`` moves.
COMMAND_FIELDS = {"trim_tab": "trim_tab_deg", "array_offset": "array_offset_deg"}


@dataclass(frozen=True)
class InitialState:
    """Initial attitude (3-1-2, rad) and rate of the body relative to the orbit
    frame, ω_BR in body axes (rad/s).  Wheel speeds default to the spacecraft's."""

    yaw_rad: float = 0.0
    roll_rad: float = 0.0
    pitch_rad: float = 0.0
    rate_wrt_orbit_radps: tuple[float, float, float] = (0.0, 0.0, 0.0)
    wheel_speeds_radps: tuple[float, ...] | None = None

    def state_vector(self, spacecraft: Spacecraft, orbit: GeoOrbit) -> np.ndarray:
        q = quat_from_euler312(self.yaw_rad, self.roll_rad, self.pitch_rad)
        c_br = dcm_from_quat(q)
        w_bn = np.asarray(self.rate_wrt_orbit_radps, float) \
            + c_br @ np.array([0.0, -orbit.rate_radps, 0.0])
        wheels = spacecraft.wheel_speeds if self.wheel_speeds_radps is None \
            else np.asarray(self.wheel_speeds_radps, float)
        if wheels.shape != (spacecraft.n_wheels,):
            raise ValueError(f"expected {spacecraft.n_wheels} wheel speeds, got {wheels.shape}")
        x0 = np.concatenate([q, w_bn, wheels])
        if not np.all(np.isfinite(x0)):
            raise ValueError("initial state contains NaN or infinity")
        return x0


class TruthModel:
    """The compiled truth step for one wheel count, built once and reused."""

    def __init__(self, n_wheels: int, chunk: int = DEFAULT_CHUNK, backend: str | None = None,
                 managed: bool = False):
        self.n_wheels = n_wheels
        self.chunk = chunk
        self.managed = managed
        self.rollout_engine = ChunkedRollout(build_step(n_wheels, managed), chunk, TAIL_CHUNK,
                                             backend)
        self.backend = self.rollout_engine.backend

    def rollout(self, x0: np.ndarray, inputs: dict[str, np.ndarray], p: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
        """Run one step per row of the per-step ``inputs`` (``step.input_layout``
        names, each (N, k)).  Returns states (N+1, n_x) including x0, and aux (N, n_aux).
        """
        arrays = [inputs[name] for name, _ in input_layout(self.n_wheels)]
        return self.rollout_engine.run(x0, arrays, p)


@lru_cache(maxsize=8)
def truth_model(n_wheels: int, chunk: int = DEFAULT_CHUNK, backend: str = "auto",
                managed: bool = False) -> TruthModel:
    return TruthModel(n_wheels, chunk, backend, managed)


def _checked(a: np.ndarray | None, shape: tuple[int, int], name: str) -> np.ndarray:
    if a is None:
        return np.zeros(shape)
    a = np.asarray(a, dtype=float)
    if a.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} contains NaN or infinity")
    return a


class TruthStream:
    """The truth of one run, simulated a window at a time.

    ``window(a, b)`` gives samples a … b−1 for contiguous, increasing windows (the
    first from 0).  Concatenated, the windows equal ``simulate_truth``'s whole-run
    arrays bit for bit, which is what ``simulate_truth`` is: one window.  Carried
    from window to window: the RK4 state, the ripple generator (whose draws
    continue the one stream) and the disturbance's generator and Gauss–Markov state
    (``disturbance.DisturbanceDraw``).  Aligned on the run: the Sun's ephemeris
    nodes (every 128 samples from the start, unwrapped over the run) and the
    shadow's coarse pass (every 64 samples from the start, its padding from the
    run's first interval).  Everything else is per sample.  Memory is the window's,
    whatever the run's length (the run's Sun nodes: 32 bytes per 128 samples).

    A ``schedule`` (``sim.events``) adds its thruster torques to the step's external
    torque, recorded as the source ``thruster``, and flies its trim_tab,
    array_offset and wheel_switch commands from their sample on: the rollout is split
    there and the parameters re-packed, as ``retrim`` does between windows.  A wheel
    switch (``switch_wheels``) needs the spacecraft's standby yaw wheel, which idles
    until then, its motor's ripple off."""

    def __init__(self, spacecraft: Spacecraft, orbit: GeoOrbit, environment: Environment,
                 control: Control, initial: InitialState, epoch: datetime, duration_s: float,
                 dt_s: float = 0.512, rng: np.random.Generator | None = None,
                 extra_torque: np.ndarray | None = None,
                 wheel_torque: np.ndarray | None = None, model: TruthModel | None = None,
                 disturbance: Disturbance | None = None,
                 disturbance_rng: np.random.Generator | None = None,
                 managed: bool = False, solar_management: SolarManagement | None = None,
                 schedule: Schedule | None = None):
        if not (np.isfinite(duration_s) and duration_s >= 0):
            raise ValueError("duration_s must be finite and non-negative")
        if not (np.isfinite(dt_s) and dt_s > 0):
            raise ValueError("dt_s must be positive")
        self.spacecraft, self.orbit, self.environment = spacecraft, orbit, environment
        self.control, self.epoch, self.dt_s = control, epoch, dt_s
        self.n_samples = int(np.floor(duration_s / dt_s + 1e-9)) + 1
        n, nw = self.n_samples, spacecraft.n_wheels
        self.sigma = environment.ripple.step_sigma_Nm(dt_s)
        if self.sigma > 0 and rng is None:
            raise ValueError("an rng is required when wheel ripple is enabled")
        self.rng = rng
        self.extra_torque = None if extra_torque is None else \
            _checked(extra_torque, (n, 3), "extra torque")
        self.wheel_torque = None if wheel_torque is None else \
            _checked(wheel_torque, (n, nw), "wheel torque")
        self.disturbance_draw = None
        if disturbance is not None and disturbance.enabled:
            if disturbance_rng is None:
                raise ValueError("a disturbance_rng is required when a disturbance is flown")
            self.disturbance_draw = DisturbanceDraw(disturbance, dt_s, disturbance_rng)
        self.schedule = schedule if schedule is not None else Schedule()
        # The managed step (``sim.step``) only where it is needed, or asked for by a run
        # that will need it later (momentum management or a command moving the array
        # offset).
        self.managed = managed or is_managed(environment, control) \
            or bool(self.schedule.of_kind("array_offset"))
        self.p = pack_params(spacecraft, orbit, environment, control, dt_s, self.managed)
        self.model = model or truth_model(nw, DEFAULT_CHUNK, requested_backend(), self.managed)
        if self.model.managed != self.managed:
            raise ValueError("the truth model's step does not match the run's (managed)")
        self.x = initial.state_vector(spacecraft, orbit)
        self.jd0 = ephemeris.julian_date(epoch)
        self.gmst0 = ephemeris.gmst_rad(self.jd0)
        self.sun_nodes = sun_nodes(n, dt_s, self.jd0)
        self.next_start = 0
        self.manager = None
        if solar_management is not None:
            if not self.managed:
                raise ValueError("solar management moves the array offset: it needs the "
                                 "managed step (managed=True)")
            self.manager = SolarManager(solar_management, spacecraft, orbit, self.gmst0, dt_s,
                                        self.sun_nodes, aux_slice(nw, "t_mtq"), self.x)
        self.thrusters = bool(self.schedule.of_kind("thruster"))
        self.commands = self._command_samples()
        # The sample the yaw demand moves to the standby wheel from (none: past the end).
        self.switch_sample = min((k for k, es in self.commands.items()
                                  if any(e.kind == "wheel_switch" for e in es)),
                                 default=self.n_samples)

    def _command_samples(self) -> dict[int, list]:
        """The commands of the schedule by the sample they apply from, the first with
        t_k ≥ t (``sim.events``): the step from it on flies the new setting."""
        out: dict[int, list] = {}
        for e in self.schedule.commands(-np.inf, np.inf):
            if e.kind == "wheel_switch":
                if self.spacecraft.standby_wheel is None:
                    raise ValueError("a wheel_switch needs a standby yaw wheel on board "
                                     "(Spacecraft.standby_wheel)")
            elif e.kind not in COMMAND_FIELDS:
                raise ValueError(f"{e.kind} events are not flown by the truth")
            elif COMMAND_FIELDS[e.kind] not in {
                    f.name for f in dataclasses.fields(self.environment.solar)}:
                raise ValueError(f"{e.kind} events need the solar torque's "
                                 f"{COMMAND_FIELDS[e.kind]}")
            k = max(0, int(np.ceil(e.t_s / self.dt_s)) - 1)
            while self._t(k) < e.t_s:     # exact against the samples' own times
                k += 1
            if k < self.n_samples:
                out.setdefault(k, []).append(e)
        return out

    def _command(self, k: int) -> None:
        """Fly the commands that apply from sample ``k``, before the piece from it rolls
        out (the parameters re-packed, as ``retrim`` does)."""
        for e in self.commands.get(k, ()):
            if e.kind == "wheel_switch":
                self.switch_wheels()
                continue
            self.retrim(dataclasses.replace(self.environment.solar,
                                            **{COMMAND_FIELDS[e.kind]: float(e.angle_deg)}))

    def switch_wheels(self) -> None:
        """Fly the yaw demand on the standby yaw wheel from the next piece on
        (``sim.control.wheel_allocation``): the parameters re-packed, nothing else
        changes (the bias stays; no wheel fails)."""
        self.control = dataclasses.replace(self.control, yaw_on_standby_wheel=True)
        self.p = pack_params(self.spacecraft, self.orbit, self.environment, self.control,
                             self.dt_s, self.managed)

    def retrim(self, solar) -> None:
        """Fly ``solar`` (a new trim-tab setting) from the next window on: the ground
        commanding the tab mid-run (``scenarios.trim_loop``).  Nothing else changes."""
        self.environment = dataclasses.replace(self.environment, solar=solar)
        self.p = pack_params(self.spacecraft, self.orbit, self.environment, self.control,
                             self.dt_s, self.managed)

    def _pieces(self, a: int, b: int, piece: int) -> list[tuple[int, int]]:
        """Rows [lo, hi) of the window's rollout pieces: ``piece`` samples each, split
        where solar management commands (``sim.momentum``)."""
        cuts = set(range(0, b - a, piece))
        if self.manager is not None:
            cuts.update(k - a for k in self.manager.breaks(a, b) if k < b)
        cuts.update(k - a for k in self.commands if a <= k < b)
        cuts = sorted(cuts) + [b - a]
        return list(zip(cuts[:-1], cuts[1:], strict=True))

    def _after_piece(self, a: int, lo: int, hi: int, states: np.ndarray, aux: np.ndarray
                     ) -> None:
        """Solar management on board: account for the piece, and command at a period's
        end (the next piece flies the new tab and offset)."""
        m = self.manager
        if m is None or not np.all(np.isfinite(states[hi])):
            return   # a diverged state is _finish's to report
        m.absorb(a + lo, states[lo:hi + 1], aux[lo:hi])
        if a + hi in m.breaks(a + hi - 1, a + hi):
            self.retrim(m.at_break(a + hi, states[hi], self.environment.solar))

    def _t(self, k: np.ndarray) -> np.ndarray:
        # Sample times rounded to the nanosecond: exact decimals (4.608, not
        # 4.6080000000000005), so every file writes the same t_s to any precision.
        return np.round(k * self.dt_s, 9)

    def _shadow(self, a: int, b: int, alpha: np.ndarray, sun: dict, every: int = 64):
        """Shadow factor of samples a … b−1, evaluated only where it can be below 1.

        A coarse pass (every ``every`` samples from the run's start) flags the
        stretches that come within the penumbra's reach of the Earth's shadow axis,
        padded by the distance the satellite covers in one coarse interval; only
        samples within ``every`` of a flagged one get the exact model.  Outside
        eclipse season nothing at all is evaluated finely."""
        model, radius, n = self.environment.shadow_model, self.orbit.radius_m, self.n_samples
        if model == "none":  # no eclipses: isolates their effect (the linearization report)
            return np.ones(b - a)
        ends = self.orbit.right_ascension(self._t(np.array([0, min(every, n - 1)])), self.gmst0)
        step_len = radius * abs(ends[1] - ends[0])
        coarse = np.arange(max(a - every, 0) // every * every, min(b + every, n), every)
        t_c = self._t(coarse)
        sun_c = sun_on_grid(t_c, self.sun_nodes)
        near = near_shadow(self.orbit.right_ascension(t_c, self.gmst0), sun_c,
                            np.arange(len(coarse)), radius, step_len)
        return shadow_fine(coarse, near, a, alpha, sun, radius, model, every)

    def _window_inputs(self, a: int, b: int) -> tuple[dict[str, np.ndarray], np.ndarray]:
        """Arrays of samples a … b−1 for the step inputs and the shadow: what is known
        without computing set (zeros, the caller's torques), the rest for ``_fill``.
        With a disturbance, ``external`` (the caller's torque) and ``disturbance`` are
        kept beside the step's ``n_ext``, their sum, so that the two are recorded
        apart (``history.truth_result``); without one, ``n_ext`` is the caller's."""
        n, nw = b - a, self.spacecraft.n_wheels
        external = np.zeros((n, 3)) if self.extra_torque is None else self.extra_torque[a:b]
        if self.thrusters:
            return self._thruster_inputs(a, b, external)
        inputs = {"sun_r": np.empty((n, 3)), "sun_scale": np.empty(n),
                  "m_prof": np.empty((n, 3)) if profiled(self.environment)
                  else np.zeros((n, 3)),
                  "n_ext": external,
                  "u_wheel": np.zeros((n, nw)) if self.wheel_torque is None
                  else self.wheel_torque[a:b],
                  "ripple": np.empty((n, nw)) if self.sigma > 0 else np.zeros((n, nw))}
        if self.disturbance_draw is not None:
            inputs["external"], inputs["disturbance"] = external, np.empty((n, 3))
            # The step's n_ext: the disturbance itself, or the caller's torque plus it.
            inputs["n_ext"] = inputs["disturbance"] if self.extra_torque is None \
                else np.empty((n, 3))
        return inputs, np.empty(n)

    def _thruster_inputs(self, a: int, b: int, external: np.ndarray
                         ) -> tuple[dict[str, np.ndarray], np.ndarray]:
        """``_window_inputs`` of a run with thruster events: their torque kept as a
        source of its own (``thruster``) beside the caller's and the disturbance, the
        step's ``n_ext`` their sum (the disturbance's share added in ``_fill``)."""
        n, nw = b - a, self.spacecraft.n_wheels
        thruster = self.schedule.thruster_torque(self._t(np.arange(a, b)))
        inputs = {"sun_r": np.empty((n, 3)), "sun_scale": np.empty(n),
                  "m_prof": np.empty((n, 3)) if profiled(self.environment)
                  else np.zeros((n, 3)),
                  "n_ext": external + thruster,
                  "u_wheel": np.zeros((n, nw)) if self.wheel_torque is None
                  else self.wheel_torque[a:b],
                  "ripple": np.empty((n, nw)) if self.sigma > 0 else np.zeros((n, nw)),
                  "external": external, "thruster": thruster}
        if self.disturbance_draw is not None:
            inputs["disturbance"] = np.empty((n, 3))
        return inputs, np.empty(n)

    def _fill(self, a: int, lo: int, hi: int, t_s: np.ndarray, inputs: dict[str, np.ndarray],
              shadow: np.ndarray, draw: bool = True) -> None:
        """Fill rows lo … hi−1 of ``_window_inputs``' arrays (samples a+lo … a+hi−1 of
        the run; ``t_s`` their times), and with ``draw`` draw their ripple and
        disturbance: pieces drawn in order continue each generator's one stream (and
        the disturbance's carried state) as a whole draw would."""
        cut = slice(lo, hi)
        sun = sun_on_grid(t_s, self.sun_nodes)
        alpha = self.orbit.right_ascension(t_s, self.gmst0)
        shadow[cut] = self._shadow(a + lo, a + hi, alpha, sun)
        step_inputs(t_s, self.epoch, self.orbit, self.environment, sun, shadow[cut],
                    {k: v[cut] for k, v in inputs.items()})
        if not draw:
            return
        if self.sigma > 0:
            rows = inputs["ripple"][cut]
            self.rng.standard_normal(out=rows)
            rows *= self.sigma
            if self.spacecraft.standby_wheel is not None:
                # An idle motor, unpowered, makes no torque ripple: the standby wheel's
                # draws (still drawn, so the stream is the same) count from its switch.
                idle = int(np.clip(self.switch_sample - (a + lo), 0, hi - lo))
                rows[:idle, self.spacecraft.standby_wheel] = 0.0
        if self.disturbance_draw is not None:
            rows = inputs["disturbance"][cut]
            self.disturbance_draw.fill(rows)
            if "thruster" in inputs:
                inputs["n_ext"][cut] += rows
            elif self.extra_torque is not None:
                np.add(inputs["external"][cut], rows, out=inputs["n_ext"][cut])

    def sun(self, a: int, b: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Samples a … b−1 (any range, no rollout, nothing carried): their times, the
        satellite-to-Sun unit vector in the orbit frame (N, 3) and the solar torque's
        scale, shadow × (1 AU / r)², exactly as ``window`` gives them to the step."""
        if not 0 <= a < b <= self.n_samples:
            raise ValueError(f"samples [{a}, {b}) are outside the run's {self.n_samples}")
        t_s = self._t(np.arange(a, b))
        inputs, shadow = self._window_inputs(a, b)
        self._fill(a, 0, b - a, t_s, inputs, shadow, draw=False)
        return t_s, inputs["sun_r"], inputs["sun_scale"]

    def window(self, a: int, b: int, sense=None, piece: int = SENSE_PIECE):
        """The truth at samples a … b−1 (the next window starts at b).

        With ``sense``, returns ``(truth, [sense(rows, lo, hi) …])`` instead, on both
        cores: this thread forms the step inputs a piece of ``piece`` samples at a
        time and hands each to a second thread, which rolls it out, then calls
        ``sense`` on the truth of each piece (``TruthResult.rows``; samples
        a+lo … a+hi−1) as soon as it is rolled out.  The truth is the same either
        way, as every window's is (the class doc); a sensor model that continues
        across calls (``sim.telemetry``'s, its generators carried) gives the whole
        window's readings piece by piece."""
        if a != self.next_start or not a < b <= self.n_samples:
            raise ValueError(f"windows must be contiguous and within the run: asked "
                             f"[{a}, {b}), next is {self.next_start} of {self.n_samples}")
        n, n_wheels = b - a, self.spacecraft.n_wheels
        t_s = self._t(np.arange(a, b))
        inputs, shadow = self._window_inputs(a, b)
        engine = self.model.rollout_engine
        states, aux = engine.allocate(n, len(self.x))
        if sense is None:
            self._fill(a, 0, n, t_s, inputs, shadow)
            x = self.x
            for lo, hi in self._pieces(a, b, n):
                self._command(a + lo)
                engine.run(x, [inputs[name][lo:hi] for name, _ in input_layout(n_wheels)],
                           self.p, out=(states[lo:hi + 1], aux[lo:hi]))
                self._after_piece(a, lo, hi, states, aux)
                x = states[hi]
            return self._finish(a, t_s, states, aux, inputs, shadow)
        bounds = self._pieces(a, b, piece)
        todo: queue.SimpleQueue = queue.SimpleQueue()
        done: queue.SimpleQueue = queue.SimpleQueue()

        def roll() -> None:
            x = self.x
            try:
                for lo, hi in iter(todo.get, None):
                    self._command(a + lo)
                    engine.run(x, [inputs[name][lo:hi] for name, _ in input_layout(n_wheels)],
                               self.p, out=(states[lo:hi + 1], aux[lo:hi]))
                    self._after_piece(a, lo, hi, states, aux)
                    x = states[hi]
                    if not np.all(np.isfinite(x)):
                        states[hi + 1:] = np.nan    # _finish says where it went
                        break
                    done.put(hi)
            finally:
                done.put(None)
        sensed = []
        with ThreadPoolExecutor(1) as pool:
            rolling = pool.submit(roll)
            try:
                for lo, hi in bounds:
                    self._fill(a, lo, hi, t_s[lo:hi], inputs, shadow)
                    todo.put((lo, hi))
            finally:
                todo.put(None)
            result = truth_result(t_s, states, aux, inputs, shadow, self.spacecraft,
                                  self.model.backend)
            for lo, hi in bounds:
                if done.get() is None:
                    break
                sensed.append(sense(result.rows(lo, hi), lo, hi))
            rolling.result()
        return self._finish(a, t_s, states, aux, inputs, shadow), sensed

    def _finish(self, a, t_s, states, aux, inputs, shadow) -> TruthResult:
        # NaN never turns finite again in the state update, so the last state tells;
        # only a failed run pays for finding where it went.
        if not np.all(np.isfinite(states[-1])):
            k = int(np.argmax(~np.isfinite(states).all(axis=1)))
            raise FloatingPointError(f"the truth became non-finite at t = "
                                     f"{(a + k) * self.dt_s:.1f} s: the closed loop is "
                                     "unstable for these gains and this step")
        self.x = states[-1].copy()
        self.next_start = a + len(t_s)
        return truth_result(t_s, states, aux, inputs, shadow, self.spacecraft,
                            self.model.backend)


def simulate_truth(spacecraft: Spacecraft, orbit: GeoOrbit, environment: Environment,
                   control: Control, initial: InitialState, epoch: datetime,
                   duration_s: float, dt_s: float = 0.512,
                   rng: np.random.Generator | None = None,
                   extra_torque: np.ndarray | None = None,
                   wheel_torque: np.ndarray | None = None,
                   model: TruthModel | None = None,
                   disturbance: Disturbance | None = None,
                   disturbance_rng: np.random.Generator | None = None,
                   managed: bool = False, schedule: Schedule | None = None) -> TruthResult:
    """Simulate the nonlinear truth on ``t = 0, dt, …`` up to ``duration_s``.

    ``rng`` supplies the wheel ripple; it is required when ripple is enabled so
    that every random draw traces back to the scenario seed.  ``extra_torque``
    (N, 3) adds a body torque and ``wheel_torque`` (N, n_wheels) adds motor torques
    to the control's, each held over its step.  ``disturbance`` (``sim.disturbance``)
    adds its random body torque, drawn from ``disturbance_rng`` (required when its
    kind is not none) and held over each step too.  ``schedule`` (``sim.events``) adds
    its thruster torques and flies its commands.  ``final_state`` is the state one
    step after the last sample (the step that produced the last sample's outputs).
    """
    stream = TruthStream(spacecraft, orbit, environment, control, initial, epoch, duration_s,
                         dt_s, rng, extra_torque, wheel_torque, model, disturbance,
                         disturbance_rng, managed, schedule=schedule)
    return stream.window(0, stream.n_samples)
