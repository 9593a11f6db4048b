"""Prior distributions for model calibration: thin wrappers of `scipy.stats` random variables, optionally truncated.

A prior is declared in a fit config as a table, e.g. ``{ kind = "lognormal", median = 1.0, sigma = 0.5 }``:

- ``normal``: mean, sigma — ``stats.Normal(mu=mean, sigma=sigma)``;
- ``lognormal``: median, sigma (of ln x) — ``stats.exp(stats.Normal(mu=ln median, sigma=sigma))``;
- ``uniform``: lo, hi — ``stats.Uniform(a=lo, b=hi)``;
- ``halfnormal``: sigma — ``stats.truncate(stats.Normal(mu=0, sigma=sigma), 0)`` (|N(0, σ²)|, support x > 0;
  ``lo``/``hi`` narrow that one truncation).

Optional ``lo``/``hi`` truncate a normal, lognormal or halfnormal prior (``stats.truncate``: the density is
renormalised on [lo, hi], 0 outside). CDFs, quantiles and draws (with the caller's generator) are scipy's. The log
density, evaluated for every walker at every step, is each kind's closed form in numpy (`JointPrior`: all of a fit's
priors and walkers in one pass), with the truncation's log mass taken once from scipy's CDF: scipy's distribution
objects spend ≈ 60 µs a call checking their arguments, which was a third of a fit's time, and one numpy pass per
prior another sixth (`tests/unit/experiments/test_fit_priors.py` holds the closed forms to scipy's densities).

>>> p = LogNormal(median=2.0, sigma=0.5)
>>> round(p.quantile(0.5), 12), round(p.quantile(0.8413447460685429), 6)   # median, median · e^σ
(2.0, 3.297443)
>>> round(Normal(mean=0.0, sigma=1.0, lo=0.0).quantile(0.5), 9)   # the half-normal median σ · Φ⁻¹(3/4)
0.67448975
"""

from __future__ import annotations

import math
from collections.abc import Sequence
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
    log_scale: ClassVar[bool] = False  # whether the closed form is a density of ln x (the lognormal's)
    _dist: Any = PrivateAttr()  # a scipy.stats random variable (untyped)
    _bounds: tuple[float, float] = PrivateAttr()  # the support, truncations applied
    _log_mass: float = PrivateAttr()  # ln of the base's probability inside the bounds (0: not truncated)
    _alone: JointPrior = PrivateAttr()  # this prior's log density (`logpdf`)

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
        self._alone = JointPrior([self])
        return self

    def __reduce__(self):
        """Pickled as its fields and built again (a held-out fold's worker process gets its priors so): the
        lognormal's scipy random variable holds a lambda, which does not pickle."""
        return type(self).model_validate, (self.model_dump(),)

    def base(self):
        """The untruncated scipy.stats random variable."""
        raise NotImplementedError

    def _closed_form(self) -> tuple[float, float, float | None]:
        """(mean, σ, constant): the base's ln p inside its support is the normal N(mean, σ²)'s at x (at ln x, less
        ln x, for `log_scale`), or `constant` when that is not None (`JointPrior` evaluates it)."""
        raise NotImplementedError

    def logpdf(self, x) -> np.ndarray:
        """ln p(x), vectorised; −inf outside the (truncated) support and for NaN."""
        x = np.asarray(x, float)
        return self._alone.terms(x.reshape(1, -1))[0].reshape(x.shape)

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

    def _closed_form(self) -> tuple[float, float, float | None]:
        return self.mean, self.sigma, None


class LogNormal(Prior):
    kind: Literal["lognormal"] = "lognormal"
    log_scale: ClassVar[bool] = True
    median: Positive = Field(description="median e^μ")
    sigma: Positive = Field(description="standard deviation of ln x")

    def base(self):
        return stats.exp(stats.Normal(mu=math.log(self.median), sigma=self.sigma))

    def _closed_form(self) -> tuple[float, float, float | None]:
        return math.log(self.median), self.sigma, None


class Uniform(Prior):
    kind: Literal["uniform"] = "uniform"
    closed: ClassVar[bool] = True
    lo: Finite = Field(description="lower bound")
    hi: Finite = Field(description="upper bound")

    def base(self):
        return stats.Uniform(a=self.lo, b=self.hi)

    def _closed_form(self) -> tuple[float, float, float | None]:
        return 0.0, 1.0, float(-np.log(self.hi - self.lo))


class HalfNormal(Prior):
    kind: Literal["halfnormal"] = "halfnormal"
    floor: ClassVar[float] = 0.0
    sigma: Positive = Field(description="scale σ of |N(0, σ²)|")

    def base(self):
        return stats.Normal(mu=0.0, sigma=self.sigma)

    def _closed_form(self) -> tuple[float, float, float | None]:
        return 0.0, self.sigma, None


_LOG_NORMALIZATION = np.log(2 * np.pi) / 2  # ln √(2π)


class JointPrior:
    """ln p(θ) = Σ_j ln p_j(θ_j) for independent priors p_j, every row of θ (walkers × parameters) at once.

    Each prior is a row of constants (bounds, `Prior._closed_form`, log mass), so a fit's log prior is one numpy pass
    per operation, not one per prior. Inside its support a parameter's term is scipy's evaluation, operation for
    operation (so that a fit's numbers do not move): the normal's −(ln √(2π) + z²/2) − ln σ with z = (y − mean)/σ,
    y = x, or y = ln x plus the change of variables' −ln x (the lognormal), or the uniform's constant; less the
    truncation's log mass. Outside the support, and for NaN, it is −inf.

    >>> joint = JointPrior([Normal(mean=0.0, sigma=1.0), Uniform(lo=0.0, hi=2.0)])
    >>> joint(np.array([[0.0, 1.0], [0.0, 3.0]])).round(6)   # −ln √(2π) − ln 2, and outside the uniform
    array([-1.612086,       -inf])
    """

    def __init__(self, priors: Sequence[Prior]):
        def column(values, dtype=float) -> np.ndarray:
            return np.array(values, dtype)[:, None]

        forms = [p._closed_form() for p in priors]
        self.lo = column([p._bounds[0] for p in priors])
        self.hi = column([p._bounds[1] for p in priors])
        self.closed = column([p.closed for p in priors], bool)
        self.log_scale = column([p.log_scale for p in priors], bool)
        self.mean = column([m for m, _, _ in forms])
        self.sigma = column([s for _, s, _ in forms])
        self.log_sigma = column([np.log(s) for _, s, _ in forms])
        self.constant = column([c is not None for _, _, c in forms], bool)
        self.constant_value = column([0.0 if c is None else c for _, _, c in forms])
        self.log_mass = column([p._log_mass for p in priors])
        # which of the steps below these priors need (the others are left out of every evaluation)
        self._any_log, self._any_constant = bool(self.log_scale.any()), bool(self.constant.any())
        self._all_open, self._all_closed = not self.closed.any(), bool(self.closed.all())

    def terms(self, x: np.ndarray) -> np.ndarray:
        """ln p_j(x_j) for x of shape (n_priors, n): row j holds prior j's values."""
        with np.errstate(all="ignore"):
            y = np.log(x, out=x.astype(float), where=self.log_scale) if self._any_log else x
            normal = -(_LOG_NORMALIZATION + ((y - self.mean) / self.sigma) ** 2 / 2) - self.log_sigma
            if self._any_log:  # normal + −y, the change of variables, on the lognormals' rows
                np.add(normal, -y, out=normal, where=self.log_scale)
            density = np.where(self.constant, self.constant_value, normal) if self._any_constant else normal
            if self._all_open:
                inside = (x > self.lo) & (x < self.hi)
            elif self._all_closed:
                inside = (x >= self.lo) & (x <= self.hi)
            else:
                inside = np.where(self.closed, (x >= self.lo) & (x <= self.hi), (x > self.lo) & (x < self.hi))
            return np.where(inside, density - self.log_mass, -np.inf)

    def __call__(self, theta: np.ndarray) -> np.ndarray:
        """Σ_j ln p_j(θ_j) for θ of shape (n, n_priors): the terms summed in the priors' order."""
        return np.ascontiguousarray(self.terms(np.ascontiguousarray(np.atleast_2d(theta).T))).sum(axis=0)


PriorSpec = Annotated[Normal | LogNormal | Uniform | HalfNormal, Field(discriminator="kind")]


def parse_prior(key: str, spec) -> Prior:
    """A prior from its config table; `ConfigError` names the key (e.g. ``parameters.x.sigma``)."""
    return check(PriorSpec, spec, key)
