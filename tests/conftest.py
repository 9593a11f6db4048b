import copy
import tomllib

import pytest

from tests.support.paths import EXAMPLE, SIM_TANK
from uwlab.experiments.acquisition.sim_rig import SimRig


@pytest.fixture
def example_raw():
    """The example design as a raw config dict (a fresh copy per test)."""
    with open(EXAMPLE, "rb") as fh:
        return copy.deepcopy(tomllib.load(fh))


@pytest.fixture(scope="module")
def sim_rig():
    """The simulated tank rig (`SIM_TANK`), started once per test module: its serial simulators are processes."""
    with SimRig(SIM_TANK) as rig:
        yield rig
