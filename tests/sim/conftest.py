from datetime import UTC, datetime

import numpy as np
import pytest

from sim.control import Control
from sim.environment import Environment
from sim.frames import GeoOrbit
from sim.spacecraft import goes_next

EQUINOX = datetime(2026, 3, 20, 12, 0, 0, tzinfo=UTC)


@pytest.fixture(scope="session")
def spacecraft():
    return goes_next()


@pytest.fixture(scope="session")
def orbit():
    return GeoOrbit()


@pytest.fixture(scope="session")
def quiet():
    """Torque-free gyrostat: every torque, the ripple and the control off."""
    return Environment.torque_free(), Control(enabled=False)


@pytest.fixture
def rng():
    return np.random.default_rng(20260320)
