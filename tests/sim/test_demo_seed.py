"""`uwlab demo --seed`: all the simulated rig's noise (cameras, spectrometer) comes from one seed.

Equal seeds must give equal measurements and equal calibration numbers; another seed must give other measurements
(otherwise the seed would not reach the noise, and equality would prove nothing). A small campaign stands in for
the demo's plan, which takes ~30 s per run.
"""

from __future__ import annotations

import json

import pandas as pd
import pytest

from uwlab.experiments.acquisition.plan import load_plan
from uwlab.experiments.acquisition.sim_rig import SimRig
from uwlab.experiments.dataset import CLOCK_COLUMNS
from uwlab.experiments.demo import run_demo

from tests.support.plans import record, write_campaign


@pytest.fixture(scope="module")
def plan_path(tmp_path_factory):
    return write_campaign(tmp_path_factory.mktemp("seeded") / "plan.toml", "seeded")


def measure(plan_path, root, seed: int) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The plan's sweeps on the simulated rig: (points without their clock times, spectra)."""
    plan = load_plan(plan_path)
    with SimRig(plan.rig_path, seed=seed) as rig:
        dataset = record(plan, root, rig)
    return dataset.points().drop(columns=list(CLOCK_COLUMNS)), dataset.spectra()


def test_equal_seeds_give_equal_measurements_and_other_seeds_other_ones(plan_path, tmp_path):
    points, spectra = measure(plan_path, tmp_path / "a", seed=5)
    again_points, again_spectra = measure(plan_path, tmp_path / "b", seed=5)
    pd.testing.assert_frame_equal(points, again_points)
    pd.testing.assert_frame_equal(spectra, again_spectra)
    other_points, other_spectra = measure(plan_path, tmp_path / "c", seed=6)
    assert not points["mean_dn"].equals(other_points["mean_dn"]), "the seed does not reach the cameras' noise"
    assert not spectra["irradiance_w_m2_nm"].equals(other_spectra["irradiance_w_m2_nm"]), (
        "the seed does not reach the spectrometer's noise"
    )


@pytest.mark.slow
def test_equal_seeds_give_equal_demo_summaries(plan_path, tmp_path):
    """Campaign, calibration and report twice with one seed: summary.json equal but for the report's path."""
    first = run_demo(tmp_path / "first", plan_path=plan_path, seed=11)
    second = run_demo(tmp_path / "second", plan_path=plan_path, seed=11)
    on_disk = json.loads((tmp_path / "second" / "summary.json").read_text())
    assert on_disk == json.loads(json.dumps(second))
    for summary in (first, second):
        summary.pop("report")
    assert first == second
    assert first["parameters"]["light_efficiency"]["median"] is not None
