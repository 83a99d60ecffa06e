"""Draw Monte Carlo case k: the dispersed values and the scenario that flies.

Case k's randomness is ``SeedSequence(seed).spawn(n)[k]``, i.e. spawn key (k,):
its sensor and ripple streams are children (k, i) (``build.streams(seed, k)``),
and each dispersed key draws from child (k, DISPERSION_STREAM, crc32(key)).  So a
case does not depend on how many cases the set has, on the other cases, or on
which other keys are dispersed.
"""

from __future__ import annotations

import zlib
from datetime import timedelta

import numpy as np
from dynprop.sim.ephemeris import parse_epoch

from ..config.build import DISPERSION_STREAM
from ..config.loader import ScenarioError, validate
from ..config.montecarlo import Normal, Uniform
from ..config.schema import Scenario


def key_rng(seed: int, case: int, key: str) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence(
        seed, spawn_key=(case, DISPERSION_STREAM, zlib.crc32(key.encode()))))


def _offsets(d: Normal | Uniform, shape: tuple[int, ...], rng) -> np.ndarray:
    """Offsets of the key's shape; a 3×3 key gets its upper triangle drawn and mirrored."""
    if len(shape) == 2:
        iu = np.triu_indices(shape[0])
        params = [np.broadcast_to(np.asarray(p, dtype=float), shape)[iu]
                  for p in ((d.sigma, d.mean) if isinstance(d, Normal) else (d.low, d.high))]
        tri = _offsets_flat(d, params, len(iu[0]), rng)
        out = np.zeros(shape)
        out[iu] = tri
        out.T[iu] = tri
        return out
    params = [np.broadcast_to(np.asarray(p, dtype=float), shape)
              for p in ((d.sigma, d.mean) if isinstance(d, Normal) else (d.low, d.high))]
    return _offsets_flat(d, params, shape, rng)


def _offsets_flat(d, params, size, rng) -> np.ndarray:
    if isinstance(d, Normal):
        sigma, mean = params
        return mean + sigma * rng.standard_normal(size)
    low, high = params
    return low + (high - low) * rng.random(size)


def _step(node, part: str):
    # A list's entries are addressed by index: events.0.time_s.
    return node[int(part)] if isinstance(node, list) else node[part]


def _get(raw: dict, key: str):
    node = raw
    for part in key.split("."):
        node = _step(node, part)
    return node


def _set(raw: dict, key: str, value) -> None:
    parts = key.split(".")
    node = raw
    for part in parts[:-1]:
        node = _step(node, part)
    node[parts[-1]] = value


def _plain(a: np.ndarray):
    """Nested lists of Python floats (exact in JSON and YAML)."""
    return float(a) if np.ndim(a) == 0 else [_plain(x) for x in a]


class UnphysicalDraw(ScenarioError):
    """A case whose drawn values fail validation; ``values`` says what was drawn."""

    def __init__(self, message: str, values: dict):
        super().__init__(message)
        self.values = values


def draw_case(s: Scenario, case: int) -> tuple[dict, Scenario]:
    """Case ``case``'s dispersed values {key: value} and its validated scenario.

    Raises ``UnphysicalDraw`` naming the key if a draw is not physical (say, an
    inertia that is no longer positive definite)."""
    raw = s.model_dump(mode="json")
    values = {}
    for key, d in sorted(s.montecarlo.dispersions.items()):
        rng = key_rng(s.seed, case, key)
        if key == "epoch_utc":
            days = int(np.rint(_offsets(d, (), rng)))
            shifted = parse_epoch(s.epoch_utc) + timedelta(days=days)
            value = shifted.isoformat().replace("+00:00", "Z")
        else:
            nominal = np.asarray(_get(raw, key), dtype=float)
            value = _plain(nominal + _offsets(d, nominal.shape, rng))
        _set(raw, key, value)
        values[key] = value
    try:
        return values, validate(raw)
    except ScenarioError as exc:
        # One line per case in the set's records and messages.
        raise UnphysicalDraw("; ".join(exc.problems), values) from None
