"""Prior distributions for model calibration: thin wrappers of `scipy.stats` random variables, optionally truncated.

A prior is declared in a fit config as a table, e.g. ``{ kind = "lognormal", median = 1.0, sigma = 0.5 }``:

- ``normal``: mean, sigma — ``stats.Normal(mu=mean, sigma=sigma)``;
- ``lognormal``: median, sigma (of ln x) — ``stats.exp(stats.Normal(mu=ln median, sigma=sigma))``;
- ``uniform``: lo, hi — ``stats.Uniform(a=lo, b=hi)``;
- ``halfnormal``: sigma — ``stats.truncate(stats.Normal(mu=0, sigma=sigma), 0)`` (|N(0, σ²)|, support x > 0).

Optional ``lo``/``hi`` truncate a normal, lognormal or halfnormal prior (``stats.truncate``: the density is
renormalised on [lo, hi], 0 outside). Densities, CDFs, quantiles and draws (with the caller's generator) are
scipy's; log densities are vectorised over walkers.

>>> p = LogNormal(median=2.0, sigma=0.5)
>>> round(p.quantile(0.5), 12), round(p.quantile(0.8413447460685429), 6)   # median, median · e^σ
(2.0, 3.297443)
>>> round(Normal(mean=0.0, sigma=1.0, lo=0.0).quantile(0.5), 9)   # the half-normal median σ · Φ⁻¹(3/4)
0.67448975
"""

from __future__ import annotations

import math
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import Field, PrivateAttr, StrictFloat, model_validator
from scipy import stats

from uwlab.model.schema import Schema, check, invalid

Finite = Annotated[float, Field(strict=True, allow_inf_nan=False)]
Positive = Annotated[float, Field(strict=True, allow_inf_nan=False, gt=0.0)]


class Prior(Schema):
    """A prior: a scipy.stats random variable (`distribution`), truncated to [lo, hi] when they are given."""

    lo: StrictFloat = Field(-math.inf, description="lower truncation bound")
    hi: StrictFloat = Field(math.inf, description="upper truncation bound")
    _dist: Any = PrivateAttr()  # a scipy.stats random variable (untyped)

    @model_validator(mode="after")
    def _random_variable(self):
        if not self.lo < self.hi:
            raise invalid("hi", self.hi, "must exceed lo")
        dist = self.distribution()
        lo, hi = dist.support()
        self._dist = dist if (self.lo <= lo and self.hi >= hi) else stats.truncate(dist, self.lo, self.hi)
        return self

    def distribution(self):
        """The untruncated scipy.stats random variable."""
        raise NotImplementedError

    def logpdf(self, x) -> np.ndarray:
        """ln p(x), vectorised; −inf outside the support."""
        with np.errstate(divide="ignore", invalid="ignore"):
            out = self._dist.logpdf(np.asarray(x, float))
        return np.where(np.isnan(out), -np.inf, out)

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

    def distribution(self):
        return stats.Normal(mu=self.mean, sigma=self.sigma)


class LogNormal(Prior):
    kind: Literal["lognormal"] = "lognormal"
    median: Positive = Field(description="median e^μ")
    sigma: Positive = Field(description="standard deviation of ln x")

    def distribution(self):
        return stats.exp(stats.Normal(mu=math.log(self.median), sigma=self.sigma))


class Uniform(Prior):
    kind: Literal["uniform"] = "uniform"
    lo: Finite = Field(description="lower bound")
    hi: Finite = Field(description="upper bound")

    def distribution(self):
        return stats.Uniform(a=self.lo, b=self.hi)


class HalfNormal(Prior):
    kind: Literal["halfnormal"] = "halfnormal"
    sigma: Positive = Field(description="scale σ of |N(0, σ²)|")

    def distribution(self):
        return stats.truncate(stats.Normal(mu=0.0, sigma=self.sigma), 0.0)


PriorSpec = Annotated[Normal | LogNormal | Uniform | HalfNormal, Field(discriminator="kind")]


def parse_prior(key: str, spec) -> Prior:
    """A prior from its config table; `ConfigError` names the key (e.g. ``parameters.x.sigma``)."""
    return check(PriorSpec, spec, key)
