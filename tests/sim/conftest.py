import copy
import tomllib
from pathlib import Path

import pytest

from uwlab.experiments.acquisition.sim_rig import SimRig

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "configs" / "design" / "example.toml"
SIM_TANK = ROOT / "configs" / "rigs" / "sim-tank.toml"


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
