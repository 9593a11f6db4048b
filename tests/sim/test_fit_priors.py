"""Priors against scipy.stats, and the split-chain R-hat on known chains."""
import numpy as np
import pytest
from scipy import stats

from uwlab.errors import ConfigError
from uwlab.experiments.calibration.fit import split_rhat
from uwlab.experiments.calibration.priors import parse_prior

X = np.array([0.2, 0.7, 1.0, 1.9, 3.5])


@pytest.mark.parametrize("spec, reference", [
    ({"kind": "normal", "mean": 1.0, "sigma": 0.5}, stats.norm(1.0, 0.5)),
    ({"kind": "lognormal", "median": 1.2, "sigma": 0.4}, stats.lognorm(0.4, scale=1.2)),
    ({"kind": "uniform", "lo": 0.1, "hi": 4.0}, stats.uniform(0.1, 3.9)),
    ({"kind": "halfnormal", "sigma": 2.0}, stats.halfnorm(scale=2.0)),
])
def test_log_density_differs_from_scipy_by_a_constant(spec, reference):
    prior = parse_prior("parameters.x", spec)
    diff = prior.logpdf(X) - reference.logpdf(X)
    assert np.ptp(diff) == pytest.approx(0.0, abs=1e-12)
    draws = prior.sample(np.random.default_rng(1), (20000,))
    assert np.median(draws) == pytest.approx(reference.median(), rel=0.03)


def test_truncation_and_support():
    prior = parse_prior("p", {"kind": "normal", "mean": 0.0, "sigma": 1.0, "lo": 0.0, "hi": 2.0})
    assert np.isneginf(prior.logpdf(np.array([-0.1, 2.1]))).all()
    assert np.all((prior.sample(np.random.default_rng(0), (1000,)) >= 0) & (prior.sample(np.random.default_rng(0), (1000,)) <= 2))
    assert np.isneginf(parse_prior("p", {"kind": "lognormal", "median": 1, "sigma": 1}).logpdf(np.array([-1.0, 0.0]))).all()


@pytest.mark.parametrize("spec, key", [
    ({"kind": "gamma"}, "parameters.x.kind"),
    ({"kind": "normal", "mean": 1.0}, "parameters.x.sigma"),
    ({"kind": "normal", "mean": 1.0, "sigma": -1}, "parameters.x.sigma"),
    ({"kind": "normal", "mean": 1.0, "sigma": 1, "width": 2}, "parameters.x.width"),
    ({"kind": "uniform", "lo": 2, "hi": 1}, "parameters.x.hi"),
    ({"kind": "lognormal", "median": "one", "sigma": 1}, "parameters.x.median"),
    (3.0, "parameters.x"),
])
def test_bad_priors_name_the_key(spec, key):
    with pytest.raises(ConfigError) as info:
        parse_prior("parameters.x", spec)
    assert str(info.value).startswith(key)


def test_split_rhat_detects_unmixed_chains():
    rng = np.random.default_rng(0)
    mixed = rng.standard_normal((2000, 16, 2))
    assert split_rhat(mixed) == pytest.approx([1.0, 1.0], abs=0.01)
    stuck = mixed + np.arange(16)[None, :, None] * 0.5  # walkers in different places
    assert np.all(split_rhat(stuck) > 1.5)
    drifting = mixed + np.linspace(0, 3, 2000)[:, None, None]
    assert np.all(split_rhat(drifting) > 1.1)
