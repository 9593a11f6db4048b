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
from uwlab.experiments.dataset import CLOCK_COLUMNS, Dataset
from uwlab.experiments.demo import run_demo

from tests.support.plans import record, write_campaign


@pytest.fixture(scope="module")
def plan_path(tmp_path_factory):
    return write_campaign(tmp_path_factory.mktemp("seeded") / "plan.toml", "seeded")


def recorded(dataset_dir) -> tuple[pd.DataFrame, pd.DataFrame]:
    """A dataset's points without their clock times, and its spectra."""
    dataset = Dataset.open(dataset_dir)
    return dataset.points().drop(columns=list(CLOCK_COLUMNS)), dataset.spectra()


@pytest.mark.slow
def test_equal_seeds_give_equal_demos_and_other_seeds_other_measurements(plan_path, tmp_path):
    """Campaign, calibration and report twice with one seed: equal measurements, and summary.json equal but for the
    report's path; the campaign with another seed measures other values."""
    first = run_demo(tmp_path / "first", plan_path=plan_path, seed=11)
    second = run_demo(tmp_path / "second", plan_path=plan_path, seed=11)
    points, spectra = recorded(tmp_path / "first" / "dataset")
    again_points, again_spectra = recorded(tmp_path / "second" / "dataset")
    pd.testing.assert_frame_equal(points, again_points)
    pd.testing.assert_frame_equal(spectra, again_spectra)
    on_disk = json.loads((tmp_path / "second" / "summary.json").read_text())
    assert on_disk == json.loads(json.dumps(second))
    for summary in (first, second):
        summary.pop("report")
    assert first == second
    assert first["parameters"]["light_efficiency"]["median"] is not None

    plan = load_plan(plan_path)
    with SimRig(plan.rig_path, seed=12) as rig:
        record(plan, tmp_path / "other", rig)
    other_points, other_spectra = recorded(tmp_path / "other")
    assert not points["mean_dn"].equals(other_points["mean_dn"]), "the seed does not reach the cameras' noise"
    assert not spectra["irradiance_w_m2_nm"].equals(other_spectra["irradiance_w_m2_nm"]), (
        "the seed does not reach the spectrometer's noise"
    )
