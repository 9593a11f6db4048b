"""Fixtures shared by the tests, and how `make test` spreads them over two workers (pytest-xdist,
``--dist loadgroup``): the integration tests (processes, devices, pseudo-terminals, GigE, the browser) run one
after another on one worker, as they always have, while the other worker runs the in-process unit and slow tests
and the doctests."""

import copy
import tomllib
from pathlib import Path

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


INTEGRATION = Path(__file__).resolve().parent / "integration"


def pytest_collection_modifyitems(items):
    for item in items:
        if Path(str(item.path)).is_relative_to(INTEGRATION):
            item.add_marker(pytest.mark.xdist_group("integration"))
