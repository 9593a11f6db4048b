"""A fit's posterior is a standard object: `FitResult.inference_data()` is an `arviz.InferenceData` of the very
samples the fit summarises, and `posterior.nc` beside the other outputs reads back with arviz, whose summary agrees
with the fit's own table to 4 significant figures."""

from __future__ import annotations

import json

import arviz
import numpy as np
import pytest

from uwlab.experiments.calibration.fit import fit_points
from uwlab.experiments.calibration.output import write_fit
from uwlab.experiments.calibration.simulate import simulate_campaign

TRUTH = {"light_efficiency": 0.8, "attenuation_scale": 1.2, "K_dn_per_e:imx250m": 0.36, "K_dn_per_e:icx285alm": 1.05}


@pytest.fixture(scope="module")
def fit_dir(tmp_path_factory):
    points, rigs = simulate_campaign(TRUTH, seed=3)
    result = fit_points(points, rigs)
    out = tmp_path_factory.mktemp("fit") / "fit"
    write_fit(result, out)
    return result, out


def test_the_inference_data_holds_the_fits_samples_per_walker(fit_dir):
    result, _ = fit_dir
    data = result.inference_data()
    walkers = result.chain.shape[1]
    for i, name in enumerate(result.names):
        values = data.posterior[name].values
        assert values.shape[0] == walkers and values.size == result.samples.shape[0]
        np.testing.assert_array_equal(np.sort(values.ravel()), np.sort(result.samples[:, i]))


def test_arviz_summary_of_the_netcdf_matches_the_fits_table(fit_dir):
    result, out = fit_dir
    data = arviz.from_netcdf(out / "posterior.nc")
    table = arviz.summary(data, stat_focus="median", hdi_prob=0.95, round_to="none")
    summary = json.loads((out / "summary.json").read_text())["parameters"]
    for name in result.names:
        ours = summary[name]
        np.testing.assert_allclose(table.loc[name, "median"], ours["median"], rtol=5e-5)
        np.testing.assert_allclose(table.loc[name, "eti_2.5%"], ours["p2_5"], rtol=5e-5)
        np.testing.assert_allclose(table.loc[name, "eti_97.5%"], ours["p97_5"], rtol=5e-5)
    assert data.posterior.attrs["converged"] == int(result.converged)
