"""Reading a fit's posterior as ArviZ InferenceData (`read_inference_data`, what `uwlab.Fit.posterior` returns):
every sample with the fit's attributes, an older fit's samples as one chain; sampler overrides validated like the
fit config file. (`arviz.summary` against the fit's own table: tests/slow/test_fit.py.)"""

import numpy as np
import pytest

from uwlab.errors import ConfigError
from uwlab.experiments.calibration.fit import FitConfig, default_config_for, fit_points
from uwlab.experiments.calibration.inference import read_inference_data, write_inference_data
from uwlab.experiments.calibration.pipeline import resolve_fit_config
from uwlab.experiments.calibration.simulate import simulate_campaign
from uwlab.model.schema import parse

TRUTH = {"light_efficiency": 0.8, "attenuation_scale": 1.2, "K_dn_per_e:imx250m": 0.36, "K_dn_per_e:icx285alm": 1.05}


@pytest.fixture(scope="module")
def short_fit(tmp_path_factory):
    points, rigs = simulate_campaign(TRUTH, seed=3)
    base = default_config_for(points[~points["saturated"]], rigs)
    config = parse(FitConfig, {"parameters": base.priors, "sampler": {"max_steps": 1000, "chunk_steps": 500}})
    result = fit_points(points, rigs, config)
    out = tmp_path_factory.mktemp("fit")
    write_inference_data(result, out)
    return result, out


def test_the_posterior_holds_every_sample_and_the_fit_attributes(short_fit):
    result, out = short_fit
    data = read_inference_data(out)
    walkers = result.chain.shape[1]
    assert dict(data.posterior.sizes) == {"chain": walkers, "draw": len(result.samples) // walkers}
    assert data.posterior.attrs["model"] == result.model.kind and data.posterior.attrs["steps"] == result.steps
    assert np.allclose(np.sort(data.sample_stats["lp"].values.ravel()), np.sort(result.log_prob))


def test_an_older_fit_without_netcdf_reads_its_samples_as_one_chain(short_fit, tmp_path):
    import pandas as pd

    result, _ = short_fit
    pd.DataFrame(result.samples, columns=list(result.names)).to_parquet(tmp_path / "samples.parquet")
    data = read_inference_data(tmp_path)
    assert data.posterior.sizes["chain"] == 1
    assert float(data.posterior["light_efficiency"].median()) == pytest.approx(np.median(result.samples[:, 0]))


def test_sampler_overrides_are_validated_like_the_file():
    points, rigs = simulate_campaign(TRUTH, seed=1, points_per_sweep=4)
    with pytest.raises(ConfigError, match="max_steps"):
        resolve_fit_config(None, points, rigs, {"max_steps": 10})
    assert resolve_fit_config(None, points, rigs, {"walkers": 40}).walkers == 40
