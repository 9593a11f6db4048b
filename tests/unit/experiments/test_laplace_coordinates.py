"""τ-conditioned sampling coordinates (`uwlab.experiments.calibration.laplace`): on Neal's funnel, whose marginal of
the scale is known in closed form, emcee in these coordinates recovers it; the map round-trips and its Jacobian is
the numerical one; the independence move (`MarginalProposal`) recovers it alone, in a few steps per draw, and still
does where the conditional is not the Gaussian its proposal assumes."""

import emcee
import numpy as np
import pytest
from scipy import stats

from uwlab.experiments.calibration.fit import proposal_moves
from uwlab.experiments.calibration.laplace import MarginalProposal, ScaleConditioned

SIGMA_V = 1.5  # ln s ~ N(0, 1.5²): s spans a factor of 20 either way (95 %)
DIM = 4  # x_i | s ~ N(0, s²)


def funnel_log_u(u: np.ndarray) -> np.ndarray:
    """Neal's funnel in the coordinates u = (s, x_1..x_4), s > 0 linear as the fit samples τ: the lognormal density
    of s times the normal densities of the x given s."""
    s, x = u[:, 0], u[:, 1:]
    with np.errstate(divide="ignore", invalid="ignore"):
        out = stats.lognorm.logpdf(s, SIGMA_V) + stats.norm.logpdf(x, scale=s[:, None]).sum(axis=1)
    return np.where(s > 0, out, -np.inf)


def t_funnel_log_u(u: np.ndarray) -> np.ndarray:
    """The funnel with x_i | s Student-t (ν = 4, scale s): heavier-tailed than the Laplace approximation's Gaussian,
    and ln s still N(0, 1.5²) (each conditional density integrates to one whatever s)."""
    s, x = u[:, 0], u[:, 1:]
    with np.errstate(divide="ignore", invalid="ignore"):
        out = stats.lognorm.logpdf(s, SIGMA_V) + stats.t.logpdf(x, 4, scale=s[:, None]).sum(axis=1)
    return np.where(s > 0, out, -np.inf)


def funnel_coordinates(log_u=funnel_log_u) -> ScaleConditioned:
    scale_range = tuple(stats.lognorm.ppf([0.001, 0.997], SIGMA_V))
    coordinates = ScaleConditioned.around(log_u, np.array([1.0, 0.0, 0.0, 0.0, 0.0]), 0, scale_range)
    assert coordinates is not None
    return coordinates


def test_the_map_round_trips_with_its_jacobian():
    coordinates = funnel_coordinates()
    rng = np.random.default_rng(0)
    w = np.column_stack([rng.uniform(-5, 5, 50), rng.standard_normal((50, DIM))])
    u, log_jacobian = coordinates.to_u(w)
    assert np.allclose(coordinates.to_w(u), w, atol=1e-9)
    for row, expected in zip(w[:5], log_jacobian[:5], strict=True):
        h = 1e-6
        steps = np.eye(5) * h
        columns = [coordinates.to_u((row + e)[None, :])[0] - coordinates.to_u((row - e)[None, :])[0] for e in steps]
        jac = np.column_stack([c[0] / (2 * h) for c in columns])
        assert np.log(abs(np.linalg.det(jac))) == pytest.approx(expected, abs=1e-5)


def test_the_funnel_is_sampled_to_its_closed_form_marginal():
    """ln s must come out N(0, 1.5²); the neck (s ≈ 0.05) and the mouth (s ≈ 20) differ by 10⁶ in the x's volume."""
    coordinates = funnel_coordinates()
    walkers = 32
    rng = np.random.default_rng(1)
    p0 = np.column_stack([rng.normal(0, 0.5, walkers), rng.standard_normal((walkers, DIM))])
    moves = [(emcee.moves.DEMove(), 0.8), (emcee.moves.DESnookerMove(), 0.2)]
    sampler = emcee.EnsembleSampler(walkers, DIM + 1, coordinates.log_w, vectorize=True, moves=moves)
    sampler.random_state = np.random.RandomState(2).get_state()
    sampler.run_mcmc(p0, 3000)
    v = np.log(coordinates.u_of(sampler.get_chain(discard=500, flat=True))[:, 0])
    # ~ 32 × 2500 / τ(≈ 30) ≈ 2700 independent draws: the quantiles' standard errors are below 0.06
    for q in (0.05, 0.25, 0.5, 0.75, 0.95):
        assert np.quantile(v, q) == pytest.approx(stats.norm.ppf(q, scale=SIGMA_V), abs=0.2), q


def independence_chain(log_u, steps: int, alone: bool = True) -> tuple[emcee.EnsembleSampler, np.ndarray]:
    """emcee with the independence move `alone` or in the fit's mixture of moves, started from the proposal's own
    draws; (sampler, ln s of the kept draws)."""
    coordinates = funnel_coordinates(log_u)
    proposal = MarginalProposal(coordinates)
    walkers = 32
    p0 = proposal.draw(walkers, np.random.RandomState(1))
    moves = [(emcee.moves.MHMove(proposal), 1.0)] if alone else proposal_moves(proposal)
    sampler = emcee.EnsembleSampler(walkers, DIM + 1, coordinates.log_w, vectorize=True, moves=moves)
    sampler.random_state = np.random.RandomState(2).get_state()
    sampler.run_mcmc(p0, steps)
    return sampler, np.log(coordinates.u_of(sampler.get_chain(discard=20, flat=True))[:, 0])


def test_the_independence_move_alone_samples_the_funnel_in_a_few_steps_per_draw():
    """Where every conditional is Gaussian the proposal is the posterior up to the spread of z: most proposals are
    accepted and the chain decorrelates in a few steps (DE moves need about 30 here)."""
    sampler, v = independence_chain(funnel_log_u, 600)
    assert np.mean(sampler.acceptance_fraction) > 0.6
    assert np.max(sampler.get_autocorr_time(tol=0)) < 4
    # 32 × 580 / τ (< 4) > 4600 independent draws: standard errors of the quantiles below 0.04
    for q in (0.05, 0.25, 0.5, 0.75, 0.95):
        assert np.quantile(v, q) == pytest.approx(stats.norm.ppf(q, scale=SIGMA_V), abs=0.12), q


def test_the_fits_moves_stay_exact_where_the_proposals_gaussian_is_wrong():
    """Student-t conditionals: the proposal's Gaussian z misses their tails (alone, the independence move puts the
    98th percentile of |x / s| at 3.3 instead of 3.75), the fit's ensemble moves reach them, and the marginal of
    ln s and the quantiles of |x / s| (Student-t, ν = 4) come out as the closed form's."""
    coordinates = funnel_coordinates(t_funnel_log_u)
    sampler, v = independence_chain(t_funnel_log_u, 3000, alone=False)
    for q in (0.05, 0.25, 0.5, 0.75, 0.95):
        assert np.quantile(v, q) == pytest.approx(stats.norm.ppf(q, scale=SIGMA_V), abs=0.12), q
    u = coordinates.u_of(sampler.get_chain(discard=20, flat=True))
    ratio = np.abs(u[:, 1:] / u[:, :1])
    for q in (0.5, 0.9, 0.98):
        assert np.quantile(ratio, q) == pytest.approx(stats.t.ppf(0.5 + q / 2, 4), rel=0.05), q
