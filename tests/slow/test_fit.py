"""Model calibration: the forward model's rescaling is exact, fits recover the simulated truth, bad fits are named;
a fit's posterior is a standard object (`FitResult.inference_data()` is an `arviz.InferenceData` of the very samples
the fit summarises, and `posterior.nc` beside the other outputs reads back with arviz, whose summary agrees with the
fit's own table to 4 significant figures)."""

import json

import arviz
import numpy as np
import pandas as pd
import pytest

from uwlab.errors import ConfigError, UwlabError
from uwlab.experiments.calibration.coverage import interval_coverage
from uwlab.experiments.calibration.fit import FitConfig, Posterior, config_offsets, fit_points
from uwlab.experiments.calibration.forward import build_forward_model, relative_flux
from uwlab.experiments.calibration.output import write_fit
from uwlab.experiments.calibration.priors import HalfNormal, Normal, Uniform
from uwlab.experiments.calibration.simulate import simulate_campaign
from uwlab.experiments.calibration.validation import point_predictions
from uwlab.model.optics import NO_LENS, LensSetting
from uwlab.model.build import build_design
from uwlab.model.chain import on_axis_electron_rate

TRUTH = {"light_efficiency": 0.8, "attenuation_scale": 1.2, "K_dn_per_e:imx250m": 0.36, "K_dn_per_e:icx285alm": 1.05}
ONE_LENS = (LensSetting(30.0, 2.0), NO_LENS)


@pytest.fixture(scope="module")
def campaign():
    return simulate_campaign(TRUTH, seed=3)


@pytest.fixture(scope="module")
def fitted(campaign):
    """The campaign fitted with the default config (one fit for the tests that only read it)."""
    points, rigs = campaign
    return fit_points(points, rigs)


@pytest.fixture(scope="module")
def fit_dir(fitted, tmp_path_factory):
    """That fit written as `uwlab fit` writes it."""
    out = tmp_path_factory.mktemp("fit") / "fit"
    write_fit(fitted, out)
    return fitted, out


def test_forward_rescaling_equals_the_full_model(campaign):
    """Changing θ by the analytic ratios gives what the full model computes with those values in the design."""
    points, rigs = campaign
    names = (
        "light_efficiency",
        "beam_half_angle_deg",
        "attenuation_scale",
        "reflectance",
        "lens_transmittance",
        "K_dn_per_e:imx250m",
    )
    lens_points = points[points["sweep_id"] == "imx250m-30mm-F2.0"].head(1)
    model = build_forward_model(lens_points, rigs, names)
    theta = np.array([[0.7, 25.0, 2.5, 0.4, 0.6, 0.5]])
    raw = {s: dict(v) for s, v in rigs["imx250m-30mm-F2.0"].items()}
    raw["light"].update(luminous_flux_lm=raw["light"]["luminous_flux_lm"] * 0.7, beam_half_angle_deg=25.0)
    raw["water"]["attenuation_scale"] = 2.5
    raw["target"]["reflectance"] = 0.4
    raw["lens"].update(transmittance=0.6, focal_length_mm=30.0, f_number=2.0)
    rate = float(on_axis_electron_rate(build_design(raw)))
    row = lens_points.iloc[0]
    vignetting = model.nominal_rate_e_per_s[0] / float(on_axis_electron_rate(model.designs[0]))
    expected = 0.5 * 2.0 ** (16 - 12) * rate * vignetting * row["exposure_us"] * 1e-6
    assert model.predict(theta)[0, 0] == pytest.approx(expected, rel=1e-9)


def test_fit_recovers_the_simulated_truth(fitted):
    summary = fitted.summary()
    assert summary["converged"] and summary["tau_multiple"] >= 50
    for name, value in TRUTH.items():
        p = summary["parameters"][name]
        assert p["p2_5"] <= value <= p["p97_5"], name
    assert summary["parameters"]["discrepancy"]["median"] < 0.02
    assert max(p["rhat"] for p in summary["parameters"].values()) < 1.1


def test_saturated_points_are_excluded_and_all_saturated_is_an_error(campaign, fitted):
    points, rigs = campaign
    assert points["saturated"].any()
    result = fitted
    assert result.model.y.size == int((~points["saturated"]).sum())
    shown = point_predictions(result)  # the left-out points are reported, marked, not dropped
    assert int(shown["saturated"].sum()) == int(points["saturated"].sum())
    assert shown.loc[shown["saturated"], "predicted_median"].isna().all()
    with pytest.raises(UwlabError, match="no unsaturated points"):
        fit_points(points.assign(saturated=True), rigs)


def test_missing_points_and_columns(campaign):
    points, rigs = campaign
    sparse = points.sample(frac=0.5, random_state=0)
    assert fit_points(sparse, rigs).converged
    with pytest.raises(ConfigError, match="signal_dn"):
        build_forward_model(points.drop(columns=["signal_dn"]), rigs, ())
    with pytest.raises(ConfigError, match="parameters.K_dn_per_e:imx999"):
        build_forward_model(points, rigs, ("K_dn_per_e:imx999",))


def test_a_wrong_prior_is_reported(campaign):
    """A prior that excludes what the data need is not hidden: the discrepancy absorbs the misfit and the
    summary says the model does not fit."""
    points, rigs = campaign
    priors = {
        "light_efficiency": Normal(mean=2.0, sigma=0.02, lo=0.0),
        "K_dn_per_e:imx250m": Normal(mean=0.36, sigma=0.001),
        "K_dn_per_e:icx285alm": Normal(mean=1.05, sigma=0.003),
        "discrepancy": HalfNormal(sigma=0.05),
    }
    result = fit_points(points, rigs, FitConfig(priors=priors))
    notes = " ".join(result.summary()["warnings"])
    assert "poor fit" in notes
    assert result.summary()["parameters"]["discrepancy"]["median"] > 0.2


def test_relative_flux_needs_a_level_one_reference():
    points = pd.DataFrame(
        {"light_level": [1.0, 0.5], "irradiance_w_m2": [10.0, 2.5], "irradiance_position": ["target"] * 2}
    )
    assert relative_flux(points).tolist() == [1.0, 0.25]
    sweeps = pd.DataFrame(
        {
            "sweep_id": ["a", "a", "b", "b", "b", "c"],
            "light_level": [1.0, 1.0, 0.5, 0.5, 0.5, 0.5],
            "irradiance_w_m2": [9.0, 11.0, 2.4, 2.7, 2.5, 3.0],
            "irradiance_position": ["target"] * 6,
        }
    )
    assert relative_flux(sweeps).tolist() == pytest.approx([1.0, 1.0, 0.25, 0.25, 0.25, 0.30])
    with pytest.raises(ConfigError, match="light_level"):
        relative_flux(points.assign(irradiance_w_m2=[10.0, None]))


def test_relative_flux_follows_a_light_drifting_during_a_sweep():
    """A level-1 sweep whose light settles by 1 % while it runs (truth known), read with 0.1 % noise and one
    glitched reading: each point's output is the drifting truth to within the noise, not the sweep's median; a
    dimmed sweep is scaled by the level-1 reference and keeps its own drift."""
    rng = np.random.default_rng(3)
    index = np.arange(12)
    truth = 1.005 - 0.01 * index / 11  # +0.5 % → −0.5 %
    readings = 20.0 * truth * (1 + 0.001 * rng.standard_normal(12))
    readings[4] *= 1.2  # a glitch
    dimmed = 5.0 * truth[:5] * (1 + 0.001 * rng.standard_normal(5))
    points = pd.DataFrame(
        {
            "sweep_id": ["full"] * 12 + ["dim"] * 5,
            "point_index": np.concatenate([index, index[:5]]),
            "light_level": [1.0] * 12 + [0.5] * 5,
            "irradiance_w_m2": np.concatenate([readings, dimmed]),
            "irradiance_position": ["target"] * 17,
        }
    )
    flux = relative_flux(points)
    assert np.max(np.abs(flux[:12] / truth - 1)) < 0.002  # the median alone would be off by up to 0.5 %
    assert np.max(np.abs(flux[12:] / (0.25 * truth[:5]) - 1)) < 0.004


def test_sampling_coordinates_round_trip_with_the_stated_jacobian(campaign):
    """u ↔ θ round trips, and log_u − log p(θ) equals ln|det ∂θ/∂u| computed by central differences."""
    points, rigs = campaign
    names = ("light_efficiency", "beam_half_angle_deg", "attenuation_scale", "K_dn_per_e:imx250m", "discrepancy")
    priors = {n: Uniform(lo=0.001, hi=100.0) for n in names}
    post = Posterior(build_forward_model(points[~points["saturated"]], rigs, names), priors)
    assert post.anchor == 0
    theta = np.array([[0.7, 25.0, 1.6, 0.33, 0.01], [1.3, 15.0, 0.6, 0.38, 0.02]])
    u = post.to_u(theta)
    assert np.allclose(post.to_theta(u), theta, rtol=1e-12)
    assert not np.allclose(u[:, 0], np.log(theta[:, 0]))
    h = 1e-6
    for row in u:
        jac = np.column_stack(
            [(post.to_theta(row + h * e) - post.to_theta(row - h * e)) / (2 * h) for e in np.eye(len(row))]
        )
        expected = np.log(abs(np.linalg.det(jac)))
        theta_row = post.to_theta(row)[None, :]
        assert post.log_u(row[None, :])[0] - post(theta_row)[0] == pytest.approx(expected, abs=1e-6)


@pytest.mark.slow
def test_credible_intervals_cover_the_truth_over_4_seeds():
    """Simulation-based calibration on 4 seeds (3 parameters each, truths drawn from the priors): at least 8 of the
    12 95 % intervals contain their truth. benchmarks/fit_coverage.py measures the coverage itself (20 seeds:
    target 90–99 %).

    Acceptance bound: with calibrated intervals each misses with probability 0.05; the seeds are independent, but
    one seed's misses need not be (the light efficiency and the attenuation scale share a ridge). Independent
    misses, Binomial(12, 0.05), reach 5 with probability 0.0002; the worst dependence within a seed consistent with
    those margins (a seed missing 0, 1, 2 or 3 with mean 0.15) gives 0.016. A posterior whose intervals cover 50 %
    (about 3× too narrow, or off by 2 σ) fails with probability 0.81 if its misses are independent (0.94 at 40 %,
    0.33 at 68 %, i.e. 2× too narrow). Intervals too wide cannot be told from right on 12 (all inside has
    probability 0.54): the benchmark's 99 % bound over 20 seeds is the finer check."""
    result = interval_coverage(4)
    assert result.total == 12
    assert result.hits >= 8, result.misses


def test_configuration_discrepancies_are_integrated_out_exactly(campaign):
    """The closed-form marginal likelihood over each configuration's discrepancy δ_k ~ N(0, τ²) equals the
    integral ∫ Π N(y | μ (1 + δ), σ²) N(δ | 0, τ²) dδ by quadrature (up to the constant n/2 ln 2π), and the
    conditional draws of δ_k have that integrand's mean and variance."""
    points, rigs = campaign
    names = (
        "light_efficiency",
        "attenuation_scale",
        "K_dn_per_e:imx250m",
        "K_dn_per_e:icx285alm",
        "discrepancy",
        "config_discrepancy",
    )
    model = build_forward_model(points[~points["saturated"]], rigs, names)
    post = Posterior(model, {n: Uniform(lo=0.0, hi=100.0) for n in names})
    theta = np.array([[0.83, 1.1, 0.35, 1.1, 0.004, 0.02]])
    mu, tau = model.predict(theta)[0], 0.02
    sigma = model.sigma(theta, mu[None])[0]
    exact, moments = 0.0, []
    for k in range(model.n_config):
        sel = model.config == k
        r, m, s = model.y[sel], mu[sel], sigma[sel]
        centre = np.sum((r - m) * m / s**2) / (np.sum(m**2 / s**2) + 1 / tau**2)
        delta = centre + np.linspace(-0.02, 0.02, 200001)
        chi = ((r[:, None] - m[:, None] * (1 + delta)) / s[:, None]) ** 2 + np.log(2 * np.pi * s[:, None] ** 2)
        log_f = -0.5 * np.sum(chi, axis=0) - 0.5 * (delta / tau) ** 2 - 0.5 * np.log(2 * np.pi * tau**2)
        top = log_f.max()
        weight = np.exp(log_f - top)
        exact += top + np.log(np.trapezoid(weight, delta))
        mean = np.trapezoid(weight * delta, delta) / np.trapezoid(weight, delta)
        moments.append((mean, np.trapezoid(weight * (delta - mean) ** 2, delta) / np.trapezoid(weight, delta)))
    closed = post.log_likelihood(theta)[0] - 0.5 * model.y.size * np.log(2 * np.pi)
    assert closed == pytest.approx(exact, abs=1e-6)
    draws = config_offsets(model, np.repeat(theta, 40000, axis=0), np.random.default_rng(0))
    for k, (mean, var) in enumerate(moments):
        assert draws[:, k].mean() == pytest.approx(mean, abs=5 * np.sqrt(var / 40000))
        assert draws[:, k].var() == pytest.approx(var, rel=0.03)


def test_the_scale_marginal_agrees_with_importance_sampling(fitted):
    """The sampled marginal of τ (config_discrepancy) against p(τ | y) computed without a sampler: on a grid of τ
    spanning its prior from the 10⁻⁶ quantile, ∫ p(u_others, τ | y) du_others by importance sampling from a
    Student t at the conditional mode (Laplace shape, twice the covariance, 4 degrees of freedom), then the CDF by
    the trapezoid rule in ln τ. In the coordinates u the ensemble missed τ's tail while its diagnostics passed
    (the funnel; `uwlab.experiments.calibration.laplace`): this test fails for it at the median."""
    from scipy import optimize, stats

    from uwlab.experiments.calibration.laplace import laplace_covariance

    post = Posterior(fitted.model, fitted.priors)
    index = fitted.names.index("config_discrepancy")
    others = [i for i in range(len(fitted.names)) if i != index]
    u_mode = post.to_u(fitted.map_start)
    prior = fitted.priors["config_discrepancy"]
    grid = np.geomspace(prior.quantile(1e-6), prior.quantile(0.997), 40)  # below, p(τ) ∝ τ in ln τ: < 1e-6 left
    rng = np.random.default_rng(0)
    x, log_z = u_mode[others], []
    for tau in grid:

        def conditional(rows, tau=tau):
            u = np.empty((rows.shape[0], len(fitted.names)))
            u[:, others], u[:, index] = rows, tau
            return post.log_u(u)

        objective = lambda z: -conditional(z[None, :])[0]  # noqa: E731
        x = optimize.minimize(objective, x, method="Nelder-Mead", options={"maxfev": 4000}).x
        proposal = stats.multivariate_t(loc=x, shape=2 * laplace_covariance(conditional, x), df=4)
        draws = proposal.rvs(size=10000, random_state=rng)
        log_w = conditional(draws) - proposal.logpdf(draws)
        log_z.append(log_w.max() + np.log(np.mean(np.exp(log_w - log_w.max()))))
    density = np.exp(np.array(log_z) - max(log_z)) * grid  # per unit ln τ
    cdf = np.concatenate([[0.0], np.cumsum(0.5 * (density[1:] + density[:-1]) * np.diff(np.log(grid)))])
    cdf /= cdf[-1]
    sampled = fitted.samples[:, index]
    for q in (0.1, 0.5, 0.9):
        assert np.interp(np.quantile(sampled, q), grid, cdf) == pytest.approx(q, abs=0.05), q


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
