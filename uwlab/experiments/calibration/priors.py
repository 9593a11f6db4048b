"""Prior distributions for model calibration: thin wrappers of `scipy.stats` random variables, optionally truncated.

A prior is declared in a fit config as a table, e.g. ``{ kind = "lognormal", median = 1.0, sigma = 0.5 }``:

- ``normal``: mean, sigma — ``stats.Normal(mu=mean, sigma=sigma)``;
- ``lognormal``: median, sigma (of ln x) — ``stats.exp(stats.Normal(mu=ln median, sigma=sigma))``;
- ``uniform``: lo, hi — ``stats.Uniform(a=lo, b=hi)``;
- ``halfnormal``: sigma — ``stats.truncate(stats.Normal(mu=0, sigma=sigma), 0)`` (|N(0, σ²)|, support x > 0;
  ``lo``/``hi`` narrow that one truncation).

Optional ``lo``/``hi`` truncate a normal, lognormal or halfnormal prior (``stats.truncate``: the density is
renormalised on [lo, hi], 0 outside). CDFs, quantiles and draws (with the caller's generator) are scipy's. The log
density, evaluated for every walker at every step, is each kind's closed form in numpy, vectorised over walkers,
with the truncation's log mass taken once from scipy's CDF: scipy's distribution objects spend ≈ 60 µs a call
checking their arguments, which was a third of a fit's time (`tests/unit/experiments/test_fit_priors.py` holds the
closed forms to scipy's densities).

>>> p = LogNormal(median=2.0, sigma=0.5)
>>> round(p.quantile(0.5), 12), round(p.quantile(0.8413447460685429), 6)   # median, median · e^σ
(2.0, 3.297443)
>>> round(Normal(mean=0.0, sigma=1.0, lo=0.0).quantile(0.5), 9)   # the half-normal median σ · Φ⁻¹(3/4)
0.67448975
"""

from __future__ import annotations

import math
from typing import Annotated, Any, ClassVar, Literal

import numpy as np
from pydantic import Field, PrivateAttr, StrictFloat, model_validator
from scipy import stats

from uwlab.model.schema import Schema, check, invalid

Finite = Annotated[float, Field(strict=True, allow_inf_nan=False)]
Positive = Annotated[float, Field(strict=True, allow_inf_nan=False, gt=0.0)]


class Prior(Schema):
    """A prior: a scipy.stats random variable (`base`, untruncated), truncated to its kind's support (`floor`) and
    to [lo, hi] when they are given."""

    lo: StrictFloat = Field(-math.inf, description="lower truncation bound")
    hi: StrictFloat = Field(math.inf, description="upper truncation bound")
    floor: ClassVar[float] = -math.inf  # the kind's own lower truncation of its base (0 for the half-normal)
    closed: ClassVar[bool] = False  # whether the support holds its bounds (scipy's: open, but the uniform's)
    _dist: Any = PrivateAttr()  # a scipy.stats random variable (untyped)
    _bounds: tuple[float, float] = PrivateAttr()  # the support, truncations applied
    _log_mass: float = PrivateAttr()  # ln of the base's probability inside the bounds (0: not truncated)

    @model_validator(mode="after")
    def _random_variable(self):
        if not self.lo < self.hi:
            raise invalid("hi", self.hi, "must exceed lo")
        base = self.base()
        support = tuple(float(b) for b in base.support())
        self._bounds = (max(support[0], self.floor, self.lo), min(support[1], self.hi))
        if self._bounds == support:
            self._dist, self._log_mass = base, 0.0
        else:
            self._dist = stats.truncate(base, *self._bounds)
            self._log_mass = float(base.logcdf(*self._bounds).real)  # as scipy's truncation computes it
        return self

    def base(self):
        """The untruncated scipy.stats random variable."""
        raise NotImplementedError

    def _log_density(self, x: np.ndarray) -> np.ndarray:
        """The base's ln p(x) in closed form, operation for operation as scipy evaluates it (so that a fit's
        numbers do not move), for x inside its support."""
        raise NotImplementedError

    def logpdf(self, x) -> np.ndarray:
        """ln p(x), vectorised; −inf outside the (truncated) support and for NaN."""
        x = np.asarray(x, float)
        lo, hi = self._bounds
        inside = (x >= lo) & (x <= hi) if self.closed else (x > lo) & (x < hi)
        out = np.full(x.shape, -np.inf)
        out[inside] = self._log_density(x[inside]) - self._log_mass
        return out

    def cdf(self, x):
        return self._dist.cdf(np.asarray(x, float))

    def quantile(self, q):
        """The q-quantile(s) (a float for a scalar q)."""
        out = self._dist.icdf(np.asarray(q, float))
        return float(out) if np.ndim(out) == 0 else out

    def sample(self, rng: np.random.Generator, size=None):
        """Draws from the prior with `rng` (a float for size None)."""
        out = self._dist.sample(() if size is None else size, rng=rng)
        return float(out) if size is None else out


class Normal(Prior):
    kind: Literal["normal"] = "normal"
    mean: Finite = Field(description="mean")
    sigma: Positive = Field(description="standard deviation")

    def base(self):
        return stats.Normal(mu=self.mean, sigma=self.sigma)

    def _log_density(self, x: np.ndarray) -> np.ndarray:
        return _normal_log_density(x, self.mean, self.sigma)


class LogNormal(Prior):
    kind: Literal["lognormal"] = "lognormal"
    median: Positive = Field(description="median e^μ")
    sigma: Positive = Field(description="standard deviation of ln x")

    def base(self):
        return stats.exp(stats.Normal(mu=math.log(self.median), sigma=self.sigma))

    def _log_density(self, x: np.ndarray) -> np.ndarray:
        # ln p_X(ln x) + ln |d ln x / dx|, scipy's change of variables
        return _normal_log_density(np.log(x), math.log(self.median), self.sigma) + -np.log(x)


class Uniform(Prior):
    kind: Literal["uniform"] = "uniform"
    closed: ClassVar[bool] = True
    lo: Finite = Field(description="lower bound")
    hi: Finite = Field(description="upper bound")

    def base(self):
        return stats.Uniform(a=self.lo, b=self.hi)

    def _log_density(self, x: np.ndarray) -> np.ndarray:
        return np.full_like(x, -np.log(self.hi - self.lo))


class HalfNormal(Prior):
    kind: Literal["halfnormal"] = "halfnormal"
    floor: ClassVar[float] = 0.0
    sigma: Positive = Field(description="scale σ of |N(0, σ²)|")

    def base(self):
        return stats.Normal(mu=0.0, sigma=self.sigma)

    def _log_density(self, x: np.ndarray) -> np.ndarray:
        return _normal_log_density(x, 0.0, self.sigma)


_LOG_NORMALIZATION = np.log(2 * np.pi) / 2  # ln √(2π)


def _normal_log_density(x: np.ndarray, mean: float, sigma: float) -> np.ndarray:
    """ln of the normal density N(mean, sigma²) at x: −(ln √(2π) + z²/2) − ln σ, z = (x − mean)/σ."""
    return -(_LOG_NORMALIZATION + ((x - mean) / sigma) ** 2 / 2) - np.log(sigma)


PriorSpec = Annotated[Normal | LogNormal | Uniform | HalfNormal, Field(discriminator="kind")]


def parse_prior(key: str, spec) -> Prior:
    """A prior from its config table; `ConfigError` names the key (e.g. ``parameters.x.sigma``)."""
    return check(PriorSpec, spec, key)
