"""Bayesian calibration of the image-formation model with emcee.

Posterior p(θ | y) ∝ p(θ) ∏_k ∫ ∏_{i∈k} N(y_i | μ_i(θ)(1 + δ_k), σ_i(θ)²) N(δ_k | 0, τ²) dδ_k with μ from
`uwlab.experiments.calibration.forward`, σ_i² = σ²_meas,i + (δ_w μ_i)² (δ_w: the fractional discrepancy of a point
within its configuration, ``discrepancy``) and δ_k the fractional discrepancy of configuration k (a sweep's camera
and lens), drawn from N(0, τ²) with the between-configuration scale τ (``config_discrepancy``): a hierarchical
model, so that a configuration the fit has not seen is predicted with the spread the seen ones show. The δ_k are
integrated out in closed form: with r = y − μ, w = 1/σ², A_k = Σ r μ w, S_k = Σ μ² w over the points of k,
ln L_k = −½ [Σ r² w − τ² A_k² / (1 + τ² S_k) + ln(1 + τ² S_k) + Σ ln σ²] (Sherman–Morrison and the matrix determinant
lemma for the covariance diag(σ²) + τ² μ μᵀ); given θ, δ_k ~ N(m_k, v_k) with v_k = τ²/(1 + τ² S_k), m_k = v_k A_k
(`config_offsets`). Saturated points are excluded.

- Start: a short search for the maximum a posteriori point (scipy.optimize, Nelder–Mead then Powell,
  `START_EVALUATIONS`), which only has to find its basin; in τ-conditioned coordinates (below) the walkers are drawn
  from the independence proposal, otherwise from the Laplace approximation at the mode, found with the full
  budget (inverse of a finite-difference Hessian), falling back to a small ball.
- Parametrisation: the multiplicative factors (light efficiency, reflectance, lens transmittance, K) are sampled
  as u = ln θ; the attenuation scale s, the beam angle β and the discrepancies δ_w, τ as they are (in ln δ the
  flat likelihood below the measurement noise would leave a long tail). The response is ∝ ε K · S_k(s, β), where
  S_k is the nonlinear beam × water-transmission shape (`ForwardModel.shape`); with few path lengths the data fix
  ln ε + ln K + ln S_k almost exactly, a ridge that is curved in (ln ε, s) by more than its width, which stalls
  every ensemble move. So the anchor ε (or the reflectance when ε is fixed) is sampled as
  u_ε = ln ε + h(s, β), h = the points' mean of ln S_k: the ridge becomes a hyperplane in u, s and β move along
  it freely. The map u → θ stays triangular, so ln p(u) = ln p(θ) + Σ ln θ over the logged parameters.
- Funnel: the data fix each configuration's level only to within τ, so the parameters that carry the levels are
  held ever more loosely as τ grows, and an ensemble sampler in u misses the tail of τ while its diagnostics look
  fine. The walkers move in τ-conditioned coordinates instead, w = (ln τ, z) with u_others = m(ln τ) + L(ln τ) z
  from Laplace approximations of the others' conditional on a grid of τ
  (`uwlab.experiments.calibration.laplace.ScaleConditioned`); the density is exact, the coordinates only rounder.
- Sampler: emcee's ensemble sampler (Foreman-Mackey et al. 2013), ``vectorize=True``, with differential-evolution
  moves (ter Braak 2006; 80 %) and snooker moves (ter Braak & Vrugt 2008; 20 %), which mix faster than the
  stretch move (Goodman & Weare 2010) on this problem's elongated posteriors. In τ-conditioned coordinates half
  the steps are an independence Metropolis–Hastings move from the same Laplace approximations
  (`uwlab.experiments.calibration.laplace.MarginalProposal`: τ from its approximate marginal, the others from
  their conditional), which carries a walker across τ's range in one step: on the demo's campaign the
  autocorrelation times fall from 35–130 steps to 5–13, and the fits from 2,000–6,500 steps to 1,000–1,750. Where a
  conditional is far from Gaussian (the attenuation scale of `simulate_campaign`'s seed 3, flat-topped with steep
  sides) fewer of its proposals are accepted and the ensemble moves do more of the work: 7,000 steps, 12,750 before.
  The run extends itself in chunks until the chain is at least 50 integrated autocorrelation times long (τ by
  emcee's estimator, Sokal 1997) and τ has stabilised (changed by < 5 % since the last check), checked every 250
  steps on the whole chain so far (emcee's own recipe, "Saving & monitoring progress", checks every 100): a run
  stops within 250 steps of meeting both.
- Threads: a fit and a held-out fold's predictions run on one BLAS thread (`one_blas_thread`). OpenBLAS splits a
  product's sums over its threads, so their last digits depend on the thread count; the start's search turns such
  digits into another mode where the posterior is flat (a scale at zero), and the chain into other numbers. On one
  thread a fit gives the same numbers in this process as in a fold's worker (`uwlab.experiments.calibration.parallel`)
  and on any core count; the demo's fits take as long on one thread as on two (its products are small).
- Diagnostics: τ per parameter, mean acceptance fraction, split-chain R-hat (Gelman et al., Bayesian Data
  Analysis, 3rd ed., §11.4) over the walkers, posterior correlations (|ρ| > 0.9 flagged as not separable).
"""

from __future__ import annotations

from typing import Annotated, Final, Literal

import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from collections.abc import Callable, Mapping

import emcee
import numpy as np
import pandas as pd
from pydantic import ConfigDict, Field, model_validator
from scipy import optimize
from threadpoolctl import threadpool_limits

from uwlab.errors import UwlabError
from uwlab.experiments.calibration.forward import (
    BARE,
    PER_LENS,
    ForwardModel,
    build_forward_model,
    characterised_sensor,
    lens_labels,
    lens_transmittances,
)
from uwlab.model.optics import NO_LENS
from uwlab.experiments.calibration.laplace import SCALE_RANGE, MarginalProposal, ScaleConditioned, laplace_covariance
from uwlab.experiments.calibration.priors import HalfNormal, JointPrior, LogNormal, Normal, Prior, PriorSpec
from uwlab.model.data import read_toml
from uwlab.model.sensor import load_sensor_profile
from uwlab.model.schema import NonEmptyText, Schema, Seed, invalid, limits, number_or, parse

MIN_TAU_MULTIPLE = 50
MAP_EVALUATIONS = 500  # per parameter and method: the reported maximum a posteriori point
# ...and for the start of a fit in τ-conditioned coordinates, which only needs the mode's basin: Newton's steps
# find each conditional mode of the grid from it (`ScaleConditioned.around`), and the walkers start from the
# independence proposal, not from the mode
START_EVALUATIONS = 100
CORRELATED = 0.9
OVERDISPERSION = 4.0
REDRAWS_PER_HALVING = 10  # initial_walkers
LINEAR = ("attenuation_scale", "beam_half_angle_deg", "discrepancy", "config_discrepancy")
DISCREPANCIES = ("discrepancy", "config_discrepancy")
SHAPE_PARAMETERS = ("attenuation_scale", "beam_half_angle_deg")
ANCHORS = ("light_efficiency", "reflectance")
ENSEMBLE_MOVES = ((emcee.moves.DEMove, 0.8), (emcee.moves.DESnookerMove, 0.2))
INDEPENDENCE_SHARE = 0.5  # of the steps in τ-conditioned coordinates: the independence move (`MarginalProposal`)


# Sampler sizes: emcee needs at least twice as many walkers as parameters; fewer than 100 steps per chunk make
# the autocorrelation estimate meaningless; the bounds above keep a typo from allocating chains of terabytes.
Walkers = Annotated[int, limits(8, 10000, "walkers", hint="", integer=True)]
ChunkSteps = Annotated[int, limits(100, 10_000_000, "steps", hint="", integer=True)]
MaxSteps = Annotated[int, limits(1000, 100_000_000, "steps", hint="", integer=True)]
Folds = Annotated[
    Annotated[int, limits(2, 100, "folds", hint="", integer=True)] | Literal["loo"],
    number_or('must be a number of folds or "loo"'),
]
LEAVE_ONE_OUT: Final = "loo"


class Sampler(Schema):
    """A fit config's [sampler] section."""

    walkers: Walkers | None = Field(None, description="ensemble size (default: max(32, 4 × parameters))")
    chunk_steps: ChunkSteps = Field(250, description="steps between convergence checks")
    max_steps: MaxSteps = Field(60000, description="stop (unconverged) after this many steps")
    seed: Seed = Field(0, description="seed of the walkers' start and of the sampler")


class Holdout(Schema):
    """A fit config's [holdout] section."""

    train: list[NonEmptyText] = Field(
        [], description="sweeps the held-out check fits (it predicts the others); default: `folds` folds"
    )
    folds: Folds = Field(
        LEAVE_ONE_OUT,
        description='folds of the held-out check: "loo", one per sweep (each predicted from a fit of all the '
        "others), or a number of folds, the sweeps dealt out in order, each predicted from a fit of the others",
    )


class FitConfig(Schema):
    """A fit config (``configs/fit/*.toml``): [parameters.NAME] prior tables (`uwlab.experiments.calibration.
    priors`) for the free parameters, [sampler] and [holdout]."""

    model_config = ConfigDict(populate_by_name=True)

    priors: dict[str, PriorSpec] = Field(alias="parameters", min_length=1, description="free parameters and priors")
    sampler: Sampler = Field(Sampler(), description=Sampler.__doc__)
    holdout: Holdout = Field(Holdout(), description=Holdout.__doc__)

    @model_validator(mode="after")
    def _enough_walkers(self):
        walkers = self.sampler.walkers
        if walkers is not None and (walkers < 2 * len(self.priors) or walkers % 2):
            raise invalid(
                "sampler.walkers", walkers, f"must be even and >= {2 * len(self.priors)} (twice the free parameters)"
            )
        return self

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(self.priors)

    @property
    def walkers(self) -> int:
        return self.sampler.walkers or max(32, 4 * len(self.priors))


K_PROFILE_SPREAD = 0.05  # a hand-written profile's K: 5 % (data sheets and unit-to-unit spread)
K_MEASURED_FLOOR = 0.01  # a characterised K: its EMVA uncertainty, at least 1 % (the bench is not the tank)
# Lens groups (docs/validation.md, "The lens groups"): a lens's transmittance × (N_marked/N_real)² against its
# table, and a bare sensor's irradiance against the model's π⟨L⟩, each 5 % (σ of ln); the discrepancy between
# configurations that remains once they are fitted, τ ~ |N(0, 0.02²)|.
LENS_SPREAD = 0.05
BARE_SPREAD = 0.05
CONFIG_SPREAD = 0.02


def default_fit_config(
    cameras: tuple[str, ...],
    nominal_k: dict[str, float],
    k_sigma: dict[str, float] | None = None,
    lenses: dict[str, float] | None = None,
    bare: bool = False,
) -> FitConfig:
    """Light efficiency (broad), attenuation scale, each camera's K (5 % around its profile, or `k_sigma` where
    it was measured), each lens setting's transmittance (`lenses`: {label: the design's T}; `LENS_SPREAD` around
    it), the bare sensor's factor when there are bare sensors (`BARE_SPREAD` around 1), the discrepancy within a
    configuration (a few per cent) and the scale τ of what remains between configurations (`CONFIG_SPREAD`)."""
    k_sigma = k_sigma or {}
    priors = {
        "light_efficiency": LogNormal(median=1.0, sigma=0.5),
        "attenuation_scale": LogNormal(median=1.0, sigma=0.3),
        **{
            f"K_dn_per_e:{c}": Normal(mean=nominal_k[c], sigma=k_sigma.get(c, K_PROFILE_SPREAD * nominal_k[c]), lo=0.0)
            for c in cameras
        },
        **{f"{PER_LENS}:{label}": LogNormal(median=t, sigma=LENS_SPREAD) for label, t in (lenses or {}).items()},
        **({BARE: LogNormal(median=1.0, sigma=BARE_SPREAD)} if bare else {}),
        "discrepancy": HalfNormal(sigma=0.05),
        "config_discrepancy": HalfNormal(sigma=CONFIG_SPREAD),
    }
    return FitConfig(priors=priors)


def default_config_for(points, rigs: dict, base_dir: Path | None = None) -> FitConfig:
    """`default_fit_config` for the cameras and lens settings of these points: K centred on their sensor profiles,
    or for a camera characterised on the EMVA bench (its rigs' ``sensor.characterised``) on the measured K, referred
    to zero signal through the measured response curve (`ResponseCurve.zero_signal_gain`), with its uncertainty (at
    least `K_MEASURED_FLOOR`); each lens setting's transmittance centred on its design's."""
    cameras = tuple(sorted(points["sensor_profile"].astype(str).unique()))
    nominal = {c: load_sensor_profile(c, base_dir).K_dn_per_e for c in cameras}
    sigma: dict[str, float] = {}
    for sweep_id, rig in rigs.items():
        source = rig.get("sensor", {}).get("characterised")
        rows = points.loc[points["sweep_id"] == sweep_id, "sensor_profile"]
        if source and len(rows):
            camera, measured = str(rows.iloc[0]), characterised_sensor(source, base_dir)
            assert measured.response is not None  # characterised_sensor refuses a profile without one
            nominal[camera] = measured.response.zero_signal_gain(measured.K_dn_per_e)
            sigma[camera] = max(measured.K_dn_per_e_std or 0.0, K_MEASURED_FLOOR * measured.K_dn_per_e)
    bare = bool(np.any(lens_labels(points) == NO_LENS.label))
    return default_fit_config(cameras, nominal, sigma, lens_transmittances(points, rigs, base_dir), bare)


def load_fit_config(path: str | Path) -> FitConfig:
    """A fit config file, validated (`ConfigError` naming the key)."""
    return parse(FitConfig, read_toml(Path(path), "--config"))


class Posterior:
    """Vectorised log posterior over θ of shape (n_walkers, n_params); `log_u` is the same in the sampling
    coordinates u (see the module docstring): u = ln θ for the multiplicative factors, u = θ for LINEAR ones, and
    the anchor (light efficiency, else reflectance) carries the mean log shape: u_a = ln θ_a + h(θ)."""

    CHUNK = 2000  # rows per shape evaluation when mapping whole chains: (CHUNK, n_config, n_λ) floats

    def __init__(self, model: ForwardModel, priors: Mapping[str, Prior]):
        self.model = model
        self.log_prior = JointPrior([priors[name] for name in model.names])
        self.logged = np.array([name not in LINEAR for name in model.names])
        anchors = [n for n in ANCHORS if n in model.names]
        shaped = any(n in model.names for n in SHAPE_PARAMETERS)
        self.anchor = model.names.index(anchors[0]) if anchors and shaped else None

    def log_likelihood(self, theta: np.ndarray, shape: np.ndarray | None = None) -> np.ndarray:
        """ln L(θ) with the configurations' discrepancies integrated out (module docstring)."""
        theta = np.atleast_2d(theta)
        mu = self.model.predict(theta, shape)
        sigma = self.model.sigma(theta, mu)
        r = self.model.y - mu
        chi = ((r / sigma) ** 2 + 2 * np.log(sigma)).sum(axis=1)
        if "config_discrepancy" not in self.model.names:
            return -0.5 * chi
        tau2 = self.model.parameter(theta, "config_discrepancy")[:, None] ** 2
        a, s = _config_sums(self.model, r, mu, sigma)
        tau2_s = tau2 * s
        return -0.5 * (chi + (np.log1p(tau2_s) - tau2 * a**2 / (1 + tau2_s)).sum(axis=1))

    def __call__(self, theta: np.ndarray, shape: np.ndarray | None = None) -> np.ndarray:
        """ln p(θ | y) up to a constant; `shape` = `model.shape(θ)` when the caller has it already."""
        theta = np.atleast_2d(theta)
        lp = self.log_prior(theta)
        ok = np.isfinite(lp)
        if ok.all():  # the usual case: no copies of the rows
            with np.errstate(all="ignore"):
                ll = self.log_likelihood(theta, shape)
            return np.where(np.isfinite(ll), lp + ll, -np.inf)
        out = np.full(theta.shape[0], -np.inf)
        if np.any(ok):
            with np.errstate(all="ignore"):
                ll = self.log_likelihood(theta[ok], None if shape is None else shape[ok])
            out[ok] = np.where(np.isfinite(ll), lp[ok] + ll, -np.inf)
        return out

    def _from_u(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """(θ, model.shape(θ)) for rows u of shape (n, n_params); the shape only when there is an anchor. It
        depends on the LINEAR parameters alone, so it is known before the anchor is."""
        with np.errstate(all="ignore"):
            theta = np.where(self.logged, np.exp(u), u)
            if self.anchor is None:
                return theta, None
            shape = self.model.shape(theta)
            theta[:, self.anchor] = np.exp(u[:, self.anchor] - self.model.mean_log(shape))
        return theta, shape

    def to_theta(self, u: np.ndarray) -> np.ndarray:
        """θ for u of any leading shape (whole chains are mapped CHUNK rows at a time)."""
        flat = u.reshape(-1, u.shape[-1])
        theta = np.concatenate([self._from_u(flat[i : i + self.CHUNK])[0] for i in range(0, flat.shape[0], self.CHUNK)])
        return theta.reshape(u.shape)

    def to_u(self, theta: np.ndarray) -> np.ndarray:
        """u for θ of shape (n_params,) or (n, n_params)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            u = np.where(self.logged, np.log(theta), theta)
            if self.anchor is not None:
                u[..., self.anchor] += self.model.mean_log(self.model.shape(theta)).reshape(u.shape[:-1])
        return u

    def log_u(self, u: np.ndarray) -> np.ndarray:
        """ln p(u | y) in the sampling coordinates: ln p(θ | y) + Σ ln θ_j over the logged parameters (the map
        u → θ is triangular with ∂θ_j/∂u_j = θ_j for those and 1 for the others, so that is its log-Jacobian)."""
        theta, shape = self._from_u(np.atleast_2d(u))
        with np.errstate(divide="ignore", invalid="ignore"):
            out = self(theta, shape) + np.log(theta[:, self.logged]).sum(axis=1)
        return np.where(np.isnan(out), -np.inf, out)


def _config_sums(model: ForwardModel, r: np.ndarray, mu: np.ndarray, sigma: np.ndarray):
    """(A_k, S_k) per walker and configuration: Σ r μ/σ², Σ μ²/σ² over each configuration's points."""
    w = 1.0 / sigma**2
    return (r * mu * w) @ model.membership, (mu**2 * w) @ model.membership


def config_offsets(model: ForwardModel, theta: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Draws of the configurations' discrepancies δ_k given θ and the data, N(m_k, v_k) (module docstring), shape
    (n_walkers, n_config); zeros when the fit has no between-configuration scale."""
    theta = np.atleast_2d(theta)
    if "config_discrepancy" not in model.names:
        return np.zeros((theta.shape[0], model.n_config))
    mu = model.predict(theta)
    sigma = model.sigma(theta, mu)
    a, s = _config_sums(model, model.y - mu, mu, sigma)
    tau2 = model.parameter(theta, "config_discrepancy")[:, None] ** 2
    v = tau2 / (1 + tau2 * s)
    return v * a + np.sqrt(v) * rng.standard_normal(v.shape)


def find_map(
    log_density: Callable[[np.ndarray], np.ndarray], start: np.ndarray, evaluations: int = MAP_EVALUATIONS
) -> np.ndarray:
    """Maximum of a vectorised log density from `start` (Nelder–Mead, then Powell to polish), each with a budget of
    `evaluations` per parameter."""
    objective = lambda x: -float(log_density(x[None, :])[0])  # noqa: E731
    if not np.isfinite(objective(start)):
        raise UwlabError("the prior medians have zero posterior density: check the priors against the data")
    best = start
    for method in ("Nelder-Mead", "Powell"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            budget = evaluations * best.size
            result = optimize.minimize(
                objective,
                best,
                method=method,
                options={"maxfev": budget, "xatol": 1e-8, "fatol": 1e-10}
                if method == "Nelder-Mead"
                else {"maxfev": budget, "xtol": 1e-8, "ftol": 1e-12},
            )
        if np.isfinite(result.fun) and result.fun <= objective(best):
            best = result.x
    return best


def initial_walkers(log_density, mode: np.ndarray, walkers: int, rng: np.random.Generator) -> np.ndarray:
    """Over-dispersed walkers (Gelman & Rubin 1992): the Laplace approximation at the mode with its covariance
    inflated OVERDISPERSION times (a small ball where it is not positive definite). A walker outside the support is
    drawn again, from a ball halved every REDRAWS_PER_HALVING draws, until its density is finite: a mode on the
    support's edge in k coordinates at once (two discrepancy scales at zero, say) leaves a draw inside one time in
    2^k, where mirroring a whole offset never mends one with mixed signs. The burn-in discards the start.

    >>> inside = lambda p: np.where((p > 0).all(axis=1), 0.0, -np.inf)  # a density on the positive quadrant
    >>> p0 = initial_walkers(inside, np.array([1e-20, 1e-25]), 32, np.random.default_rng(0))
    >>> p0.shape, bool((p0 > 0).all())
    ((32, 2), True)
    """
    cov = laplace_covariance(log_density, mode)

    def ball(n: int, scale: float) -> np.ndarray:
        if cov is not None:
            return rng.multivariate_normal(np.zeros(mode.size), scale**2 * OVERDISPERSION * cov, size=n)
        return scale * 1e-3 * rng.standard_normal((n, mode.size))

    p0 = mode + ball(walkers, 1.0)
    for attempt in range(1, 81):
        bad = ~np.isfinite(log_density(p0))
        if not bad.any():
            return p0
        p0[bad] = mode + ball(int(bad.sum()), 0.5 ** (attempt // REDRAWS_PER_HALVING))
    raise UwlabError("could not place the walkers where the posterior is finite")


def proposal_moves(proposal: MarginalProposal) -> list[tuple[emcee.moves.Move, float]]:
    """The moves in τ-conditioned coordinates: the independence move with `INDEPENDENCE_SHARE` of the steps, and
    the ensemble moves, which reach what its Gaussian misses (heavier tails than a Laplace approximation's)."""
    moves: list[tuple[emcee.moves.Move, float]] = [(emcee.moves.MHMove(proposal), INDEPENDENCE_SHARE)]
    return moves + [(move(), (1 - INDEPENDENCE_SHARE) * share) for move, share in ENSEMBLE_MOVES]


def proposal_walkers(log_density, proposal: MarginalProposal, walkers: int, rng: np.random.Generator) -> np.ndarray:
    """Walkers drawn from the independence proposal (`MarginalProposal`), an approximation of the posterior
    itself, each redrawn until its density is finite: the chain starts near its stationary distribution."""
    random = np.random.RandomState(int(rng.integers(2**31)))
    p0 = proposal.draw(walkers, random)
    for _ in range(80):
        bad = ~np.isfinite(log_density(p0))
        if not bad.any():
            return p0
        p0[bad] = proposal.draw(int(bad.sum()), random)
    raise UwlabError("could not place the walkers where the posterior is finite")


def split_rhat(chain: np.ndarray) -> np.ndarray:
    """Split-chain potential scale reduction R̂ per parameter for a chain of shape (steps, walkers, params)."""
    n = chain.shape[0] // 2
    halves = np.concatenate([chain[:n], chain[n : 2 * n]], axis=1)
    means = halves.mean(axis=0)
    w = halves.var(axis=0, ddof=1).mean(axis=0)
    b = n * means.var(axis=0, ddof=1)
    return np.sqrt(((n - 1) / n * w + b / n) / w)


@dataclass
class FitResult:
    names: tuple[str, ...]
    samples: np.ndarray  # (n_samples, n_params), burn-in discarded and thinned (emcee's slicing), step-major
    chain: np.ndarray  # (steps, walkers, params), full
    log_prob: np.ndarray  # (n_samples,)
    map_start: np.ndarray  # where `theta_map` is sought from: the start's mode or the best sample, the higher
    tau: np.ndarray
    acceptance: float
    rhat: np.ndarray
    converged: bool
    steps: int
    model: ForwardModel = field(repr=False)
    priors: dict = field(repr=False, default_factory=dict)
    burn: int = 0  # steps discarded at the start of every walker's chain
    thin: int = 1  # every thin-th step kept after them
    saturated: pd.DataFrame | None = field(repr=False, default=None)  # points left out of the fit (saturated)

    @cached_property
    def theta_map(self) -> np.ndarray:
        """The maximum a posteriori θ (`find_map` from `map_start`), sought when first asked for: a held-out fold's
        fit never is."""
        return find_map(Posterior(self.model, self.priors), self.map_start)

    def median(self, name: str) -> float | None:
        """The posterior median of a parameter (None when the fit has no such parameter)."""
        return float(np.median(self.samples[:, self.names.index(name)])) if name in self.names else None

    def inference_data(self):
        """The posterior as an `arviz.InferenceData`: ``posterior`` with one variable per parameter over (chain =
        emcee walker, draw = kept step), the very samples of `samples`; ``sample_stats.lp``, the log posterior
        density of each; the posterior group's attributes: the chain fitted and the convergence figures. arviz is
        imported here (it loads xarray)."""
        import arviz

        # (draws, walkers, params): `samples` unflattened, as emcee's get_chain(discard=burn, thin=thin) slices
        kept = self.chain[self.burn + self.thin - 1 :: self.thin]
        draws, walkers = kept.shape[:2]
        lp = np.asarray(self.log_prob).reshape(draws, walkers).T
        posterior = {name: kept[:, :, i].T for i, name in enumerate(self.names)}
        attrs = {
            "inference_library": "emcee",
            "model": self.model.kind,
            "converged": int(self.converged),
            "steps": self.steps,
            "burn": self.burn,
            "thin": self.thin,
            "acceptance": self.acceptance,
            "max_autocorrelation_steps": float(np.max(self.tau)),
        }
        data = arviz.from_dict(posterior=posterior, sample_stats={"lp": lp})
        data.posterior.attrs.update(attrs)  # where ArviZ's own converters put inference_library
        return data

    def correlations(self) -> np.ndarray:
        return np.corrcoef(self.samples.T) if len(self.names) > 1 else np.ones((1, 1))

    def warnings(self, q: np.ndarray) -> list[str]:
        """Plain-language problems: unconverged chains, posteriors pushed into a prior's tail, a poor model fit."""
        notes = []
        if not self.converged:
            notes.append(
                f"not converged: {self.steps} steps are {self.steps / np.max(self.tau):.0f} τ (< {MIN_TAU_MULTIPLE})"
            )
        for i, name in enumerate(self.names):
            prior = self.priors[name]
            tail = float(prior.cdf(q[2, i]))
            if min(tail, 1 - tail) < 0.005 and name not in DISCREPANCIES:
                notes.append(f"prior tension: {name} posterior median {q[2, i]:.4g} lies in the outer 1 % of its prior")
        if "discrepancy" in self.names:
            delta = q[2, self.names.index("discrepancy")]
            if delta > 0.05:
                notes.append(f"poor fit: the model discrepancy is {100 * delta:.1f} % of the response")
        return notes

    def summary(self) -> dict:
        """Per-parameter median, 2.5/16/84/97.5 percentiles and τ; diagnostics; unseparable pairs."""
        q = np.percentile(self.samples, [2.5, 16, 50, 84, 97.5], axis=0)
        corr = self.correlations()
        pairs = [
            {"a": self.names[i], "b": self.names[j], "rho": float(corr[i, j])}
            for i in range(len(self.names))
            for j in range(i + 1, len(self.names))
            if abs(corr[i, j]) > CORRELATED
        ]
        return {
            "parameters": {
                name: {
                    "median": float(q[2, i]),
                    "p2_5": float(q[0, i]),
                    "p16": float(q[1, i]),
                    "p84": float(q[3, i]),
                    "p97_5": float(q[4, i]),
                    "tau": float(self.tau[i]),
                    "rhat": float(self.rhat[i]),
                    "map": float(self.theta_map[i]),
                }
                for i, name in enumerate(self.names)
            },
            "converged": self.converged,
            "acceptance_fraction": self.acceptance,
            "steps": self.steps,
            "walkers": int(self.chain.shape[1]),
            "samples": int(self.samples.shape[0]),
            "tau_multiple": float(self.steps / np.max(self.tau)),
            "not_separable": pairs,
            "warnings": self.warnings(q),
            "correlation": {"names": list(self.names), "matrix": corr.tolist()},
            "points_used": int(self.model.y.size),
        }


class _Interruptible:
    """A vectorised log-probability that lets Ctrl-C leave emcee cleanly: emcee's wrapper prints a traceback for
    anything the log-probability raises, KeyboardInterrupt included, before re-raising it. Here the interrupt is
    noted, the step finishes with every proposal rejected (−∞), and the caller raises it between steps."""

    def __init__(self, log_probability: Callable[[np.ndarray], np.ndarray]):
        self.log_probability = log_probability
        self.interrupted = False

    def __call__(self, u: np.ndarray) -> np.ndarray:
        if not self.interrupted:
            try:
                return self.log_probability(u)
            except KeyboardInterrupt:
                self.interrupted = True
        return np.full(len(u), -np.inf)


def sampling_coordinates(post: Posterior, priors: Mapping[str, Prior], u_mode: np.ndarray) -> ScaleConditioned | None:
    """The coordinates the walkers move in: for a fit with a between-configuration scale τ, τ-conditioned ones
    (`uwlab.experiments.calibration.laplace.ScaleConditioned`, which undo the funnel τ makes with the levels);
    None (the coordinates u) for a fit without one, or where they cannot be built."""
    names = post.model.names
    if "config_discrepancy" not in names or len(names) < 2:
        return None
    lo, hi = priors["config_discrepancy"].quantile(np.array(SCALE_RANGE))
    return ScaleConditioned.around(post.log_u, u_mode, names.index("config_discrepancy"), (float(lo), float(hi)))


def start_mode(post: Posterior, priors: Mapping[str, Prior]) -> np.ndarray:
    """The start's search for the mode (module docstring), in u: from the prior medians (a discrepancy's at least
    1e-3), `START_EVALUATIONS` per parameter and method."""
    medians = {n: priors[n].quantile(0.5) for n in post.model.names}
    start = np.array([medians[n] if n not in DISCREPANCIES else max(medians[n], 1e-3) for n in post.model.names])
    return find_map(post.log_u, post.to_u(start), START_EVALUATIONS)


@contextmanager
def one_blas_thread() -> Iterator[None]:
    """BLAS on one thread inside the block (or the decorated function: ``@one_blas_thread()``), its thread count
    restored after (module docstring, "Threads")."""
    with threadpool_limits(limits=1, user_api="blas"):
        yield


@one_blas_thread()
def run_fit(model: ForwardModel, config: FitConfig, progress: Callable[[int, float], None] | None = None) -> FitResult:
    """The start (module docstring), then emcee until ≥ 50 τ (or max_steps, then converged = False), on one BLAS
    thread."""
    post = Posterior(model, config.priors)
    rng = np.random.default_rng(config.sampler.seed)
    u_map = start_mode(post, config.priors)
    coordinates = sampling_coordinates(post, config.priors, u_map)
    log_density: Callable[[np.ndarray], np.ndarray]
    if coordinates is None:
        u_map = find_map(post.log_u, u_map)
        log_density, to_u = post.log_u, lambda w: w
        p0 = initial_walkers(log_density, u_map, config.walkers, rng)
        moves = [(move(), share) for move, share in ENSEMBLE_MOVES]
    else:
        log_density, to_u = coordinates.log_w, coordinates.u_of
        proposal = MarginalProposal(coordinates)
        p0 = proposal_walkers(log_density, proposal, config.walkers, rng)
        moves = proposal_moves(proposal)
    log_w = _Interruptible(log_density)
    sampler = emcee.EnsembleSampler(config.walkers, len(model.names), log_w, vectorize=True, moves=moves)
    sampler.random_state = np.random.RandomState(int(rng.integers(2**31))).get_state()
    state, old_tau, converged = p0, None, False
    while sampler.iteration < config.sampler.max_steps:
        for step in sampler.sample(state, iterations=config.sampler.chunk_steps):
            if log_w.interrupted:
                raise KeyboardInterrupt
            state = step
        tau = sampler.get_autocorr_time(tol=0)
        steady = old_tau is not None and np.all(np.abs(old_tau - tau) / tau < 0.05)
        if progress:
            progress(sampler.iteration, float(sampler.iteration / np.max(tau)))
        if np.all(np.isfinite(tau)) and sampler.iteration >= MIN_TAU_MULTIPLE * np.max(tau) and steady:
            converged = True
            break
        old_tau = tau
    tau = sampler.get_autocorr_time(tol=0)
    burn = int(2 * np.max(tau))
    thin = max(1, int(0.5 * np.min(tau)))
    chain = post.to_theta(to_u(sampler.get_chain()))
    samples = post.to_theta(to_u(sampler.get_chain(discard=burn, thin=thin, flat=True)))
    log_prob = post(samples)
    mode = post.to_theta(u_map)
    best = int(np.argmax(log_prob))
    return FitResult(
        names=model.names,
        samples=samples,
        chain=chain,
        log_prob=log_prob,
        map_start=samples[best] if log_prob[best] > post(mode[None, :])[0] else mode,
        tau=tau,
        acceptance=float(np.mean(sampler.acceptance_fraction)),
        rhat=split_rhat(chain[burn:]),
        converged=converged,
        steps=sampler.iteration,
        model=model,
        priors=config.priors,
        burn=burn,
        thin=thin,
    )


def fit_points(
    points,
    rigs: dict,
    config: FitConfig | None = None,
    base_dir: Path | None = None,
    progress=None,
    kind: str | None = None,
) -> FitResult:
    """Fit the unsaturated points of a dataset table; `config` None uses `default_fit_config`; `kind` ("paper" or
    "extended") replaces the rigs' chain."""
    used = points[~points["saturated"].astype(bool)]
    if used.empty:
        raise UwlabError("no unsaturated points to fit")
    config = config or default_config_for(used, rigs, base_dir)
    model = build_forward_model(used, rigs, config.names, base_dir, kind)
    if model.y.size <= len(config.names):
        raise UwlabError(f"{model.y.size} unsaturated points cannot constrain {len(config.names)} free parameters")
    result = run_fit(model, config, progress)
    result.saturated = points[points["saturated"].astype(bool)].reset_index(drop=True)
    return result
