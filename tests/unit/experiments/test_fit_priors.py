"""Priors against closed forms, their log densities (computed without scipy) against scipy's random variables, their
keys in errors, and the split-chain R-hat on known chains."""

import math

import numpy as np
import pytest

from uwlab.errors import ConfigError
from uwlab.experiments.calibration.fit import split_rhat
from uwlab.experiments.calibration.priors import HalfNormal, JointPrior, LogNormal, Normal, Uniform, parse_prior

PHI_1 = 0.8413447460685429  # Φ(1), the standard normal CDF at one sigma
PHI_INV_3_4 = 0.6744897501960817  # Φ⁻¹(3/4): the median of |N(0, 1)|


def test_lognormal_median_quantiles_and_density_are_the_closed_forms():
    median, sigma = 1.2, 0.4
    prior = parse_prior("parameters.x", {"kind": "lognormal", "median": median, "sigma": sigma})
    assert prior.quantile(0.5) == pytest.approx(median, rel=1e-12)
    assert prior.quantile([1 - PHI_1, PHI_1]) == pytest.approx([median * math.exp(-sigma), median * math.exp(sigma)])
    x = np.array([0.2, 0.7, 1.0, 1.9, 3.5])
    closed = -np.log(x * sigma * math.sqrt(2 * math.pi)) - (np.log(x / median)) ** 2 / (2 * sigma**2)
    assert prior.logpdf(x) == pytest.approx(closed, rel=1e-12)
    assert np.isneginf(prior.logpdf(np.array([-1.0, 0.0]))).all()


def test_normal_uniform_and_halfnormal_closed_forms():
    normal = Normal(mean=1.0, sigma=0.5)
    assert normal.logpdf(2.0) == pytest.approx(-math.log(0.5 * math.sqrt(2 * math.pi)) - 2.0, rel=1e-12)
    assert normal.quantile(PHI_1) == pytest.approx(1.5, rel=1e-12)
    uniform = Uniform(lo=0.1, hi=4.0)
    assert uniform.logpdf(np.array([0.5, 3.9])) == pytest.approx([-math.log(3.9)] * 2)
    assert np.isneginf(uniform.logpdf(np.array([0.05, 4.1]))).all()
    assert uniform.quantile(0.25) == pytest.approx(0.1 + 0.25 * 3.9)
    half = HalfNormal(sigma=2.0)
    assert half.quantile(0.5) == pytest.approx(2.0 * PHI_INV_3_4, rel=1e-12)
    assert half.logpdf(1.0) == pytest.approx(math.log(2) - math.log(2.0 * math.sqrt(2 * math.pi)) - 0.125, rel=1e-12)
    assert np.isneginf(half.logpdf(-0.1))


def test_truncation_respects_the_support():
    prior = parse_prior("p", {"kind": "normal", "mean": 0.0, "sigma": 1.0, "lo": 0.0, "hi": 2.0})
    assert np.isneginf(prior.logpdf(np.array([-0.1, 2.1]))).all()
    draws = prior.sample(np.random.default_rng(0), (5000,))
    assert draws.min() >= 0.0 and draws.max() <= 2.0
    one_sided = Normal(mean=0.0, sigma=1.0, lo=0.0)  # N(0, 1) on x ≥ 0 is |N(0, 1)|
    assert one_sided.quantile(0.5) == pytest.approx(PHI_INV_3_4, rel=1e-9)
    assert one_sided.cdf(PHI_INV_3_4) == pytest.approx(0.5, rel=1e-9)


def test_draws_follow_the_seed_and_the_distribution():
    prior = LogNormal(median=0.8, sigma=0.2)
    a = prior.sample(np.random.default_rng(7), (20000,))
    assert np.array_equal(a, prior.sample(np.random.default_rng(7), (20000,)))
    assert isinstance(prior.sample(np.random.default_rng(7)), float)
    # E[x] = median · e^(σ²/2); the sample mean's standard error is sd/√n ≈ 0.16/141
    assert a.mean() == pytest.approx(0.8 * math.exp(0.02), abs=5 * 0.8 * 0.2 / math.sqrt(20000))


@pytest.mark.parametrize(
    "spec, key",
    [
        ({"kind": "gamma"}, "parameters.x.kind"),
        ({"kind": "normal", "mean": 1.0}, "parameters.x.sigma"),
        ({"kind": "normal", "mean": 1.0, "sigma": -1}, "parameters.x.sigma"),
        ({"kind": "normal", "mean": 1.0, "sigma": 1, "width": 2}, "parameters.x.width"),
        ({"kind": "uniform", "lo": 2, "hi": 1}, "parameters.x.hi"),
        ({"kind": "lognormal", "median": "one", "sigma": 1}, "parameters.x.median"),
        (3.0, "parameters.x"),
    ],
)
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


PRIORS = [
    Normal(mean=1.0, sigma=0.5),
    Normal(mean=0.0, sigma=1.0, lo=0.0, hi=2.0),
    Normal(mean=0.3, sigma=2.0, hi=0.5),
    LogNormal(median=1.2, sigma=0.4),
    LogNormal(median=1.2, sigma=0.4, lo=0.5, hi=3.0),
    LogNormal(median=0.8, sigma=0.2, lo=-1.0),
    Uniform(lo=0.1, hi=4.0),
    HalfNormal(sigma=2.0),
    HalfNormal(sigma=2.0, hi=1.5),
]


def scipy_logpdf(prior, x: np.ndarray) -> np.ndarray:
    """scipy's own (truncated) random variable's log density, −inf where it is NaN."""
    with np.errstate(divide="ignore", invalid="ignore"):
        expected = prior._dist.logpdf(x)
    return np.where(np.isnan(expected), -np.inf, expected)


@pytest.mark.parametrize(
    "prior",
    PRIORS,
    ids=lambda p: p.model_dump_json(),
)
def test_the_log_density_is_scipys(prior):
    """The closed forms (evaluated without scipy) equal the densities of scipy's own truncated random variables bit
    for bit, through the tails, at and beyond the bounds, and for NaN; a half-normal narrowed by hi, which scipy
    cannot truncate twice, included."""
    x = np.concatenate([np.linspace(-3.0, 5.0, 801), [0.0, 0.1, 0.5, 1.5, 2.0, 3.0, 4.0, np.nan, np.inf, -np.inf]])
    expected = scipy_logpdf(prior, x)
    got = prior.logpdf(x)
    assert np.array_equal(np.isneginf(got), np.isneginf(expected))
    finite = np.isfinite(expected)
    assert np.array_equal(got[finite], expected[finite])  # bit for bit: a fit's numbers do not move


@pytest.mark.parametrize("walkers", [1, 2, 9, 64])
def test_the_joint_prior_of_every_kind_is_the_sum_of_scipys_densities(walkers):
    """A fit's log prior (`JointPrior`: all priors, all walkers in one pass) is Σ_j of scipy's log densities, each
    parameter its own kind and bounds: −inf as soon as one parameter is outside its support or NaN."""
    rng = np.random.default_rng(walkers)
    theta = np.stack([p.sample(rng, walkers) for p in PRIORS], axis=1)
    if walkers > 1:
        theta[0, 3] = np.nan
        theta[-1, 1] = 2.5  # above the truncated normal's hi
    expected = np.sum([scipy_logpdf(p, theta[:, j]) for j, p in enumerate(PRIORS)], axis=0)
    got = JointPrior(PRIORS)(theta)
    assert got.shape == (walkers,)
    assert np.array_equal(np.isneginf(got), np.isneginf(expected))
    finite = np.isfinite(expected)
    assert finite.sum() >= walkers - 2
    assert got[finite] == pytest.approx(expected[finite], rel=1e-14, abs=1e-14)


def test_a_truncated_normal_is_renormalised_on_its_bounds():
    """N(0, 1) on [0, 2]: φ(x) / (Φ(2) − Φ(0)), Φ(2) = 0.9772498680518208."""
    prior = Normal(mean=0.0, sigma=1.0, lo=0.0, hi=2.0)
    x = np.array([1e-9, 0.5, 1.999])
    closed = -0.5 * x**2 - 0.5 * math.log(2 * math.pi) - math.log(0.9772498680518208 - 0.5)
    assert prior.logpdf(x) == pytest.approx(closed, rel=1e-12)


@pytest.mark.parametrize(
    "prior",
    [
        LogNormal(median=1.2, sigma=0.4),
        Normal(mean=1.0, sigma=0.5, lo=0.0),
        Uniform(lo=0.5, hi=2.0),
        HalfNormal(sigma=0.05, hi=0.2),
    ],
)
def test_priors_pickle_to_the_same_distribution(prior):
    """A held-out fold's worker process gets its priors pickled (the lognormal's scipy variable holds a lambda)."""
    import pickle

    again = pickle.loads(pickle.dumps(prior))
    x = np.array([0.01, 0.1, 0.7, 1.0, 1.9])
    assert type(again) is type(prior) and again.model_dump() == prior.model_dump()
    assert again.logpdf(x) == pytest.approx(prior.logpdf(x), rel=1e-15)
    assert again.quantile([0.1, 0.5, 0.9]) == pytest.approx(prior.quantile([0.1, 0.5, 0.9]), rel=1e-12)
