"""Fixtures shared by the tests."""

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


# The tests that run a whole simulated campaign with its fit (the README's script, the notebook, the demo and its
# seeded twin) each use both cores (the held-out folds' workers are one per core). Under pytest-xdist (`make test`:
# four workers on two cores, `--dist loadfile`) they run last, one after another on one worker, once every other
# test has been handed out: beside the rest of the suite they took 1.5–2.3 times their time alone (the README's
# script 75 s), so their times said more about their neighbours than about them. Alone at the end they take about
# their own time (25–42 s); the suite takes 1–1½ minutes longer.
CAMPAIGN_FILES = (
    "tests/integration/test_api_script.py",
    "tests/integration/test_notebook.py",
    "tests/integration/test_demo_report.py",
    "tests/integration/test_demo_seed.py",
)
CAMPAIGN_LANE = "whole campaigns, last"


def pytest_collection_modifyitems(items):
    """The campaign files' tests last (`CAMPAIGN_FILES`), every test else in its order."""
    items.sort(key=lambda item: item.nodeid.split("::", 1)[0] in CAMPAIGN_FILES)


@pytest.hookimpl(optionalhook=True)  # pytest-xdist's hook: unknown to a run without it
def pytest_xdist_make_scheduler(config, log):
    """Under ``--dist loadfile``, the campaign files one unit of work (`CAMPAIGN_FILES`); else xdist's own."""
    if config.getoption("dist") != "loadfile":
        return None
    from xdist.scheduler import LoadFileScheduling

    class CampaignLane(LoadFileScheduling):
        def _split_scope(self, nodeid: str) -> str:
            scope = super()._split_scope(nodeid)
            return CAMPAIGN_LANE if scope in CAMPAIGN_FILES else scope

    return CampaignLane(config, log)
